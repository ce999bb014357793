"""SoftCast (Jakubczak and Katabi, 2011): the training-free linear analog image code.

Transmitter, per image:

1. subtract each colour plane's mean (three 16-bit numbers of metadata) and rotate the
   planes by the orthonormal opponent transform :data:`COLOUR` (luma and two chroma
   planes; orthonormal, so squared errors are the same in both spaces);
2. take each plane's orthonormal 2-D DCT and cut it into ``chunks_per_side`` x
   ``chunks_per_side`` rectangular chunks;
3. keep the chunks of highest variance ``lambda_i`` (mean square coefficient) that fit the
   budget, drop the rest (received as zeros);
4. scale chunk ``i`` by ``g_i = c * lambda_i^(-1/4)`` (the MSE-optimal allocation under a
   total power constraint at high SNR), ``c`` such that the analog symbols' mean ``|x|^2`` is
   exactly 1, and pair the scaled coefficients into complex symbols.

Metadata: the kept-chunk bitmap (one bit per chunk), each kept chunk's variance quantised to
:data:`VARIANCE_BITS` bits on a log scale (both ends use the quantised value), the plane
means and the power scale ``c``; sent with a robust digital code at :data:`METADATA_BITS_PER_SYMBOL`
bits per complex symbol, charged to the symbol budget, and assumed received intact.

Receiver: the LLSE estimate of each coefficient from its unbiased (ZF) symbol and that
symbol's measured noise variance ``nv`` (``nv / 2`` per real dimension):
``c_hat = g lambda / (g^2 lambda + nv / 2) * y``; then the inverse DCT, colour transform and
means. The PSNR rises smoothly with the channel SNR: nothing is ever lost.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from torch import Tensor

from common import psnr
from semcodec.contract.protocol import check_images, symbol_budget
from semcodec.contract.transmit import TransmitResult, check_num_symbols, run_link
from semcodec.links.framed import FramedReception, FramedScheme

COLOUR = np.array(
    [
        [1 / math.sqrt(3), 1 / math.sqrt(3), 1 / math.sqrt(3)],
        [1 / math.sqrt(2), 0.0, -1 / math.sqrt(2)],
        [1 / math.sqrt(6), -2 / math.sqrt(6), 1 / math.sqrt(6)],
    ]
)
"""Orthonormal opponent colour transform (rows: luma, red-blue, green-magenta)."""
CHUNKS_PER_SIDE = 24
"""Chunks per side of each plane's DCT (24 x 24 x 3 = 1,728 chunks per image)."""
VARIANCE_BITS = 8
"""Bits of each kept chunk's variance: log10 on [:data:`LOG10_VAR_RANGE`], uniform."""
LOG10_VAR_RANGE = (-12.0, 4.0)
MEAN_BITS = 16
"""Bits of each colour plane's mean."""
SCALE_BITS = 32
"""Bits of the power scale ``c`` (one float32 per image)."""
METADATA_BITS_PER_SYMBOL = 0.5
"""The metadata's code: QPSK at rate 1/4 (0.5 information bits per complex symbol)."""


@dataclass(frozen=True)
class SoftcastPlan:
    """One image's SoftCast transmitter choices (all of it known to the receiver through the
    metadata).

    Attributes:
        shape: (3, height, width).
        means: [3] the colour planes' means.
        edges_h, edges_w: chunk boundaries of the DCT rows and columns (``chunks_per_side + 1``).
        kept: [num_kept] flat chunk indices (plane, row, col) sent, highest variance first.
        variances: [num_kept] their quantised variances ``lambda_i``.
        gains: [num_kept] their scales ``g_i`` (mean analog ``|x|^2`` = 1).
        metadata_bits: bitmap + variances + means.
        metadata_symbols: the symbols the metadata takes (charged to the budget).
    """

    shape: tuple[int, int, int]
    means: np.ndarray
    edges_h: np.ndarray
    edges_w: np.ndarray
    kept: np.ndarray
    variances: np.ndarray
    gains: np.ndarray
    metadata_bits: int
    metadata_symbols: int

    @property
    def chunks_per_side(self) -> int:
        return len(self.edges_h) - 1

    def chunk_slices(self, index: int) -> tuple[int, slice, slice]:
        """(plane, row slice, column slice) of flat chunk ``index``."""
        k = self.chunks_per_side
        p, rest = divmod(int(index), k * k)
        i, j = divmod(rest, k)
        eh, ew = self.edges_h, self.edges_w
        return p, slice(int(eh[i]), int(eh[i + 1])), slice(int(ew[j]), int(ew[j + 1]))

    @property
    def num_values(self) -> int:
        """Real values sent (the kept chunks' coefficients)."""
        return int(sum(self.chunk_size(i) for i in self.kept))

    @property
    def analog_symbols(self) -> int:
        return (self.num_values + 1) // 2

    def chunk_size(self, index: int) -> int:
        _, r, c = self.chunk_slices(index)
        return (r.stop - r.start) * (c.stop - c.start)


