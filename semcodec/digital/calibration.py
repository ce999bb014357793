"""The honest digital link's MCS choice: a shipped calibration table, no CSI at the transmitter.

The transmitter knows the channel *kind* (its fading distribution), the *average* SNR, the
number of symbols per image and its own image; it does not know this image's fade. It picks
the MCS of :data:`phy.digital.MCS_TABLE` that maximises the expected PSNR

    E[PSNR] = (1 - BLER) * PSNR(rate) + BLER * PSNR(lost)

where BLER is the probability that some payload codeword of the image fails over the
channel's fading distribution, PSNR(rate) the image codec's rate-distortion curve (Kodak,
:data:`semcodec.digital.IMAGE_CODECS`, container stripped) at the MCS's payload bits per pixel, the
best over the scales the image may be sent at (downscaled and upscaled at the receiver,
:func:`semcodec.digital.image_codecs.encode_scaled_to_budget`), and PSNR(lost) that of the mid-grey
a lost image is shown as. Deep fades cost outages.

What the table (``semcodec/data/digital_calibration.json``) holds and how it was computed
(``python -m semcodec.digital.calibration --kodak KODAK --out PATH`` recomputes it, about
30 CPU minutes; :data:`HOW` is what the file says of itself):

* ``codeword_curves[channel][mcs][E]``: the block error probability of one codeword of
  ``E`` coded bits against SNR, a probit ``Q((snr_db - t) / s)`` fitted by maximum
  likelihood to Monte-Carlo counts (kept beside it) of :func:`phy.digital.codeword_errors`:
  AWGN (E = 960, 1920, 3840), and fast Rayleigh fading with perfect-CSI ZF (each codeword
  sees many fades; E = 3840, used for shorter codewords too).
* ``rate_distortion[codec][scale]``: mean bpp (bits per pixel of the full image) and mean
  PSNR (the upscaled image against the full one) over the 24 Kodak images per quality, the
  image sent downscaled by ``scale``.
* ``lost_psnr_db``: mean PSNR of mid-grey (0.5) against the Kodak images.

Image BLER with ``C`` codewords (they are independent given the fade):

* awgn, fast fading: ``1 - (1 - p(snr))^C``;
* block fading (``rayleigh``, ``rician``): the AWGN curve averaged over the fade,
  ``E_g[1 - (1 - p(snr * g))^C]`` with ``g = |h|^2`` ~ Exp(1) (Rayleigh) or the scaled
  non-central chi-square (Rician, the channel's default K), by quadrature on a log grid.

Channels without a curve of their own use the nearest calibrated one (:data:`ALIASES`).

Planning from an estimate (``snr_error_db`` > 0): the transmitter's SNR estimate is the true
average SNR plus a zero-mean Gaussian error of ``snr_error_db``; given the estimate, the
true SNR is (flat prior) the estimate plus that error, and every loss probability above is
averaged over it (:func:`error_grid`): a link adapter's back-off, priced rather than fixed.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import sys
import time
import zlib
from collections.abc import Mapping
from pathlib import Path

import numpy as np

from common import psnr, write_text
from phy import OFDM_CHANNELS
from phy.digital import MCS_TABLE, MOTHER_RATE, codeword_layout, get_mcs, payload_capacity_bits
from semcodec.digital.image_codecs import IMAGE_CODECS, usable_scales
from semcodec.digital.measurement import (
    QUALITIES,
    kodak_images,
    measure_curve,
    measure_rate_distortion,
    q_function,
)
from semcodec.digital.measurement import fit_probit as fit_probit  # where tests read it

CALIBRATION_PATH = Path(__file__).resolve().parents[1] / "data" / "digital_calibration.json"
CODEWORD_BITS = (960, 1920, 3840)
"""Codeword lengths E (coded bits) with a measured curve; others interpolate in log E.
Below rate 1/5 these are the mother codeword's distinct bits (:func:`measured_lengths`)."""
MEASURED = {"awgn": CODEWORD_BITS, "rayleigh_fast": (3840,)}
BLOCK_FADING = {"rayleigh": ("awgn", "rayleigh"), "rician": ("awgn", "rician")}
"""Block-fading channel -> (curve it averages, fade distribution)."""
_OFDM_REASON = "fast Rayleigh curve: an OFDM codeword spans many independent subcarrier fades"
ALIASES = {
    "rician_fast": "rayleigh_fast",
    **{name: "rayleigh_fast" for name in sorted(OFDM_CHANNELS)},
}
"""Channels calibrated by another one's table, and why (``ALIAS_REASONS``): every OFDM
channel of ``phy`` (tdl, cdl, the TS 38.101-4 conditions) by the fast Rayleigh table."""
ALIAS_REASONS = {
    "rician_fast": "fast Rayleigh curve: pessimistic for a line-of-sight component",
    **{name: _OFDM_REASON for name in sorted(OFDM_CHANNELS)},
}
RICIAN_K_DB = 6.0  # phy.RicianFading's default
HOW = (
    "codeword_curves[channel][mcs][E]: block error probability of one LDPC codeword of E coded "
    "bits vs Es/N0 (dB), probit Q((snr_db - t_db) / s_db) fitted by maximum likelihood to the "
    "Monte-Carlo points [snr_db, errors, trials] of phy.digital.codeword_errors (CRC24B, 5G "
    "LDPC, QAM, BP <= 20 iterations); awgn at E = 960, 1920, 3840; rayleigh_fast (perfect-CSI "
    "ZF, a fade per symbol) at E = 3840. Block fading = the awgn curve averaged over the fade. "
    "rate_distortion[codec][scale]: mean bpp (wire bytes, container stripped, per pixel of the "
    "full image) and mean PSNR (upscaled with Lanczos against the full image) over the Kodak "
    "images per quality, the image sent downscaled by scale. lost_psnr_db: mean PSNR of mid-grey "
    "against Kodak. Recompute: "
    "python -m semcodec.digital.calibration --kodak KODAK --out FILE (about 30 CPU minutes)."
)


