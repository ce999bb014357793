"""semcodec: the semantic codec (SNR- and rate-adaptive JSCC with on-demand object focus)
and the baselines it is judged against (digital, ideal, analog).

The codec contract (:mod:`semcodec.contract.protocol`), which every codec on osnerf's links meets:

* ``encode(images, snr_db, cbr, mask=None, demand_weights=None) -> Encoded``: images
  ``[batch, 3, height, width]`` float32 in [0, 1], SNR (Es/N0, dB; float or ``[batch]``),
  CBR in ``cbr_range``, optional object masks ``[batch, K, height, width]`` (codecs with
  ``supports_focus``) -> ``Encoded.symbols`` ``[batch, num_symbols]`` complex64, mean
  ``|x|^2 = 1`` per image, and ``Encoded.meta`` (side information: ``height``, ``width``,
  ``num_symbols``, ``cbr``, ``codec_sha256``, ...).
* ``decode(x_hat, meta, snr_db, expected_sha256=None, noise_var=None) -> images``: unbiased
  equalised symbols ``[batch, num_symbols]`` complex64 and their effective noise variance
  (float, ``[batch]`` or ``[batch, num_symbols]``) -> ``[batch, 3, height, width]`` float32;
  ``KnowledgeBaseMismatch`` when the transmitter's hash is not the receiver's.
* ``name``, ``sha256`` (architecture + weights: the knowledge-base identity),
  ``cbr_range``, ``snr_range_db``, ``supports_focus``.

``SemanticCodec`` is the runtime-checkable protocol; ``TrainableCodec`` adds what the trainer
needs, and ``train_channel`` applies a training channel to its symbols (returning what
``decode`` receives). Optional capabilities a codec declares (``decode_differentiable``,
``input_size``, ``input_multiple``, ``symbol_multiple``) are read by ``codec_limits``;
commands check them up front (``require_capabilities``) and tile or pad for a codec with a
declared input size (``fit_encode`` / ``fit_decode``); ``symbol_budget`` is what a ``cbr``
asks for, reported against what was sent.
Codecs register in ``CODECS`` (name -> factory(checkpoint or None)), also from the
entry-point group ``semcodec.codecs``; ``make_codec("NAME[:CHECKPOINT]")`` builds one, ``open_codec`` also takes a bare checkpoint path.
``encode_with_focus`` / ``decode_received`` serve a focus demand with any codec (a codec
without ``supports_focus`` sends the objects' box at the same symbol budget,
``focus_by_box`` / ``decode_box``).
``LINK_SCHEMES`` is the one table of link-level schemes; those that cross a framed link
(two radios) carry their transmitter and receiver apart (``LinkScheme.framed``,
:mod:`semcodec.contract.framed`).

Imports only ``phy`` of osnerf.
"""

from semcodec.contract.box_focus import (
    BoxMeta,
    decode_box,
    decode_received,
    encode_with_focus,
    focus_by_box,
    mask_box,
)
from semcodec.contract.checkpoint import (
    KnowledgeBaseMismatch,
    load_checkpoint,
    read_card,
    save_checkpoint,
    weights_sha256,
)
from semcodec.contract.fitting import TiledMeta, fit_decode, fit_encode
from semcodec.contract.framed import (
    FramedReception,
    FramedScheme,
    FramedSettings,
    ReceivedBlock,
    frame_payload_bytes,
)
from semcodec.contract.protocol import (
    CapabilityError,
    CodecLimits,
    CodecMeta,
    DifferentiableDecoder,
    Encoded,
    SemanticCodec,
    TrainableCodec,
    box_bits,
    box_side_symbols,
    capability_record,
    check_images,
    codec_limits,
    is_trainable,
    is_trained,
    refinement_status,
    require_capabilities,
    snr_per_image,
    symbol_budget,
)
from semcodec.contract.registry import (
    CODECS,
    CodecPluginError,
    UntrainedCodecError,
    codec_names,
    make_codec,
    open_codec,
    parse_codec_spec,
    plugin_origin,
    resolve_codec_spec,
)
from semcodec.contract.transmit import LOST_IMAGE_VALUE, TransmitResult
from semcodec.digital.image_codecs import (
    IMAGE_CODECS,
    SCALES,
    decode_image,
    encode_image,
    encode_to_budget,
)
from semcodec.digital.link import transmit_digital, transmit_ideal
from semcodec.digital.timing import digital_timing
from semcodec.evaluation import (
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
    ms_ssim,
    schemes_help,
    ssim,
)
from semcodec.jscc.codec import DEFAULT_CHECKPOINT, Codec, for_fusion, learned_only, load_codec
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
    make_model,
    symbols_to_features,
)
from semcodec.softcast import transmit_softcast
from semcodec.training.channels import TRAIN_CHANNELS, train_channel
from semcodec.training.config import TrainConfig
from semcodec.training.loop import build_codec, train, train_inputs, validate, with_architecture
from semcodec.training.state import (
    RESUMABLE_FIELDS,
    ResumeRefused,
    check_resume,
    describe_changes,
    load_train_state,
)
from semcodec.uncoded import transmit_analog

