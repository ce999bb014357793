"""``osnerf run`` as stages, in the order of DESIGN.md's data flow:

scene -> on-demand collector -> SCU plan per view -> each scheme transmits its views ->
a radiance field per scheme on what arrived (in memory) -> scores -> :class:`Report`.

Stages are cached under ``RUN_DIR/cache/<config key>/`` (the plan once, each scheme's
transmission and reconstruction under its own name), so an interrupted run resumes and a
scheme's results do not depend on which other schemes run.
"""

from __future__ import annotations

import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

import renderer
import semcodec
from common import to_hwc, write_png
from osnerf.collect import Collection, Demand
from osnerf.plan import RunPlan
from osnerf.provenance import codec_record, open_codec
from osnerf.report import Report, SchemeReport, ViewsSummary, codec_use_line
from osnerf.run.cache import StageCache
from osnerf.run.compare import comparisons
from osnerf.run.compare import unequal_budgets as unequal_budgets  # where tests read it
from osnerf.run.config import RunConfig
from osnerf.run.links import build_links
from osnerf.run.reconstruct import Reconstruction, received_dataset, reconstruct, view_metrics
from osnerf.scenes import SceneViews, build_scene_dataset, load_scene_views
from osnerf.scheme_types import NerfBudget, RunContext, Scheme, Transmission, scheme_seed
from osnerf.schemes import get_scheme
from osnerf.scu import RatePolicy, SemanticControlUnit
from osnerf.scu.selection import radio_tie
from semcodec import SemanticCodec

METRIC_NOTES = (
    "psnr/ssim/ms_ssim/lpips: mean over held-out views of per-view values on the whole view "
    "(object-routed schemes: against the demanded objects on the background colour, since "
    "they never send the rest of the scene); ms_ssim: pytorch-msssim, null under 161 px; "
    "lpips: AlexNet LPIPS (lower is better); "
    "psnr_object: PSNR over the demanded objects' visible pixels (mask > 0.5) of held-out "
    "views showing them; mask_iou: rendered opacity > 0.5 vs the objects' mask (object-routed "
    "schemes only); air = symbols_sent / symbol_rate_hz; seconds.nerf follows --nerf-clock; "
    "object-routed separate schemes get the on-demand plan's symbol budget per view; "
    "schemes marked (bound) are not real systems; nerf_curve: psnr_object on the held-out "
    "views during NeRF training; comparisons.processing_jscc_over_full_at_equal_psnr_object: "
    "jscc's encode + decode + NeRF seconds until its curve first reaches full's final "
    "psnr_object, over full's processing_seconds (None: never reached)."
)


def _log(msg: str) -> None:
    print(f"[osnerf run] {msg}", file=sys.stderr, flush=True)


@dataclass
class Prepared:
    """What the cheap checks produce before any heavy work."""

    demand: Demand
    schemes: dict[str, Scheme]
    codec: SemanticCodec | None
    rx_codec: SemanticCodec | None
    scu: SemanticControlUnit


def prepare(cfg: RunConfig) -> Prepared:
    """Names, the SNR against the codec's range and the knowledge base (cheap)."""
    demand = cfg.demand_obj()
    schemes = {name: get_scheme(name) for name in cfg.schemes}
    scu = SemanticControlUnit(demand, rate_policy=RatePolicy())
    codec = rx = None
    if any(s.needs_codec for s in schemes.values()):
        codec = open_codec(cfg.codec, cfg.allow_untrained)
        lo, hi = (float(v) for v in codec.snr_range_db)
        if not lo <= cfg.snr_db <= hi:
            raise ValueError(
                f"--snr-db {cfg.snr_db:g} is outside the codec's range [{lo:g}, {hi:g}] dB"
            )
        rx = codec
        if cfg.receiver_codec:
            rx = open_codec(cfg.receiver_codec, cfg.allow_untrained, "--receiver-codec")
        scu.check_knowledge_base(codec.sha256, rx.sha256)
        limits = semcodec.require_capabilities(codec)  # a malformed declaration: one line
        if limits.line():  # what it lacks, before any work (refinement off is reported)
            _log(limits.line())
        rx = semcodec.jscc.for_fusion(rx, cfg.layer_fusion)
    return Prepared(demand, schemes, codec, rx, scu)


