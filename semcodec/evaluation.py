"""Scheme registry and per-image scoring for ``osnerf eval-codec`` and the benchmark.

:data:`SCHEMES`: name -> function(ctx, image [1, 3, H, W], snr_db, cbr, generator) ->
TransmitResult. One table; unknown names raise KeyError listing the known ones.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from phy import num_symbols_for_cbr
from semcodec.baselines import (
    ENVELOPE,
    TransmitResult,
    transmit_analog,
    transmit_digital,
    transmit_ideal,
    transmit_jscc,
)
from semcodec.codec import MIN_SIDE_PX, Codec
from semcodec.image_codecs import read_image_file

EVAL_CHANNELS = ("awgn", "rayleigh")
DEFAULT_FIXED_MCS = "16qam-1/2"


@dataclass
class EvalContext:
    """What the schemes share: codec, links, fixed MCS."""

    channel: str
    codec: Codec | None = None
    fixed_mcs: str = DEFAULT_FIXED_MCS
    links: dict = field(default_factory=dict)

    def link(self, equalizer: str):
        """phy.FlatLink over AWGN or Rayleigh block fading with perfect CSI."""
        if equalizer not in self.links:
            import phy

            self.links[equalizer] = phy.FlatLink(
                phy.make_channel(self.channel), csi="perfect", equalizer=equalizer
            )
        return self.links[equalizer]


def _n(img, cbr) -> int:
    return num_symbols_for_cbr(cbr, img.shape[2], img.shape[3])


def _jscc(ctx, img, snr, cbr, gen):
    return transmit_jscc(ctx.codec, img, ctx.link("mmse"), snr, cbr, generator=gen)


def _digital(codec_name, mcs_attr=None):
    def run(ctx, img, snr, cbr, gen):
        mcs = getattr(ctx, mcs_attr) if mcs_attr else ENVELOPE
        return transmit_digital(
            img, ctx.link("zf"), snr, _n(img, cbr), mcs=mcs, image_codec=codec_name, generator=gen
        )

    return run


def _ideal(codec_name):
    def run(ctx, img, snr, cbr, gen):
        return transmit_ideal(img, snr, _n(img, cbr), image_codec=codec_name)

    return run


def _analog(ctx, img, snr, cbr, gen):
    return transmit_analog(img, ctx.link("mmse"), snr, _n(img, cbr), generator=gen)


SCHEMES: dict[str, Callable[..., TransmitResult]] = {
    "jscc": _jscc,
    "digital": _digital("avif"),
    "digital_fixed": _digital("avif", "fixed_mcs"),
    "ideal": _ideal("avif"),
    "analog": _analog,
    "digital_webp": _digital("webp"),
    "digital_jpeg": _digital("jpeg"),
    "ideal_webp": _ideal("webp"),
    "ideal_jpeg": _ideal("jpeg"),
}


def parse_schemes(text: str) -> list[str]:
    names = [s.strip() for s in str(text).split(",") if s.strip()]
    if not names:
        raise ValueError(f"--schemes must list at least one of {sorted(SCHEMES)}")
    for s in names:
        if s not in SCHEMES:
            raise KeyError(f"--schemes: unknown scheme {s!r}; known: {sorted(SCHEMES)}")
    return names


def load_image_folder(folder: str | Path) -> tuple[list[str], list[torch.Tensor]]:
    """Every PNG/JPEG of a folder as [1, 3, H, W] float32 in [0, 1]; one-line errors on bad files."""
    folder = Path(folder)
    if not folder.is_dir():
        raise FileNotFoundError(f"--images folder not found: {folder}")
    paths = sorted(p for p in folder.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg"))
    if not paths:
        raise FileNotFoundError(f"--images folder {folder} holds no PNG/JPEG files")
    names, images = [], []
    for p in paths:
        try:
            im = read_image_file(p)
        except ValueError as e:
            raise ValueError(f"--images: {e}") from None
        mode, a = im.mode, np.asarray(im)
        if mode != "RGB":
            raise ValueError(
                f"--images: {p.name} is not RGB (mode {mode}); convert it to 8-bit RGB"
            )
        if min(a.shape[:2]) < MIN_SIDE_PX:
            raise ValueError(
                f"--images: {p.name} is {a.shape[1]}x{a.shape[0]} px; images must be at least {MIN_SIDE_PX}x{MIN_SIDE_PX}"
            )
        names.append(p.name)
        images.append(
            torch.from_numpy(a.astype(np.float32) / 255.0).permute(2, 0, 1)[None].contiguous()
        )
    return names, images


def psnr(x: torch.Tensor, y: torch.Tensor) -> float:
    """PSNR in dB with peak 1.0 of one image pair [1, 3, H, W]."""
    mse = float(((x.clamp(0, 1) - y) ** 2).mean())
    return float(10 * np.log10(1.0 / max(mse, 1e-12)))


def ssim(x: torch.Tensor, y: torch.Tensor) -> float:
    """SSIM (scikit-image, Gaussian weights as Wang et al.) of one image pair [1, 3, H, W]."""
    from skimage.metrics import structural_similarity

    a = x[0].clamp(0, 1).permute(1, 2, 0).numpy()
    b = y[0].permute(1, 2, 0).numpy()
    return float(
        structural_similarity(
            a,
            b,
            channel_axis=2,
            data_range=1.0,
            gaussian_weights=True,
            sigma=1.5,
            use_sample_covariance=False,
        )
    )
