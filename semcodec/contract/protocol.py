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
  ``codec_sha256`` and ``side_info_bits()``, bits per image),
  e.g. :class:`semcodec.jscc.EncodedMeta`.
* ``decode(x_hat, meta, snr_db, expected_sha256=None, noise_var=None) -> images``:
  ``x_hat`` ``[batch, num_symbols]`` complex64 *unbiased* equalised symbols (``x + e``),
  ``noise_var`` the effective variance of ``e`` (None: ``10**(-snr_db/10)``; a float,
  ``[batch]`` or ``[batch, num_symbols]``). Returns ``[batch, 3, height, width]`` float32 in
  [0, 1]. Raises :class:`semcodec.KnowledgeBaseMismatch` when ``expected_sha256`` or
  ``meta.codec_sha256`` is not its own ``sha256``.
* Attributes: ``name`` (str), ``sha256`` (hex sha256 of its architecture and weights: its
  knowledge-base identity), ``cbr_range`` and ``snr_range_db`` ((low, high) floats), and
  ``supports_focus`` (bool: ``encode`` accepts ``mask``).

Optional capabilities, each declared by the codec itself (absent: not offered), read and
checked by :func:`codec_limits`:

* ``decode_differentiable(x_hat, meta, snr_db, noise_var=None) -> images``
  (:class:`DifferentiableDecoder`): ``decode`` with autograd on and without the hash checks;
  ``snr_db`` ``[batch]`` float32 (:func:`snr_per_image`). Transmitter-side refinement
  (``jscc_refined``, ``osnerf run --refine-steps``) needs it; a codec without it is sent as
  encoded, and a command asked for refinement by name refuses it in one line.
* ``input_size``: ``(height, width)`` in pixels: ``encode`` takes only this size. The
  commands tile every image into such tiles (edge-padded), encode each tile, and send the
  tiles' symbols one after another (:func:`semcodec.fit_encode`).
* ``input_multiple``: int >= 1: ``encode`` takes sides that are multiples of it; the
  commands edge-pad and the receiver crops.
* ``symbol_multiple``: int >= 1: ``num_symbols`` of every image is a multiple of it (the
  codec's rate granularity).

**Budget.** ``cbr`` asks for ``round(cbr * 3 * height * width)`` symbols per image (at least
one): the image's *symbol budget*. A codec may send fewer (its rate granularity, padding, a
rate above its range), never more, except at the smallest rate of its ``cbr_range``.
``meta.num_symbols`` is what it sent; the link carries exactly that and every command
reports the symbols sent against the budget (:func:`symbol_budget`): unused budget is
stated, never silent.

A codec that the trainer can train is also a :class:`TrainableCodec`; its
``forward_train`` sends its symbols through :func:`semcodec.training.train_channel`, which returns
what ``decode`` receives at inference.

The contract owns the types and checks both ends of every codec share (:class:`Encoded`,
:class:`CodecMeta`, :func:`check_images`, the focus box's side-information cost
:func:`box_bits` / :func:`box_side_symbols`); it imports nothing of semcodec's own codec,
which implements it. Focus for codecs without ``supports_focus`` is
:mod:`semcodec.contract.box_focus`.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

import torch
from torch import Tensor, nn

from phy import validate_snr_db

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
    """A semantic codec that :func:`semcodec.training.loop.train` can train.

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
            channel: a name of ``semcodec.training.TRAIN_CHANNELS``; apply it to the symbols with
                ``semcodec.training.train_channel(symbols, snr_db, channel, generator)``, which
                returns ``decode``'s inputs (unbiased estimates, noise variance).
            generator: the channel's noise and fading draws.
        Returns:
            [batch, 3, height, width] float32 reconstruction.
        """
        ...

    def save(self, path: str | os.PathLike, card: dict) -> str:
        """Write a checkpoint that the registry's factory loads; returns (and adopts) its sha256."""
        ...

    def load_compatible(self, init: TrainableCodec) -> None:
        """Start from ``init``'s weights; ValueError naming both architectures if they do not
        fit."""
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
            f"{name} must be a float32 torch.Tensor [batch, 3, height, width], got "
            f"{type(images).__name__}"
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


@runtime_checkable
class DifferentiableDecoder(Protocol):
    """Optional capability of a :class:`SemanticCodec`: a decoder the transmitter can
    differentiate through (refinement of its symbols for the image it holds)."""

    def decode_differentiable(
        self, x_hat: Tensor, meta: CodecMeta, snr_db: Tensor, noise_var=None
    ) -> Tensor:
        """``decode`` with autograd on and without its checks (the receiver as the
        transmitter simulates it).

        Args:
            x_hat: [batch, num_symbols] complex64 unbiased equalised symbols.
            meta: the codec's own meta from its ``encode`` (never a wrapper of ours).
            snr_db: [batch] float32 Es/N0 per complex symbol (:func:`snr_per_image`).
            noise_var: as for ``decode``.
        Returns:
            [batch, 3, height, width] float32, differentiable in ``x_hat``.
        """
        ...


class CapabilityError(ValueError):
    """A command was asked for what its codec does not declare (one line, bad input)."""


