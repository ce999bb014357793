"""The receive side of an over-the-air burst: find, synchronise and equalise every frame
of a capture, number the frames from their headers and the burst's layout, and reassemble
the blocks (symbols of lost frames come back erased)."""

from __future__ import annotations

import numpy as np

from common import one_blas_thread
from hil.ota.burst import as_numpy
from hil.ota.config import OtaConfig
from hil.ota.header import HEADER_BITS, header_mismatch, header_symbols

ERASED_NOISE_VAR = 1e3  # noise variance reported for symbols of lost frames (an erasure)


def assign_frames(
    starts: np.ndarray, headers: list, positions: np.ndarray, repeat: int, tolerance: float
) -> list:
    """The frame number of each detected frame, from its header and its place in the burst.

    At -10 dB one header (128 BPSK symbols) does not decode reliably on its own, but the
    burst's layout is known: frame i starts ``positions[i]`` samples after the burst. Every
    (detection, frame) pair proposes a burst offset; the offset under which the detections'
    soft header correlations with their frames' headers sum highest wins, and each
    detection is the frame that starts there (within ``tolerance`` samples), else None.

    Args:
        starts: [num_detected] start of each detected frame in the capture.
        headers: per detection ``(x_hat [>= 16 * repeat] complex, noise_var [same])``.
        positions: [num_frames] ascending start of each frame in the burst.
    Returns:
        list of frame numbers (int) or None, one per detection.
    """
    starts = np.asarray(starts, np.float64)
    positions = np.asarray(positions, np.float64)
    if starts.size == 0 or positions.size == 0:
        return [None] * starts.size
    n = HEADER_BITS * repeat
    codes = np.stack([header_symbols(i, repeat).real for i in range(positions.size)])  # [F, n]
    score = np.zeros((starts.size, positions.size))
    for j, (x_hat, nv) in enumerate(headers):
        w = 1.0 / np.maximum(np.asarray(nv, np.float64)[:n], 1e-6)  # MRC of unbiased symbols
        soft = w * np.real(np.asarray(x_hat)[:n])
        score[j] = codes @ soft / np.sqrt(max(float(w.sum()), 1e-12) / 2)  # N(0, 1) if wrong

    def explain(offset):
        rel = starts - offset
        i = np.clip(np.searchsorted(positions, rel), 1, positions.size - 1)
        i = np.where(np.abs(positions[i - 1] - rel) <= np.abs(positions[i] - rel), i - 1, i)
        if positions.size == 1:
            i = np.zeros(starts.size, np.int64)
        ok = np.abs(positions[i] - rel) <= tolerance
        return i, ok, float(score[np.flatnonzero(ok), i[ok]].sum())

    offsets = (starts[:, None] - positions[None, :]).reshape(-1)
    best = max((explain(o) for o in offsets), key=lambda e: e[2])
    return [int(i) if ok else None for i, ok in zip(*best[:2])]


@one_blas_thread
def receive_burst(
    capture: np.ndarray, reports: list, layout: list, block_sizes: list, cfg: OtaConfig, frames
):
    """Find, synchronise and equalise every frame of ``capture``; reassemble the blocks.

    Frame numbers come from the headers and the burst's layout together
    (:func:`assign_frames`); a detection whose header then contradicts its number
    (:func:`hil.ota.header.header_mismatch`) is dropped, its frame lost, and the reason kept
    in the frame's ``header_error``. Fills ``reports`` (detected, start, SNR, CFO) in place.
    Returns:
        list of ``(x_hat [n] complex64, noise_var [n] float32)``, one per block.
    """
    x_hats = [np.zeros(n, np.complex64) for n in block_sizes]
    nvs = [np.full(n, ERASED_NOISE_VAR, np.float32) for n in block_sizes]
    n_frame_syms = cfg.header_symbols + cfg.symbols_per_frame
    frame_len = max(r.num_samples for r in reports) if reports else 0
    found = []
    for start in frames.find(capture):
        lo = max(0, start - cfg.gap_samples // 2)
        seg = capture[lo : start + frame_len + cfg.gap_samples // 2]
        res = frames.receive(seg, n_frame_syms)
        if not bool(getattr(res, "detected", True)):
            continue
        sym = as_numpy(res.symbols).reshape(-1).astype(np.complex64)
        nv = np.broadcast_to(as_numpy(res.noise_var).astype(np.float32).reshape(-1), sym.shape)
        found.append((lo + int(getattr(res, "start_index", start - lo)), sym, nv, res))
    sizes = np.array([r.num_samples + cfg.gap_samples for r in reports], np.float64)
    positions = cfg.gap_samples + np.concatenate([[0.0], np.cumsum(sizes)[:-1]])
    span = float(positions[-1]) if positions.size else 0.0
    numbers = assign_frames(
        np.array([f[0] for f in found]),
        [(f[1], f[2]) for f in found],
        positions,
        cfg.header_repeat,
        tolerance=8 + 1e-4 * span,  # sampling clocks up to 100 ppm apart
    )
    for (start, sym, nv, res), number in zip(found, numbers):
        if number is None or reports[number].detected:
            continue  # not where a frame of this burst starts, or a duplicate detection
        rep = reports[number]
        rep.header_error = header_mismatch(sym, cfg.header_repeat, number, nv)
        if rep.header_error is not None:
            continue  # the header says this is not frame `number`: lost, not misplaced
        rep.detected = True
        rep.start_index = start
        snr = getattr(res, "snr_db_estimate", None)
        rep.snr_db = None if snr is None else float(as_numpy(snr))
        cfo = getattr(res, "cfo_hz", None)
        rep.cfo_hz = None if cfo is None else float(as_numpy(cfo))
        b, offset, length = layout[number]
        x_hats[b][offset : offset + length] = sym[cfg.header_symbols : cfg.header_symbols + length]
        nvs[b][offset : offset + length] = nv[cfg.header_symbols : cfg.header_symbols + length]
    return list(zip(x_hats, nvs))
