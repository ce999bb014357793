"""The run report: ``report.json``, a picture grid, plots, and ``report.html`` (pictures inline).

``report.json`` = ``result_header(config, seed)`` (config, seed, git_commit, versions) plus
the pipeline's dict, whose ``schemes`` maps each scheme to ``psnr``, ``psnr_object``,
``ssim``, ``symbols_sent`` and ``seconds`` (``encode``, ``air``, ``decode``, ``nerf``).
"""

from __future__ import annotations

import base64
import html
import io
from pathlib import Path

import numpy as np

from osnerf.provenance import result_header, write_json_atomic


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


def plots(report: dict) -> dict[str, bytes]:
    """PNG plots: object PSNR and symbols per scheme; measured SNR and CBR per view."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out = {}
    schemes = report["schemes"]
    names = list(schemes)
    fig, (a1, a2, a3) = plt.subplots(1, 3, figsize=(11, 3))
    a1.bar(names, [schemes[s]["psnr_object"] or 0 for s in names], color="tab:blue")
    a1.set_ylabel("object PSNR (dB)")
    a2.bar(names, [schemes[s]["symbols_sent"] for s in names], color="tab:orange")
    a2.set_ylabel("channel symbols sent")
    bottom = np.zeros(len(names))
    for key, col in (
        ("encode", "tab:green"),
        ("decode", "tab:red"),
        ("nerf", "tab:purple"),
        ("air", "tab:gray"),
    ):
        vals = np.asarray([schemes[s]["seconds"].get(key, 0.0) for s in names])
        a3.bar(names, vals, bottom=bottom, color=col, label=key)
        bottom += vals
    a3.set_ylabel("seconds")
    a3.legend(fontsize=7)
    fig.suptitle(
        f"{report['scene']['name']}, {report['link']['channel']}, SNR {report['snr_db']:g} dB"
    )
    fig.tight_layout()
    out["schemes"] = _fig_png(fig)
    plt.close(fig)
    v = report["views"]
    ids = [int(k) for k in v["measured_snr_db"]]
    if ids:
        fig, ax = plt.subplots(figsize=(7, 2.8))
        ax.plot(ids, list(v["link_snr_db"].values()), "o-", label="link SNR (dB)")
        ax.plot(ids, list(v["measured_snr_db"].values()), "s--", label="measured SNR (dB)")
        ax.set_xlabel("drone view")
        ax.set_ylabel("dB")
        sent = set(v["sent_on_demand"])
        ax.plot(
            [i for i in ids if i in sent],
            [v["measured_snr_db"][str(i)] for i in ids if i in sent],
            "k*",
            label="sent on demand",
        )
        ax2 = ax.twinx()
        ax2.step(ids, list(v["cbr"].values()), "g-", where="mid", label="CBR")
        ax2.set_ylabel("CBR")
        ax.legend(fontsize=7, loc="lower left")
        fig.tight_layout()
        out["views"] = _fig_png(fig)
        plt.close(fig)
    return out


def _img(data: bytes, alt: str) -> str:
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{base64.b64encode(data).decode()}"/>'


def render_html(report: dict, images: dict[str, bytes]) -> str:
    """A self-contained HTML page (pictures as base64 data URIs)."""
    s = report["schemes"]
    keys = [
        "psnr",
        "psnr_object",
        "ssim",
        "mask_iou",
        "symbols_sent",
        "views_sent",
        "processing_seconds",
    ]
    rows = "".join(
        "<tr><td>"
        + html.escape(n)
        + "</td>"
        + "".join(
            f"<td>{v:.3f}</td>"
            if isinstance(v := s[n].get(k), float)
            else f"<td>{html.escape(str(v))}</td>"
            for k in keys
        )
        + "".join(
            f"<td>{s[n]['seconds'].get(k, 0.0):.2f}</td>"
            for k in ("encode", "air", "decode", "nerf")
        )
        + "</tr>"
        for n in s
    )
    head = "".join(
        f"<th>{k}</th>" for k in ["scheme", *keys, "encode s", "air s", "decode s", "nerf s"]
    )
    comp = "".join(
        f"<li>{html.escape(k)}: {'n/a' if v is None else f'{v:.3f}'}</li>"
        for k, v in report.get("comparisons", {}).items()
    )
    dec = "".join(
        f"<li><b>{html.escape(d['stage'])}</b>: {html.escape(d['decision'])}</li>"
        for d in report.get("scu_decisions", [])
    )
    pics = "".join(f"<h3>{html.escape(k)}</h3>{_img(v, k)}" for k, v in images.items())
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>osnerf run: {html.escape(report["scene"]["name"])}</title>
<style>body{{font-family:sans-serif;max-width:1100px;margin:auto}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:3px 6px;font-size:13px}}img{{max-width:100%}}</style></head><body>
<h1>osnerf run: {html.escape(report["scene"]["name"])}</h1>
<p>demand {html.escape(", ".join(report["demand"]["objects"]))}; channel {html.escape(str(report["link"]["channel"]))};
SNR {report["snr_db"]:g} dB; seed {report.get("seed")}; commit {html.escape(str(report.get("git_commit")))};
symbol rate {report["symbol_rate_hz"]:g} Hz.</p>
<table><tr>{head}</tr>{rows}</table><ul>{comp}</ul>
<p>{html.escape(report.get("metric_notes", ""))}</p>{pics}
<h2>Semantic control unit decisions</h2><ol>{dec}</ol></body></html>
"""


def write_report(out_dir: Path, config: dict, seed: int, body: dict, pictures: dict) -> dict:
    """Write report.json, grid.png, received.png, plots and report.html into ``out_dir``."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    report = {**result_header(config, seed), **body}
    names = list(body["schemes"])
    images = {
        "novel views (held out)": picture_grid(pictures, names),
        "received views": received_grid(pictures, names),
    }
    for k, v in plots(report).items():
        images[f"plot: {k}"] = v
    files = {
        "novel views (held out)": "grid.png",
        "received views": "received.png",
        "plot: schemes": "plot_schemes.png",
        "plot: views": "plot_views.png",
    }
    for k, data in images.items():
        (out_dir / files[k]).write_bytes(data)
    (out_dir / "report.html").write_text(render_html(report, images))
    write_json_atomic(out_dir / "report.json", report)
    return report
