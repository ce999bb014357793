"""The over-the-air receiver chain stage by stage, beside its reference implementation
(benchmarks.reference_receiver.receiver, benchmarks.reference_receiver.detection) in the same run:
real-time factors at several sample rates, and a profile of where the time goes.

Both implementations are timed alternately, call by call, so that load on a shared machine
hits them alike; the ratio reference / new is the number to read. Real-time factors come
from this process's CPU time (what the code costs on one core) and from wall time.
"""

from __future__ import annotations

import cProfile
import math
import pstats
import statistics
import time

import numpy as np

import phy
from benchmarks.reference_receiver import detection as detection_reference
from benchmarks.reference_receiver import receiver as receiver_reference
from common import one_blas_thread
from phy import detection, receiver

RATES_HZ = (2e6, 10e6, 20e6)
CFO_HZ = 49e3  # 20 ppm at 2.45 GHz
NUM_SYMBOLS = 12_000  # payload symbols: about 26k samples per frame
NUM_FRAMES = 8  # frames in the capture that the search runs over


def frame_capture(rng, cfg, n: int, snr_db: float, cfo: float) -> tuple[np.ndarray, np.ndarray]:
    """(payload [n] QPSK, capture [2000 + frame + 2000] complex64): multipath, CFO, AWGN."""
    bits = rng.integers(0, 2, size=(n, 2))
    x = (((1 - 2 * bits[:, 0]) + 1j * (1 - 2 * bits[:, 1])) / math.sqrt(2)).astype(np.complex64)
    t = phy.build_frame(x, cfg)
    s = np.r_[np.zeros(2000), t, np.zeros(2000)].astype(np.complex128)
    s = np.convolve(s, [1, 0, 0.4j, 0, 0.2])[: s.size] * np.exp(
        2j * np.pi * cfo * np.arange(s.size) / cfg.fft_size
    )
    nv = np.mean(np.abs(t) ** 2) * 10 ** (-snr_db / 10)
    r = s + math.sqrt(nv / 2) * (rng.standard_normal(s.size) + 1j * rng.standard_normal(s.size))
    return x, r.astype(np.complex64)


def side_by_side(new, ref, repeats: int) -> dict:
    """Median CPU and wall seconds of ``new()`` and ``ref()``, called alternately after one
    warm-up call each."""
    new(), ref()
    times: dict[str, list[float]] = {"new_cpu": [], "new_wall": [], "ref_cpu": [], "ref_wall": []}
    for _ in range(repeats):
        for name, fn in (("new", new), ("ref", ref)):
            c0, w0 = time.process_time(), time.perf_counter()
            fn()
            times[name + "_cpu"].append(time.process_time() - c0)
            times[name + "_wall"].append(time.perf_counter() - w0)
    return {k: statistics.median(v) for k, v in times.items()}


def _factors(t: dict, num_samples: int, rate: float) -> dict:
    """Real-time factors (> 1: faster than real time) of a :func:`side_by_side` result."""
    air = num_samples / rate
    out = {f"{k}_realtime_factor": air / max(v, 1e-12) for k, v in t.items()}
    out["speedup_cpu"] = t["ref_cpu"] / max(t["new_cpu"], 1e-12)
    out["speedup_wall"] = t["ref_wall"] / max(t["new_wall"], 1e-12)
    out["num_samples"] = num_samples
    return out


def _bits(res) -> np.ndarray:
    s = res.symbols.numpy()
    return np.stack([s.real > 0, s.imag > 0], axis=-1)


def _per_frame(mod, capture: np.ndarray, cfg, n: int) -> list:
    """The frames of a capture as a stream receiver without a batched call decodes them:
    the search, then ``receive_frame`` on each frame with the 2000 samples either side."""
    length = cfg.num_samples(n)
    out = []
    for start in mod.find_frames(capture, cfg):
        lo = max(0, start - 2000)
        seg = capture[lo : start + length + 2000]
        if start + length <= capture.size:
            res = mod.receive_frame(seg, cfg, n, equalizer="zf")
            res.start_index += lo
            out.append(res)
    return out


