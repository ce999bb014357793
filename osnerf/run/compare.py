"""The schemes of one run side by side, as its report states them: NeRF budgets that differ
beyond a tolerance, schemes nothing arrived from, and the pairwise comparisons."""

from __future__ import annotations

from osnerf.report import SchemeReport
from osnerf.scheme_types import Scheme

BUDGET_TOLERANCE = 0.10
"""Two schemes' NeRF budgets (steps) differing by more than this fraction make their
comparison unfair: it is flagged in the report and on stderr."""


def unequal_budgets(results: dict[str, SchemeReport]) -> list[str]:
    """One line per pair of schemes whose NeRF fields took steps differing by more than
    :data:`BUDGET_TOLERANCE` (e.g. one hit the ``max_seconds`` cap, or a wall-clock budget
    on a busy machine)."""
    steps = {n: r.nerf_steps for n, r in results.items() if r.nerf_steps}
    out = []
    names = list(steps)
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            lo, hi = sorted((steps[a], steps[b]))
            if hi > (1 + BUDGET_TOLERANCE) * lo:
                out.append(
                    f"{a} ({steps[a]} NeRF steps) vs {b} ({steps[b]} NeRF steps): "
                    f"budgets differ by {hi / lo - 1:.0%}, their comparison is not fair"
                )
    return out


def _all_lost(r: SchemeReport) -> bool:
    lost = r.views_lost or {}
    n = int(sum(lost.values())) if isinstance(lost, dict) else int(lost)
    return r.views_sent > 0 and n >= r.views_sent


def nothing_arrived(results: dict[str, SchemeReport]) -> list[str]:
    """One line per scheme none of whose views arrived (a fixed MCS that fits no view, or a
    channel that lost them all): its field saw nothing, so it is compared with nothing."""
    out = []
    for name, r in results.items():
        if _all_lost(r):
            lost = r.views_lost if isinstance(r.views_lost, dict) else {"all": r.views_lost}
            why = ", ".join(f"{n} to the {k}" for k, n in lost.items() if n)
            out.append(
                f"{name}: none of its {r.views_sent} views arrived ({why}); its field saw "
                "nothing and is compared with nothing"
            )
    return out


def comparisons(results: dict[str, SchemeReport], schemes: dict[str, Scheme]) -> dict:
    """The headline numbers: the headline scheme (jscc) minus every other scheme in object
    PSNR; against the first whole-view scheme (full) its symbols, processing time and the
    paper's claim (processing time to the same object PSNR); ``unequal_budgets``: the pairs
    whose NeRF budgets differ (:func:`unequal_budgets`); ``nothing_arrived``: the schemes
    none of whose views arrived (:func:`nothing_arrived`), whose differences are None."""
    out: dict[str, object] = {
        "unequal_budgets": unequal_budgets(results),
        "nothing_arrived": nothing_arrived(results),
    }
    subject = next((n for n, s in schemes.items() if s.headline), None)
    j = results.get(subject) if subject is not None else None
    if j is None or j.psnr_object is None:
        return out
    empty = {n for n, r in results.items() if _all_lost(r)}
    for other, o in results.items():
        if other != subject and o.psnr_object is not None:
            key = f"{subject}_minus_{other}_psnr_object_db"
            # a field that saw no view is no comparison: the key stays, with no number
            out[key] = None if other in empty else j.psnr_object - o.psnr_object
    whole = next((n for n, s in schemes.items() if not s.object_routed), None)
    f = results.get(whole) if whole is not None else None
    if f is None:
        return out
    if f.symbols_sent:
        out[f"symbols_{subject}_over_{whole}"] = j.symbols_sent / f.symbols_sent
    if j.processing_seconds and f.processing_seconds:
        out[f"processing_{subject}_over_{whole}"] = j.processing_seconds / f.processing_seconds
        if f.psnr_object is not None and j.nerf_curve:
            reached = [
                c
                for c in j.nerf_curve
                if c.get("psnr_object") is not None and c["psnr_object"] >= f.psnr_object
            ]
            at = (
                reached[0]["seconds"] + j.seconds["encode"] + j.seconds["decode"]
                if reached
                else None
            )
            out[f"{subject}_processing_seconds_to_{whole}_psnr_object"] = at
            out[f"processing_{subject}_over_{whole}_at_equal_psnr_object"] = (
                None if at is None else at / f.processing_seconds
            )
    return out