def transmit(
    scheme: Scheme, ctx: RunContext, views: SceneViews, col: Collection, cache
) -> Transmission:
    """The scheme's views through the links (cached under its name)."""
    plans = ctx.plan.for_scheme(scheme.object_routed)
    cached = cache.load(f"{scheme.name}_tx")
    if cached is None:
        _log(
            f"{scheme.name}: sending {len(plans)} views over {ctx.send.channel} at "
            f"{ctx.send.snr_db:g} dB"
        )
        pixels = col.images if scheme.object_routed else views.images[[p.view for p in plans]]
        images = torch.from_numpy(np.ascontiguousarray(pixels)).permute(0, 3, 1, 2).float()
        tx = scheme.transmit(ctx, plans, images)
        cache.save(f"{scheme.name}_tx", *tx.to_cache())
        return tx
    return Transmission.from_cache(*cached)


def reconstruct_and_score(
    scheme: Scheme,
    tx: Transmission,
    ctx: RunContext,
    budget: NerfBudget,
    prep: Prepared,
    views,
    col,
    cache,
    out_dir,
) -> tuple[SchemeReport, Reconstruction]:
    """A radiance field on the views that arrived (in memory), trained within ``budget`` and
    scored on the held-out views."""
    plans = ctx.plan.for_scheme(scheme.object_routed)
    arrived = np.ones(len(plans), bool) if tx.received is None else np.asarray(tx.received, bool)
    ids = [p.view for p in plans]
    kept = [v for v, a in zip(ids, arrived) if a]
    aabb = prep.scu.route(scheme.name, scheme.object_routed, kept, views.meta)
    ds = received_dataset(
        tx.images[torch.from_numpy(arrived)],
        views.poses[kept],
        views.intrinsics,
        views.background,
        aabb,
        None if tx.rx_masks is None else tx.rx_masks[arrived],
    )
    cached = cache.load(f"{scheme.name}_nerf")
    if cached is None:
        export_views(Path(out_dir) / "received" / scheme.name, ds)
        _log(f"{scheme.name}: training the radiance field ({budget.describe()})")
        union = np.stack([views.masks[o][views.indices("test")] for o in prep.demand.objects]).max(
            0
        )
        seed = scheme_seed(ctx.send.seed, scheme.name, "nerf")
        rec = reconstruct(ds, views, union, budget, seed, scheme.object_routed)
        cache.save(f"{scheme.name}_nerf", *rec.to_cache())
    else:
        rec = Reconstruction.from_cache(*cached)
    m = dict(rec.metrics)
    n_sym = int(np.sum(tx.symbols))
    seconds = {
        "encode": float(tx.seconds.get("encode", 0.0)),
        "air": n_sym / ctx.send.symbol_rate_hz,
        "decode": float(tx.seconds.get("decode", 0.0)),
        "nerf": float(m.pop("nerf_seconds")),
        **{
            k: float(v)
            for k, v in tx.seconds.items()
            if k in ("encode_cpu", "decode_cpu", "codec_and_ldpc")
        },
    }
    sent = col.images if scheme.object_routed else views.images[ids]
    received = to_hwc(tx.images)
    report = SchemeReport(
        symbols_sent=n_sym,
        views_sent=len(ids),
        seconds=seconds,
        processing_seconds=seconds["encode"]
        + seconds["decode"]
        + seconds["nerf"]
        + seconds.get("codec_and_ldpc", 0.0),
        side_info_bits=tx.side_info_bits,
        views_lost=tx.views_lost,
        failed_codewords=tx.failed_codewords,
        codec_use=tx.codec_use,
        bound=scheme.bound,
        help=scheme.help,
        training_bounds="demanded objects" if scheme.object_routed else "whole scene",
        **view_metrics(received, sent, col.masks if scheme.object_routed else None),
        **m,
    )
    return report, rec


