"""phy: the link layer. Conventions, channels, OFDM, synchronisation, digital baseline.

Imports nothing else of osnerf. See ``phy.conventions`` for power and SNR definitions.
sionna is imported lazily (only by the blocks that need it), so ``import phy`` is cheap.
"""

from phy._llvm import configure_llvm, require_llvm

configure_llvm()  # before anything imports sionna.rt or mitsuba

from phy.channels import (  # noqa: E402
    AWGN,
    CHANNELS,
    Channel,
    ChannelOutput,
    RayleighFading,
    RicianFading,
    make_channel,
)
from phy.conventions import (  # noqa: E402
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
from phy.link import FlatLink, LinkOutput  # noqa: E402
from phy.ofdm import equalize, post_equalization_snr  # noqa: E402

__all__ = [
    "AWGN",
    "CHANNELS",
    "Channel",
    "ChannelOutput",
    "FlatLink",
    "LinkOutput",
    "RayleighFading",
    "RicianFading",
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
    "require_llvm",
    "snr_db_to_ebno_db",
    "snr_db_to_noise_var",
    "validate_snr_db",
]
