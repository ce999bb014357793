"""The SCU's typed plan: how each drone view is sent (:class:`ViewPlan`), for one run
(:class:`RunPlan`). Decided by :class:`osnerf.scu.SemanticControlUnit` before any scheme
runs; the pipeline and the schemes carry it out.

A view's plan has its measured link, a whole-view part and, when the view is sent on
demand, an on-demand part of the same type (:class:`Allocation`); a scheme carries out one
of them (:meth:`RunPlan.for_scheme` -> :class:`ViewSend`). Views in outage have no plan
(:attr:`RunPlan.outage`). View ids are ints throughout; JSON
(string keys) exists only in :meth:`RunPlan.to_dict` / :meth:`RunPlan.from_dict`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass


@dataclass(frozen=True)
class ViewLink:
    """A view's link as the SCU measured it.

    Attributes:
        snr_db: the SNR its link runs at (Es/N0, dB).
        measured_snr_db: post-equalisation SNR measured with pilot blocks (what the rate
            uses).
    """

    snr_db: float
    measured_snr_db: float


@dataclass(frozen=True)
class Allocation:
    """How one part of a view (the whole view, or its on-demand focus) is sent.

    Attributes:
        cbr: channel symbols per source value (on demand: of the oversampled view).
        repetitions: copies of each block (MRC-combined at the receiver).
        encoder_snr_db: the SNR the codec is told: the average SNR of the symbols after the
            receiver combines the copies, ``measured + 10 log10(repetitions)`` (MRC of r
            copies adds their SNRs), clamped to the codec's range.
        symbols: channel symbols incl. repetitions (on demand: the budget every
            object-routed scheme gets).
    """

    cbr: float
    repetitions: int
    encoder_snr_db: float
    symbols: int


@dataclass(frozen=True)
class ViewPlan:
    """How one drone view with a propagation path is sent (decided by the SCU before any
    scheme runs).

    Attributes:
        view: index in ``SceneViews``.
        link: its measured link.
        whole: the whole view (what a full-scene scheme sends).
        focus: the view masked to the demanded objects, at the plan's oversampling, when the
            view shows them well enough to be sent on demand; else None. Its copies are the
            whole view's where copies fade independently or the SNR is very low, else 1
            (:meth:`osnerf.scu.SemanticControlUnit.choose_focus_repetitions`).
    """

    view: int
    link: ViewLink
    whole: Allocation
    focus: Allocation | None = None

    @property
    def on_demand(self) -> bool:
        return self.focus is not None

    def to_dict(self) -> dict:
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict) -> ViewPlan:
        """The inverse of :meth:`to_dict`; also reads the flat plan of reports written
        before the plan had parts (``cbr``, ``focus_cbr``, ``budget_symbols``, ...; not
        of a view in outage, which has no plan now)."""
        if "whole" not in d:
            return cls._from_flat(d)
        focus = None if d["focus"] is None else Allocation(**d["focus"])
        return cls(int(d["view"]), ViewLink(**d["link"]), Allocation(**d["whole"]), focus)

    @classmethod
    def _from_flat(cls, d: dict) -> ViewPlan:
        link = ViewLink(d["snr_db"], d["measured_snr_db"])
        whole = Allocation(d["cbr"], d["repetitions"], d["encoder_snr_db"], d["full_symbols"])
        focus = None
        if d["on_demand"]:
            reps, snr = d.get("focus_repetitions"), d.get("focus_encoder_snr_db")
            reps = d["repetitions"] if reps is None else reps
            snr = d["encoder_snr_db"] if snr is None else snr
            focus = Allocation(d["focus_cbr"], reps, snr, d["budget_symbols"])
        return cls(int(d["view"]), link, whole, focus)


@dataclass(frozen=True)
class ViewSend:
    """One view as a scheme sends it: the part of its plan the scheme carries out.

    Attributes:
        view: index in ``SceneViews``; snr_db: the SNR its link runs at.
        part: the plan's on-demand part (object-routed schemes) or its whole view.
        measured_snr_db: what the transmitter believes the SNR is (the SCU's estimate).
    """

    view: int
    snr_db: float
    part: Allocation
    measured_snr_db: float | None = None


@dataclass(frozen=True)
class RunPlan:
    """The SCU's plan for one run: a :class:`ViewPlan` per candidate view with a
    propagation path.

    Attributes:
        views: one plan per candidate view not in outage, in view order.
        outage: the candidate views without a propagation path (never sent).
        oversampling: factor by which on-demand views are upsampled before encoding.
        height, width: captured view size, pixels.
        static_link: the pilot copies did not fade independently (``phy.CopyFading``): a
            static link, which the codec's AWGN simulation of its split represents.
    """

    views: tuple[ViewPlan, ...]
    outage: tuple[int, ...]
    oversampling: int
    height: int
    width: int
    static_link: bool

    def on_demand(self) -> list[ViewPlan]:
        """Views sent on demand."""
        return [p for p in self.views if p.on_demand]

    def for_scheme(self, object_routed: bool) -> list[ViewSend]:
        """The views a scheme sends: the on-demand part of each on-demand view when it is
        object-routed, else the whole part of every view."""
        if object_routed:
            return [
                ViewSend(p.view, p.link.snr_db, p.focus, p.link.measured_snr_db)
                for p in self.views
                if p.focus is not None
            ]
        return [
            ViewSend(p.view, p.link.snr_db, p.whole, p.link.measured_snr_db) for p in self.views
        ]

    @property
    def full_scene_symbols(self) -> int:
        return int(sum(p.whole.symbols for p in self.views))

    def to_dict(self) -> dict:
        return {
            "views": [p.to_dict() for p in self.views],
            "outage": list(self.outage),
            "oversampling": self.oversampling,
            "height": self.height,
            "width": self.width,
            "static_link": self.static_link,
        }

    @classmethod
    def from_dict(cls, d: dict) -> RunPlan:
        return cls(
            tuple(ViewPlan.from_dict(p) for p in d["views"]),
            tuple(int(v) for v in d["outage"]),
            int(d["oversampling"]),
            int(d["height"]),
            int(d["width"]),
            bool(d["static_link"]),
        )
