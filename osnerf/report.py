"""The run report: one schema (:class:`Report`, :class:`SchemeReport`) and its files:
``report.json``, a picture grid, plots, and ``report.html`` (pictures inline).

``report.json`` = ``result_header(config, seed)`` (config, seed, git_commit, versions) plus
``Report.to_dict()``. The CLI, ``osnerf sweep``'s metric rules and the plots read it back
with :meth:`Report.from_dict`. View ids are ints in the types; the JSON's string keys exist
only in ``to_dict`` / ``from_dict``.
"""

from __future__ import annotations

import base64
import dataclasses
import html
import statistics
from dataclasses import asdict, dataclass, field
from pathlib import Path

from common import path_kind, to_json, write_files
from osnerf.link_report import LinkReport
from osnerf.plan import ViewPlan
from osnerf.provenance import result_header
from osnerf.report_figures import picture_grid, plots, received_grid

QUALITY_METRICS = ("psnr", "ssim", "ms_ssim", "lpips", "psnr_object")
"""Per-scheme quality metrics of a run (LPIPS: lower is better)."""


@dataclass
class SchemeReport:
    """One scheme's result in a run.

    Attributes:
        psnr, ssim, lpips: held-out novel views, whole view (object-routed schemes against
            the demanded objects on the background colour).
        ms_ssim: MS-SSIM of the same (pytorch-msssim, five scales); None when the views are
            under 161 px a side.
        psnr_object: over the demanded objects' pixels of held-out views showing them.
        mask_iou: rendered opacity vs the objects' mask (object-routed schemes only).
        symbols_sent, views_sent: what crossed the channel; side_info_bits: focus side info.
        views_lost: {"budget": n, "channel": m} for separate (digital) schemes, else None.
        failed_codewords: LDPC codewords that failed (digital), else None.
        seconds: encode, air, decode, nerf (and encode_cpu, decode_cpu, codec_and_ldpc).
        processing_seconds: encode + decode + NeRF (+ codec and LDPC).
        psnr_received, psnr_received_object: the received views against what was sent.
        nerf_steps, nerf_curve, nerf_wall_seconds: the radiance field's training.
        bound: None, or what this scheme bounds (not a real system).
        training_bounds: "demanded objects" or "whole scene".
        codec_use: semantic schemes: the codec's declared limits, refinement on or off (and
            why), symbols sent against the plan's budget (``osnerf.semantic_send.codec_use``).
        renderers: None (skipped), or for the full render and the learned renderer
            ("full", "features" of ``renderer.RENDERERS``) on the held-out views in order:
            psnr_object (as above), seconds_per_view (one thread), setup_seconds and
            setup_cpu_seconds
            (distilling the learned renderer), setup_stats (its steps and teachers),
            speedup_vs_full, settings; psnr and ssim (against the ground-truth views) for
            whole-scene schemes only.
    """

    psnr: float
    ssim: float
    lpips: float | None
    psnr_object: float | None
    mask_iou: float | None
    symbols_sent: int
    views_sent: int
    seconds: dict
    processing_seconds: float
    side_info_bits: int = 0
    views_lost: dict | None = None
    failed_codewords: int | None = None
    psnr_received: float | None = None
    psnr_received_object: float | None = None
    num_test_views: int = 0
    num_test_views_with_object: int = 0
    nerf_steps: int = 0
    nerf_curve: list = field(default_factory=list)
    nerf_wall_seconds: float = 0.0
    bound: str | None = None
    training_bounds: str = "demanded objects"
    help: str = ""
    renderers: dict | None = None
    ms_ssim: float | None = None
    codec_use: dict | None = None


_VIEW_MAPS = (
    "not_sent",
    "link_snr_db",
    "measured_snr_db",
    "cbr",
    "cbr_on_demand",
    "repetitions",
    "repetitions_on_demand",
)
"""The :class:`ViewsSummary` fields keyed by view id (string keys in JSON only)."""


