"""phy: the link layer. Conventions, channels, OFDM, synchronisation, digital baseline.

Imports nothing else of osnerf. See ``phy.conventions`` for power and SNR definitions.
"""

from phy._llvm import configure_llvm, require_llvm

configure_llvm()  # before anything imports sionna.rt or mitsuba

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

__all__ = [
    "cbr",
    "clip_papr",
    "configure_llvm",
    "ebno_db_to_snr_db",
    "noise_var_to_snr_db",
    "num_symbols_for_cbr",
    "papr_db",
    "parse_cbr",
    "power_normalize",
    "require_llvm",
    "snr_db_to_ebno_db",
    "snr_db_to_noise_var",
    "validate_snr_db",
]