def export_views(folder: Path, ds) -> None:
    """The views a scheme received, as a nerfstudio folder (for people and other tools)."""
    (folder / "images").mkdir(parents=True, exist_ok=True)
    names = []
    for k in range(ds.num_views):
        names.append(f"images/r_{k:03d}.png")
        write_png(folder / names[-1], renderer.to_uint8(ds.images[k]))
    renderer.write_transforms(
        folder / "transforms.json",
        ds.poses,
        ds.intrinsics,
        names,
        ds.aabb,
        {"background": list(ds.background)},
    )


def run_pipeline(
    cfg: RunConfig,
    out_dir: Path,
    cache_dir: Path | None = None,
    prepared: Prepared | None = None,
) -> tuple[Report, dict]:
    """Run every stage (resuming cached ones); returns the :class:`Report` and the pictures.
    ``prepared``: :func:`prepare`'s result when the caller checked the inputs with it."""
    t_run = time.perf_counter()
    prep = prepared if prepared is not None else prepare(cfg)
    cache = StageCache(Path(out_dir) / "cache" / cfg.key())
    t = time.perf_counter()
    folder = build_scene_dataset(
        cfg.scene, prep.demand.objects, cfg.render_config(), cache_dir=cache_dir
    )
    views = load_scene_views(folder)
    scene_seconds = time.perf_counter() - t
    _log(f"scene {cfg.scene}: {len(views.images)} views in {folder} ({scene_seconds:.1f} s)")
    col = prep.scu.collect(views)
    links = build_links(cfg, views, col.candidates)
    try:
        col = choose_views(prep, col, links.snr_db, views, cfg.view_selection, cfg.max_views)
        plan, col = _plan_run(cfg, prep, col, links, views, cache)
        ctx = RunContext(
            cfg.send_settings(),
            links.links,
            plan,
            prep.codec,
            prep.rx_codec,
            np.asarray(views.background, np.float32),
            prep.scu.feature_routing(col),
        )
        budget = cfg.nerf_budget()
        results, received, renders = {}, {}, {}
        for name, scheme in prep.schemes.items():
            tx = transmit(scheme, ctx, views, col, cache)
            results[name], rec = reconstruct_and_score(
                scheme, tx, ctx, budget, prep, views, col, cache, out_dir
            )
            received[name], renders[name] = to_hwc(tx.images), rec.rgb
            _log(
                f"{name}: psnr_object {results[name].psnr_object}, symbols "
                f"{results[name].symbols_sent}"
            )
            if (use := results[name].codec_use) is not None:
                _log(codec_use_line(name, use))
    finally:
        links.close()
    test = views.indices("test")
    report = Report(
        scene=scene_summary(cfg.scene, cfg.ground_station_m, folder, views, col),
        demand={"objects": list(prep.demand.objects), "weights": list(prep.demand.weights)},
        link=links.report,
        snr_db=cfg.snr_db,
        symbol_rate_hz=cfg.symbol_rate_hz,
        codec=(None if prep.codec is None else codec_summary(prep, cfg.codec, cfg.receiver_codec)),
        views=views_summary(plan, col),
        schemes=results,
        comparisons=_flag(comparisons(results, prep.schemes)),
        scu_decisions=prep.scu.decisions,
        metric_notes=METRIC_NOTES,
        seconds_total=time.perf_counter() - t_run,
        scene_seconds=scene_seconds,
    )
    gt_masks = np.stack([views.masks[o][test] for o in prep.demand.objects]).max(0)
    return report, {
        "gt": views.images[test],
        "gt_masks": gt_masks,
        "received": received,
        "renders": renders,
    }


def _plan_run(cfg: RunConfig, prep: Prepared, col: Collection, links, views, cache):
    """The SCU's plan of every view (cached), within the codec's CBR and SNR ranges."""
    codec = prep.codec
    return prep.scu.plan_run(
        collection=col,
        links=links,
        cbr_range=_range(codec.cbr_range) if codec is not None else (1 / 48, 1 / 6),
        snr_range_db=_range(codec.snr_range_db) if codec is not None else (-10.0, 20.0),
        height=views.intrinsics.height,
        width=views.intrinsics.width,
        seed=cfg.seed,
        cache=cache,
        plan_snr_db=cfg.plan_snr_db,
        snr_error_db=cfg.snr_error_db,
    )


