"""Backward elimination: which terms of a model no longer pay once the others are in.

Part of the selection of :mod:`.selection` (``../shared/IDENTIFICATION.md`` §3), by the
same rule (:meth:`.selection.Engine.pays`) and, like it, never by an effect's name:

* :func:`backward`, after each forward step: a term whose removal no longer hurts goes
  (once each, worst first), with the others' nonlinear parameters as fitted; or it is
  replaced by the term its shared columns contain (:func:`nested`) when its own extra
  parameters are within two standard errors of zero.
* :func:`prune`, once on the final model: each removal judged against H0 of the smaller
  model (:func:`without`: every other term's nonlinear parameters and structures searched
  again), as the forward step that would add the term back to it, against the lower of
  the two models' noise floors.
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from motor_comp.physics.effects import TERMS
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.library import ORDER, Spec, context, n_params, owned_columns
from motor_comp.workbench.result import Estimate, estimate
from motor_comp.workbench.heldout import cv_design
from motor_comp.workbench.varpro import refine_structure, search, searched

if TYPE_CHECKING:
    from motor_comp.workbench.selection import Engine

#: the selection's report of one step: (effect, action, estimate, text)
Step = Callable[[str, str, Estimate, str], None]


def vector(t: Any, data: Dataset) -> bool:
    """Whether a term has a vector parameter (its full search is the expensive one)."""
    return any(p.vector for p in t.space(data.summary, context(Spec((), {}), data)))


def nested(spec: Spec, name: str) -> list[str]:
    """Return the absent terms whose columns all lie in ``name``'s shared bases.

    Such a term is ``name`` without its own extra columns (an offset inside a spring's
    constant, or inside an asymmetry's constant while sliding): backward elimination
    may replace ``name`` by it.
    """
    ctx = context(spec)
    mine = {c.basis for c in TERMS[name].columns(spec.of(name), ctx) if c.basis}
    out = []
    for n in ORDER:
        t = TERMS[n]
        if n in spec.names or searched(t):
            continue
        cols = t.columns({}, ctx)
        if cols and all(c.basis and c.basis in mine for c in cols):
            out.append(n)
    return out


def _extra_flat(est: Estimate, name: str, sub: str) -> bool:
    """Whether ``name``'s parameters beyond those ``sub`` keeps are within 2 SE of zero."""
    spec = est.spec
    owned = {(n, c.label) for n, c in owned_columns(spec, context(spec))}
    flat = True
    for (n, lab), v in est.values.items():
        if n != name or (n, lab) not in owned:
            continue
        basis = next((c.basis for c in TERMS[n].columns(spec.of(n), context(spec))
                      if c.label == lab), '')
        if basis:
            continue
        se = est.se.get(n, {}).get(lab)
        if se is None or not np.isfinite(se) or abs(v) >= 2.0 * se:
            flat = False
    return flat


def backward(eng: Engine, est: Estimate, just: str, step: Step,
             removed_once: set) -> Estimate:
    """Drop terms whose removal no longer hurts (once each), worst first.

    A term another present term requires stays.  A term whose own extra parameters
    are within two standard errors of zero is also tried as the nested term its shared
    columns contain (:func:`nested`).
    """
    while True:
        worst = None
        for n in est.spec.names:
            if n == just or any(n in TERMS[m].requires for m in est.spec.names if m != n):
                continue
            trials = [(est.spec.without(n), None)]
            for sub in nested(est.spec, n):
                if _extra_flat(est, n, sub):
                    trials.append((est.spec.without(n).with_(sub), sub))
            D = eng.data_for(est.spec)
            floor = lambda: eng.floor_sse(est)  # noqa: E731
            for spec, sub in trials:
                sse = cv_design(D, spec, est.model)[0]
                dp = n_params(est.spec) - n_params(spec)
                ok, explained, b = eng.pays(sse, est.sse_cv, dp, D, floor=floor)
                # a term the others pushed out of its declared domain goes although
                # it pays: it stands in for something else (said so, not "no longer pays")
                why = est.inadmissible.get(n, '') if ok else ''
                ok = ok and not why
                if not ok and (worst is None or explained < worst[1]):
                    worst = (n, explained, spec, sub, why)
        if worst is None:
            return est
        n, _, spec, sub, why = worst
        est = estimate(eng.data_for(spec), spec, est.model)
        removed_once.add(n)
        if sub is not None:
            step(n, 'remove', est, f'replaced {n} by {sub}: only its shared part still pays')
            step(sub, 'add', est, '')
            continue
        step(n, 'remove', est, f'removed {n}: {why} (with the others in)' if why
             else f'removed {n}: no longer pays once the others are in')


def without(eng: Engine, est: Estimate, name: str) -> Estimate:
    """Return ``est``'s model without ``name``: H0 of the smaller model.

    Fitted on the rows the smaller model is judged on; every other term's nonlinear
    parameters are searched again from where they are (one term less moves them, it
    does not send them to another basin: the grid is not scored again), vector ones
    (the structure of a pre-sliding curve) too, kept where the held-out error does not
    rise.
    """
    spec = est.spec.without(name)
    D = eng.data_for(spec)
    e = estimate(D, spec, est.model)
    for n in e.spec.names:
        t = TERMS[n]
        if not searched(t):
            continue
        eta = refine_structure(D, e.spec, n, e.model) if vector(t, D) else \
            search(D, e.spec, n, e.model, local=True)
        if eta != e.spec.of(n):
            new = estimate(D, e.spec.with_(n, eta), e.model)
            if new.sse_cv <= e.sse_cv:
                e = new
    return e


def _floor(eng: Engine, models: tuple, D: Dataset, sse0: float) -> float:
    """Return the lower of the models' floor SSEs on ``D`` (0 when neither measures one).

    The floor is the run's; each model's twin estimates it with its own departures from
    the run, and a model missing a term departs most: without its viscous friction the
    ball-screw's twin left 2.2 %, its own NRMSE on the run, and the full model's 0.4 %.
    A floor at or above ``sse0`` (what the smaller model leaves) is no floor of this run.
    """
    fs = [f for f in (eng.floor_sse(m, D) for m in models) if 0.0 < f < sse0]
    return min(fs, default=0.0)


def _pays(eng: Engine, est: Estimate, e: Estimate, sse0: float, dp: int, D: Dataset,
          name: str) -> tuple[bool, float, float]:
    """Return :meth:`~.selection.Engine.pays` of ``e`` → ``est`` with :func:`_floor`.

    The smaller model's floor (an anchored simulation) is not run when the full model's
    decides: a term that pays with the full model's floor by a fall of ``min_drop`` or
    more pays with any lower floor too (the fall only grows, and the bar is never above
    ``min_drop``).
    """
    full = eng.floor_sse(est, D)
    if 0.0 < full < sse0:
        ok, explained, b = eng.pays(sse0, est.sse_cv, dp, D, floor=full)
        fall = eng.nrmse(sse0, D) - max(eng.nrmse(est.sse_cv, D), eng.nrmse(full, D))
        if ok and fall >= eng.min_drop:
            return ok, explained, b
    return eng.pays(sse0, est.sse_cv, dp, D, floor=lambda: _floor(eng, (e, est), D, sse0),
                    placebo=eng.refuter(e, D, name))


def prune(eng: Engine, est: Estimate, step: Step) -> Estimate:
    """Backward elimination of the final model, each removal judged against H0 without it.

    :func:`backward` judges a removal with the others' nonlinear parameters as fitted
    with the term in: a term that joined to mend what an earlier term's structure got
    wrong then seems to pay (a 5.6 ms dead time beside a pre-sliding curve fitted before
    the viscous slope, on a sine run without delay: 0.46 % force NRMSE and the mass −63 %;
    without it and the curve searched again, 0.04 %, the true model's).  Here the
    smaller model is H0 of its own (:func:`without`), and the term must pay against it
    on the model's rows as the forward step that would add it back.
    """
    while True:
        D = eng.data_for(est.spec)
        worst = None
        for n in est.spec.names:
            if any(n in TERMS[m].requires for m in est.spec.names if m != n):
                continue
            e = without(eng, est, n)
            sse0 = e.sse_cv if eng.data_for(e.spec) is D else \
                cv_design(D, e.spec, e.model)[0]
            dp = n_params(est.spec) - n_params(e.spec)
            ok, explained, _ = _pays(eng, est, e, sse0, dp, D, n)
            if not ok and (worst is None or explained < worst[0]):
                worst = (explained, n, e)
        if worst is None:
            return est
        _, n, est = worst
        step(n, 'remove', est, f'removed {n}: no longer pays once the others are searched '
             'again without it')


__all__ = ['Step', 'backward', 'nested', 'prune', 'vector', 'without']
