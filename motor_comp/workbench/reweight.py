"""The final weighted refit: residual variance by speed band (feasible GLS).

On a run with many turns the rows near a turn carry residuals 10–50× those of the
sliding rows (how a turn is resolved between samples is modelled, but not exactly);
ordinary least squares lets those few rows set the parameters that trade with them — a
dead time came out 0.2–0.3 ms long on the independent generator's Coulomb + ripple +
delay chirps, whose sliding rows put it within 0.01 ms.  When the residual variance
differs between speed bands by more than :data:`WEIGHT_CONTRAST`, the final parameters
are re-estimated with weights 1/variance per equal-count band, twice, the input effect
(a dead time) searched again under the weights — unless a term of the model has its
evidence at low speed, at the turns or at the stops (declared), which the weights would
suppress.  A sliding term that then pays only through the turns is dropped, and so is
one whose shape parameter sits within two standard errors of the value at which it
vanishes.  The held-out NRMSE reported is unweighted.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import TERMS, EffectKind
from motor_comp.physics.effects.identification import Signal
from motor_comp.workbench.bands import PROTECTED, WEIGHT_BANDS, WEIGHT_CONTRAST, SpeedBands, \
    SpeedWeights
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.library import Spec, design, n_params
from motor_comp.workbench.lsq import bic, solve_gram, sse_with
from motor_comp.workbench.result import Estimate, estimate
from motor_comp.workbench.heldout import cv_design
from motor_comp.workbench.varpro import search


def reweighted(eng: Any, est: Estimate) -> tuple[Estimate, str, list[str]] | None:
    """Re-estimate the final model by weighted least squares over speed bands (FGLS).

    Returns the new estimate, the sentence of the ``refit`` step and the terms removed,
    or None when the rows are nearly homoscedastic or a term's evidence is where the
    weights would suppress it (see the module docstring).
    """
    D = eng.data
    if any(TERMS[n].evidence & PROTECTED for n in est.spec.names):
        return None
    speed = np.abs(D.at().signal(Signal.VELOCITY))
    spec = est.spec
    weights: SpeedWeights | None = None
    first = None
    for _ in range(2):
        dw = design(D, spec, est.model, weights=weights)
        th, _ = solve_gram(dw.gram(), dw.bounds)
        d0 = design(D, spec, est.model)
        bands = SpeedBands.of(speed, d0.y - d0.X @ th)
        if bands is None:
            break
        if first is None:
            if bands.contrast < WEIGHT_CONTRAST:
                return None
            first = bands
        weights = bands.weights
        for n in spec.names:
            t = TERMS[n]
            if t.params and t.kind is EffectKind.INPUT:
                spec = spec.with_(n, search(D, spec, n, est.model, weights=weights))
    if first is None or weights is None:
        return None
    var, med, edges = first.var, float(np.median(first.var)), first.edges
    spec, removed = _weighted_elimination(eng, spec, est.model, weights)
    new = estimate(D, spec, est.model, cv=False, weights=weights)
    sse = cv_unweighted(D, spec, est.model, weights)
    new = dataclasses.replace(new, sse_cv=sse, nrmse_cv=eng.nrmse(sse))
    worst = int(np.argmax(var))
    lo_v = edges[worst]
    hi_v = edges[worst + 1] if worst + 1 < WEIGHT_BANDS else float(np.max(speed))
    u = eng.units
    moved = '; '.join(f'{g}.{k} {v:.4g} (was {est.scalars[g][k]:.4g})'
                      for g, d in new.scalars.items() for k, v in d.items()
                      if k in est.scalars.get(g, {}) and est.se.get(g, {}).get(k)
                      and abs(v - est.scalars[g][k]) > est.se[g][k])
    text = (f'weighted by speed band: residual {math.sqrt(var[worst] / med):.0f}× the typical '
            f'at |v| {lo_v:.3g}–{hi_v:.3g} {u.velocity}; '
            + (moved or 'no parameter moved by more than its standard error'))
    if removed:
        text += '; ' + ', '.join(removed) + ' removed: it pays only through the turns'
    return new, text, removed


def cv_unweighted(D: Dataset, spec: Spec, model: AxisModel, weights: SpeedWeights) -> float:
    """Return the held-out SSE [N²], unweighted, of fold fits made with ``weights``."""
    dw = design(D, spec, model, weights=weights)
    d0 = design(D, spec, model)
    Pw = D.part_grams(np.column_stack([dw.X, dw.y]))
    P = D.part_grams(np.column_stack([d0.X, d0.y]))
    total = 0.0
    for tr, te in zip(D.train_parts, D.test_parts):
        th, _ = solve_gram(Pw[tr].sum(axis=0), dw.bounds)
        total += sse_with(P[te].sum(axis=0), th)
    return float(total)


def _weighted_elimination(eng: Any, spec: Spec, model: AxisModel,
                          weights: SpeedWeights) -> tuple[Spec, list[str]]:
    """Drop a nonlinear sliding term that no longer pays once the rows are weighted.

    Chosen by the unweighted held-out score, a nonlinear term can pay only by fitting
    how the model misses the turns (a 1.2 ms dead time on a chirp with none planted).
    Each is scored out under the weights (BIC on the weighted held-out SSE) and the
    worst dropped while one does not pay; a term whose shape parameter is within two
    standard errors of the value at which it vanishes is dropped too.
    """
    D = eng.data
    removed: list[str] = []
    while True:
        base = cv_design(D, spec, model, weights)[0]
        worst = None
        for n in spec.names:
            if not TERMS[n].params:
                continue
            s1 = spec.without(n)
            b = bic(D.n_eff, cv_design(D, s1, model, weights)[0], base,
                    n_params(spec) - n_params(s1))
            if b > 0 and (worst is None or b > worst[0]):
                worst = (b, n)
        if worst is None:
            break
        spec = spec.without(worst[1])
        removed.append(worst[1])
    est = None
    for n in spec.names:
        null = TERMS[n].null
        if null is None:
            continue
        est = est or estimate(D, spec, model, cv=False, weights=weights)
        key, zero = null
        v, se = est.scalars.get(n, {}).get(key), est.se.get(n, {}).get(key)
        if v is not None and se is not None and math.isfinite(se) \
                and abs(v - zero) < 2.0 * se:
            spec = spec.without(n)
            removed.append(n)
    return spec, removed


__all__ = ['WEIGHT_BANDS', 'WEIGHT_CONTRAST', 'cv_unweighted', 'reweighted']