def dct2(planes: np.ndarray) -> np.ndarray:
    """Orthonormal 2-D DCT-II of [3, height, width] float64 planes."""
    from scipy.fft import dctn

    return dctn(planes, type=2, axes=(1, 2), norm="ortho")


def idct2(coeffs: np.ndarray) -> np.ndarray:
    """Inverse of :func:`dct2`."""
    from scipy.fft import idctn

    return idctn(coeffs, type=2, axes=(1, 2), norm="ortho")


def quantise_variance(var: np.ndarray, bits: int = VARIANCE_BITS) -> np.ndarray:
    """Variances as the receiver reads them: log10 quantised to ``bits`` on
    :data:`LOG10_VAR_RANGE` (rounded to the nearest level)."""
    lo, hi = LOG10_VAR_RANGE
    levels = 2**bits - 1
    x = np.clip(np.log10(np.maximum(var, 10.0**lo)), lo, hi)
    return 10.0 ** (lo + np.round((x - lo) / (hi - lo) * levels) * (hi - lo) / levels)


def metadata_bits(num_chunks: int, num_kept: int) -> int:
    """Bitmap (a bit per chunk) + a quantised variance per kept chunk + three plane means +
    the power scale."""
    return num_chunks + num_kept * VARIANCE_BITS + 3 * MEAN_BITS + SCALE_BITS


def metadata_symbols(num_chunks: int, num_kept: int) -> int:
    """Symbols the metadata takes at :data:`METADATA_BITS_PER_SYMBOL`."""
    return math.ceil(metadata_bits(num_chunks, num_kept) / METADATA_BITS_PER_SYMBOL)


def allocate_gains(variances: np.ndarray, energies: np.ndarray, num_symbols: int) -> np.ndarray:
    """``g_i = c lambda_i^(-1/4)`` with ``c`` such that the mean |x|^2 of the analog symbols
    (two real values each) is exactly 1: ``sum_i g_i^2 E_i = num_symbols``.

    Args:
        variances: [num_kept] chunk variances lambda_i > 0 (the quantised ones both ends
            know: they set the shape of the allocation).
        energies: [num_kept] the chunks' actual energies (sum of squared coefficients), which
            set ``c`` (sent as :data:`SCALE_BITS` bits of metadata).
        num_symbols: the analog symbols they fill.
    Returns:
        [num_kept] float64 gains.
    """
    g = np.asarray(variances, dtype=np.float64) ** (-0.25)
    return g * math.sqrt(num_symbols / float(np.sum(g**2 * np.asarray(energies, np.float64))))


def llse_gain(gains: np.ndarray, variances: np.ndarray, noise_var_real) -> np.ndarray:
    """The LLSE estimate's factor ``g lambda / (g^2 lambda + sigma^2)`` on each received value
    (``sigma^2`` = noise variance per real dimension; arrays broadcast)."""
    g = np.asarray(gains, dtype=np.float64)
    lam = np.asarray(variances, dtype=np.float64)
    return g * lam / (g**2 * lam + np.asarray(noise_var_real, dtype=np.float64))


