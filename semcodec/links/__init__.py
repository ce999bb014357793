"""The link-level schemes: the one table (LINK_SCHEMES) every command reads, and the training-free
analog baselines."""

from semcodec.links.framed import (
    FramedReception,
    FramedScheme,
    FramedSettings,
    ReceivedBlock,
    frame_payload_bytes,
)
from semcodec.links.schemes import (
    ANALOG,
    DEFAULT_FIXED_MCS,
    DIGITAL,
    EVAL_MIN_SIDE_PX,
    IDEAL,
    JSCC,
    LINK_SCHEMES,
    SCHEME_KINDS,
    EvalContext,
    eval_channels,
    load_image_folder,
    schemes_help,
    ssim,
)
from semcodec.links.softcast import transmit_softcast
from semcodec.links.uncoded import transmit_analog

__all__ = [
    "ANALOG",
    "DEFAULT_FIXED_MCS",
    "DIGITAL",
    "EVAL_MIN_SIDE_PX",
    "EvalContext",
    "FramedReception",
    "FramedScheme",
    "FramedSettings",
    "IDEAL",
    "JSCC",
    "LINK_SCHEMES",
    "ReceivedBlock",
    "SCHEME_KINDS",
    "eval_channels",
    "frame_payload_bytes",
    "load_image_folder",
    "schemes_help",
    "ssim",
    "transmit_analog",
    "transmit_softcast",
]