def rate_run(rate: float, rng: np.random.Generator) -> dict:
    """The chain and each stage at one sample rate, new beside reference."""
    cfg = phy.FrameConfig(sample_rate_hz=rate)
    cfo = CFO_HZ / cfg.subcarrier_spacing_hz
    n = NUM_SYMBOLS
    _, r = frame_capture(rng, cfg, n, 20.0, cfo)
    capture = np.concatenate([frame_capture(rng, cfg, n, 20.0, cfo)[1] for _ in range(NUM_FRAMES)])
    length = cfg.num_samples(n)
    region = receiver._without_dc(r[: r.size - length + cfg.sync_length])  # what it searches
    clean = receiver._without_dc(capture)
    start = detection.find_preambles(region, cfg)[0].start
    frame = r[start : start + length] - receiver._dc_estimate(r, start, length)
    rows = receiver._layout(cfg, n).body - cfg.backoff
    stages = {
        "chain (receive_frame)": (
            lambda: phy.receive_frame(r, cfg, n, equalizer="zf"),
            lambda: receiver_reference.receive_frame(r, cfg, n, equalizer="zf"),
            r.size,
            15,
        ),
        "detection in the chain (find_preambles)": (
            lambda: detection.find_preambles(region, cfg),
            lambda: detection_reference.find_preambles(region, cfg),
            r.size,
            15,
        ),
        "demodulation + estimation + equalisation (_demodulate)": (
            lambda: receiver._demodulate(frame, cfo, n, cfg, "zf"),
            lambda: receiver_reference._demodulate(frame, cfo, n, cfg, "zf"),
            r.size,
            15,
        ),
        "ofdm demodulation alone (_windows)": (
            lambda: receiver._windows(frame, rows, cfo, cfg.fft_size),
            lambda: receiver_reference._windows(frame, rows, cfo, cfg.fft_size),
            r.size,
            15,
        ),
        "frame search over a capture (find_frames)": (
            lambda: phy.find_frames(capture, cfg),
            lambda: receiver_reference.find_frames(capture, cfg),
            capture.size,
            5,
        ),
        "frames of a capture, one search (receive_frames)": (
            lambda: phy.receive_frames(capture, cfg, n, equalizer="zf"),
            lambda: _per_frame(receiver_reference, capture, cfg, n),
            capture.size,
            5,
        ),
        "search statistic alone (_search)": (
            lambda: detection._search(clean, cfg),
            lambda: detection_reference._search(clean, cfg),
            capture.size,
            5,
        ),
    }
    out: dict = {"sample_rate_hz": rate, "cfo_subcarriers": cfo, "stages": {}}
    for name, (new, ref, size, repeats) in stages.items():
        out["stages"][name] = _factors(side_by_side(new, ref, repeats), size, rate)
    res, res_ref = (
        mod.receive_frame(r, cfg, n, equalizer="zf") for mod in (phy, receiver_reference)
    )
    out["same_frames"] = phy.find_frames(capture, cfg) == receiver_reference.find_frames(
        capture, cfg
    )
    out["frames_found"] = len(phy.find_frames(capture, cfg))
    batch, per_frame = phy.receive_frames(capture, cfg, n, "zf"), _per_frame(phy, capture, cfg, n)
    out["same_frames_batched"] = [b.start_index for b in batch] == [
        f.start_index for f in per_frame
    ] and all(np.array_equal(_bits(b), _bits(f)) for b, f in zip(batch, per_frame))
    out["same_start"] = res.start_index == res_ref.start_index
    out["same_bits"] = bool(np.array_equal(_bits(res), _bits(res_ref)))
    return out


def profile(rate: float, rng: np.random.Generator, top: int = 12, runs: int = 20) -> dict:
    """Where the new chain's time goes: cProfile's own time per function over receive_frame
    and find_frames (shares of the total; the profiler inflates small calls)."""
    cfg = phy.FrameConfig(sample_rate_hz=rate)
    cfo = CFO_HZ / cfg.subcarrier_spacing_hz
    _, r = frame_capture(rng, cfg, NUM_SYMBOLS, 20.0, cfo)
    capture = np.concatenate([r] * NUM_FRAMES)
    out = {}
    for name, fn in (
        ("receive_frame", lambda: phy.receive_frame(r, cfg, NUM_SYMBOLS, equalizer="zf")),
        ("find_frames", lambda: phy.find_frames(capture, cfg)),
    ):
        fn()
        prof = cProfile.Profile()
        prof.enable()
        for _ in range(runs):
            fn()
        prof.disable()
        stats = pstats.Stats(prof).stats  # {(file, line, func): (cc, nc, tt, ct, callers)}
        total = sum(v[2] for v in stats.values())
        rows = sorted(stats.items(), key=lambda kv: -kv[1][2])[:top]
        out[name] = [
            {
                "function": f"{k[0].rsplit('/', 1)[-1]}:{k[2]}",
                "calls_per_run": v[1] / runs,
                "own_share": v[2] / total,
                "cumulative_share": v[3] / total,
            }
            for k, v in rows
        ]
    return out


@one_blas_thread
def run_all(rng: np.random.Generator) -> dict:
    """Every rate and the profile with numpy's BLAS pool at one thread, as the chain runs its
    stages (``phy.receive_frame`` bounds it): both sides alike, whatever the environment."""
    return {
        "note": (
            "new beside reference (benchmarks.reference_receiver.receiver), alternating calls, "
            "one BLAS thread; realtime factor > 1 is faster than real time; "
            "speedup = reference / new"
        ),
        "rates": {f"{rate / 1e6:g} MS/s": rate_run(rate, rng) for rate in RATES_HZ},
        "profile_at_20msps": profile(20e6, rng),
    }