def plan_image(
    image: Tensor,
    num_symbols: int,
    chunks_per_side: int = CHUNKS_PER_SIDE,
    allow_empty: bool = False,
) -> tuple[SoftcastPlan, np.ndarray]:
    """The transmitter's plan of one image [3, height, width] and its DCT coefficients.

    Keeps the most chunks, highest variance first, whose coefficients and metadata fit
    ``num_symbols``. When not one chunk fits: ValueError, or with ``allow_empty`` (and the
    metadata fitting) no chunk at all: the receiver shows the planes' means.
    Returns (plan, coefficients [3, height, width] float64).
    """
    x = image.detach().to(torch.float64).numpy()
    _, h, w = x.shape
    k = int(chunks_per_side)
    if not 1 <= k <= min(h, w):
        raise ValueError(f"chunks_per_side must be in [1, {min(h, w)}], got {chunks_per_side}")
    means = x.reshape(3, -1).mean(axis=1)
    planes = np.einsum("ij,jhw->ihw", COLOUR, x - means[:, None, None])
    coeffs = dct2(planes)
    eh = np.linspace(0, h, k + 1).round().astype(int)
    ew = np.linspace(0, w, k + 1).round().astype(int)
    num_chunks = 3 * k * k
    var = np.empty(num_chunks)
    size = np.empty(num_chunks, dtype=np.int64)
    for p in range(3):
        for i in range(k):
            for j in range(k):
                c = coeffs[p, eh[i] : eh[i + 1], ew[j] : ew[j + 1]]
                var[(p * k + i) * k + j] = float(np.mean(c**2))
                size[(p * k + i) * k + j] = c.size
    order = np.argsort(-var, kind="stable")
    slots = np.cumsum(size[order])  # real values of the first m chunks
    kept_n = 0
    for m in range(num_chunks, 0, -1):
        if (int(slots[m - 1]) + 1) // 2 + metadata_symbols(num_chunks, m) <= num_symbols:
            kept_n = m
            break
    if kept_n == 0 and not (allow_empty and metadata_symbols(num_chunks, 0) <= num_symbols):
        raise ValueError(
            f"softcast: {num_symbols} symbols hold no chunk of a {h}x{w} image with its metadata"
        )
    kept = order[:kept_n]
    q = quantise_variance(var[kept])
    gains = (
        allocate_gains(q, var[kept] * size[kept], (int(slots[kept_n - 1]) + 1) // 2)
        if kept_n
        else np.zeros(0)
    )
    bits = metadata_bits(num_chunks, kept_n)
    plan = SoftcastPlan(
        (3, h, w), means, eh, ew, kept, q, gains, bits, metadata_symbols(num_chunks, kept_n)
    )
    return plan, coeffs


def plan_fitting(
    image: Tensor, num_symbols: int, chunks_per_side: int = CHUNKS_PER_SIDE
) -> tuple[SoftcastPlan, np.ndarray]:
    """:func:`plan_image` at ``chunks_per_side`` (at most the image's shorter side), or, when
    the metadata of that many chunks leaves no room (small images, small budgets), at the
    most chunks per side that fit; below that, the planes' means alone (no chunk)."""
    k = min(int(chunks_per_side), *image.shape[-2:])
    while True:
        try:
            return plan_image(image, num_symbols, k, allow_empty=k == 1)
        except ValueError:
            if k == 1:
                raise
            k = max(1, k // 2)


def encode_chunks(coeffs: np.ndarray, plan: SoftcastPlan) -> Tensor:
    """The kept chunks' scaled coefficients paired into symbols: [analog_symbols] complex64."""
    vals = [
        plan.gains[n] * coeffs[p, r, c].reshape(-1)
        for n, (p, r, c) in enumerate(plan.chunk_slices(i) for i in plan.kept)
    ]
    v = np.concatenate(vals) if vals else np.zeros(0)
    if v.size % 2:
        v = np.concatenate([v, [0.0]])
    return torch.view_as_complex(torch.from_numpy(v.reshape(-1, 2)).to(torch.float32).contiguous())


def decode_chunks(x_hat: Tensor, noise_var: Tensor, plan: SoftcastPlan) -> Tensor:
    """LLSE of the coefficients from the unbiased symbols and their noise variance, then the
    inverse transforms: [3, height, width] float32 (not clamped).

    Args:
        x_hat: [analog_symbols] complex.
        noise_var: [analog_symbols] (or one value) noise variance per complex symbol.
    """
    y = torch.view_as_real(x_hat.to(torch.complex128)).reshape(-1).numpy()
    nv = np.broadcast_to(np.asarray(noise_var, dtype=np.float64).reshape(-1), (x_hat.shape[0],))
    sigma2 = np.repeat(nv / 2.0, 2)  # per real dimension
    coeffs = np.zeros(plan.shape)
    at = 0
    for n, i in enumerate(plan.kept):
        p, r, c = plan.chunk_slices(i)
        size = (r.stop - r.start) * (c.stop - c.start)
        a = llse_gain(plan.gains[n], plan.variances[n], sigma2[at : at + size])
        coeffs[p, r, c] = (a * y[at : at + size]).reshape(r.stop - r.start, c.stop - c.start)
        at += size
    planes = np.einsum("ji,jhw->ihw", COLOUR, idct2(coeffs))  # COLOUR^T: its inverse
    return torch.from_numpy(planes + plan.means[:, None, None]).to(torch.float32)


def transmit_softcast(
    images: Tensor,
    link,
    snr_db,
    num_symbols: int,
    generator: torch.Generator | None = None,
    chunks_per_side: int = CHUNKS_PER_SIDE,
) -> TransmitResult:
    """SoftCast through ``link`` in ``num_symbols`` symbols per image (metadata included).

    The transmitter plans nothing from the SNR: the same symbols at every SNR.

    Args:
        images: [batch, 3, height, width] float32 in [0, 1].
        link: a ``phy`` link with ZF (or a bare channel): unbiased symbols and each symbol's
            noise variance, which the LLSE uses.
        snr_db: the channel's average Es/N0 (float or [batch]).
    Returns:
        TransmitResult; stats: num_symbols (analog + metadata), side_info_bits, chunks_kept
        and chunks per image, failed_codewords 0.
    """
    x = check_images(images)
    n = check_num_symbols(num_symbols)
    plans, syms = [], []
    for img in x:
        plan, coeffs = plan_fitting(img, n, chunks_per_side)
        plans.append(plan)
        syms.append(encode_chunks(coeffs, plan))
    width = max(max(s.shape[0] for s in syms), 1)  # one symbol when only means are sent
    block = torch.zeros(len(syms), width, dtype=torch.complex64)
    for b, s in enumerate(syms):  # images of one batch share a size: one width
        block[b, : s.shape[0]] = s
    with torch.no_grad():
        x_hat, nv = run_link(link, block, snr_db, generator)
    nv = torch.as_tensor(nv, dtype=torch.float64)
    nv = nv.reshape(-1, 1) if nv.dim() == 1 else nv
    nv = nv.broadcast_to(block.shape)  # [batch, num_symbols]
    out = [
        decode_chunks(x_hat[b, : s.shape[0]], nv[b, : s.shape[0]], plans[b])
        for b, s in enumerate(syms)
    ]
    return TransmitResult(
        torch.stack(out).clamp(0, 1),
        {
            "num_symbols": sum(p.analog_symbols + p.metadata_symbols for p in plans),
            "side_info_bits": sum(p.metadata_bits for p in plans),
            "chunks_kept": [len(p.kept) for p in plans],
            "chunks": [3 * p.chunks_per_side**2 for p in plans],
            "failed_codewords": 0,
        },
    )


def _framed_transmit(images, settings):
    """Per image: the analog symbols at ``settings.cbr`` (its metadata inside that budget).
    The state is each image's plan (the metadata the receiver is sent)."""
    blocks, plans = [], []
    for img in np.asarray(images, np.float32):
        x = torch.from_numpy(img)
        plan, coeffs = plan_fitting(x, symbol_budget(settings.cbr, *img.shape[-2:]))
        blocks.append(encode_chunks(coeffs, plan).numpy())
        plans.append(plan)
    return blocks, plans


def _framed_receive(received, plans, images, settings):
    """LLSE of each block from its zero-forced symbols and their noise variance; a lost
    frame's symbols come back erased (0, ``semcodec.links.ReceivedBlock``), which the LLSE
    maps to the chunks' mean, 0."""
    out = []
    for block, plan, img in zip(received, plans, np.asarray(images, np.float32)):
        x = torch.from_numpy(np.asarray(block.x_hat, np.complex64))
        nv = np.asarray(block.noise_var, np.float64)
        rec = decode_chunks(x, torch.from_numpy(nv), plan).clamp(0, 1).numpy()
        stats = {
            "decoded": True,
            "num_symbols": plan.analog_symbols + plan.metadata_symbols,
            "symbol_budget": symbol_budget(settings.cbr, *img.shape[-2:]),
            "side_info_bits": plan.metadata_bits,
        }
        out.append(FramedReception(rec, psnr(rec, img), stats, [None] * len(block.frames_detected)))
    return out


def framed_softcast():
    """SoftCast's transmitter and receiver around a framed link (``osnerf ota``): the analog
    symbols framed, the metadata as side information (charged in ``num_symbols``)."""
    return FramedScheme(_framed_transmit, _framed_receive)
