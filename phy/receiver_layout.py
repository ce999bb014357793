"""The index arrays of one frame length that the receiver's estimation and equalisation
work on (:mod:`phy.receiver`), built once per (configuration, payload length)."""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

from phy import estimation
from phy.frame import FrameConfig, interleaver, long_training_symbol


@dataclass(frozen=True)
class _Layout:
    """Index arrays of one frame length (cached): rows are the two training symbols, then
    the data OFDM symbols; ``known`` entries (training carriers, pilots) row-major."""

    rows: int
    body: np.ndarray  # [rows] body start of each row, samples from the frame start
    times: np.ndarray  # [rows] centre of each row's body, samples
    k_row: np.ndarray  # [num_known] row of each known value
    k_col: np.ndarray  # [num_known] carrier (centred order)
    k_flat: np.ndarray  # [num_known] row * fft_size + FFT bin (natural order) of each
    k_pos: np.ndarray  # [num_known] position of its carrier among the used ones
    x_known: np.ndarray  # [num_known] complex64 known value (|x| = 1)
    counts: np.ndarray  # [num_used] observations per used carrier
    smoothers: tuple  # (P [num_models, num_used, num_used] complex64, mse factors
    # [num_models, num_used], dofs [num_models]): the candidate channel models, shortest
    # delay window first, per-carrier LS last
    bands: np.ndarray  # [num_models, num_used, 2] int64: each row's non-zero columns [lo, hi)
    smoother_training: np.ndarray  # [num_used, num_used] training sums -> smoothed channel
    pairs: np.ndarray  # pilot indices j whose pilot j + 1 is one comb step above
    d_col: np.ndarray  # [num_symbols] carrier of each payload symbol's data element
    d_row: np.ndarray  # [num_symbols] its row
    d_bin: np.ndarray  # [num_symbols] its FFT bin (natural order)
    d_flat: np.ndarray  # [num_symbols] row * fft_size + FFT bin (natural order)
    used: np.ndarray  # used carriers (centred order)
    used_nat: np.ndarray  # their FFT bins (natural order)
    centred: np.ndarray  # [fft_size] carrier (centred order) of each FFT bin
    pilots: np.ndarray  # pilot carriers (centred order)
    pilot_in_used: np.ndarray  # position of each pilot carrier among the used ones
    num_training_values: int  # known entries of the two training rows (come first)
    fft_size: int


@functools.lru_cache(maxsize=32)
def _layout(cfg: FrameConfig, num_symbols: int) -> _Layout:
    grid = cfg.data_grid(num_symbols)
    n, cp, s = cfg.fft_size, cfg.cp_length, cfg.symbol_length
    used, pk = grid.used_subcarriers, grid.pilot_subcarriers
    rows = 2 + grid.num_ofdm_symbols
    body = cfg.sync_length + cp + s * np.arange(rows)
    x = np.zeros((rows, n), np.complex64)  # [rows, fft_size]
    x[:2, used] = long_training_symbol(cfg)[used]
    x[2:, pk] = grid.pilots.numpy().reshape(grid.num_ofdm_symbols, pk.size)
    k_row, k_col = np.nonzero(x)
    data = np.zeros((rows, n), bool)
    data[2:] = grid.data_mask.numpy()
    d_row, d_col = np.nonzero(data)  # row-major: resource element j
    # payload symbol i sits on resource element perm^-1[i]
    order = np.argsort(interleaver(d_row.size)) if cfg.interleave else np.arange(d_row.size)
    d_row, d_col = d_row[order[:num_symbols]], d_col[order[:num_symbols]]
    # candidate channel models: taps from backoff samples before the detected first path,
    # as many as the comb has pilots per symbol (more are ill-determined between pilots at
    # low SNR), the whole prefix, and per-carrier LS (no smoothing: high SNR, long channels)
    counts = np.bincount(k_col, minlength=n)[used].astype(np.float64)
    smoothers = []
    for num_taps in sorted({min(cp, pk.size), cp}):
        basis = estimation.delay_basis(used, n, np.arange(num_taps) - cfg.backoff)
        p_mat, factor = estimation.channel_smoother(counts, basis)
        smoothers.append((p_mat.astype(np.complex64), factor, num_taps))
    smoothers.append((np.diag(1.0 / counts).astype(np.complex64), 1.0 / counts, used.size))
    short = estimation.delay_basis(used, n, np.arange(min(cp, pk.size)) - cfg.backoff)
    smoother_training, _ = estimation.channel_smoother(np.full(used.size, 2.0), short)
    return _Layout(
        rows=rows,
        body=body,
        times=(body + n / 2).astype(np.float64),
        k_row=k_row,
        k_col=k_col,
        k_flat=k_row * n + (k_col + n // 2) % n,
        k_pos=np.searchsorted(used, k_col),
        x_known=x[k_row, k_col],
        counts=counts,
        smoothers=(
            np.stack([m[0] for m in smoothers]),
            np.stack([m[1] for m in smoothers]),
            np.array([m[2] for m in smoothers], np.float64),
        ),
        bands=_bands(np.stack([m[0] for m in smoothers])),
        smoother_training=smoother_training.astype(np.complex64),
        pairs=np.flatnonzero(np.diff(pk) == cfg.pilot_subcarrier_spacing),
        d_col=d_col,
        d_row=d_row,
        d_bin=(d_col + n // 2) % n,
        d_flat=d_row * n + (d_col + n // 2) % n,
        used=used,
        used_nat=(used + n // 2) % n,
        centred=(np.arange(n) + n // 2) % n,
        pilots=pk,
        pilot_in_used=np.searchsorted(used, pk),
        num_training_values=2 * used.size,
        fft_size=n,
    )


def _bands(p_mats: np.ndarray) -> np.ndarray:
    """[num_models, num_rows, 2] int64: the first and one past the last non-zero column of
    each row of each matrix (0, 0 for a zero row)."""
    nz = p_mats != 0
    cols = nz.shape[-1]
    lo = np.where(nz.any(-1), nz.argmax(-1), 0)
    hi = np.where(nz.any(-1), cols - nz[..., ::-1].argmax(-1), 0)
    return np.stack([lo, hi], axis=-1).astype(np.int64)
