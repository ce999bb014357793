"""Analog refinement layer: the JSCC base's residual sent as SoftCast-style linear symbols.

A learned JSCC's quality saturates with rate (its decoder has a ceiling: past a base rate
more symbols add little to its reconstruction). Hybrid digital-analog
transmission spends the symbols above a base rate on the residual instead: the transmitter,
which holds the decoder (the shared knowledge base), decodes its own noiseless base symbols
at the nominal SNR, and sends ``residual = image - that decode`` uncoded, as SoftCast does
for whole frames (Jakubczak and Katabi, MobiCom 2011):

* an orthonormal colour transform and a full-frame orthonormal 2-D DCT per colour plane;
* each plane's coefficients split into ``G x G`` frequency chunks with mean energies
  ``lambda_k``, coded in ``VAR_BITS`` bits each as half-octave steps below the image's
  strongest chunk (whose code takes 16 bits);
* the largest-energy chunks, in decreasing order, fill the layer's real dimensions (two per
  complex symbol); chunk ``k`` is scaled by ``g_k ~ lambda_k**(-1/4)`` (the power allocation
  minimising the linear MSE), all gains by one factor giving unit mean symbol power;
* the side information is what the receiver needs to rebuild that plan: the sent chunks'
  energies and which chunks they are, in the cheapest of three formats (every chunk's
  energy; a bitmap of the sent chunks and their energies; a list of (index, energy) pairs,
  usually far the cheapest: a small box's layer touches two or three of its 48 chunks),
  plus one 16-bit power scale per image (:func:`side_info_bits`,
  :meth:`AnalogSide.sent_chunks`, :meth:`AnalogSide.from_sent_chunks`);
* the receiver's estimate is the per-coefficient LMMSE ``g lambda / (g**2 lambda + nv/2)
  * y`` from the unbiased symbol estimates and their effective noise variance (the codec's
  equaliser convention), then the inverse transforms.

Everything is linear in the symbols and written in torch, so transmitter-side refinement
(``semcodec.jscc.link.refine_symbols``) differentiates through the layer as through the
decoder. The side information is charged to the layer's own budget at ``SIDE_BITS_PER_SYMBOL``
bits per channel symbol (a robust QPSK rate-1/4 code), so the layer's CBR is what crosses
the channel.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import torch
from torch import Tensor

from semcodec.contract.protocol import SIDE_BITS_PER_SYMBOL

VAR_BITS = 6  # bits per chunk energy: 64 half-octave steps below the strongest chunk
REFERENCE_BITS = 16  # the strongest chunk's code
POWER_SCALE_BITS = 16  # one float16 power scale per image
FORMAT_BITS = 2  # which of the three formats the chunk energies are sent in
_LOG2_STEP = 0.5  # quantisation step of log2(chunk energy)
_LOG2_MIN = -60.0  # energies below 2**-60 (all-zero chunks) are coded as 2**-60

# orthonormal colour transform: luminance-like sum and two colour differences
_COLOUR = torch.tensor(
    [
        [1 / math.sqrt(3), 1 / math.sqrt(3), 1 / math.sqrt(3)],
        [1 / math.sqrt(2), -1 / math.sqrt(2), 0.0],
        [1 / math.sqrt(6), 1 / math.sqrt(6), -2 / math.sqrt(6)],
    ]
)


def chunk_grid(height: int, width: int) -> int:
    """Chunks per axis of each colour plane's DCT: 4 for images up to ~200 px, up to 16
    for multi-megapixel ones (more chunks adapt the power better; each costs side bits)."""
    return int(min(16, max(4, math.isqrt(height * width) // 40)))


@lru_cache(maxsize=64)
def _smallest_chunks_cumsum(height: int, width: int) -> Tensor:
    """[3 G^2] cumulative coefficient counts of the chunks, smallest first."""
    k = 3 * chunk_grid(height, width) ** 2
    sizes = torch.bincount(chunk_index(height, width, chunk_grid(height, width)), minlength=k)
    return torch.cumsum(torch.sort(sizes).values, 0)


def max_sent_chunks(height: int, width: int, num_symbols: int) -> int:
    """Most chunks a layer of ``num_symbols`` complex symbols can touch (whole chunks in
    turn, the last one in part): as many as the smallest chunks that hold its reals."""
    cum = _smallest_chunks_cumsum(height, width)
    return min(int(torch.searchsorted(cum, 2 * int(num_symbols))) + 1, cum.numel())


def side_info_bits(height: int, width: int, num_symbols: int) -> int:
    """Bits of side information for a layer of ``num_symbols`` over a ``height x width``
    region, for the worst case of which chunks are sent: the cheapest of every chunk's
    energy code, a bitmap of the sent chunks with their codes, or (index, code) pairs."""
    k_all = 3 * chunk_grid(height, width) ** 2
    k = max_sent_chunks(height, width, num_symbols)
    index_bits = math.ceil(math.log2(k_all))
    energies = min(k_all * VAR_BITS, k_all + k * VAR_BITS, k * (index_bits + VAR_BITS))
    return FORMAT_BITS + REFERENCE_BITS + POWER_SCALE_BITS + energies


def side_symbols(height: int, width: int, num_symbols: int) -> int:
    """Channel symbols the side information of a layer of ``num_symbols`` costs per image."""
    return math.ceil(side_info_bits(height, width, num_symbols) / SIDE_BITS_PER_SYMBOL)


def layer_symbols(height: int, width: int, available: int) -> int:
    """The most layer symbols ``n`` (at most one per two coefficients) whose side
    information fits beside them in ``available`` symbols; 0 when none does."""
    lo, hi = 0, min(int(available), 3 * height * width // 2)
    while lo < hi:  # n + side_symbols(n) is increasing in n
        mid = (lo + hi + 1) // 2
        if mid + side_symbols(height, width, mid) <= available:
            lo = mid
        else:
            hi = mid - 1
    return lo


@lru_cache(maxsize=16)
def _dct_matrix(n: int) -> Tensor:
    """[n, n] orthonormal DCT-II matrix D (coefficients = D @ signal)."""
    k = torch.arange(n, dtype=torch.float64)[:, None]
    i = torch.arange(n, dtype=torch.float64)[None, :]
    d = torch.cos(math.pi * (2 * i + 1) * k / (2 * n)) * math.sqrt(2.0 / n)
    d[0] /= math.sqrt(2.0)
    return d.float()


@lru_cache(maxsize=16)
def chunk_index(height: int, width: int, grid: int) -> Tensor:
    """[3 * height * width] int64: chunk of each coefficient (plane-major, row-major)."""
    rows = torch.div(torch.arange(height) * grid, height, rounding_mode="floor")
    cols = torch.div(torch.arange(width) * grid, width, rounding_mode="floor")
    plane = rows[:, None] * grid + cols[None, :]  # [h, w]
    return torch.cat([plane.flatten() + p * grid * grid for p in range(3)])


def transform(res: Tensor) -> Tensor:
    """[b, 3, h, w] residual -> [b, 3*h*w] DCT coefficients of the colour-transformed planes."""
    b, _, h, w = res.shape
    c = torch.einsum("ij,bjhw->bihw", _COLOUR, res)
    coef = _dct_matrix(h) @ c @ _dct_matrix(w).T
    return coef.reshape(b, -1)


def inverse_transform(coef: Tensor, h: int, w: int) -> Tensor:
    """Inverse of :func:`transform`."""
    c = _dct_matrix(h).T @ coef.reshape(-1, 3, h, w) @ _dct_matrix(w)
    return torch.einsum("ji,bjhw->bihw", _COLOUR, c)


@dataclass(frozen=True)
class AnalogSide:
    """The layer's side information for a batch of images of one size.

    Attributes:
        height, width: size of the region the residual covers (pixels).
        num_symbols: complex symbols of the layer per image (side information excluded).
        codes: [batch, 3 * G * G] int16 chunk energies as multiples of half an octave
            (``2**(code / 2)``), each within ``2**VAR_BITS - 1`` of the image's largest.
        power_scale: [batch] float16 common gain factor (unit mean symbol power).
    """

    height: int
    width: int
    num_symbols: int
    codes: Tensor = field(compare=False)
    power_scale: Tensor = field(compare=False)

    def side_info_bits(self) -> int:
        """Bits of side information per image (:func:`side_info_bits`)."""
        return side_info_bits(self.height, self.width, self.num_symbols)

    def sent_chunks(self) -> tuple[Tensor, Tensor]:
        """What crosses the channel of the chunk energies: ([b, k] chunk indices in sending
        order, [b, k] their codes), k = :func:`max_sent_chunks` (entries past an image's
        last sent chunk repeat the next-ranked chunks and are not needed)."""
        k = max_sent_chunks(self.height, self.width, self.num_symbols)
        rank = torch.argsort(-self.codes.float(), dim=1, stable=True)[:, :k]
        return rank, torch.gather(self.codes, 1, rank)

    @classmethod
    def from_sent_chunks(
        cls,
        height: int,
        width: int,
        num_symbols: int,
        index: Tensor,
        codes: Tensor,
        power_scale: Tensor,
    ) -> AnalogSide:
        """The receiver's side information from :meth:`sent_chunks`: the chunks not listed
        rank below every listed one, so the plan (order, priors, gains) is the sender's."""
        k_all = 3 * chunk_grid(height, width) ** 2
        floor = codes.min(dim=1, keepdim=True).values.to(torch.int32) - 1
        full = floor.expand(codes.shape[0], k_all).clone()
        full.scatter_(1, index, codes.to(torch.int32))
        return cls(height, width, num_symbols, full.to(torch.int16), power_scale)

    def sent_coefficients(self) -> tuple[Tensor, Tensor, Tensor]:
        """(coefficient order [b, 2n] int64, prior energy [b, 2n], gain [b, 2n]) of the sent
        reals."""
        return self._plan

    @cached_property
    def _plan(self) -> tuple[Tensor, Tensor, Tensor]:
        """:meth:`sent_coefficients`, derived once from the side information (the sort over
        every coefficient is most of a decode, which refinement repeats every step)."""
        h, w = self.height, self.width
        lam = torch.exp2(self.codes.float() * _LOG2_STEP)  # [b, K]
        chunk = chunk_index(h, w, chunk_grid(h, w))  # [3hw]
        # chunks in decreasing energy (ties: lower index first), coefficients in index order
        rank = torch.argsort(torch.argsort(-self.codes.float(), dim=1, stable=True), dim=1)
        key = rank[:, chunk] * chunk.numel() + torch.arange(chunk.numel())  # [b, 3hw]
        order = torch.argsort(key, dim=1)[:, : 2 * self.num_symbols]
        prior = torch.gather(lam, 1, chunk[order])
        gain = prior.clamp_min(2.0**_LOG2_MIN) ** -0.25 * self.power_scale.float()[:, None]
        return order, prior, gain