def measured_lengths(channel: str, mcs: str) -> list[int]:
    """Codeword lengths E measured for ``mcs`` on ``channel``: :data:`MEASURED`'s, or below
    rate 1/5 the lengths whose mother codewords have that many bits (the same information
    bits per codeword as at rate 1/5)."""
    m = get_mcs(mcs)
    scale = max(MOTHER_RATE / m.code_rate, 1)
    out = []
    for e in MEASURED[channel]:
        x = math.floor(e * scale)
        out.append(x - x % m.bits_per_symbol)
    return out


# ----------------------------------------------------------------------------- fades
@functools.lru_cache(maxsize=8)
def fade_grid(kind: str, k_factor_db: float = RICIAN_K_DB) -> tuple[np.ndarray, np.ndarray]:
    """Quadrature of a block fade's power ``g = |h|^2`` (E[g] = 1) on a log grid.

    Returns:
        (gain_db [num_points], weight [num_points]) with ``sum(weight) == 1``: the weights are
        exact CDF differences between log-midpoints, so ``sum(weight * f(gain))`` is
        ``E[f(g)]`` up to the variation of ``f`` within one 0.05 dB step.
    """
    edges_db = np.arange(-80.0, 25.0 + 1e-9, 0.05)
    g_edges = 10.0 ** (edges_db / 10.0)
    if kind == "rayleigh":
        cdf = -np.expm1(-g_edges)
    elif kind == "rician":
        from scipy.stats import ncx2

        k = 10.0 ** (k_factor_db / 10.0)
        cdf = ncx2.cdf(2.0 * (k + 1.0) * g_edges, df=2, nc=2.0 * k)
    else:
        raise KeyError(f"unknown fade {kind!r}; known: ['rayleigh', 'rician']")
    cdf = np.concatenate([[0.0], cdf[1:-1], [1.0]])
    w = np.diff(cdf)
    mid = 0.5 * (edges_db[1:] + edges_db[:-1])
    return mid, w / w.sum()


ERROR_GRID_STEP = 0.05
ERROR_GRID_SIGMAS = 5.0


@functools.lru_cache(maxsize=1)
def error_grid() -> tuple[np.ndarray, np.ndarray]:
    """Quadrature of a standard normal error ``z``: (z [num_points], weight [num_points]),
    ``sum(weight) == 1``, exact CDF differences between midpoints on [-5, 5] in steps of
    0.05 (the loss curves are near steps, which Gauss-Hermite nodes would miss)."""
    from scipy.stats import norm

    edges = np.arange(-ERROR_GRID_SIGMAS, ERROR_GRID_SIGMAS + 1e-9, ERROR_GRID_STEP)
    cdf = norm.cdf(edges)
    cdf[0], cdf[-1] = 0.0, 1.0
    w = np.diff(cdf)
    return 0.5 * (edges[1:] + edges[:-1]), w / w.sum()