@dataclass(frozen=True)
class CodecLimits:
    """What a codec declares beyond the required members (:func:`codec_limits`).

    Attributes:
        name: the codec's name.
        differentiable_decode: it has ``decode_differentiable`` (refinement possible).
        input_size: (height, width) px ``encode`` takes, or None (any size).
        input_multiple: ``encode``'s sides are multiples of this (1: any).
        symbol_multiple: ``num_symbols`` is a multiple of this (1: any).
    """

    name: str
    differentiable_decode: bool = False
    input_size: tuple[int, int] | None = None
    input_multiple: int = 1
    symbol_multiple: int = 1

    @property
    def any_size(self) -> bool:
        """``encode`` takes every image as it is (no tiling or padding)."""
        return self.input_size is None and self.input_multiple == 1

    def lacks(self) -> list[str]:
        """What the codec lacks or limits, in words (empty: nothing)."""
        out = []
        if not self.differentiable_decode:
            out.append("no differentiable decode (decode_differentiable): refinement off")
        if self.input_size is not None:
            h, w = self.input_size
            out.append(f"fixed input {h}x{w} px: images tiled and edge-padded")
        elif self.input_multiple > 1:
            out.append(f"input sides multiples of {self.input_multiple} px: images edge-padded")
        if self.symbol_multiple > 1:
            out.append(f"symbols in multiples of {self.symbol_multiple}")
        return out

    def line(self) -> str:
        """One line for stderr: what the codec lacks ('' when nothing)."""
        lacks = self.lacks()
        return f"codec {self.name!r}: " + "; ".join(lacks) if lacks else ""

    def as_dict(self) -> dict:
        """JSON-able, for result files."""
        return {
            "differentiable_decode": self.differentiable_decode,
            "input_size": None if self.input_size is None else list(self.input_size),
            "input_multiple": self.input_multiple,
            "symbol_multiple": self.symbol_multiple,
            "lacks": self.lacks(),
        }


def _positive_int(codec, attr: str, value, low: int) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < low:
        raise CapabilityError(
            f"codec {getattr(codec, 'name', '?')!r} declares {attr}={value!r}; "
            f"it must be an integer >= {low}"
        )
    return value


def codec_limits(codec) -> CodecLimits:
    """Read and check a codec's optional declarations (module docstring).

    Raises:
        CapabilityError: a declaration is malformed (one line naming the attribute).
    """
    size = getattr(codec, "input_size", None)
    if size is not None:
        ok = isinstance(size, (tuple, list)) and len(size) == 2
        ok = ok and all(isinstance(v, int) and not isinstance(v, bool) for v in size)
        if not ok or min(size) < MIN_SIDE_PX:
            raise CapabilityError(
                f"codec {getattr(codec, 'name', '?')!r} declares input_size={size!r}; it must be "
                f"None or (height, width), integers >= {MIN_SIDE_PX}"
            )
        size = (int(size[0]), int(size[1]))
    return CodecLimits(
        name=str(codec.name),
        differentiable_decode=callable(getattr(codec, "decode_differentiable", None)),
        input_size=size,
        input_multiple=_positive_int(
            codec, "input_multiple", getattr(codec, "input_multiple", 1), 1
        ),
        symbol_multiple=_positive_int(
            codec, "symbol_multiple", getattr(codec, "symbol_multiple", 1), 1
        ),
    )


def require_capabilities(codec, refine: bool = False, asked_by: str = "") -> CodecLimits:
    """A command's check before any work: the codec's :class:`CodecLimits`, or a one-line
    :class:`CapabilityError` when ``refine`` was asked for (``asked_by`` names the flag) and
    the codec has no differentiable decode."""
    limits = codec_limits(codec)
    if refine and not limits.differentiable_decode:
        raise CapabilityError(
            f"{asked_by or 'refinement'} needs a differentiable decode; codec "
            f"{limits.name!r} declares none (no decode_differentiable)"
        )
    return limits


def refinement_status(codec, steps: int) -> dict:
    """What a command did about refinement for ``codec`` with ``steps`` asked for:
    ``{"on": bool, "steps": int, "why": str}`` for the report."""
    steps = int(steps)
    if steps <= 0:
        return {"on": False, "steps": 0, "why": "refinement steps set to 0"}
    if not codec_limits(codec).differentiable_decode:
        why = f"codec {codec.name!r} has no differentiable decode (decode_differentiable)"
        return {"on": False, "steps": 0, "why": why}
    return {"on": True, "steps": steps, "why": f"{steps} Adam steps per image"}


def capability_record(codec, refine_steps: int | None = None) -> dict:
    """A result file's record of the codec's declarations (``limits``) and, where the command
    could refine (``refine_steps`` not None), whether it did (``refinement``)."""
    out = {"limits": codec_limits(codec).as_dict()}
    if refine_steps is not None:
        out["refinement"] = refinement_status(codec, refine_steps)
    return out


def symbol_budget(cbr: float, height: int, width: int) -> int:
    """Complex symbols per image that ``cbr`` asks for: ``round(cbr * 3 * height * width)``,
    at least 1 (the budget a codec may not exceed; module docstring)."""
    return max(int(round(float(cbr) * 3 * int(height) * int(width))), 1)


def snr_per_image(snr_db, batch: int) -> Tensor:
    """``snr_db`` (float or [batch]) as [batch] float32 dB; ValueError for another count or a
    value outside ``phy``'s SNR range."""
    validate_snr_db(snr_db)
    s = torch.as_tensor(snr_db, dtype=torch.float32).flatten()
    if s.numel() not in (1, batch):
        raise ValueError(f"snr_db must be a float or have {batch} (batch) values, got {s.numel()}")
    return s.expand(batch) if s.numel() == 1 else s
