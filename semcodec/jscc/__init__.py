"""semcodec's own JSCC: the network, rate by truncation, the analog refinement layer, on-demand
focus, its link, and the Deep JSCC anchor."""

from semcodec.jscc.channels import TRAIN_CHANNELS, train_channel
from semcodec.jscc.codec import DEFAULT_CHECKPOINT, Codec, for_fusion, learned_only, load_codec
from semcodec.jscc.deep_jscc import make_deep_jscc
from semcodec.jscc.encoded_meta import EncodedMeta, receiver_mask
from semcodec.jscc.focus import attribution_box, demand_heatmap, demand_weight_map, densest_box
from semcodec.jscc.focus_eval import focus_gain
from semcodec.jscc.grid import (
    BLOCK_PX,
    focus_blocks,
    focus_coverage,
    focus_pixel_masks,
    full_rate_symbols,
)
from semcodec.jscc.link import REFINE_STEPS, refine_symbols, transmit_jscc
from semcodec.jscc.model import (
    JSCC_ARCHITECTURES,
    JSCCConfig,
    JSCCModel,
    features_to_symbols,
    load_checkpoint,
    make_model,
    symbols_to_features,
)

__all__ = [
    "BLOCK_PX",
    "Codec",
    "DEFAULT_CHECKPOINT",
    "EncodedMeta",
    "JSCCConfig",
    "JSCCModel",
    "JSCC_ARCHITECTURES",
    "REFINE_STEPS",
    "TRAIN_CHANNELS",
    "attribution_box",
    "demand_heatmap",
    "demand_weight_map",
    "densest_box",
    "features_to_symbols",
    "focus_blocks",
    "focus_coverage",
    "focus_gain",
    "focus_pixel_masks",
    "for_fusion",
    "full_rate_symbols",
    "learned_only",
    "load_checkpoint",
    "load_codec",
    "make_deep_jscc",
    "make_model",
    "receiver_mask",
    "refine_symbols",
    "symbols_to_features",
    "train_channel",
    "transmit_jscc",
]
