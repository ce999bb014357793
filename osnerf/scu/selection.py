"""Which of the collector's views to send: by sight, by radio, or both.

Every rule picks views greedily, one at a time, the highest score first (ties: the lower
view index). The terms:

* **coverage gain** of view ``i`` given the views already chosen ``S``:
  ``f(S + {i}) - f(S)`` with ``f(S) = mean_k max_{j in S} max(0, d_j . d_k)``, where
  ``d_k`` is the unit direction from the demanded objects' centre to candidate ``k``'s drone
  and ``k`` runs over every candidate: how much better the chosen views' directions
  represent all the directions the object can be seen from (a facility-location coverage;
  ``f`` of every candidate is 1).
* **link quality** of view ``i``: ``log2(1 + snr_i) / log2(1 + snr_max)``, its expected
  spectral efficiency over the best candidate's (linear SNRs, in (0, 1]): the share of
  the best link's rate the view can be carried at.

Rules (:data:`VIEW_SELECTIONS`): ``sight`` scores the coverage gain, ``radio`` the expected
SNR, ``joint`` coverage gain times link quality.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass

import numpy as np

from common import Registry
from osnerf.collect import Collection


@dataclass(frozen=True)
class SelectionRule:
    """A view-selection rule.

    Attributes:
        help: one line.
        score: (coverage_gain [n], link_quality [n], expected_snr_db [n]) -> score [n].
    """

    help: str
    score: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


VIEW_SELECTIONS = Registry[SelectionRule]("view selection")
VIEW_SELECTIONS.register(
    "sight",
    SelectionRule(
        "what the cameras see: every visible view; with a view count, greedy coverage of "
        "the object's viewing directions",
        lambda gain, quality, snr_db: gain,
    ),
)
VIEW_SELECTIONS.register(
    "radio",
    SelectionRule(
        "the visible views with the highest expected SNR",
        lambda gain, quality, snr_db: snr_db,
    ),
)
VIEW_SELECTIONS.register(
    "joint",
    SelectionRule(
        "greedy coverage gain of the object's viewing directions times link quality "
        "(expected spectral efficiency over the best candidate's)",
        lambda gain, quality, snr_db: gain * quality,
    ),
)


@dataclass(frozen=True)
class ViewChoice:
    """Why a view was chosen.

    Attributes:
        view: view index; rank: 0 for the first chosen.
        expected_snr_db: the SNR its link is expected to run at.
        coverage_gain: what it added to the coverage when chosen.
        link_quality: its link-quality term.
        score: the rule's score when chosen.
    """

    view: int
    rank: int
    expected_snr_db: float
    coverage_gain: float
    link_quality: float
    score: float

    def to_dict(self) -> dict:
        return asdict(self)


def link_quality(snr_db) -> np.ndarray:
    """[n] ``log2(1 + snr) / max log2(1 + snr)`` of expected SNRs in dB, in (0, 1]."""
    c = np.log2(1.0 + 10.0 ** (np.asarray(snr_db, np.float64) / 10.0))
    return c / c.max()


def coverage(directions: np.ndarray, chosen) -> float:
    """``f(S)``: mean over the candidates of the best ``max(0, cos)`` to a chosen direction.

    Args:
        directions: [num_candidates, 3] unit vectors; chosen: indices into them.
    """
    chosen = list(chosen)
    if not chosen:
        return 0.0
    sim = np.clip(directions @ directions[chosen].T, 0.0, None)  # [num_candidates, num_chosen]
    return float(sim.max(axis=1).mean())


def select_views(
    rule: str,
    views,
    expected_snr_db,
    directions_m,
    max_views: int | None,
) -> list[ViewChoice]:
    """Choose at most ``max_views`` of ``views`` greedily by ``rule`` (module docstring).

    Args:
        rule: a name of :data:`VIEW_SELECTIONS`.
        views: [num_candidates] view indices.
        expected_snr_db: [num_candidates] the SNR each view's link is expected to run at.
        directions_m: [num_candidates, 3] vectors from the objects' centre to each drone.
        max_views: the most views to choose (>= 1); None: every view.
    Returns:
        The chosen views in the order chosen.
    """
    score = VIEW_SELECTIONS[rule].score
    views = [int(v) for v in views]
    snr = np.asarray(expected_snr_db, np.float64).reshape(-1)
    d = np.asarray(directions_m, np.float64).reshape(-1, 3)
    if not (len(views) == len(snr) == len(d)) or not views:
        raise ValueError(
            f"views, expected_snr_db and directions_m must have one entry per candidate, got "
            f"{len(views)}, {len(snr)}, {len(d)}"
        )
    if max_views is not None and (isinstance(max_views, bool) or max_views < 1):
        raise ValueError(f"max_views must be an integer >= 1 or None, got {max_views!r}")
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    sim = np.clip(d @ d.T, 0.0, None)  # [candidate, view]: max(0, cos)
    quality = link_quality(snr)
    order = np.argsort(views, kind="stable")  # ties go to the lower view index
    left = [int(k) for k in order]
    n = len(views) if max_views is None else min(int(max_views), len(views))
    best = np.zeros(len(views))  # each candidate's best max(0, cos) to a chosen view
    out = []
    for rank in range(n):
        gain = np.maximum(best[:, None], sim[:, left]).mean(axis=0) - best.mean()
        s = np.round(score(gain, quality[left], snr[left]), 9)
        j = int(np.argmax(s))
        k = left.pop(j)
        best = np.maximum(best, sim[:, k])
        out.append(
            ViewChoice(
                views[k], rank, float(snr[k]), float(gain[j]), float(quality[k]), float(s[j])
            )
        )
    return out


def radio_tie(rule: str, expected_snr_db) -> str | None:
    """Why ``rule`` cannot rank the views by radio (every view expects the same SNR: a
    channel without a per-view SNR), or None. Sight alone never needs the SNR."""
    snr = np.asarray(expected_snr_db, np.float64).reshape(-1)
    if rule == "sight" or len(snr) < 2 or np.ptp(snr) > 0:
        return None
    what = "ranks nothing" if rule == "radio" else "adds nothing to coverage"
    return (
        f"--view-selection {rule}: every one of the {len(snr)} views expects {snr[0]:g} dB "
        f"(the channel gives no per-view SNR), so radio {what}; ties go to the lower view "
        "index, not to a better link"
    )


def choose_views(
    log: Callable[..., None],
    collection: Collection,
    snr_db: dict,
    directions_m: dict,
    rule: str,
    max_views: int | None,
) -> Collection:
    """The collection cut to the views :func:`select_views` chooses, each logged through
    ``log(stage, decision, **details)`` with its expected SNR, coverage gain, link quality
    and score.

    Args:
        snr_db: view -> expected SNR (views without one, in outage, are never chosen).
        directions_m: view -> [3] from the demanded objects' centre to its drone.
    """
    views = [int(v) for v in collection.indices if int(v) in snr_db]
    if not views:
        return collection
    tie = radio_tie(rule, [snr_db[v] for v in views])
    if tie is not None:
        log("selection", f"warning: {tie}", rule=rule, tie=True)
    choices = select_views(
        rule, views, [snr_db[v] for v in views], [directions_m[v] for v in views], max_views
    )
    log(
        "selection",
        f"{rule}: send {len(choices)} of {len(views)} visible views ({VIEW_SELECTIONS[rule].help})",
        rule=rule,
        max_views=max_views,
        views=[c.view for c in choices],
    )
    for c in choices:
        log(
            "selection",
            f"view {c.view} (#{c.rank + 1}): expected {c.expected_snr_db:.1f} dB, coverage "
            f"gain {c.coverage_gain:.3f}, link quality {c.link_quality:.2f}, score {c.score:.3f}",
            **c.to_dict(),
        )
    return collection.subset(np.isin(collection.indices, [c.view for c in choices]))
