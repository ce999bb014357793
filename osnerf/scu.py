"""The semantic control unit (SCU): demand -> collector and encoder settings, one typed
:class:`ViewPlan` per view (link SNR, measured SNR, CBR, focus, repetitions, outage), the
knowledge-base check, and routing of each scheme's views to the renderer. Every decision is
logged (``SemanticControlUnit.decisions``) and ends up in the report.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field, replace

import numpy as np
import torch

from osnerf.collect import Collection, CollectorConfig, Demand
from semcodec.checkpoint import KnowledgeBaseMismatch as KnowledgeBaseError  # the one error
from semcodec.codec import BLOCK_PX


@dataclass(frozen=True)
class ViewPlan:
    """How one drone view is sent (decided by the SCU before any scheme runs).

    Attributes:
        view: index in ``SceneViews``.
        snr_db: the SNR its link runs at (Es/N0, dB); None in outage.
        measured_snr_db: post-equalisation SNR measured with pilot blocks (what the rate
            uses); None in outage.
        encoder_snr_db: the SNR the codec is told: the average SNR of the symbols after the
            receiver combines the copies, ``measured + 10 log10(repetitions)`` (MRC of r
            copies adds their SNRs), clamped to the codec's range; None in outage. Telling
            the encoder the single-copy SNR instead cost 0.67 dB of received object PSNR on
            the default scene (block Rayleigh, 0 dB, 2 copies, mean of 6 seeds).
        cbr: whole-view CBR from the measured SNR.
        repetitions: copies of each block (MRC-combined at the receiver).
        on_demand: the view shows the demanded objects well enough to be sent on demand.
        focus_cbr: on-demand CBR (of the oversampled view), None when not on demand.
        budget_symbols: on-demand symbol budget incl. repetitions (0 when not on demand);
            every object-routed scheme gets the same budget.
        full_symbols: whole-view symbols incl. repetitions.
        outage: no propagation path: never sent.
        focus_repetitions: copies of the on-demand block (``repetitions`` where the copies
            fade independently or the SNR is very low, else 1: the budget is spent as rate;
            :meth:`SemanticControlUnit.choose_focus_repetitions`); None when not on demand.
        focus_encoder_snr_db: ``encoder_snr_db`` for ``focus_repetitions`` copies.
    """

    view: int
    snr_db: float | None
    measured_snr_db: float | None
    encoder_snr_db: float | None
    cbr: float
    repetitions: int
    on_demand: bool
    focus_cbr: float | None
    budget_symbols: int
    full_symbols: int
    outage: bool = False
    focus_repetitions: int | None = None
    focus_encoder_snr_db: float | None = None


@dataclass(frozen=True)
class RunPlan:
    """The SCU's plan for one run: a :class:`ViewPlan` per candidate view.

    Attributes:
        views: one plan per candidate view, in view order (outage views included, flagged).
        oversampling: factor by which on-demand views are upsampled before encoding.
        height, width: captured view size, pixels.
    """

    views: tuple[ViewPlan, ...]
    oversampling: int
    height: int
    width: int

    def on_demand(self) -> list[ViewPlan]:
        """Views sent on demand (not in outage)."""
        return [p for p in self.views if p.on_demand and not p.outage]

    def whole(self) -> list[ViewPlan]:
        """Every candidate view not in outage (what a full-scene scheme sends)."""
        return [p for p in self.views if not p.outage]

    def for_scheme(self, object_routed: bool) -> list[ViewPlan]:
        """The views a scheme sends: on demand (with the on-demand copies and encoder SNR in
        ``repetitions`` and ``encoder_snr_db``) when it is object-routed, else every one."""
        if not object_routed:
            return self.whole()
        return [
            replace(p, repetitions=p.focus_repetitions, encoder_snr_db=p.focus_encoder_snr_db)
            for p in self.on_demand()
        ]

    @property
    def full_scene_symbols(self) -> int:
        return int(sum(p.full_symbols for p in self.whole()))

    def to_dict(self) -> dict:
        return {
            "views": [asdict(p) for p in self.views],
            "oversampling": self.oversampling,
            "height": self.height,
            "width": self.width,
        }

    @classmethod
    def from_dict(cls, d: dict) -> RunPlan:
        return cls(
            tuple(ViewPlan(**p) for p in d["views"]),
            int(d["oversampling"]),
            d["height"],
            d["width"],
        )


@dataclass(frozen=True)
class CopyFading:
    """Whether two copies of a block see independent fades, measured with pilot copies
    (:func:`measure_copy_fading`).

    Attributes:
        spread_db: std of the per-symbol post-equalisation SNR (dB) about each view's mean.
        correlation: correlation of those deviations between the two copies of each symbol.
    """

    spread_db: float
    correlation: float

    def independent(self, policy: RatePolicy) -> bool:
        """The copies fade, and not together: MRC of copies buys diversity."""
        return (
            self.spread_db >= policy.copy_spread_db
            and self.correlation < policy.max_copy_correlation
        )


@dataclass(frozen=True)
class RatePolicy:
    """CBR per measured SNR: lower SNR -> more channel symbols per source value.

    The SNR (dB) falls in band ``k`` when it is below ``thresholds_db[k]`` (and above the
    previous one); the last band is everything above the last threshold.

    Attributes:
        thresholds_db: ascending band edges, dB.
        cbrs: one CBR per band (len(thresholds_db) + 1), each in (0, 1].
        repeat_below_db: below it a block is sent twice and the copies MRC-combined.
    """

    thresholds_db: tuple[float, ...] = (0.0, 5.0, 10.0)
    cbrs: tuple[float, ...] = (1 / 8, 1 / 12, 1 / 16, 1 / 24)
    repeat_below_db: float = 3.0
    """Below this measured SNR every view costs twice its CBR, sent as two MRC-combined copies.
    On-demand views send copies only where they fade independently (:class:`CopyFading`);
    otherwise the second copy's symbols are spent as rate (on a static channel a copy buys
    only the 3 dB combining gain, which the codec's rate beats: tiny scene, over the air at
    0 dB, s = 3 in one copy against s = 2 in two, seeds 0 / 1 at 9,000 NeRF steps: received
    object PSNR +0.20 / +0.08 dB, the field's +0.26 / +0.04)."""
    copy_spread_db: float = 1.0
    """Copies can fade independently only where the per-symbol SNR spreads (std about each
    view's mean, dB) by at least this: a flat static channel (AWGN) has no fades to escape."""
    max_copy_correlation: float = 0.5
    """... and where the two copies' per-symbol SNR deviations correlate less than this (a
    static multipath channel repeats its frequency fades in every copy: 0.87 between the
    emulated HackRFs at 0 dB, 0.67 at -5 dB; block, fast and TDL fading about 0). At -10 dB
    over the air the receiver's channel estimates are noisy enough to decorrelate the
    copies' reported reliabilities (0.36), and the copies are kept."""
    static_repeat_below_db: float = -5.0
    """Where copies do not fade independently, views measured below this still send copies:
    near the bottom of the codec's SNR range 3 dB of SNR is worth more than the rate (tiny
    scene over the air, received object PSNR, two copies at s = 2 against one at s = 3:
    0 dB -0.20 / -0.08 (seeds 0 / 1), -5 dB +0.02, -10 dB +0.32)."""
    max_object_oversampling: int = 3
    """Largest factor s by which the demanded objects are upsampled before encoding (s^2 times
    the feature positions), >= 1."""
    object_budget_fraction: float = 2 / 3
    """On-demand views cost this fraction of what sending every view whole would cost at the
    same SNR (the full-scene budget): the symbols saved by not sending the background are
    spent on the objects through oversampling. In (0, 1]."""
    min_fill: float = 0.5
    """The SCU takes the largest oversampling whose full rate (every channel on every position
    touching the objects) the on-demand budget covers at least this fraction of, and scales
    the rate to spend the budget, in (0, 1]. Default scene, block Rayleigh 0 dB, received
    object PSNR at about the same symbols: s = 3 at 0.6 of full rate 21.0 dB against s = 2
    at 1.25 20.6; tiny scene: s = 2 at 0.77 20.6 against s = 3 at 0.34 20.0 (too few channels
    per position), and 18.4 at s = 1, which left two thirds of the budget unspent."""

    def __post_init__(self):
        if len(self.cbrs) != len(self.thresholds_db) + 1:
            raise ValueError(
                f"cbrs must have len(thresholds_db) + 1 = {len(self.thresholds_db) + 1} entries"
            )
        if list(self.thresholds_db) != sorted(self.thresholds_db):
            raise ValueError(f"thresholds_db must be ascending, got {self.thresholds_db}")
        if any(not 0 < c <= 1 for c in self.cbrs):
            raise ValueError(f"cbrs must be in (0, 1], got {self.cbrs}")
        if self.max_object_oversampling < 1:
            raise ValueError(
                f"max_object_oversampling must be >= 1, got {self.max_object_oversampling}"
            )
        if self.copy_spread_db < 0:
            raise ValueError(f"copy_spread_db must be >= 0, got {self.copy_spread_db}")
        if not -1 <= self.max_copy_correlation <= 1:
            raise ValueError(
                f"max_copy_correlation must be in [-1, 1], got {self.max_copy_correlation}"
            )
        for name in ("object_budget_fraction", "min_fill"):
            if not 0 < getattr(self, name) <= 1:
                raise ValueError(f"{name} must be in (0, 1], got {getattr(self, name)}")

    def cbr_for(self, snr_db: float) -> float:
        """The CBR of the band ``snr_db`` falls in."""
        k = int(np.searchsorted(np.asarray(self.thresholds_db), float(snr_db), side="right"))
        return float(self.cbrs[k])


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
                f"receiver codec sha256 {receiver_sha256[:12]}; load the same checkpoint on both ends"
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
        coverage * max_cbr``, at most the codec's largest CBR and at least one symbol (focus
        mode takes any rate below the largest; logged per view).

        Args:
            masks: [num_views, height, width] union masks of the demanded objects.
            oversampling: the views are encoded upsampled by this factor (the CBR refers to
                the upsampled image).
            scale: the rate relative to all channels (:meth:`choose_oversampling`).
        """
        h, w = np.asarray(masks).shape[1:]
        one_symbol = 1.0 / (3 * oversampling * h * oversampling * w)
        out = []
        for v, cov in zip(views, focus_coverage(masks, block_px, oversampling)):
            c = float(np.clip(scale * cov * cbr_range[1], one_symbol, cbr_range[1]))
            out.append(c)
            self.log(
                "rate",
                f"view {int(v)}: focus cbr {c:.4f} ({cov:.0%} of feature positions hold the demand)",
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
        ``rate_policy.max_object_oversampling`` whose full rate (every channel on every
        position touching the objects, times the repetitions) the budget covers at least
        ``rate_policy.min_fill`` of (else s = 1), and scale = budget / that full rate
        (logged). The codec sends at most all channels over its box, so a scale above 1
        spends only what the box's rim can take.

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
            if budget >= pol.min_fill * n or s == 1:
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
        copy_fading: CopyFading,
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
        if copy_fading.independent(pol):
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
        copy_fading: CopyFading,
    ) -> RunPlan:
        """One :class:`ViewPlan` per candidate view (logged).

        Args:
            candidates: every view considered; on_demand: the collector's selection.
            link_snr_db, measured_snr_db: per view not in outage.
            outage: views without a propagation path.
            masks: [len(on-demand views not in outage), height, width] union masks of the
                demanded objects, in the order of ``on_demand``.
            copy_fading: whether copies fade independently on these links.
        """
        outage = {int(v) for v in outage}
        whole = [int(v) for v in candidates if int(v) not in outage]
        sent = [int(v) for v in on_demand if int(v) not in outage]
        meas = np.asarray([measured_snr_db[v] for v in whole])
        self.log(
            "link",
            f"pilot copies: per-symbol SNR spread {copy_fading.spread_db:.2f} dB, correlation "
            f"between copies {copy_fading.correlation:.2f}",
            spread_db=copy_fading.spread_db,
            correlation=copy_fading.correlation,
        )
        cbrs = dict(zip(whole, self.choose_cbr(meas, cbr_range, whole)))
        reps = dict(zip(whole, self.choose_repetitions(meas, whole)))
        full = {v: int(round(cbrs[v] * height * width * 3)) * int(reps[v]) for v in whole}
        focus_reps = self.choose_focus_repetitions(
            masks,
            cbr_range,
            np.asarray([reps[v] for v in sent]),
            np.asarray([measured_snr_db[v] for v in sent]),
            sum(full.values()),
            copy_fading,
        )
        focus_reps = dict(zip(sent, focus_reps.tolist()))
        s, scale = self.choose_oversampling(
            masks, cbr_range, np.asarray([focus_reps[v] for v in sent]), sum(full.values())
        )
        focus = dict(zip(sent, self.focus_cbr(masks, cbr_range, sent, oversampling=s, scale=scale)))
        plans = []
        for v in (int(v) for v in candidates):
            if v in outage:
                plans.append(ViewPlan(v, None, None, None, 0.0, 0, False, None, 0, 0, True))
                continue
            f = focus.get(v)
            fr = focus_reps.get(v) if f else None
            budget = int(round(f * (s * height) * (s * width) * 3)) * int(fr) if f else 0
            plans.append(
                ViewPlan(
                    view=v,
                    snr_db=float(link_snr_db[v]),
                    measured_snr_db=float(measured_snr_db[v]),
                    encoder_snr_db=combined_snr_db(measured_snr_db[v], reps[v], snr_range_db),
                    cbr=float(cbrs[v]),
                    repetitions=int(reps[v]),
                    on_demand=f is not None,
                    focus_cbr=None if f is None else float(f),
                    budget_symbols=budget,
                    full_symbols=full[v],
                    focus_repetitions=fr,
                    focus_encoder_snr_db=None
                    if fr is None
                    else combined_snr_db(measured_snr_db[v], fr, snr_range_db),
                )
            )
        if outage:
            self.log("link", "views in outage are not sent", views=sorted(outage))
        return RunPlan(tuple(plans), int(s), int(height), int(width))

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


def combined_snr_db(measured_snr_db: float, repetitions: int, snr_range_db) -> float:
    """The average SNR after MRC of ``repetitions`` copies (their SNRs add), clamped to the
    codec's range: what the encoder is told and the decoder's AF modules see."""
    snr = float(measured_snr_db) + 10.0 * math.log10(max(int(repetitions), 1))
    return float(np.clip(snr, *snr_range_db))


def padded_aabb(bounds: np.ndarray, pad_fraction: float = 0.1) -> np.ndarray:
    """[2, 3] box grown by ``pad_fraction`` of its largest side on every face."""
    b = np.asarray(bounds, np.float64)
    pad = pad_fraction * float((b[1] - b[0]).max())
    return np.stack([b[0] - pad, b[1] + pad])


def full_rate_symbols(
    masks: np.ndarray,
    cbr_range: tuple[float, float],
    repetitions: np.ndarray,
    oversampling: int,
    block_px: int = BLOCK_PX,
) -> float:
    """Symbols of the on-demand views at the codec's largest CBR on every feature position
    touching the objects, upsampled by ``oversampling``, times their copies."""
    h, w = np.asarray(masks).shape[1:]
    cov = focus_coverage(masks, block_px, oversampling)
    s = oversampling
    return float(np.sum(cov * cbr_range[1] * (s * h) * (s * w) * 3 * np.asarray(repetitions)))


def focus_blocks(masks: np.ndarray, block_px: int = BLOCK_PX, oversampling: int = 1) -> np.ndarray:
    """The codec's feature positions (``block_px`` squares of the image upsampled by
    ``oversampling``) that touch the objects' mask (> 0.05).

    Args:
        masks: [num_views, height, width] in [0, 1].
    Returns:
        [num_views, ceil(s*height/block_px), ceil(s*width/block_px)] bool.
    """
    m = np.asarray(masks) > 0.05
    if oversampling > 1:
        m = m.repeat(oversampling, axis=1).repeat(oversampling, axis=2)
    n, h, w = m.shape
    hf, wf = -(-h // block_px), -(-w // block_px)
    pad = np.zeros((n, hf * block_px, wf * block_px), bool)
    pad[:, :h, :w] = m
    return pad.reshape(n, hf, block_px, wf, block_px).any((2, 4))


def focus_coverage(
    masks: np.ndarray, block_px: int = BLOCK_PX, oversampling: int = 1
) -> np.ndarray:
    """Fraction of the feature positions of :func:`focus_blocks` that touch the objects,
    per view: [num_views] float64 in [0, 1]."""
    return focus_blocks(masks, block_px, oversampling).mean((1, 2)).astype(np.float64)


def focus_pixel_masks(
    masks: np.ndarray, block_px: int = BLOCK_PX, oversampling: int = 1
) -> np.ndarray:
    """[num_views, height, width] float32: 1 on the pixels that the feature positions of
    :func:`focus_blocks` cover (at the captured resolution)."""
    n, h, w = np.asarray(masks).shape
    b = focus_blocks(masks, block_px, oversampling)
    px = b.repeat(block_px, axis=1).repeat(block_px, axis=2)[
        :, : oversampling * h, : oversampling * w
    ]
    return px.reshape(n, h, oversampling, w, oversampling).any((2, 4)).astype(np.float32)


def qpsk_pilots(num_blocks: int, num_pilots: int, generator: torch.Generator) -> torch.Tensor:
    """[num_blocks, num_pilots] unit-power QPSK symbols, complex64."""
    bits = torch.randint(0, 2, (num_blocks, num_pilots, 2), generator=generator)
    return ((1 - 2 * bits[..., 0]) + 1j * (1 - 2 * bits[..., 1])).to(torch.complex64) / math.sqrt(2)


def measure_snr_db(
    links, snr_db, generator: torch.Generator, num_pilots: int = 256, num_blocks: int = 8
) -> np.ndarray:
    """Post-equalisation SNR per view from known QPSK pilot blocks sent through its link.

    The links hand back unbiased estimates with their per-symbol noise variance; per block,
    the LMMSE pilots ``x_hat / (1 + noise_var) = g x + e`` give the gain ``g = <x, x_hat> / <x, x>``
    and the unbiased SNR ``|g|^2 / var(e)`` (``|h|^2 snr`` on block fading, ``1 / noise_var``
    on AWGN; robust to the deep fades of fast fading, where ZF's error alone would diverge).
    The linear SNR is averaged over ``num_blocks`` blocks (independent fades on a
    block-fading link: the long-term SNR the rate is chosen on).

    Args:
        links: one link per view, ``link(x, snr_db, generator=None) -> LinkOutput``.
        snr_db: one SNR per view (what its link runs at).
    Returns:
        [num_views] float measured SNR in dB.
    """
    out = []
    for link, s in zip(links, snr_db):
        x = qpsk_pilots(num_blocks, num_pilots, generator)
        y = link(x, float(s), generator=generator)
        z = y.x_hat / (1.0 + y.noise_var.clamp(0.0, 1e6))  # LMMSE
        g = (x.conj() * z).sum(-1, keepdim=True) / (x.abs() ** 2).sum(
            -1, keepdim=True
        )  # [blocks, 1]
        e = (z - g * x).abs().pow(2).mean(-1)  # [blocks]
        snr = (g.abs().squeeze(-1) ** 2 / e.clamp_min(1e-12)).mean()
        out.append(10 * math.log10(max(float(snr), 1e-3)))
    return np.asarray(out)


def measure_copy_fading(
    links, snr_db, generator: torch.Generator, num_pilots: int = 256, num_pairs: int = 4
) -> CopyFading:
    """Whether copies fade independently: ``num_pairs`` QPSK pilot blocks per view, each
    sent twice back to back (as the copies of a view are), and the per-symbol SNR the
    receiver reports (``1 / noise_var``, dB) compared between the two copies, pooled over
    the views after removing each view's mean.

    Args:
        links: one link per view, ``link(x, snr_db, generator=None) -> LinkOutput``.
        snr_db: one SNR per view (what its link runs at).
    """
    first, second = [], []
    for link, s in zip(links, snr_db):
        x = qpsk_pilots(num_pairs, num_pilots, generator)
        y = link(x.repeat_interleave(2, dim=0), float(s), generator=generator)
        db = -10.0 * torch.log10(y.noise_var.double().clamp(1e-12, 1e12))
        db = db - db.mean()
        first.append(db[0::2].flatten())
        second.append(db[1::2].flatten())
    a, b = torch.cat(first), torch.cat(second)
    va, vb = float((a * a).mean()), float((b * b).mean())
    spread = math.sqrt((va + vb) / 2.0)
    corr = float((a * b).mean()) / math.sqrt(va * vb) if va * vb > 1e-18 else 0.0
    return CopyFading(spread_db=spread, correlation=corr)
