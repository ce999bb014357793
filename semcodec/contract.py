"""The public codec contract: what any semantic codec must offer to run on osnerf's links.

A *semantic codec* (:class:`SemanticCodec`) maps images to unit-power channel symbols and
back, with the SNR and the rate as inputs:

* ``encode(images, snr_db, cbr, mask=None, demand_weights=None) -> Encoded``:
  images ``[batch, 3, height, width]`` float32 in [0, 1]; ``snr_db`` a float or ``[batch]``
  (Es/N0 per complex symbol, dB); ``cbr`` channel symbols per real source value in
  ``cbr_range``; ``mask`` optional ``[batch, K, height, width]`` object masks in [0, 1]
  (only codecs with ``supports_focus``; see :func:`encode_with_focus` for the others).
  Returns :class:`Encoded`: ``symbols`` ``[batch, num_symbols]`` complex64 with
  mean ``|x|^2 = 1`` per image, ``meta`` the side information: any :class:`CodecMeta`
  (``height``, ``width``, ``num_symbols``, ``cbr`` (num_symbols / (3 * height * width)),
  ``codec_sha256`` and ``side_info_bits()``, bits per image), e.g. :class:`semcodec.EncodedMeta`.
* ``decode(x_hat, meta, snr_db, expected_sha256=None, noise_var=None) -> images``:
  ``x_hat`` ``[batch, num_symbols]`` complex64 *unbiased* equalised symbols (``x + e``),
  ``noise_var`` the effective variance of ``e`` (None: ``10**(-snr_db/10)``; a float,
  ``[batch]`` or ``[batch, num_symbols]``). Returns ``[batch, 3, height, width]`` float32 in
  [0, 1]. Raises :class:`semcodec.KnowledgeBaseMismatch` when ``expected_sha256`` or
  ``meta.codec_sha256`` is not its own ``sha256``.
* Attributes: ``name`` (str), ``sha256`` (hex sha256 of its architecture and weights: its
  knowledge-base identity), ``cbr_range`` and ``snr_range_db`` ((low, high) floats), and
  ``supports_focus`` (bool: ``encode`` accepts ``mask``).

A codec that the trainer can train is also a :class:`TrainableCodec`.

The contract owns the types and checks both ends of every codec share (:class:`Encoded`,
:class:`CodecMeta`, :func:`check_images`, the focus box's side-information cost
:func:`box_bits` / :func:`box_side_symbols`); it imports nothing of semcodec's own codec,
which implements it. Focus for codecs without ``supports_focus`` is
:mod:`semcodec.box_focus`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import torch
from torch import Tensor, nn

MIN_SIDE_PX = 8  # the smallest image side a codec must accept
FOCUS_FILL = 0.5  # what the receiver shows outside the focus box
SIDE_BITS_PER_SYMBOL = 0.5  # side information at QPSK with a rate-1/4 code

CODEC_MEMBERS = (
    "name",
    "sha256",
    "cbr_range",
    "snr_range_db",
    "supports_focus",
    "encode",
    "decode",
)
TRAINABLE_MEMBERS = (
    "module",
    "rate_levels",
    "architectures",
    "untrained",
    "forward_train",
    "save",
    "load_compatible",
)


@runtime_checkable
class SemanticCodec(Protocol):
    """Encoder + decoder of a semantic (JSCC) codec; see the module docstring for shapes."""

    name: str
    sha256: str
    cbr_range: tuple[float, float]
    snr_range_db: tuple[float, float]
    supports_focus: bool

    def encode(
        self, images: Tensor, snr_db, cbr: float, mask: Tensor | None = None, demand_weights=None
    ) -> Encoded: ...

    def decode(
        self,
        x_hat: Tensor,
        meta: CodecMeta,
        snr_db,
        expected_sha256: str | None = None,
        noise_var=None,
    ) -> Tensor: ...


@runtime_checkable
class TrainableCodec(SemanticCodec, Protocol):
    """A semantic codec that :func:`semcodec.training.train` can train.

    Attributes:
        module: the ``nn.Module`` holding every trained parameter (its ``state_dict`` is what
            checkpoints and resumes store).
        rate_levels: the CBRs the codec serves, ascending (the trainer draws from them).
        architectures: names accepted by :meth:`untrained` (the first is the default).
    """

    module: nn.Module
    rate_levels: tuple[float, ...]
    architectures: tuple[str, ...]

    def untrained(self, architecture: str | None = None) -> TrainableCodec:
        """A new codec of this kind with freshly initialised weights (torch's global RNG)."""
        ...

    def forward_train(
        self,
        x: Tensor,
        snr_db: Tensor,
        cbr: Tensor,
        channel: str,
        generator: torch.Generator | None,
    ) -> Tensor:
        """Differentiable encode -> power normalisation -> training channel -> decode.

        Args:
            x: [batch, 3, height, width] float32 in [0, 1] (height, width multiples of 4).
            snr_db: [batch] float32 Es/N0 per complex symbol.
            cbr: [batch] float32, each a value of ``rate_levels``.
            channel: a name of ``semcodec.TRAIN_CHANNELS``.
            generator: the channel's noise and fading draws.
        Returns:
            [batch, 3, height, width] float32 reconstruction.
        """
        ...

    def save(self, path: str | os.PathLike, card: dict) -> str:
        """Write a checkpoint that the registry's factory loads; returns (and adopts) its sha256."""
        ...

    def load_compatible(self, init: TrainableCodec) -> None:
        """Start from ``init``'s weights; ValueError naming both architectures if they do not fit."""
        ...


def missing_members(obj, members=CODEC_MEMBERS) -> list[str]:
    """The names of ``members`` that ``obj`` lacks (empty: it satisfies the protocol)."""
    return [m for m in members if not hasattr(obj, m)]


def is_trainable(codec) -> bool:
    """True when ``codec`` has every :class:`TrainableCodec` member."""
    return not missing_members(codec, CODEC_MEMBERS + TRAINABLE_MEMBERS)


def is_trained(codec) -> bool:
    """The optional member ``trained`` (bool), True when absent. A factory sets it False on
    a codec whose weights were never trained (freshly initialised: no checkpoint named and
    no default weights); commands run such a codec only when asked with
    ``--allow-untrained``, and its results say "untrained"."""
    return bool(getattr(codec, "trained", True))


@runtime_checkable
class CodecMeta(Protocol):
    """The side information a codec's ``encode`` returns and its ``decode`` reads: whatever
    the codec needs, with at least these members."""

    @property
    def height(self) -> int:
        """Original image height in pixels."""
        ...

    @property
    def width(self) -> int:
        """Original image width in pixels."""
        ...

    @property
    def num_symbols(self) -> int:
        """Complex channel symbols per image."""
        ...

    @property
    def cbr(self) -> float:
        """num_symbols / (3 * height * width)."""
        ...

    @property
    def codec_sha256(self) -> str:
        """The transmitting codec's ``sha256`` (knowledge-base identity)."""
        ...

    def side_info_bits(self) -> int:
        """Bits of side information per image."""
        ...


@dataclass(frozen=True)
class Encoded:
    """Transmitter output: ``symbols`` [batch, num_symbols] complex64 (mean |x|^2 = 1 per image)."""

    symbols: Tensor
    meta: CodecMeta


def check_images(images, name: str = "images") -> Tensor:
    """Raise ValueError unless ``images`` is [batch, 3, height, width] float in [0, 1]."""
    if not isinstance(images, Tensor):
        raise ValueError(
            f"{name} must be a float32 torch.Tensor [batch, 3, height, width], got {type(images).__name__}"
        )
    if images.dim() != 4 or images.shape[1] != 3:
        raise ValueError(
            f"{name} must be [batch, 3, height, width] (RGB), got shape {tuple(images.shape)}"
        )
    if images.shape[2] < MIN_SIDE_PX or images.shape[3] < MIN_SIDE_PX:
        raise ValueError(
            f"{name} must be at least {MIN_SIDE_PX}x{MIN_SIDE_PX} px, got {tuple(images.shape[2:])}"
        )
    if not images.is_floating_point():
        raise ValueError(f"{name} must be float32 in [0, 1], got dtype {images.dtype}")
    if not torch.isfinite(images).all() or images.min() < 0 or images.max() > 1:
        raise ValueError(f"{name} values must be finite and in [0, 1]")
    return images.float()


def box_bits(height: int, width: int) -> int:
    """Bits of a focus box's side information in a ``height x width`` image: its top, left,
    height and width in 4-pixel units (the feature grid's), each in as many bits as the
    image's size in those units needs."""
    rows, cols = -(-int(height) // 4), -(-int(width) // 4)
    return 2 * (math.ceil(math.log2(rows + 1)) + math.ceil(math.log2(cols + 1)))


def box_side_symbols(height: int, width: int) -> int:
    """Channel symbols a focus box's side information (:func:`box_bits`) costs per image,
    at :data:`SIDE_BITS_PER_SYMBOL` like the analog layer's: in focus mode it
    is charged to the view's budget."""
    return math.ceil(box_bits(height, width) / SIDE_BITS_PER_SYMBOL)
