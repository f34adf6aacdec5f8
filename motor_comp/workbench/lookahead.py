"""Look-ahead of the forward selection: two steps judged against one, or two together.

Part of the selection of :mod:`.selection` (``../shared/IDENTIFICATION.md`` §3), by the
same rule (:meth:`.selection.Engine.pays`) and, like it, never by an effect's name:

* :func:`simpler`: a flexible term that wins a greedy step is weighed against the two
  strongest simpler ones, each with its best follow-up (two steps against two);
* :func:`pair`: when no candidate pays alone, two strong ones that pay together.

Work that cannot change a verdict is not done: a pair's second step is not scored where
no model could pay against the current one (:meth:`.selection.Engine.can_pay`).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Sequence

from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.library import candidates, n_params
from motor_comp.workbench.result import CandidateResult, estimate
from motor_comp.workbench.heldout import cv_design

if TYPE_CHECKING:
    from motor_comp.workbench.result import Estimate
    from motor_comp.workbench.selection import Engine

#: most candidates tried in pairs (the strongest by held-out BIC)
PAIR_TOP = 3


def simpler(eng: Engine, est: Estimate, best: CandidateResult,
            scored: Sequence[CandidateResult]) -> CandidateResult:
    """Return a simpler candidate when it and a second simple one together beat the best.

    A flexible term (many parameters) can take the shape of two simple ones at once:
    friction knots along the travel are, on a sine, also a function of the speed, and
    win a greedy step against a viscous term and a Stribeck curve that the run shows
    together.  Each of the two strongest supported candidates with fewer parameters is
    fitted in turn, as the forward step would take it (the other terms' nonlinear
    parameters searched again, :meth:`.selection.Engine.joined`), and every other
    candidate with fewer parameters than the flexible one is scored on top of it — also
    those that did not pay alone: a Stribeck rise does not, before the viscous slope it
    sits on is in the model.  The flexible term gets the same look-ahead (two steps
    against two: its best supported follow-up among the same lighter candidates), and
    when a pair improves the held-out BIC more, its first term is taken (the second is
    judged in the next step).  Judged one step against two, an offset and a Coulomb
    level beat a direction asymmetry (which holds the offset) on HSM150's four runs, and
    the asymmetry's viscous part, left for a later step, no longer paid.
    """
    lighter = sorted((c for c in scored if c.supported and c.n_params < best.n_params),
                     key=lambda c: c.bic_delta)[:2]
    if not lighter:
        return best
    # a term's parameter count as this round scored it
    size = {c.effect: c.n_params for c in scored}

    def follow_up(a: CandidateResult, skip: str) -> float:
        # on the model the step would make: the next round finds the taken one scored
        first = eng.joined(a)
        gains = [0.0]
        for n in candidates(first.spec, eng.data):
            if n == skip or size.get(n, best.n_params) >= best.n_params:
                continue
            second = eng.score(first, n)
            if second.supported:
                gains.append(second.bic_delta)
        return a.bic_delta + min(gains)
    choice, total = best, follow_up(best, best.effect)
    for a in lighter:
        t = follow_up(a, best.effect)
        if t < total:
            choice, total = a, t
    return choice


def pair(eng: Engine, est: Estimate, scored: Sequence[CandidateResult]) \
        -> CandidateResult | None:
    """Return the first of two effects that pay together when neither pays alone.

    Each strong candidate — the held-out gain every candidate must show (``min_gain``),
    the BIC improving, in its domain — is fitted in and the others are scored on top
    of it (the three strongest; half the residual, asked before, left a Stribeck rise
    at 49.8 % and a dead time unpaired on a speed sweep); the pair is taken
    when the second then pays and the two together pay against the current model for
    both their parameters (a Stribeck curve and a dead time on a speed sweep each hide
    the other's worth).
    """
    strong = sorted((c for c in scored if not c.supported and not c.why_not
                     and c.explained >= eng.min_gain and c.bic_delta < 0),
                    key=lambda c: c.bic_delta)[:PAIR_TOP]
    best = None
    # the current model's SSE on each processing's rows, and whether any pair judged
    # there could pay against it (else its second step is not scored)
    base: dict = {}

    def against(D: Dataset) -> tuple[float, bool]:
        hit = base.get(D.processing)
        if hit is None:
            sse0 = est.sse_cv if D is eng.data_for(est.spec) else \
                cv_design(D, est.spec, est.model)[0]
            hit = base[D.processing] = (sse0, eng.can_pay(
                sse0, D, floor=lambda: eng.floor_sse(est, D)))
        return hit
    for c in strong:
        first = None
        for n in candidates(c.spec, eng.data):
            other = next((s for s in scored if s.effect == n), None)
            if other is None or other.why_not or other.explained < eng.min_gain \
                    or other.bic_delta >= 0:
                continue
            D = eng.data_for(c.spec.with_(n, {}))
            sse0, reachable = against(D)
            if not reachable:
                continue
            if first is None:
                first = estimate(eng.data_for(c.spec), c.spec, c.model)
            second = eng.score(first, n)
            if not second.supported:
                continue
            sse = (first.sse_cv if D is eng.data_for(first.spec) else
                   cv_design(D, first.spec, first.model)[0]) * (1.0 - second.explained)
            dp = n_params(second.spec) - n_params(est.spec)
            ok, _, b = eng.pays(sse0, sse, dp, D, floor=lambda: eng.floor_sse(est, D))
            if ok and (best is None or b < best[0]):
                best = (b, c)
    return None if best is None else best[1]


__all__ = ['PAIR_TOP', 'pair', 'simpler']