def encode_residual(residual: Tensor, num_symbols: int) -> tuple[Tensor, AnalogSide]:
    """Residual images -> layer symbols with unit mean power and their side information.

    Args:
        residual: [batch, 3, height, width] float32 (image minus the base's decode).
        num_symbols: complex symbols of the layer per image, 1 <= n <= 3*height*width/2.
    Returns:
        (symbols [batch, num_symbols] complex64, :class:`AnalogSide`).
    """
    b, _, h, w = residual.shape
    if not 1 <= num_symbols <= 3 * h * w // 2:
        raise ValueError(f"num_symbols must be in [1, {3 * h * w // 2}], got {num_symbols}")
    coef = transform(residual.float())
    chunk = chunk_index(h, w, chunk_grid(h, w))
    k = 3 * chunk_grid(h, w) ** 2
    energy = torch.zeros(b, k).index_add_(1, chunk, coef.detach() ** 2)
    energy = energy / torch.bincount(chunk, minlength=k)
    codes = torch.round(torch.log2(energy.clamp_min(2.0**_LOG2_MIN)) / _LOG2_STEP)
    top = codes.max(dim=1, keepdim=True).values
    codes = torch.maximum(codes, top - (2**VAR_BITS - 1)).to(torch.int16)
    side = AnalogSide(h, w, num_symbols, codes, torch.ones(b, dtype=torch.float16))
    order, _, gain = side.sent_coefficients()
    sent = torch.gather(coef, 1, order) * gain
    scale = (sent.detach().pow(2).mean(1) * 2).clamp_min(1e-30).rsqrt()  # per real: 1/2
    scale = scale.clamp(max=6e4).to(torch.float16)  # an all-zero residual sends zeros
    side = AnalogSide(h, w, num_symbols, codes, scale)
    sent = sent * scale.float()[:, None]
    return torch.view_as_complex(sent.reshape(b, num_symbols, 2).contiguous()), side


def decode_residual(x_hat: Tensor, noise_var: Tensor, side: AnalogSide) -> Tensor:
    """LMMSE estimate of the residual from the layer's unbiased symbol estimates.

    Args:
        x_hat: [batch, num_symbols] complex64, unbiased estimates of the layer's symbols.
        noise_var: [batch, num_symbols] (or broadcastable) effective noise variance per
            complex symbol.
    Returns:
        [batch, 3, height, width] float32.
    """
    b = x_hat.shape[0]
    n = side.num_symbols
    order, prior, gain = side.sent_coefficients()
    y = torch.view_as_real(x_hat.to(torch.complex64)).reshape(b, 2 * n)
    nv = torch.broadcast_to(torch.as_tensor(noise_var, dtype=torch.float32), (b, n))
    nv = torch.nan_to_num(nv, nan=1e6, posinf=1e6).clamp(0.0, 1e6)
    nv_real = nv.repeat_interleave(2, dim=1) / 2
    est = gain * prior / (gain**2 * prior + nv_real) * y
    est = torch.where(torch.isfinite(est), est, torch.zeros_like(est))
    coef = torch.zeros(b, 3 * side.height * side.width).scatter(1, order, est)
    return inverse_transform(coef, side.height, side.width)
