"""Digital baseline: bytes -> CRC -> 5G LDPC -> QAM -> link -> back (all sionna.phy blocks).

``import phy.digital`` is cheap: sionna is imported on the first encode or decode.
"""

from phy.digital.bler import codeword_errors
from phy.digital.chain import (
    DEFAULT_NUM_ITER,
    DigitalResult,
    decode_symbols,
    encode_bytes,
    transmit_bytes,
)
from phy.digital.layout import (
    CRC_BITS,
    MAX_CODED_BITS,
    CodewordLayout,
    codeword_layout,
    max_codeword_bits,
    min_num_symbols,
    mother_bits,
    payload_capacity_bits,
)
from phy.digital.mcs import MCS, MCS_TABLE, MOTHER_RATE, get_mcs

__all__ = [
    "CRC_BITS",
    "DEFAULT_NUM_ITER",
    "MAX_CODED_BITS",
    "MCS",
    "MCS_TABLE",
    "MOTHER_RATE",
    "CodewordLayout",
    "DigitalResult",
    "codeword_errors",
    "codeword_layout",
    "max_codeword_bits",
    "decode_symbols",
    "encode_bytes",
    "get_mcs",
    "min_num_symbols",
    "mother_bits",
    "payload_capacity_bits",
    "transmit_bytes",
]
