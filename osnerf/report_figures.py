"""The run report's pictures: the grid of renders and received views, and the plots (time per
scheme in one set of parts, quality, views), as PNG bytes for ``report.html`` and files."""

from __future__ import annotations

import io
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:  # annotations only: the report imports these pictures
    from osnerf.report import Report


def _fig_png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=100, bbox_inches="tight")
    return buf.getvalue()


def picture_grid(pictures: dict, schemes: list[str], max_views: int = 4) -> bytes:
    """PNG: rows = held-out views; columns = ground truth | novel view of each scheme."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    gt = pictures["gt"]
    n = min(max_views, len(gt))
    cols = ["ground truth"] + [s for s in schemes if s in pictures["renders"]]
    fig, axes = plt.subplots(n, len(cols), figsize=(1.6 * len(cols), 1.6 * n), squeeze=False)
    for r in range(n):
        for c, name in enumerate(cols):
            img = gt[r] if c == 0 else pictures["renders"][name][r]
            axes[r, c].imshow(np.clip(img, 0, 1))
            axes[r, c].set_xticks([])
            axes[r, c].set_yticks([])
            if r == 0:
                axes[r, c].set_title(name if c == 0 else f"{name} (novel)", fontsize=8)
    fig.tight_layout()
    data = _fig_png(fig)
    plt.close(fig)
    return data


def received_grid(pictures: dict, schemes: list[str], max_views: int = 6) -> bytes:
    """PNG: rows = schemes; columns = the first received views."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [s for s in schemes if s in pictures["received"]]
    n = max(1, min(max_views, max(len(pictures["received"][s]) for s in rows)))
    fig, axes = plt.subplots(len(rows), n, figsize=(1.4 * n, 1.5 * len(rows)), squeeze=False)
    for r, s in enumerate(rows):
        rec = pictures["received"][s]
        for c in range(n):
            ax = axes[r, c]
            ax.set_xticks([])
            ax.set_yticks([])
            if c < len(rec):
                ax.imshow(np.clip(rec[c], 0, 1))
            if c == 0:
                ax.set_ylabel(f"{s} (received)", fontsize=8)
    fig.tight_layout()
    data = _fig_png(fig)
    plt.close(fig)
    return data


TIME_PARTS = ("encode + decode", "nerf", "air")
"""The names every scheme's time is drawn under (:func:`time_parts`)."""


def time_parts(seconds: dict) -> dict[str, float]:
    """A scheme's seconds under :data:`TIME_PARTS`: its coding (the codec's encode and decode,
    or a separate scheme's image codec and LDPC, ``codec_and_ldpc``), the NeRF and the air
    time. The first two add up to its ``processing_seconds``."""
    coding = sum(float(seconds.get(k, 0.0)) for k in ("encode", "decode", "codec_and_ldpc"))
    return {
        "encode + decode": coding,
        "nerf": float(seconds.get("nerf", 0.0)),
        "air": float(seconds.get("air", 0.0)),
    }


def plots(report: Report) -> dict[str, bytes]:
    """PNG plots: object PSNR and symbols per scheme; measured SNR and CBR per view."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = {}
    schemes = report.schemes
    names = list(schemes)
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(11, 3))
    a1.bar(names, [schemes[s].psnr_object or 0 for s in names], color="tab:blue")
    a1.set_ylabel("object PSNR (dB)")
    a2.bar(names, [schemes[s].symbols_sent for s in names], color="tab:orange")
    a2.set_ylabel("channel symbols sent")
    bottom = np.zeros(len(names))
    parts = {s: time_parts(schemes[s].seconds) for s in names}
    for key, col in zip(TIME_PARTS, ("tab:green", "tab:purple", "tab:gray")):
        vals = np.asarray([parts[s][key] for s in names])
        a3.bar(names, vals, bottom=bottom, color=col, label=key)
        bottom += vals
    a3.set_ylabel("seconds")
    a3.legend(fontsize=7)
    fig.suptitle(f"{report.scene['name']}, {report.link.channel}, SNR {report.snr_db:g} dB")
    fig.tight_layout()
    out["schemes"] = _fig_png(fig)
    plt.close(fig)
    v = report.views
    ids = list(v.measured_snr_db)
    if ids:
        fig, ax = plt.subplots(figsize=(7, 2.8))
        ax.plot(ids, list(v.link_snr_db.values()), "o-", label="link SNR (dB)")
        ax.plot(ids, list(v.measured_snr_db.values()), "s--", label="measured SNR (dB)")
        ax.set_xlabel("drone view")
        ax.set_ylabel("dB")
        sent = set(v.sent_on_demand)
        ax.plot(
            [i for i in ids if i in sent],
            [v.measured_snr_db[i] for i in ids if i in sent],
            "k*",
            label="sent on demand",
        )
        ax2 = ax.twinx()
        ax2.step(ids, list(v.cbr.values()), "g-", where="mid", label="CBR")
        ax2.set_ylabel("CBR")
        ax.legend(fontsize=7, loc="lower left")
        fig.tight_layout()
        out["views"] = _fig_png(fig)
        plt.close(fig)
    return out
