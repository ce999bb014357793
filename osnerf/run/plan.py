"""The SCU's typed plan: how each drone view is sent (:class:`ViewPlan`), for one run
(:class:`RunPlan`). Decided by :class:`osnerf.scu.SemanticControlUnit` before any scheme
runs; the pipeline and the schemes carry it out."""

from __future__ import annotations

from dataclasses import asdict, dataclass, replace


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
            copies adds their SNRs), clamped to the codec's range; None in outage.
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
            :meth:`osnerf.scu.SemanticControlUnit.choose_focus_repetitions`); None when not on demand.
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
        static_link: the pilot copies did not fade independently (``phy.CopyFading``): a
            static link, which the codec's AWGN simulation of its split represents.
    """

    views: tuple[ViewPlan, ...]
    oversampling: int
    height: int
    width: int
    static_link: bool

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
            "static_link": self.static_link,
        }

    @classmethod
    def from_dict(cls, d: dict) -> RunPlan:
        return cls(
            tuple(ViewPlan(**p) for p in d["views"]),
            int(d["oversampling"]),
            d["height"],
            d["width"],
            bool(d["static_link"]),
        )
