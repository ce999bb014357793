"""The digital baselines: classic image codecs, their files through CRC + 5G LDPC + QAM, and the
MCS choice from the calibration table."""

from semcodec.digital.image_codecs import (
    IMAGE_CODECS,
    SCALES,
    decode_image,
    encode_image,
    encode_to_budget,
)
from semcodec.digital.link import transmit_digital, transmit_ideal
from semcodec.digital.timing import digital_timing

__all__ = [
    "IMAGE_CODECS",
    "SCALES",
    "decode_image",
    "digital_timing",
    "encode_image",
    "encode_to_budget",
    "transmit_digital",
    "transmit_ideal",
]
