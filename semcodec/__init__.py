"""semcodec: the semantic codec (SNR- and rate-adaptive JSCC with on-demand object focus)
and the baselines it is judged against (digital, ideal, analog).

Imports only ``phy`` of osnerf.
"""

from semcodec.baselines import (
    LOST_IMAGE_VALUE,
    TransmitResult,
    refine_symbols,
    transmit_analog,
    transmit_digital,
    transmit_ideal,
    transmit_jscc,
)
from semcodec.channel_layers import TRAIN_CHANNELS
from semcodec.checkpoint import (
    KnowledgeBaseMismatch,
    load_checkpoint,
    save_checkpoint,
    weights_sha256,
)
from semcodec.codec import (
    BLOCK_PX,
    DEFAULT_CHECKPOINT,
    Codec,
    Encoded,
    EncodedMeta,
    check_images,
    load_codec,
    positions_to_mask,
    receiver_mask,
)
from semcodec.evaluation import SCHEMES
from semcodec.focus import attribution_box, demand_heatmap, demand_weight_map, select_positions
from semcodec.focus_eval import focus_gain
from semcodec.image_codecs import IMAGE_CODECS, decode_image, encode_image, encode_to_budget
from semcodec.model import (
    MODELS,
    JSCCConfig,
    JSCCModel,
    features_to_symbols,
    make_model,
    symbols_to_features,
)

__all__ = [
    "DEFAULT_CHECKPOINT",
    "IMAGE_CODECS",
    "LOST_IMAGE_VALUE",
    "SCHEMES",
    "TRAIN_CHANNELS",
    "TransmitResult",
    "decode_image",
    "encode_image",
    "encode_to_budget",
    "transmit_analog",
    "transmit_digital",
    "transmit_ideal",
    "refine_symbols",
    "transmit_jscc",
    "MODELS",
    "BLOCK_PX",
    "Codec",
    "positions_to_mask",
    "receiver_mask",
    "Encoded",
    "EncodedMeta",
    "JSCCConfig",
    "JSCCModel",
    "KnowledgeBaseMismatch",
    "attribution_box",
    "check_images",
    "focus_gain",
    "demand_heatmap",
    "demand_weight_map",
    "features_to_symbols",
    "load_checkpoint",
    "load_codec",
    "make_model",
    "save_checkpoint",
    "select_positions",
    "symbols_to_features",
    "weights_sha256",
]
