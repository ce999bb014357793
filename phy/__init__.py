"""phy: the link layer. Conventions, channels, OFDM, synchronisation, digital baseline.

Imports nothing else of osnerf. See ``phy.conventions`` for power and SNR definitions.
sionna is imported lazily (only by the blocks that need it), so ``import phy`` is cheap.

* channels (``phy.CHANNELS``, ``phy.make_channel``):
  ``channel(x, snr_db, generator) -> ChannelOutput``
* links (``FlatLink``, ``OFDMLink``):
  ``link(x, snr_db, generator) -> LinkOutput(x_hat, noise_var)``;
  ``phy.models``: which link each channel runs on and what a transmitter assumes;
  ``phy.measure``: pilot measurements of a link's SNR and of its copies' fading
* OFDM (``phy.ofdm``): ``ResourceGrid``, (de)modulation, LS estimation, ZF/MMSE equalisation
* over the air (``phy.frame``, ``phy.receiver``, ``phy.sync``): ``build_frame``, ``find_frames``,
  ``receive_frame``, ``receive_frames``
* theory (``phy.theory``, ``phy.modulation``): uncoded BER/SER closed forms, Gray constellations
* ``phy.digital`` (CRC + 5G LDPC + QAM) and ``phy.raytrace`` (sionna-rt channels) are subpackages.
"""

from phy._llvm import configure_llvm, require_llvm

configure_llvm()  # before anything imports sionna.rt or mitsuba

from phy.ber import simulate_uncoded  # noqa: E402
from phy.channels import (  # noqa: E402
    AWGN,
    CHANNELS,
    Channel,
    ChannelOutput,
    RayleighFading,
    RicianFading,
    make_channel,
)
from phy.channels.tr38901 import CDLChannel, TDLChannel  # noqa: E402
from phy.conventions import (  # noqa: E402
    SNR_DB_RANGE,
    cbr,
    clip_papr,
    ebno_db_to_snr_db,
    noise_var_to_snr_db,
    num_symbols_for_cbr,
    papr_db,
    parse_cbr,
    power_normalize,
    snr_db_to_ebno_db,
    snr_db_to_noise_var,
    validate_snr_db,
)
from phy.frame import FrameConfig, build_frame  # noqa: E402
from phy.link import (  # noqa: E402
    CSI_OFDM,
    FlatLink,
    Link,
    LinkOutput,
    OFDMLink,
    combine_repetitions,
)
from phy.measure import CopyFading, measure_copy_fading, measure_snr_db, qpsk_pilots  # noqa: E402
from phy.models import (  # noqa: E402
    OFDM_CHANNELS,
    assumed_channel,
    channel_kind,
    channel_link,
    channel_record,
    receiver_description,
    symbol_model,
)
from phy.modulation import (  # noqa: E402
    MODULATIONS,
    bits_per_symbol,
    constellation,
    demap_hard,
    hard_decision,
    map_bits,
)
from phy.ofdm import (  # noqa: E402
    ResourceGrid,
    equalize,
    extract_data,
    interpolation_matrix,
    ls_channel_estimate,
    map_to_grid,
    ofdm_demodulate,
    ofdm_modulate,
    post_equalization_snr,
)
from phy.receiver import FrameResult, find_frames, receive_frame, receive_frames  # noqa: E402
from phy.theory import THEORY_CHANNELS, ber_theory, ser_theory  # noqa: E402

__all__ = [
    "SNR_DB_RANGE",
    "THEORY_CHANNELS",
    "simulate_uncoded",
    "OFDM_CHANNELS",
    "CopyFading",
    "assumed_channel",
    "channel_kind",
    "channel_record",
    "channel_link",
    "measure_copy_fading",
    "measure_snr_db",
    "qpsk_pilots",
    "receiver_description",
    "symbol_model",
    "AWGN",
    "CDLChannel",
    "CHANNELS",
    "CSI_OFDM",
    "Channel",
    "ChannelOutput",
    "FlatLink",
    "Link",
    "combine_repetitions",
    "FrameConfig",
    "FrameResult",
    "LinkOutput",
    "MODULATIONS",
    "OFDMLink",
    "RayleighFading",
    "ResourceGrid",
    "RicianFading",
    "TDLChannel",
    "ber_theory",
    "bits_per_symbol",
    "build_frame",
    "constellation",
    "demap_hard",
    "extract_data",
    "find_frames",
    "hard_decision",
    "interpolation_matrix",
    "ls_channel_estimate",
    "map_bits",
    "map_to_grid",
    "ofdm_demodulate",
    "ofdm_modulate",
    "ser_theory",
    "cbr",
    "clip_papr",
    "configure_llvm",
    "ebno_db_to_snr_db",
    "equalize",
    "make_channel",
    "noise_var_to_snr_db",
    "num_symbols_for_cbr",
    "papr_db",
    "parse_cbr",
    "post_equalization_snr",
    "power_normalize",
    "receive_frame",
    "receive_frames",
    "require_llvm",
    "snr_db_to_ebno_db",
    "snr_db_to_noise_var",
    "validate_snr_db",
]