# ----------------------------------------------------------------------------- the table
class DigitalCalibration:
    """Lookups in the shipped calibration table (see the module docstring)."""

    def __init__(self, doc: dict):
        self.doc = doc
        self.curves = doc["codeword_curves"]
        self.rd = doc["rate_distortion"]
        self.lost_psnr_db = float(doc["lost_psnr_db"])
        self._choices: dict = {}
        self._blers: dict = {}  # image_bler's values: a pure function of the table

    @property
    def channels(self) -> list[str]:
        """Channel names this table serves (measured, block-fading and aliases)."""
        return sorted(set(self.curves) | set(BLOCK_FADING) | set(ALIASES))

    def source(self, channel: str) -> str:
        """How ``channel`` is calibrated, in words (for result files)."""
        if channel in self.curves:
            return f"{channel}: measured codeword curves"
        if channel in BLOCK_FADING:
            base, fade = BLOCK_FADING[channel]
            return f"{channel}: {base} curves averaged over the {fade} block fade"
        if channel in ALIASES:
            return f"{channel}: {ALIASES[channel]} table ({ALIAS_REASONS[channel]})"
        raise KeyError(f"no digital calibration for channel {channel!r}; known: {self.channels}")

    def codeword_bler(self, curve: str, mcs: str, snr_db, coded_bits: int) -> np.ndarray:
        """Probit curve of one codeword of ``coded_bits`` bits at ``snr_db`` (array ok);
        thresholds and slopes interpolate linearly in log2(E) between measured lengths."""
        fits = self.curves[curve][mcs]
        es = sorted(int(e) for e in fits)
        x = math.log2(min(max(coded_bits, es[0]), es[-1]))
        t = np.interp(x, [math.log2(e) for e in es], [fits[str(e)]["t_db"] for e in es])
        s = np.interp(x, [math.log2(e) for e in es], [fits[str(e)]["s_db"] for e in es])
        return q_function((np.asarray(snr_db, dtype=np.float64) - t) / s)

    def image_bler(
        self,
        channel: str,
        mcs: str,
        snr_db: float,
        num_symbols: int,
        snr_error_db: float = 0.0,
    ) -> float:
        """Probability that an image of ``num_symbols`` symbols at ``mcs`` is lost to the
        channel (some codeword fails) at average SNR ``snr_db`` over ``channel``'s fades.

        ``snr_error_db`` > 0: ``snr_db`` is an estimate, the true average SNR is ``snr_db +
        snr_error_db * z`` with z ~ N(0, 1), and the probability is averaged over z (one
        failed codeword still loses the whole image: ``1 - (1 - p)^C`` inside the average).
        """
        key = (channel, mcs, float(snr_db), int(num_symbols), float(snr_error_db))
        if key not in self._blers:
            self._blers[key] = self._image_bler(*key)
        return self._blers[key]

    def _image_bler(
        self, channel: str, mcs: str, snr_db: float, num_symbols: int, snr_error_db: float
    ) -> float:
        self.source(channel)
        if snr_error_db < 0:
            raise ValueError(f"snr_error_db must be >= 0, got {snr_error_db}")
        lay = codeword_layout(int(num_symbols), mcs)
        c, e = lay.num_codewords, lay.coded_bits(0)
        if snr_error_db > 0:
            z, wz = error_grid()
            snrs = float(snr_db) + float(snr_error_db) * z  # [num_error_points]
        else:
            snrs, wz = None, None
        if channel in BLOCK_FADING:
            base, fade = BLOCK_FADING[channel]
            gain_db, w = fade_grid(fade)
            if snrs is not None:  # [num_error_points, num_fade_points]
                p = self.codeword_bler(base, mcs, snrs[:, None] + gain_db[None, :], e)
                w = wz[:, None] * w[None, :]
            else:
                p = self.codeword_bler(base, mcs, float(snr_db) + gain_db, e)
            return float(np.sum(w * -np.expm1(c * np.log1p(-np.minimum(p, 1 - 1e-15)))))
        curve = ALIASES.get(channel, channel)
        if snrs is not None:
            p = self.codeword_bler(curve, mcs, snrs, e)
            return float(np.sum(wz * -np.expm1(c * np.log1p(-np.minimum(p, 1 - 1e-15)))))
        p = float(self.codeword_bler(curve, mcs, float(snr_db), e))
        return float(-math.expm1(c * math.log1p(-min(p, 1 - 1e-15))))

    def psnr_at_bpp(self, image_codec: str, bpp: float, scales=None) -> float:
        """The codec's mean Kodak PSNR at ``bpp``: the best over ``scales`` (default every
        measured one) of each scale's curve, linear in log2 bpp (PSNR(lost) below a curve's
        lowest rate, its highest PSNR above its highest)."""
        if image_codec not in self.rd:
            raise KeyError(
                f"no rate-distortion curve for {image_codec!r}; known: {sorted(self.rd)}"
            )
        best = self.lost_psnr_db
        for scale, pts in self.rd[image_codec].items():
            if scales is not None and int(scale) not in scales:
                continue
            b = np.array([p["bpp"] for p in pts])
            q = np.array([p["psnr_db"] for p in pts])
            order = np.argsort(b)
            b, q = b[order], q[order]
            if bpp >= b[0]:
                best = max(best, float(np.interp(math.log2(bpp), np.log2(b), q)))
        return best

    def expected_psnr(
        self,
        channel: str,
        mcs: str,
        snr_db: float,
        num_symbols: int,
        num_pixels: int,
        image_codec: str = "avif",
        min_bytes=None,
        snr_error_db: float = 0.0,
    ) -> float:
        """E[PSNR] of sending at ``mcs``: (1 - BLER) PSNR(rate) + BLER PSNR(lost).

        ``min_bytes``: ``{scale: bytes}``, the smallest file the codec makes of this image at
        each scale it may be sent at (the transmitter knows them), or one number for the
        full image alone; the scales whose smallest file exceeds the payload capacity are
        out, and with none left the image is lost with certainty. None: every scale of the
        table, at least one byte each. ``snr_error_db``: the estimate's error (BLER averaged
        over it, :meth:`image_bler`).
        """
        if not self.fits(mcs, num_symbols, image_codec, min_bytes):
            return self.lost_psnr_db
        cap = payload_capacity_bits(int(num_symbols), mcs)
        bler = self.image_bler(channel, mcs, snr_db, num_symbols, snr_error_db)
        good = self.psnr_at_bpp(
            image_codec,
            cap / float(num_pixels),
            self._fitting(mcs, num_symbols, image_codec, min_bytes),
        )
        return (1.0 - bler) * good + bler * self.lost_psnr_db

    def fits(self, mcs: str, num_symbols: int, image_codec: str = "avif", min_bytes=None) -> bool:
        """Whether some file of the image fits ``mcs``'s payload in ``num_symbols`` (see
        :meth:`expected_psnr` for ``min_bytes``); False: lost to the budget for certain."""
        return bool(self._fitting(mcs, num_symbols, image_codec, min_bytes))

    def _fitting(self, mcs, num_symbols, image_codec, min_bytes) -> list[int]:
        if min_bytes is None:
            smallest = {int(s): 1 for s in self.rd.get(image_codec, {1: None})}
        elif isinstance(min_bytes, Mapping):
            smallest = dict(min_bytes)
        else:
            smallest = {1: int(min_bytes)}
        cap = payload_capacity_bits(int(num_symbols), mcs)
        return [s for s, b in smallest.items() if cap >= 8 * max(int(b), 1)]

    def image_loss(
        self,
        channel: str,
        mcs: str,
        snr_db: float,
        num_symbols: int,
        image_codec: str = "avif",
        min_bytes=None,
        snr_error_db: float = 0.0,
    ) -> float:
        """The planner's forecast that the image is lost at ``mcs``: 1 when no file fits,
        else :meth:`image_bler` (the probability that a measured fraction of lost images
        should match)."""
        if not self.fits(mcs, num_symbols, image_codec, min_bytes):
            return 1.0
        return self.image_bler(channel, mcs, snr_db, num_symbols, snr_error_db)

    def choose_mcs(
        self,
        channel: str,
        snr_db: float,
        num_symbols: int,
        num_pixels: int,
        image_codec: str = "avif",
        min_bytes=None,
        snr_error_db: float = 0.0,
    ) -> tuple[str, float]:
        """(MCS name, its expected PSNR): the argmax of :meth:`expected_psnr` over
        :data:`phy.digital.MCS_TABLE` (ties: the lower rate). No channel draw is consulted.
        ``snr_db`` is what the transmitter believes; ``snr_error_db`` the standard deviation
        of its belief's error (0: it plans as if it were exact). Answers are memoised per
        argument set."""
        smallest = tuple(sorted(min_bytes.items())) if isinstance(min_bytes, Mapping) else min_bytes
        key = (
            channel,
            float(snr_db),
            int(num_symbols),
            int(num_pixels),
            image_codec,
            smallest,
            float(snr_error_db),
        )
        if key in self._choices:
            return self._choices[key]
        best = None
        for name in MCS_TABLE:
            v = self.expected_psnr(
                channel, name, snr_db, num_symbols, num_pixels, image_codec, min_bytes, snr_error_db
            )
            if best is None or v > best[1] + 1e-9:
                best = (name, v)
        self._choices[key] = best
        return best


