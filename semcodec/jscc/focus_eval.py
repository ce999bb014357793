"""What on-demand focus buys: object-region PSNR at equal symbols, and symbols saved.

Compares, over one link, sending the whole image at CBR ``cbr`` against sending only the
feature positions that serve the demanded object (Grad-CAM-style ranking, see
:mod:`semcodec.jscc.focus`) at fractions of the same number of symbols, and finds the smallest
focused budget whose object-region PSNR matches the whole-image one.
"""

from __future__ import annotations

import torch

from common import psnr
from semcodec.jscc.codec import Codec
from semcodec.jscc.link import transmit_jscc


def focus_gain(
    codec: Codec,
    image: torch.Tensor,
    mask: torch.Tensor,
    link,
    snr_db: float,
    cbr: float,
    seed: int = 0,
    fractions=(0.125, 0.25, 0.375, 0.5, 0.75, 1.0),
) -> dict:
    """Whole image vs focus for one image [1, 3, H, W] and object mask [1, 1, H, W].

    Returns a dict with whole_symbols, whole_object_psnr, focus_object_psnr_same_symbols, the
    focused object PSNR per budget fraction, and ``symbols_saved`` = 1 - the smallest
    fraction whose focused object PSNR >= the whole-image one (0 when none does).
    """
    whole = transmit_jscc(
        codec, image, link, snr_db, cbr, generator=torch.Generator().manual_seed(seed)
    )
    p_whole = psnr(whole.images, image, mask)
    curve = []
    for f in fractions:
        res = transmit_jscc(
            codec,
            image,
            link,
            snr_db,
            cbr * f,
            mask=mask,
            generator=torch.Generator().manual_seed(seed),
        )
        curve.append(
            {
                "fraction": f,
                "num_symbols": res.stats["num_symbols"],
                "object_psnr": psnr(res.images, image, mask),
            }
        )
    enough = [r["fraction"] for r in curve if r["object_psnr"] >= p_whole]
    return {
        "snr_db": snr_db,
        "cbr": cbr,
        "whole_symbols": whole.stats["num_symbols"],
        "whole_object_psnr": p_whole,
        "whole_psnr": psnr(whole.images, image, torch.ones_like(mask)),
        "focus_object_psnr_same_symbols": curve[-1]["object_psnr"],
        "focus_curve": curve,
        "object_fraction": float((mask > 0.5).float().mean()),
        "symbols_saved": 1.0 - min(enough) if enough else 0.0,
    }
