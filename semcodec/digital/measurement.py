"""How the digital calibration table is measured (:mod:`semcodec.digital.calibration` reads it):
Monte-Carlo codeword error counts with their maximum-likelihood probit fit, and the image
codecs' rate-distortion curves on Kodak."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

import phy
from common import psnr, read_image, to_chw, to_hwc
from phy.digital import MCS_TABLE, codeword_errors
from semcodec.digital.image_codecs import decode_scaled, downscale, encode_image


def q_function(x):
    """The standard normal tail probability Q(x) = P(N(0, 1) > x)."""
    from scipy.special import erfc

    return 0.5 * erfc(np.asarray(x, dtype=np.float64) / math.sqrt(2.0))


def fit_probit(snr_db, errors, trials) -> tuple[float, float]:
    """Maximum-likelihood (t, s) of ``p = Q((snr_db - t) / s)`` to binomial counts."""
    from scipy.optimize import minimize

    x = np.asarray(snr_db, float)
    k = np.asarray(errors, float)
    n = np.asarray(trials, float)

    def nll(v):
        t, log_s = v
        p = np.clip(q_function((x - t) / math.exp(log_s)), 1e-12, 1 - 1e-12)
        return -np.sum(k * np.log(p) + (n - k) * np.log1p(-p))

    frac = k / n
    t0 = float(x[np.argmin(np.abs(frac - 0.5))])
    res = minimize(nll, [t0, math.log(0.3)], method="Nelder-Mead", options={"xatol": 1e-4})
    return float(res.x[0]), float(math.exp(res.x[1]))


def _link(channel: str):
    return phy.FlatLink(phy.make_channel(channel), csi="perfect", equalizer="zf")


def measure_curve(
    channel: str, mcs: str, coded_bits: int, seed: int = 0, quick: bool = False
) -> dict:
    """Monte-Carlo points of one codeword curve and their probit fit.

    Bisection for the 50 % point (40 codewords a step), then points around it (80 each).
    """
    import torch

    m = MCS_TABLE[mcs]
    cap_db = 10 * math.log10(2.0**m.spectral_efficiency - 1.0)
    fast = channel != "awgn"
    lo, hi = cap_db - 3.0, cap_db + (16.0 if fast else 8.0)
    gen = torch.Generator().manual_seed(seed)
    link = _link(channel)
    pts: list[tuple[float, int, int]] = []
    n_bis, n_pt = (16, 24) if quick else (40, 80)

    def trial(snr, n):
        e = codeword_errors(mcs, coded_bits, link, snr, n, generator=gen)
        pts.append((round(float(snr), 3), int(e.sum()), n))
        return float(e.float().mean())

    for _ in range(4 if quick else 6):
        mid = 0.5 * (lo + hi)
        if trial(mid, n_bis) > 0.5:
            lo = mid
        else:
            hi = mid
    t = 0.5 * (lo + hi)
    span = (-4.0, -2.0, -1.0, 1.0, 2.0, 4.0) if fast else (-1.0, -0.5, -0.25, 0.25, 0.5, 1.0)
    for d in span:
        trial(t + d, n_pt)
    t_fit, s_fit = fit_probit(*zip(*pts))
    return {"t_db": round(t_fit, 3), "s_db": round(s_fit, 4), "points": pts}


def measure_rate_distortion(images, image_codec: str, qualities, scale: int = 1) -> list[dict]:
    """Mean bpp (wire bytes: container stripped, per pixel of the full image) and mean PSNR
    (upscaled against the full image) per quality over ``images`` ([3, H, W] float tensors)
    sent downscaled by ``scale``."""
    out = []
    for q in qualities:
        bpps, psnrs = [], []
        for img in images:
            data = encode_image(downscale(img, scale), image_codec, q)
            h, w = img.shape[1:]
            rec = decode_scaled(data, image_codec, h, w, scale).astype(np.float64) / 255.0
            ref = np.round(to_hwc(img) * 255) / 255.0
            bpps.append(8 * len(data) / (h * w))
            psnrs.append(psnr(rec, ref))
        out.append(
            {
                "quality": q,
                "bpp": round(float(np.mean(bpps)), 5),
                "psnr_db": round(float(np.mean(psnrs)), 3),
            }
        )
    return out


def kodak_images(folder: Path, limit: int | None):

    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".png")[:limit]
    return [to_chw(read_image(p)) for p in paths]


QUALITIES = {
    "avif": (0, 5, 10, 15, 20, 25, 30, 35, 40, 45, 50, 55, 60, 65, 70, 75, 80, 85, 90),
    "webp": (0, 5, 10, 20, 30, 40, 50, 60, 70, 80, 90, 95),
    "jpeg": (1, 5, 10, 20, 30, 40, 50, 60, 70, 80, 90, 95),
}