__all__ = [
    "ANALOG",
    "DEFAULT_FIXED_MCS",
    "DIGITAL",
    "EVAL_MIN_SIDE_PX",
    "IDEAL",
    "JSCC",
    "SCHEME_KINDS",
    "EvalContext",
    "eval_channels",
    "load_image_folder",
    "schemes_help",
    "ssim",
    "ms_ssim",
    "SCALES",
    "REFINE_STEPS",
    "TrainConfig",
    "load_train_state",
    "RESUMABLE_FIELDS",
    "ResumeRefused",
    "check_resume",
    "describe_changes",
    "build_codec",
    "train",
    "with_architecture",
    "train_inputs",
    "validate",
    "BoxMeta",
    "CODECS",
    "CodecMeta",
    "CodecPluginError",
    "SemanticCodec",
    "TrainableCodec",
    "codec_names",
    "decode_box",
    "decode_received",
    "encode_with_focus",
    "focus_by_box",
    "is_trainable",
    "is_trained",
    "plugin_origin",
    "read_card",
    "resolve_codec_spec",
    "UntrainedCodecError",
    "for_fusion",
    "learned_only",
    "make_codec",
    "open_codec",
    "mask_box",
    "parse_codec_spec",
    "DEFAULT_CHECKPOINT",
    "IMAGE_CODECS",
    "LOST_IMAGE_VALUE",
    "LINK_SCHEMES",
    "FramedReception",
    "FramedScheme",
    "FramedSettings",
    "ReceivedBlock",
    "frame_payload_bytes",
    "TRAIN_CHANNELS",
    "train_channel",
    "CapabilityError",
    "CodecLimits",
    "DifferentiableDecoder",
    "capability_record",
    "codec_limits",
    "refinement_status",
    "require_capabilities",
    "snr_per_image",
    "symbol_budget",
    "TiledMeta",
    "fit_decode",
    "fit_encode",
    "TransmitResult",
    "decode_image",
    "encode_image",
    "encode_to_budget",
    "transmit_analog",
    "transmit_softcast",
    "digital_timing",
    "transmit_digital",
    "transmit_ideal",
    "refine_symbols",
    "transmit_jscc",
    "JSCC_ARCHITECTURES",
    "BLOCK_PX",
    "Codec",
    "focus_blocks",
    "focus_coverage",
    "focus_pixel_masks",
    "full_rate_symbols",
    "receiver_mask",
    "Encoded",
    "EncodedMeta",
    "JSCCConfig",
    "JSCCModel",
    "KnowledgeBaseMismatch",
    "attribution_box",
    "box_bits",
    "box_side_symbols",
    "check_images",
    "focus_gain",
    "demand_heatmap",
    "demand_weight_map",
    "densest_box",
    "features_to_symbols",
    "load_checkpoint",
    "load_codec",
    "make_model",
    "save_checkpoint",
    "symbols_to_features",
    "weights_sha256",
]