@functools.lru_cache(maxsize=4)
def load_calibration(path: str | None = None) -> DigitalCalibration:
    """The shipped table (or one at ``path``)."""
    p = Path(path) if path else CALIBRATION_PATH
    return DigitalCalibration(json.loads(p.read_text()))


def main(argv: list[str] | None = None) -> int:
    """Recompute the table: ``python -m semcodec.digital.calibration --out PATH``."""
    import torch

    p = argparse.ArgumentParser(prog="python -m semcodec.digital.calibration")
    p.add_argument("--out", required=True, help=f"JSON path (the shipped one: {CALIBRATION_PATH})")
    p.add_argument("--kodak", required=True, help="Kodak folder (rate-distortion curves)")
    p.add_argument("--part", choices=("all", "curves", "rd"), default="all")
    p.add_argument("--quick", action="store_true", help="fewer trials (tests, smoke runs)")
    p.add_argument("--max-images", type=int, default=None)
    p.add_argument(
        "--channels", default=",".join(MEASURED), help=f"curves to measure, of {list(MEASURED)}"
    )
    args = p.parse_args(argv)
    channels = args.channels.split(",")
    for ch in channels:
        if ch not in MEASURED:
            p.error(f"--channels: {ch!r} is not one of {list(MEASURED)}")
    torch.set_num_threads(1)
    out = Path(args.out)
    doc = json.loads(out.read_text()) if out.exists() else {}
    doc.setdefault("codeword_curves", {})
    doc["how"] = HOW
    if args.part in ("all", "curves"):
        for ch in channels:
            for mcs in MCS_TABLE:
                for e in measured_lengths(ch, mcs):
                    if str(e) in doc["codeword_curves"].get(ch, {}).get(mcs, {}):
                        continue
                    t0 = time.perf_counter()
                    fit = measure_curve(
                        ch, mcs, e, seed=zlib.crc32(f"{ch}/{mcs}/{e}".encode()), quick=args.quick
                    )
                    doc["codeword_curves"].setdefault(ch, {}).setdefault(mcs, {})[str(e)] = fit
                    print(
                        f"{ch} {mcs} E={e}: t={fit['t_db']:.2f} dB s={fit['s_db']:.3f} "
                        f"({time.perf_counter() - t0:.0f} s)",
                        file=sys.stderr,
                    )
                    write_text(out, json.dumps(doc, indent=1))
    if args.part in ("all", "rd"):
        imgs = kodak_images(Path(args.kodak), args.max_images)
        scales = usable_scales(*imgs[0].shape[1:])
        doc["rate_distortion"] = {
            c: {str(s): measure_rate_distortion(imgs, c, QUALITIES[c], s) for s in scales}
            for c in IMAGE_CODECS
        }
        grey = [psnr(im, torch.full_like(im, 0.5)) for im in imgs]
        doc["lost_psnr_db"] = round(float(np.mean(grey)), 3)
        doc["rd_images"] = f"{len(imgs)} Kodak images"
        write_text(out, json.dumps(doc, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
