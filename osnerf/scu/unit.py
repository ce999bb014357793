"""The semantic control unit (SCU): it decides, and the pipeline carries out what it
decides. It turns the demand into collector and encoder settings, measures each link with
pilots, and returns one typed :class:`osnerf.plan.ViewPlan` per view with a propagation path
(measured link, whole-view and on-demand parts); it checks the knowledge base (both ends hold the
same codec) and routes each scheme's views to the renderer. It owns its decision log
(``SemanticControlUnit.decisions``), cached with the plan, which ends up in the report.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np
import torch

import phy
from osnerf.collect import Collection, CollectorConfig, Demand, collect
from osnerf.plan import Allocation, RunPlan, ViewLink, ViewPlan
from osnerf.scheme_types import scheme_seed
from osnerf.scu.policy import RatePolicy, combined_snr_db, transmitter_estimate
from osnerf.scu.selection import choose_views
from semcodec import KnowledgeBaseMismatch as KnowledgeBaseError  # the one error
from semcodec.contract import box_side_symbols
from semcodec.jscc import BLOCK_PX, focus_coverage, full_rate_symbols


@dataclass
class SemanticControlUnit:
    """Drives one run: turns the demand into settings and logs why.

    Attributes:
        demand: the user's objects and weights.
        collector: the collector settings it chose.
        rate_policy: CBR per measured SNR.
        decisions: the log (one dict per decision: ``stage``, ``decision``, details).
    """

    demand: Demand
    collector: CollectorConfig = field(default_factory=CollectorConfig)
    rate_policy: RatePolicy = field(default_factory=RatePolicy)
    decisions: list[dict] = field(default_factory=list)

    def log(self, stage: str, decision: str, **details) -> None:
        self.decisions.append({"stage": stage, "decision": decision, **details})

    def collector_settings(self) -> CollectorConfig:
        """Collector settings for the demand (logged)."""
        self.log(
            "collector",
            f"send views where one of {', '.join(self.demand.objects)} is visible enough",
            **asdict(self.collector),
            demand=str(self.demand),
        )
        return self.collector

    def collect(self, views) -> Collection:
        """The on-demand collector's views for the demand, with why each other view is not
        sent (logged)."""
        col = collect(views, self.demand, self.collector_settings())
        for v, why in sorted(col.reasons.items()):
            self.log("collector", f"view {v}: not sent", view=v, reason=why)
        self.log(
            "collector",
            f"send {col.num_sent} of {len(col.candidates)} views",
            views=col.indices.tolist(),
        )
        return col

    def choose_views(
        self, collection: Collection, snr_db: dict, directions_m: dict, rule: str, max_views
    ) -> Collection:
        """At most ``max_views`` of the collection's views by ``rule``, each logged with why
        (:func:`osnerf.scu.selection.choose_views`)."""
        return choose_views(self.log, collection, snr_db, directions_m, rule, max_views)

    def check_knowledge_base(self, transmitter_sha256: str, receiver_sha256: str) -> None:
        """Refuse to run when the two ends hold different codecs.

        Raises:
            KnowledgeBaseError: the hashes differ (names both, short).
        """
        if transmitter_sha256 != receiver_sha256:
            self.log(
                "knowledge_base",
                "refused",
                transmitter=transmitter_sha256,
                receiver=receiver_sha256,
            )
            raise KnowledgeBaseError(
                f"knowledge-base mismatch: transmitter codec sha256 {transmitter_sha256[:12]} != "
                f"receiver codec sha256 {receiver_sha256[:12]}; load the same checkpoint on both "
                "ends"
            )
        self.log("knowledge_base", "agreed", sha256=transmitter_sha256)

    def feature_routing(self, collection: Collection) -> tuple[torch.Tensor, tuple[float, ...]]:
        """Encoder routing for the selected views: per-object masks [n, K, h, w] and the K
        demand weights (the codec's focus mode keeps the feature positions they weigh most)."""
        m = torch.from_numpy(collection.object_masks).float()
        self.log(
            "encoder",
            "route features of the demanded objects (focus mode)",
            views=collection.indices.tolist(),
            weights=list(self.demand.weights),
            mean_mask_fraction=float(collection.masks.mean()),
        )
        return m, self.demand.weights

    def focus_cbr(
        self,
        masks: np.ndarray,
        cbr_range: tuple[float, float],
        views,
        block_px: int = BLOCK_PX,
        oversampling: int = 1,
        scale: float = 1.0,
    ) -> np.ndarray:
        """CBR per on-demand view: every feature position (``block_px`` square) touching the
        objects' mask with all of the codec's channels, times ``scale``, i.e. ``scale *
        coverage * max_cbr``, at most the codec's largest CBR and at least what carries the focus
        box's side information and one symbol (focus mode takes any rate below the largest;
        logged per view).

        Args:
            masks: [num_views, height, width] union masks of the demanded objects.
            oversampling: the views are encoded upsampled by this factor (the CBR refers to
                the upsampled image).
            scale: the rate relative to all channels (:meth:`choose_oversampling`).
        """
        h, w = np.asarray(masks).shape[1:]
        sh, sw = oversampling * h, oversampling * w
        least = (box_side_symbols(sh, sw) + 1) / (3 * sh * sw)
        out = []
        for v, cov in zip(views, focus_coverage(masks, block_px, oversampling)):
            c = float(np.clip(scale * cov * cbr_range[1], least, cbr_range[1]))
            out.append(c)
            self.log(
                "rate",
                f"view {int(v)}: focus cbr {c:.4f} ({cov:.0%} of feature positions hold the "
                "demand)",
                view=int(v),
                coverage=float(cov),
                cbr=c,
                oversampling=int(oversampling),
            )
        return np.asarray(out, np.float64)

    def choose_oversampling(
        self,
        masks: np.ndarray,
        cbr_range: tuple[float, float],
        repetitions: np.ndarray,
        full_scene_symbols: int,
        block_px: int = BLOCK_PX,
    ) -> tuple[int, float]:
        """The object oversampling s and the rate scale that spend the on-demand budget
        (``rate_policy.object_budget_fraction`` of the full-scene budget): the largest s <=
        ``rate_policy.max_object_oversampling`` at which the budget gives every position
        touching the objects at least ``rate_policy.min_position_cbr`` (else s = 1), and
        scale = budget / the full rate at s (every channel, i.e. the codec's largest CBR, on
        every such position, times the repetitions; logged). The codec sends at most all
        channels over its box, so a scale above 1 spends only what the box's rim can take.

        Args:
            masks: [num_views, height, width] union masks of the on-demand views.
            repetitions: [num_views] copies of each on-demand view.
            full_scene_symbols: what sending every candidate view whole would cost.
        Returns:
            (s, scale > 0).
        """
        pol = self.rate_policy
        budget = pol.object_budget_fraction * full_scene_symbols
        tried = {}
        for s in range(pol.max_object_oversampling, 0, -1):
            n = full_rate_symbols(masks, cbr_range, repetitions, s, block_px)
            tried[s] = int(round(n))
            if budget >= pol.min_position_cbr / cbr_range[1] * n or s == 1:
                break
        scale = float(budget / max(n, 1e-9))
        self.log(
            "rate",
            f"objects encoded at {s}x their captured resolution at {scale:.2f} of the full rate: "
            f"the on-demand budget of {budget:.0f} symbols, {pol.object_budget_fraction:.0%} "
            "of the full-scene budget",
            oversampling=s,
            rate_scale=scale,
            full_rate_symbols_by_oversampling={str(k): v for k, v in sorted(tried.items())},
            full_scene_symbols=int(full_scene_symbols),
        )
        return s, scale

    def choose_focus_repetitions(
        self,
        masks: np.ndarray,
        cbr_range: tuple[float, float],
        repetitions: np.ndarray,
        measured_snr_db: np.ndarray,
        full_scene_symbols: int,
        copy_fading: phy.CopyFading,
        block_px: int = BLOCK_PX,
    ) -> np.ndarray:
        """Copies of each on-demand view's block: its whole-view ``repetitions`` where copies
        fade independently (diversity) or its measured SNR is below
        ``rate_policy.static_repeat_below_db``; elsewhere one copy, the budget spent as
        rate, unless the largest oversampling at every channel cannot take the budget so
        (logged).

        Args:
            masks: [num_views, height, width] union masks of the on-demand views.
            repetitions: [num_views] whole-view copies of each on-demand view.
            measured_snr_db: [num_views] their measured SNRs.
        """
        pol = self.rate_policy
        reps = np.asarray(repetitions, np.int64)
        if not np.any(reps > 1):
            return reps
        details = {"spread_db": copy_fading.spread_db, "correlation": copy_fading.correlation}
        if pol.copies_independent(copy_fading):
            self.log("rate", "on-demand copies fade independently: send copies", **details)
            return reps
        out = np.where(np.asarray(measured_snr_db) < pol.static_repeat_below_db, reps, 1)
        s = pol.max_object_oversampling
        budget = pol.object_budget_fraction * full_scene_symbols
        if budget > full_rate_symbols(masks, cbr_range, out, s, block_px):
            self.log(
                "rate",
                f"copies do not fade independently, but fewer copies at {s}x cannot take the "
                "on-demand budget: send copies",
                **details,
            )
            return reps
        self.log(
            "rate",
            f"copies do not fade independently (spread {copy_fading.spread_db:.1f} dB, "
            f"correlation {copy_fading.correlation:.2f}): one copy of the "
            f"{int(np.sum((out == 1) & (reps > 1)))} on-demand views measured at or above "
            f"{pol.static_repeat_below_db:g} dB, the budget spent as rate",
            **details,
        )
        return out

    def choose_repetitions(self, measured_snr_db: np.ndarray, views) -> np.ndarray:
        """Copies of each view's block: 2 below ``rate_policy.repeat_below_db``, else 1 (logged)."""
        out = []
        for v, snr in zip(views, measured_snr_db):
            r = 2 if float(snr) < self.rate_policy.repeat_below_db else 1
            out.append(r)
            if r > 1:
                self.log(
                    "rate",
                    f"view {int(v)}: send twice (measured {float(snr):.1f} dB)",
                    view=int(v),
                    repetitions=r,
                )
        return np.asarray(out, np.int64)

    def choose_cbr(
        self, measured_snr_db: np.ndarray, cbr_range: tuple[float, float], views
    ) -> np.ndarray:
        """CBR per view from its measured SNR, clamped to the codec's range (logged per view)."""
        lo, hi = cbr_range
        out = []
        for v, s in zip(views, measured_snr_db):
            c = float(np.clip(self.rate_policy.cbr_for(float(s)), lo, hi))
            out.append(c)
            self.log(
                "rate", f"view {int(v)}: cbr {c:.4f}", view=int(v), measured_snr_db=float(s), cbr=c
            )
        return np.asarray(out, np.float64)

    def plan(
        self,
        *,
        candidates,
        on_demand,
        link_snr_db: dict[int, float],
        measured_snr_db: dict[int, float],
        outage,
        masks: np.ndarray,
        cbr_range: tuple[float, float],
        snr_range_db: tuple[float, float],
        height: int,
        width: int,
        copy_fading: phy.CopyFading,
    ) -> RunPlan:
        """One :class:`ViewPlan` per candidate view not in outage (logged).

        Args:
            candidates: every view considered; on_demand: the collector's selection.
            link_snr_db, measured_snr_db: per view not in outage.
            outage: views without a propagation path.
            masks: [num_sent, height, width] union masks of the demanded objects in the
                on-demand views not in outage, in the order of ``on_demand``.
            cbr_range, snr_range_db: the codec's; height, width: the views' size, pixels.
            copy_fading: whether copies fade independently on these links.
        """
        outage = {int(v) for v in outage}
        whole = [int(v) for v in candidates if int(v) not in outage]
        sent = [int(v) for v in on_demand if int(v) not in outage]
        meas = np.asarray([measured_snr_db[v] for v in whole])
        fading = {"spread_db": copy_fading.spread_db, "correlation": copy_fading.correlation}
        self.log(
            "link",
            f"pilot copies: per-symbol SNR spread {copy_fading.spread_db:.2f} dB, correlation "
            f"between copies {copy_fading.correlation:.2f}",
            **fading,
        )
        cbrs = dict(zip(whole, self.choose_cbr(meas, cbr_range, whole)))
        reps = dict(zip(whole, self.choose_repetitions(meas, whole)))
        full = {v: int(round(cbrs[v] * height * width * 3)) * int(reps[v]) for v in whole}
        sent_reps, sent_snr = [reps[v] for v in sent], [measured_snr_db[v] for v in sent]
        focus_reps = self.choose_focus_repetitions(
            masks, cbr_range, sent_reps, sent_snr, sum(full.values()), copy_fading
        )
        focus_reps = dict(zip(sent, focus_reps.tolist()))
        s, scale = self.choose_oversampling(
            masks, cbr_range, np.asarray([focus_reps[v] for v in sent]), sum(full.values())
        )
        focus = dict(zip(sent, self.focus_cbr(masks, cbr_range, sent, oversampling=s, scale=scale)))
        plans = []
        for v in whole:
            m_db = measured_snr_db[v]
            whole_part = Allocation(
                float(cbrs[v]), int(reps[v]), combined_snr_db(m_db, reps[v], snr_range_db), full[v]
            )
            focus_part = None
            if v in focus:
                f, fr = float(focus[v]), int(focus_reps[v])
                focus_part = Allocation(
                    f,
                    fr,
                    combined_snr_db(m_db, fr, snr_range_db),
                    int(round(f * s * height * s * width * 3)) * fr,
                )
            link = ViewLink(float(link_snr_db[v]), float(m_db))
            plans.append(ViewPlan(v, link, whole_part, focus_part))
        if outage:
            self.log("link", "views in outage are not sent", views=sorted(outage))
        static = not self.rate_policy.copies_independent(copy_fading)
        no_path = tuple(int(v) for v in candidates if int(v) in outage)
        return RunPlan(tuple(plans), no_path, int(s), int(height), int(width), static)

    def plan_run(
        self,
        *,
        collection: Collection,
        links,
        cbr_range: tuple[float, float],
        snr_range_db: tuple[float, float],
        height: int,
        width: int,
        seed: int,
        cache,
        plan_snr_db: float | None = None,
        snr_error_db: float = 0.0,
    ) -> tuple[RunPlan, Collection]:
        """Measure every link with pilots, then :meth:`plan` the run. The plan and the
        decisions that made it are cached together, so a resumed run logs them as the
        first did.

        Args:
            collection: the collector's views.
            links: ``osnerf.run.links.RunLinks`` (``links``, ``snr_db``, ``outage``).
            seed: the run seed (the pilots' draws come from it).
            cache: the run's ``StageCache``.
            plan_snr_db, snr_error_db: what the transmitters believe in place of the
                measurement, and the error on it (:func:`transmitter_estimate`).
        Returns:
            (the plan, the collection without views in outage).
        Raises:
            ValueError: every on-demand view is in outage.
        """
        sent = [int(v) for v in collection.indices if int(v) not in links.outage]
        if not sent:
            raise ValueError(
                "every view showing the demanded objects is in outage: nothing can be sent"
            )
        collection = collection.subset(np.isin(collection.indices, sent))
        cached = cache.load("plan")
        if cached is not None:
            self.decisions.extend(cached[1].get("decisions", []))
            return RunPlan.from_dict(cached[1]), collection
        first = len(self.decisions)
        whole = [int(v) for v in collection.candidates if int(v) not in links.outage]
        gen = torch.Generator().manual_seed(scheme_seed(seed, "scu", "measure"))
        view_links, view_snr = [links.links[v] for v in whole], [links.snr_db[v] for v in whole]
        measured = phy.measure_snr_db(view_links, view_snr, gen)
        fading = phy.measure_copy_fading(view_links, view_snr, gen)  # after: the same draws
        measured = transmitter_estimate(measured, plan_snr_db, snr_error_db, seed)
        plan = self.plan(
            candidates=collection.candidates,
            on_demand=sent,
            link_snr_db=links.snr_db,
            measured_snr_db=dict(zip(whole, measured.tolist())),
            outage=links.outage,
            masks=collection.masks,
            cbr_range=cbr_range,
            snr_range_db=snr_range_db,
            height=height,
            width=width,
            copy_fading=fading,
        )
        cache.save("plan", {}, {**plan.to_dict(), "decisions": self.decisions[first:]})
        return plan, collection

    def route(self, scheme: str, object_routed: bool, views, meta: dict) -> np.ndarray:
        """Where the renderer of ``scheme`` trains: the demanded objects' box (padded) for
        object-routed schemes, else the whole scene's (logged). Returns the [2, 3] aabb."""
        if object_routed:
            b = np.stack([np.asarray(meta["object_aabb"][o]) for o in self.demand.objects])
            aabb = padded_aabb(np.stack([b[:, 0].min(0), b[:, 1].max(0)]))
        else:
            aabb = np.asarray(meta["aabb"], np.float64)
        self.log(
            "renderer",
            f"{scheme}: train on {len(views)} decoded views",
            scheme=scheme,
            aabb=np.asarray(aabb).tolist(),
            bounds="demanded objects" if object_routed else "whole scene",
        )
        return aabb


def padded_aabb(bounds: np.ndarray, pad_fraction: float = 0.1) -> np.ndarray:
    """[2, 3] box grown by ``pad_fraction`` of its largest side on every face."""
    b = np.asarray(bounds, np.float64)
    pad = pad_fraction * float((b[1] - b[0]).max())
    return np.stack([b[0] - pad, b[1] + pad])