def choose_views(
    prep: Prepared, col: Collection, snr_db: dict, views, selection: str, max_views: int | None
) -> Collection:
    """The SCU's choice among the collected views (``--view-selection``, ``--max-views``);
    the default (sight, no count) keeps every view untouched."""
    if selection == "sight" and max_views is None:
        return col

    tie = radio_tie(selection, [snr_db[int(v)] for v in col.indices if int(v) in snr_db])
    if tie is not None:
        _log(f"warning: {tie}")
    directions = view_directions(views, prep.demand.objects)
    return prep.scu.choose_views(col, snr_db, directions, selection, max_views)


def view_directions(views: SceneViews, objects) -> dict[int, np.ndarray]:
    """view -> [3] from the centre of the objects' bounds to the view's drone (metres)."""
    b = np.asarray([views.meta["object_aabb"][o] for o in objects], np.float64)  # [k, 2, 3]
    centre = (b[:, 0].min(0) + b[:, 1].max(0)) / 2
    return {k: p - centre for k, p in enumerate(views.drone_positions_m)}


def scene_summary(scene: str, ground_station_m, folder, views: SceneViews, col: Collection) -> dict:
    """The scene as the report shows it (``ground_station_m``: the run's, or None for the
    scene's own)."""
    return {
        "name": scene,
        "folder": str(folder),
        "objects": list(views.objects),
        "num_train_views": int(len(col.candidates)),
        "num_test_views": int(len(views.indices("test"))),
        "resolution_px": [views.intrinsics.height, views.intrinsics.width],
        "render_seconds": views.meta.get("render_seconds"),
        "ground_station_m": list(ground_station_m or views.meta["ground_station_m"]),
    }


def _range(pair) -> tuple[float, float]:
    lo, hi = pair
    return float(lo), float(hi)


def codec_summary(prep: Prepared, codec_spec: str | None, receiver_spec: str | None) -> dict:
    """The codec as the report shows it: its record (:func:`osnerf.provenance.codec_record`:
    knowledge-base identity, trained or not, a plugin's distribution), its ranges, and the
    receiver's record when ``receiver_spec`` names one (None: the same codec)."""
    codec = prep.codec
    assert codec is not None  # called for runs with a codec only
    receiver = None
    if receiver_spec is not None:
        receiver = codec_record(prep.rx_codec, receiver_spec)
    return {
        **codec_record(codec, codec_spec),
        "cbr_range": list(codec.cbr_range),
        "snr_range_db": list(codec.snr_range_db),
        "receiver": receiver,
    }


def _flag(comp: dict) -> dict:
    for line in [*comp.get("unequal_budgets", []), *comp.get("nothing_arrived", [])]:
        _log(f"warning: {line}")
    return comp


def views_summary(plan: RunPlan, col: Collection) -> ViewsSummary:
    """The per-view plan as the report shows it."""
    whole, sent = plan.views, plan.on_demand()
    return ViewsSummary(
        candidates=[int(v) for v in col.candidates],
        sent_on_demand=[p.view for p in sent],
        not_sent={int(k): v for k, v in sorted(col.reasons.items())},
        outage=list(plan.outage),
        link_snr_db={p.view: p.link.snr_db for p in whole},
        measured_snr_db={p.view: p.link.measured_snr_db for p in whole},
        cbr={p.view: p.whole.cbr for p in whole},
        cbr_on_demand={p.view: p.focus.cbr for p in sent if p.focus is not None},
        repetitions={p.view: p.whole.repetitions for p in whole},
        repetitions_on_demand={p.view: p.focus.repetitions for p in sent if p.focus is not None},
        object_oversampling=plan.oversampling,
        full_scene_symbols=plan.full_scene_symbols,
        plan=list(plan.views),
    )
