"""semcodec: the semantic codec (SNR- and rate-adaptive JSCC with on-demand object focus)
and the baselines it is judged against (digital, ideal, analog).

The codec contract (:mod:`semcodec.contract`), which every codec on osnerf's links meets:

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

Subpackages (each re-exports its public names)::

    semcodec.contract   the contract, the registry CODECS (also the entry-point group
                        ``semcodec.codecs``), checkpoints, focus and fitting for any codec,
                        framed links, what every scheme returns
    semcodec.jscc       our JSCC: the network, truncation, the analog refinement layer,
                        focus, its link; the Deep JSCC anchor
    semcodec.digital    classic image codecs through CRC + 5G LDPC + QAM, the MCS choice
    semcodec.training   training any trainable codec through a channel
    semcodec.links      LINK_SCHEMES, the one table of link-level schemes, and the analog
                        baselines

The names a user needs (the contract, the registry, checkpoints, focus for any codec, the
scheme table, our codec and its training) are here at the top. Imports only ``common`` and
``phy`` of osnerf.
"""

from semcodec.contract import (
    CODECS,
    LOST_IMAGE_VALUE,
    CapabilityError,
    CodecLimits,
    CodecMeta,
    CodecPluginError,
    Encoded,
    KnowledgeBaseMismatch,
    SemanticCodec,
    TrainableCodec,
    TransmitResult,
    UntrainedCodecError,
    capability_record,
    codec_limits,
    codec_names,
    decode_received,
    encode_with_focus,
    fit_decode,
    fit_encode,
    is_trainable,
    is_trained,
    make_codec,
    open_codec,
    parse_codec_spec,
    plugin_origin,
    read_card,
    refinement_status,
    require_capabilities,
    resolve_codec_spec,
    save_checkpoint,
    symbol_budget,
    weights_sha256,
)
from semcodec.jscc import DEFAULT_CHECKPOINT, load_checkpoint, load_codec
from semcodec.links import LINK_SCHEMES, EvalContext
from semcodec.training import TrainConfig, train

__all__ = [
    "CODECS",
    "CapabilityError",
    "CodecLimits",
    "CodecMeta",
    "CodecPluginError",
    "DEFAULT_CHECKPOINT",
    "Encoded",
    "EvalContext",
    "KnowledgeBaseMismatch",
    "LINK_SCHEMES",
    "LOST_IMAGE_VALUE",
    "SemanticCodec",
    "TrainConfig",
    "TrainableCodec",
    "TransmitResult",
    "UntrainedCodecError",
    "capability_record",
    "codec_limits",
    "codec_names",
    "decode_received",
    "encode_with_focus",
    "fit_decode",
    "fit_encode",
    "is_trainable",
    "is_trained",
    "load_checkpoint",
    "load_codec",
    "make_codec",
    "open_codec",
    "parse_codec_spec",
    "plugin_origin",
    "read_card",
    "refinement_status",
    "require_capabilities",
    "resolve_codec_spec",
    "save_checkpoint",
    "symbol_budget",
    "train",
    "weights_sha256",
]
