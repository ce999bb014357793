"""phy throughput: channel simulation rate per channel (with sionna's AWGN side by side),
OFDM link rate, and the over-the-air receiver chain (detection + sync + OFDM demodulation +
estimation + equalisation) in samples/s against real time at 4 and 20 MS/s.

Timings are wall-clock medians on a shared machine: read ratios, not absolute numbers.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path

import numpy as np
import torch

import phy

REPEATS = 5


def _median_seconds(fn, repeats: int = REPEATS) -> float:
    """Median wall-clock seconds of ``fn()`` after one warm-up call."""
    return _timed(fn, repeats)[0]


def _timed(fn, repeats: int = REPEATS) -> tuple[float, float]:
    """(median wall seconds, mean CPU seconds of this process) per call, after a warm-up.

    On a shared machine the CPU time says what the code costs; the wall time what it got.
    """
    fn()  # warm-up (lazy imports, caches)
    times = []
    cpu0 = time.process_time()
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times), (time.process_time() - cpu0) / repeats


def _channels(gen: torch.Generator) -> dict:
    x = phy.power_normalize(torch.randn(64, 16384, dtype=torch.complex64, generator=gen))
    grid_x = x.reshape(64, 256, 64)  # [batch, num_ofdm_symbols, fft_size] for TDL/CDL
    out = {}
    for name in sorted(phy.CHANNELS):
        if name == "raytraced":
            continue  # needs a scene: benchmarked by phy.raytrace's owner
        ch = phy.make_channel(name)
        inp = grid_x if name in ("tdl", "cdl") else x
        s = _median_seconds(
            lambda ch=ch, inp=inp: ch(inp, 10.0, generator=gen),
            3 if name in ("tdl", "cdl") else REPEATS,
        )
        out[name] = {"symbols_per_s": x.numel() / s, "seconds": s, "num_symbols": x.numel()}
    from sionna.phy.channel import AWGN as SionnaAWGN

    ref = SionnaAWGN(precision="single", device="cpu")
    s = _median_seconds(lambda: ref(x, 0.1))
    out["sionna_awgn_reference"] = {"symbols_per_s": x.numel() / s, "seconds": s}
    out["awgn_vs_sionna_speed_ratio"] = (
        out["awgn"]["symbols_per_s"] / out["sionna_awgn_reference"]["symbols_per_s"]
    )
    return out


def _links(gen: torch.Generator) -> dict:
    x = phy.power_normalize(torch.randn(16, 16384, dtype=torch.complex64, generator=gen))
    grid = phy.ResourceGrid()
    links = {
        "flat_rayleigh_mmse": phy.FlatLink(phy.RayleighFading("block")),
        "ofdm_rayleigh_ls": phy.OFDMLink(grid, phy.RayleighFading("block"), csi="ls"),
        "ofdm_tdl_ls": phy.OFDMLink(grid, phy.TDLChannel("A"), csi="ls"),
    }
    out = {}
    for name, link in links.items():
        s = _median_seconds(lambda link=link: link(x, 10.0, generator=gen), 3)
        out[name] = {"symbols_per_s": x.numel() / s, "seconds": s}
    return out


def _receiver(rng: np.random.Generator) -> dict:
    cfg = phy.FrameConfig()
    n = 12_000  # payload symbols: about 25k samples per frame
    bits = rng.integers(0, 2, size=(n, 2))
    x = (((1 - 2 * bits[:, 0]) + 1j * (1 - 2 * bits[:, 1])) / math.sqrt(2)).astype(np.complex64)
    t = phy.build_frame(x, cfg)
    s = np.r_[np.zeros(2000), t, np.zeros(2000)].astype(np.complex128)
    s = np.convolve(s, [1, 0, 0.4j, 0, 0.2])[: s.size] * np.exp(
        2j * np.pi * 3.3 * np.arange(s.size) / cfg.fft_size
    )
    nv = np.mean(np.abs(t) ** 2) * 10 ** (-20 / 10)
    r = (
        s + math.sqrt(nv / 2) * (rng.standard_normal(s.size) + 1j * rng.standard_normal(s.size))
    ).astype(np.complex64)
    sec, cpu = _timed(lambda: phy.receive_frame(r, cfg, n))
    res = phy.receive_frame(r, cfg, n)
    mse = float(np.mean(np.abs(res.symbols.numpy() - x) ** 2))
    rate = r.size / sec
    capture = np.concatenate([r] * 8)  # 8 frames: detection only over a longer capture
    sec_find = _median_seconds(lambda: phy.find_frames(capture, cfg), 3)
    return {
        "frame_samples": int(r.size),
        "receive_frame_seconds": sec,
        "receive_frame_samples_per_s": rate,
        "realtime_factor_at_4msps": rate / 4e6,
        "realtime_factor_at_20msps": rate / 20e6,
        "receive_frame_cpu_seconds": cpu,
        "cpu_samples_per_s": r.size / cpu,
        "cpu_realtime_factor_at_4msps": r.size / cpu / 4e6,
        "cpu_realtime_factor_at_20msps": r.size / cpu / 20e6,
        "find_frames_samples_per_s": capture.size / sec_find,
        "find_frames_realtime_factor_at_20msps": capture.size / sec_find / 20e6,
        "frames_found": len(phy.find_frames(capture, cfg)),
        "detected": res.detected,
        "cfo_error_subcarriers": abs(res.cfo_subcarriers - 3.3),
        "payload_mse": mse,
        "reported_noise_var": float(res.noise_var.mean()),
    }


def run(out_dir: Path) -> dict:
    torch.set_num_threads(min(2, torch.get_num_threads()))
    gen = torch.Generator().manual_seed(0)
    return {
        "note": "wall-clock medians on a shared 2-core machine; realtime_factor > 1 means faster than real time",
        "torch_threads": torch.get_num_threads(),
        "channels": _channels(gen),
        "links": _links(gen),
        "receiver_chain": _receiver(np.random.default_rng(0)),
    }