@dataclass
class ViewsSummary:
    """The per-view plan as the report shows it (view ids as ints).

    Attributes:
        candidates: every view considered; sent_on_demand: the on-demand views.
        not_sent: view -> why the collector skipped it; outage: views without a path.
        link_snr_db, measured_snr_db, cbr, repetitions: per view not in outage (the whole
            view's part of the plan).
        cbr_on_demand, repetitions_on_demand: per on-demand view (its on-demand part).
        object_oversampling: the plan's oversampling of on-demand views.
        full_scene_symbols: what sending every view whole costs.
        plan: the SCU's plan of every candidate view not in outage.
    """

    candidates: list[int] = field(default_factory=list)
    sent_on_demand: list[int] = field(default_factory=list)
    not_sent: dict[int, str] = field(default_factory=dict)
    outage: list[int] = field(default_factory=list)
    link_snr_db: dict[int, float] = field(default_factory=dict)
    measured_snr_db: dict[int, float] = field(default_factory=dict)
    cbr: dict[int, float] = field(default_factory=dict)
    cbr_on_demand: dict[int, float] = field(default_factory=dict)
    repetitions: dict[int, int] = field(default_factory=dict)
    repetitions_on_demand: dict[int, int] = field(default_factory=dict)
    object_oversampling: int = 1
    full_scene_symbols: int = 0
    plan: list[ViewPlan] = field(default_factory=list)

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        for k in _VIEW_MAPS:
            d[k] = {str(v): x for v, x in d[k].items()}
        d["plan"] = [p.to_dict() for p in self.plan]
        return d

    @classmethod
    def from_dict(cls, d: dict) -> ViewsSummary:
        body = {f.name: d[f.name] for f in dataclasses.fields(cls) if f.name in d}
        for k in _VIEW_MAPS:
            if k in body:
                body[k] = {int(v): x for v, x in body[k].items()}
        plans = body.get("plan", [])  # reports before the typed plan listed outage views too
        body["plan"] = [ViewPlan.from_dict(p) for p in plans if not p.get("outage")]
        return cls(**body)


