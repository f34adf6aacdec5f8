"""Held-out scores of a design and of a candidate term, its nonlinear choices made in-fold.

A candidate's held-out SSE is its cross-validated one over the dataset's folds (blocks
of the run dealt to folds, :mod:`.dataset`): its nonlinear parameters are searched on
all rows (:mod:`.varpro`), then each fold chooses among the grid and that choice's
neighbourhood (:func:`.varpro.fold_trials`) on its own training rows and is scored on
its held-out rows, so nothing chosen from the data is scored on the rows it was chosen
on.  A term that claims to repeat along the travel is first held to that claim
(:func:`.repeats.block_cv`).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable, Mapping, Sequence

import numpy as np

from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import TERMS
from motor_comp.workbench.bands import SpeedWeights
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.library import Spec, design
from motor_comp.workbench.lsq import Bounds, solve_gram, sse_with
from motor_comp.workbench.repeats import REPEATS, block_cv
from motor_comp.workbench.varpro import fold_trials, refine_structure, search, searched, \
    vp_sse


def cv_design(data: Dataset, spec: Spec, model: AxisModel | None,
              weights: SpeedWeights | None = None) -> tuple[float, float]:
    """Return the held-out and in-sample SSE of ``spec`` (bounded least squares)."""
    d = design(data, spec, model, weights=weights)
    P = d.part_grams()
    _, sse = solve_gram(P.sum(axis=0), d.bounds)
    return _held_out(data, P, d.bounds), sse


def _held_out(data: Dataset, P: np.ndarray, bounds: Bounds) -> float:
    """Return the held-out SSE over the folds from per-part Grams ``P``."""
    train, test = data.fold_grams(P)
    return sum(sse_with(te, solve_gram(tr, bounds)[0]) for tr, te in zip(train, test))


def cv_choices(data: Dataset, specs: Sequence[Spec], model: AxisModel | None) -> float:
    """Return the held-out SSE when each fold picks, on its training rows, the best spec."""
    best: list = [None] * data.folds
    for s in specs:
        d = design(data, s, model)
        train, test = data.fold_grams(d.part_grams())
        for f, (tr, te) in enumerate(zip(train, test)):
            th, sse = solve_gram(tr, d.bounds)
            if best[f] is None or sse < best[f][0]:
                best[f] = (sse, th, te)
    return sum(sse_with(te, th) for _, th, te in best)


@dataclasses.dataclass(frozen=True)
class CandidateCV:
    """A candidate's held-out score: SSE, its all-data nonlinear parameters, and why not.

    ``why_not`` is set when the term failed a claim it makes about itself (a ripple
    that does not repeat along the travel): it then scores as the model without it.
    """

    sse_cv: float
    eta: dict
    why_not: str = ''


def cv_candidate(data: Dataset, spec: Spec, name: str, model: AxisModel | None, *,
                 screen: float = 0.0, least: Callable[[], float] | None = None,
                 start: Mapping | None = None,
                 refused: Callable[[dict], bool] | None = None) -> CandidateCV:
    """Return the held-out SSE of ``spec`` + ``name`` (η chosen in-fold) and the all-data η.

    With ``screen`` > 0, a candidate whose all-data (in-sample) gain is below
    ``screen`` is scored with its nonlinear parameters held at the all-data choice
    (it cannot pay on held-out data anyway, and the in-fold choices are the cost),
    and its search stops at the starts when even the best gains less than half of
    ``screen``.  ``least()``, called only for a candidate past those, is the least
    held-out share any term could pay with against ``spec``
    (:meth:`.selection.Engine.least_share`: above ``2·screen`` when the model is
    within reach of its noise floor, infinite where nothing could pay): the same
    screen and stop then hold at half and a quarter of it.  A candidate that
    ``refused(η)`` says cannot be taken whatever its score (fitted outside the term's
    declared domain) is scored at its all-data choice too.  ``start`` is where the
    search of the nonlinear parameters starts (default the grid).
    """
    t = TERMS[name]
    if not searched(t):
        return CandidateCV(cv_design(data, spec.with_(name), model)[0], {})
    sse0 = vp_sse(data, spec, model) if screen > 0 else math.inf
    bars: list = [sse0 * (1.0 - 0.5 * screen)]
    if screen > 0 and least is not None:
        def bar() -> float:
            share = least()
            return sse0 * (1.0 - 0.25 * share) if math.isfinite(share) else -math.inf
        bars.append(bar)
    eta_all = search(data, spec.with_(name, dict(start or {})), name, model,
                     stop_above=bars, refine=screen <= 0)
    s1 = spec.with_(name, eta_all)
    if screen > 0:
        sse1 = vp_sse(data, s1, model)
        gain = 1.0 - sse1 / sse0 if sse0 > 0 else 0.0
        if sse0 <= 0 or gain < screen or (least is not None and gain < 0.5 * least()):
            return CandidateCV(cv_design(data, s1, model)[0], eta_all)
        eta_all = refine_structure(data, s1, name, model)
    if refused is not None and refused(eta_all):
        return CandidateCV(cv_design(data, spec.with_(name, eta_all), model)[0], eta_all)
    length = t.repeats_every(eta_all)
    if length is not None:
        b = block_cv(data, spec.with_(name, eta_all), name, model, length)
        if not b.repeats:
            # it does not repeat along the travel as it claims: no held-out gain
            seen = b.nothing - b.seen
            part = (b.nothing - b.held) / seen if seen > 0 else 0.0
            how = (f'{100 * part:.0f} % as well as where fitted' if part > 0 else
                   'no better than the model without it')
            return CandidateCV(cv_design(data, spec, model)[0], eta_all,
                               'it does not repeat along the travel: fitted with one '
                               'period of the travel left out at a time, it predicts '
                               f'that period {how} (a periodic force: '
                               f'{100 * REPEATS:.0f} % as well or more)')
    trials = fold_trials(data, spec, name, eta_all)
    return CandidateCV(cv_choices(data, [spec.with_(name, e) for e in trials], model), eta_all)


__all__ = ['CandidateCV', 'cv_candidate', 'cv_choices', 'cv_design']