@dataclass
class Report:
    """Everything ``osnerf run`` reports (besides the provenance header)."""

    scene: dict
    demand: dict
    link: LinkReport
    snr_db: float
    symbol_rate_hz: float
    codec: dict | None
    views: ViewsSummary
    schemes: dict[str, SchemeReport]
    comparisons: dict
    scu_decisions: list
    metric_notes: str
    seconds_total: float
    scene_seconds: float

    def to_dict(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["schemes"] = {n: asdict(r) for n, r in self.schemes.items()}
        d["views"] = self.views.to_dict()
        d["link"] = self.link.to_dict()
        return d

    @classmethod
    def from_dict(cls, d: dict) -> Report:
        """Read a ``report.json`` dict (extra header keys are ignored)."""
        names = {f.name for f in dataclasses.fields(cls)}
        missing = names - set(d)
        if missing:
            raise ValueError(f"not an osnerf run report: missing {', '.join(sorted(missing))}")
        body = {k: v for k, v in d.items() if k in names}
        sfields = {f.name for f in dataclasses.fields(SchemeReport)}
        body["schemes"] = {
            n: SchemeReport(**{k: v for k, v in s.items() if k in sfields})
            for n, s in d["schemes"].items()
        }
        body["views"] = ViewsSummary.from_dict(d["views"])
        body["link"] = LinkReport.from_dict(d["link"])
        return cls(**body)


def _img(data: bytes, alt: str) -> str:
    src = base64.b64encode(data).decode()
    return f'<img alt="{html.escape(alt)}" src="data:image/png;base64,{src}"/>'


def codec_use_line(scheme: str, use: dict) -> str:
    """One line of what a semantic scheme did with its codec: refinement on or off (and
    why), symbols sent against the budget."""
    ref = use["refinement"]
    state = f"on ({ref['why']})" if ref["on"] else f"off ({ref['why']})"
    return (
        f"{scheme}: codec {use['codec']}: refinement {state}; {use['symbols_sent']} symbols sent "
        f"of a {use['symbol_budget']} budget ({use['symbols_unused']} unused)"
    )


def motion_summary(link: LinkReport) -> str:
    """The drones' speed and Doppler in words (a ray-traced run's link, in the air or over
    it), else ``""``."""
    moving = link.motion or link.traced_air
    if moving is None:
        return ""
    spread = moving.median_rms_doppler_spread_hz
    return (
        f"drone speed {moving.drone_speed_m_s:g} m/s, max Doppler "
        f"{moving.max_doppler_hz:.1f} Hz, median RMS Doppler spread "
        + ("n/a" if spread is None else f"{spread:.1f} Hz")
    )


def position_summary(link: LinkReport) -> str:
    """Where a ray-traced run's radio ends were, in words, else ``""``."""
    at = link.positions
    if at is None:
        return ""
    gs = ", ".join(f"{v:g}" for v in at.ground_station_m)
    dist = list(at.distance_to_ground_station_m.values())
    return (
        f"ground station at ({gs}) m ({at.ground_station_from}), drone ring radius "
        f"{at.drone_ring['radius_m']:.2f} m"
        + (f", median drone distance {statistics.median(dist):.1f} m" if dist else "")
    )


HTML_COLUMNS = (
    "psnr",
    "psnr_object",
    "ssim",
    "ms_ssim",
    "lpips",
    "mask_iou",
    "symbols_sent",
    "views_sent",
    "processing_seconds",
)
"""The schemes' columns of ``report.html``, in order (then the seconds of each part)."""


def _scheme_rows(report: Report) -> tuple[str, str]:
    """(the header row's cells, one table row per scheme) of ``report.html``."""
    s = {n: asdict(r) for n, r in report.schemes.items()}
    keys = list(HTML_COLUMNS)
    rows = "".join(
        "<tr><td>"
        + html.escape(n + (" (bound)" if s[n]["bound"] else ""))
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
    return head, rows


def render_html(report: Report, header: dict, images: dict[str, bytes]) -> str:
    """A self-contained HTML page (pictures as base64 data URIs)."""
    motion = "; ".join(t for t in (motion_summary(report.link), position_summary(report.link)) if t)
    head, rows = _scheme_rows(report)
    comp = (
        "".join(
            f"<li>{html.escape(k)}: {'n/a' if v is None else f'{v:.3f}'}</li>"
            for k, v in report.comparisons.items()
            if not isinstance(v, list)
        )
        + "".join(
            f"<li><b>unfair</b>: {html.escape(line)}</li>"
            for line in report.comparisons.get("unequal_budgets", [])
        )
        + "".join(
            f"<li><b>no comparison</b>: {html.escape(line)}</li>"
            for line in report.comparisons.get("nothing_arrived", [])
        )
    )
    bounds = "".join(
        f"<li>{html.escape(n)} is a bound, not a real system: {html.escape(r.bound)}</li>"
        for n, r in report.schemes.items()
        if r.bound
    )
    bounds += "".join(
        f"<li>{html.escape(codec_use_line(n, r.codec_use))}</li>"
        for n, r in report.schemes.items()
        if r.codec_use
    )
    dec = "".join(
        f"<li><b>{html.escape(d['stage'])}</b>: {html.escape(d['decision'])}</li>"
        for d in report.scu_decisions
    )
    pics = "".join(f"<h3>{html.escape(k)}</h3>{_img(v, k)}" for k, v in images.items())
    name = html.escape(report.scene["name"])
    demand = html.escape(", ".join(report.demand["objects"]))
    channel = html.escape(report.link.channel)
    commit = html.escape(str(header.get("git_commit")))
    moving = "; " + html.escape(motion) if motion else ""
    style = (
        "body{font-family:sans-serif;max-width:1100px;margin:auto}table{border-collapse:collapse}"
        "\ntd,th{border:1px solid #ccc;padding:3px 6px;font-size:13px}img{max-width:100%}"
    )
    return f"""<!doctype html><html><head><meta charset="utf-8"><title>osnerf run: {name}</title>
<style>{style}</style></head><body>
<h1>osnerf run: {name}</h1>
<p>demand {demand}; channel {channel};
SNR {report.snr_db:g} dB; seed {header.get("seed")}; commit {commit};
symbol rate {report.symbol_rate_hz:g} Hz{moving}.</p>
<table><tr>{head}</tr>{rows}</table><ul>{bounds}</ul><ul>{comp}</ul>
<p>{html.escape(report.metric_notes)}</p>{pics}
<h2>Semantic control unit decisions</h2><ol>{dec}</ol></body></html>
"""


REPORT_PICTURES = {
    "novel views (held out)": "grid.png",
    "received views": "received.png",
    "plot: schemes": "plot_schemes.png",
    "plot: views": "plot_views.png",
}
"""Picture title -> its file beside ``report.json``."""


def write_report(out_dir: Path, config: dict, seed: int, report: Report, pictures: dict) -> dict:
    """Write report.json, grid.png, received.png, plots and report.html into ``out_dir``.

    The files are one set (:func:`common.write_files`): every byte is made in memory and
    written before any file is replaced, report.json last; a full disk raises one
    ``OSError`` naming the file and leaves the previous report whole. A picture that this
    report has no data for (``plot_views.png`` without per-view measurements) is removed
    once the new set is in place, so no picture of an earlier run stays beside it.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    header = result_header(config, seed)
    names = list(report.schemes)
    images = {
        "novel views (held out)": picture_grid(pictures, names),
        "received views": received_grid(pictures, names),
    }
    for k, v in plots(report).items():
        images[f"plot: {k}"] = v
    full = {**header, **report.to_dict()}
    files = {out_dir / REPORT_PICTURES[k]: data for k, data in images.items()}
    files[out_dir / "report.html"] = render_html(report, header, images).encode("utf-8")
    files[out_dir / "report.json"] = to_json(full).encode("utf-8")
    write_files(files)
    for k, name in REPORT_PICTURES.items():
        if k not in images and path_kind(out_dir / name) == "a file":
            (out_dir / name).unlink()
    return full
