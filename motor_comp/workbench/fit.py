"""Refit a model, add effects to it, or build it from ``effects: {}`` (``--auto``).

A front-end: every fit is the joint inverse-dynamic-model least squares of
:mod:`.library` (mass/inertia and every linear coefficient re-estimated together each
time the effect set changes, nonlinear parameters by variable projection,
:mod:`.varpro`), ``--auto`` the selection of :mod:`.selection`.  ``input_gain``,
``back_emf`` and ``damping`` stay fixed (the drive's data: a gain error scales every
force and is named as such when every force parameter moved by one factor).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Sequence

from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import TERMS
from motor_comp.threads import single_threaded_blas
from motor_comp.workbench import selection as sel
from motor_comp.workbench.aliases import ambiguities
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.library import ORDER
from motor_comp.workbench.result import Estimate, estimate
from motor_comp.workbench.reweight import reweighted
from motor_comp.workbench.scan import scan
from motor_comp.workbench.uncertainty import measurement_spread, processing_spread, \
    profile_se
from motor_comp.workbench.heldout import cv_design
from motor_comp.workbench.varpro import search, searched
from motor_comp.workbench.wording import MASS, REFIT, common_scale, experiment_notes, \
    identifiability_notes, model_scalars, params_text, rows_name, scale_forces, \
    significant_changes


def _figure(eng: sel.Engine, before: Estimate, est: Estimate) -> str:
    """Return a step's force NRMSE, with the model before it on the same rows if they moved.

    Two figures on different rows (:func:`.wording.rows_name`) do not compare, so a step
    that changes the rows also gives the model before it on the new ones (the same
    definition, ``cv_design``).
    """
    D = eng.data_for(est.spec)
    if eng.data_for(before.spec) is D:
        return f'force NRMSE {100 * est.nrmse_cv:.1f} %'
    was = eng.nrmse(cv_design(D, before.spec, before.model)[0], D)
    a, b = _distinct(est.nrmse_cv, was)
    return (f'force NRMSE {a} % on {rows_name(D.processing.turns)}, where the model '
            f'before this step leaves {b} %')


def _distinct(x: float, y: float) -> tuple[str, str]:
    """Return two fractions as percentages with the fewest decimals (1–3) that tell them apart."""
    for d in (1, 2):
        a, b = f'{100 * x:.{d}f}', f'{100 * y:.{d}f}'
        if a != b:
            return a, b
    return f'{100 * x:.3f}', f'{100 * y:.3f}'


@dataclasses.dataclass(frozen=True)
class FitStep:
    """One step: the effect added/removed (None = starting model) and its held-out error."""

    effect: str | None
    force_nrmse: float
    model: AxisModel
    summary: str = ''
    action: str = 'add'

    def as_dict(self) -> dict[str, Any]:
        """Return the JSON form (DESIGN.md §6 ``steps`` entry)."""
        return {'effect': self.effect, 'action': self.action,
                'force_nrmse': float(self.force_nrmse), 'summary': self.summary}


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Steps from the starting model to the fitted one, with uncertainties.

    ``model``, ``params`` (reported parameters per effect), ``se`` (their standard
    errors) and ``nrmse`` (the final held-out force NRMSE) are the result;
    :meth:`as_dict` is its JSON form.
    """

    steps: tuple
    model: AxisModel
    uncertainty: dict = dataclasses.field(default_factory=dict)
    identifiability: tuple = ()
    experiment: tuple = ()
    at_bound: dict = dataclasses.field(default_factory=dict)
    params: dict = dataclasses.field(default_factory=dict)
    unexplained: Any = None

    @property
    def se(self) -> dict:
        """Standard errors of the reported parameters (SI)."""
        return self.uncertainty

    @property
    def nrmse(self) -> float:
        """Held-out force NRMSE of the final model."""
        return float(self.steps[-1].force_nrmse)

    def as_dict(self) -> dict[str, Any]:
        """Return the JSON form of DESIGN.md §6 (``steps``, ``model``, notes)."""
        return {'steps': [s.as_dict() for s in self.steps], 'model': self.model.to_dict(),
                'params': self.params, 'uncertainty': self.uncertainty,
                'force_nrmse': self.nrmse,
                'identifiability': list(self.identifiability),
                'experiment': list(self.experiment), 'at_bound': self.at_bound,
                'unexplained': (self.unexplained.as_dict() if self.unexplained is not None
                                else None),
                'summary': self.unexplained.summary if self.unexplained is not None else ''}


def _check_add_list(model: AxisModel, names: Sequence[str]) -> None:
    """Check a whole ``add`` list before any fitting, effect by effect in order."""
    present = set(model.names)
    for name in names:
        if name == MASS:
            continue
        if name not in ORDER:
            raise ParameterError(f'unknown effect {name!r} (known: {", ".join(ORDER)})')
        if name in present:
            raise ParameterError(f'the model already has {name!r}; it is refit anyway'
                                 if model.has(name) else f'{name!r} is added twice')
        t = TERMS[name]
        missing = [r for r in t.requires if r not in present]
        if missing:
            raise ParameterError(f'cannot add {name!r} to this model (add {missing[0]} '
                                 'first)')
        present.add(name)


@single_threaded_blas()
def fit(kin: Kinematics | Sequence[Kinematics], model: AxisModel, *,
        add: Sequence[str] = (), auto: bool = False, folds: int = 5,
        min_gain: float = 0.1, min_drop: float = 0.01, max_steps: int = 10,
        progress: Callable[[str], None] | None = None, rotary: bool = False) -> FitResult:
    """Refit ``model``; add ``add`` (a step each); with ``auto``, stepwise selection.

    Parameters
    ----------
    kin : Kinematics or sequence of Kinematics
        One run or several (one experiment, one model).
    model : AxisModel
        The starting model (``effects: {}`` and a rough mass are fine with ``auto``).
    add : sequence of str
        Effects to add, in order (``mass`` is always refit and accepted as a no-op).
    auto : bool
        Forward selection with backward elimination until nothing pays.
    folds, min_gain, min_drop : int, float, float
        Validation folds, the least held-out share of the residual a supported effect
        removes and the least NRMSE fall it brings (unless the noise floor is smaller;
        see :mod:`.selection`).
    max_steps : int
        Most selection changes with ``auto``.
    progress : callable, optional
        Called with one line per step.
    rotary : bool
        Treat the position as an angle even if the model file says linear.

    Returns
    -------
    FitResult
        Steps (the first is the starting model, ``effect=None``, its NRMSE without any
        fitting, the same figure ``compare`` reports); every later NRMSE is held-out.
    """
    say = progress or (lambda s: None)
    kins = [kin] if isinstance(kin, Kinematics) else list(kin)
    _check_add_list(model, add)
    eng = sel.Engine(kins, model, folds=folds, min_gain=min_gain, min_drop=min_drop,
                     rotary=rotary)
    model = eng.model
    u = eng.units
    steps = [FitStep(None, eng.nrmse_given, model, 'starting model', 'start')]
    say(f'start: force NRMSE {100 * steps[0].force_nrmse:.1f} % (as given)')

    shown: list[Estimate] = []

    def step(effect: str, action: str, est: Estimate, text: str) -> None:
        if not text:
            text = f'added {effect}: {params_text(est, effect, u)}'
        steps.append(FitStep(effect, est.nrmse_cv, est.model, text, action))
        say(f'{text}; {_figure(eng, shown[-1], est)}')
        shown.append(est)
    est = eng.h0(model)
    shown.append(est)
    refit = eng.refit_result(est)
    changes = '; '.join(c.sentence(u) for c in refit.changes) or 'no parameter moved'
    if not add and not auto:
        step(REFIT, REFIT, est, 'refit of all parameters: ' + changes)
    elif auto and refit.supported:
        step(REFIT, REFIT, est, 'own parameters refitted: ' + changes)
    for name in add:
        if name == MASS:
            continue
        D = eng.data_for(est.spec.with_(name, {}))
        eta = search(D, est.spec.with_(name, {}), name, est.model) \
            if searched(TERMS[name]) else {}
        est = sel.research(eng, estimate(D, est.spec.with_(name, eta), est.model), name)
        step(name, 'add', est, '')
    if auto:
        est = sel.select(eng, est, step, say, max_steps)
    exp = experiment_notes(eng.summary, u)
    unweighted = est
    rw = reweighted(eng, est)
    weights = None
    if rw is not None:
        est, text, removed = rw
        weights = True
        for name in removed:
            step(name, 'remove', est, f'removed {name}: it pays only through the turns (no '
                 'longer once the rows are weighted by speed band)')
        step(REFIT, REFIT, est, text)
    unc = _uncertainty(eng, est, floor=unweighted.se if weights else None)
    final = est.model
    s = common_scale(model, est)
    if s is not None and set(final.names) >= set(model.names):
        # every force parameter moved by one factor: the simpler explanation is one
        # wrong number, the input gain
        final = scale_forces(final, s)
        unc = {g: {k: v / s for k, v in d.items()} for g, d in unc.items()}
        exp.insert(0, f'every force parameter moved by ×{s:.3f}: input_gain corrected '
                      f'from {model.input_gain:.4g} to {final.input_gain:.4g}')
        steps.append(FitStep('input_gain', est.nrmse_cv, final,
                             f'input_gain is {final.input_gain:.4g}, not '
                             f'{model.input_gain:.4g}', REFIT))
        say(steps[-1].summary)
    un = scan(eng.data_for(est.spec), est, eng.floor(est), units=u, nrmse=steps[-1].force_nrmse,
              verdicts=eng.verdicts.on(est.spec))
    notes = [a.sentence() for a in ambiguities(eng.data_for(est.spec), est)]
    return FitResult(steps=tuple(steps), model=final, uncertainty=unc,
                     identifiability=tuple(notes + identifiability_notes(est.correlations)),
                     experiment=tuple(exp), at_bound=dict(est.at_bound),
                     params=model_scalars(final), unexplained=un)


def _uncertainty(eng: sel.Engine, est: Estimate, *,
                 floor: dict | None = None) -> dict[str, dict[str, float]]:
    """Return the standard errors with the processing's and the measurement's share [SI].

    ``√(SE² + spread²)`` for each spread (:func:`~.uncertainty.processing_spread`,
    :func:`~.uncertainty.measurement_spread`); a parameter declared ``profile`` gets at
    least its profile interval's SE.  With ``floor`` (another fit's SEs), each SE is at
    least that: the weighted fit's own SEs came out 2–3× smaller than its errors (the
    weights are estimated from the same residuals).
    """
    D = eng.data_for(est.spec)
    spreads = (processing_spread(D, est.spec, est.model),
               measurement_spread(D, est.spec, est.model))
    floor = floor or {}

    def se_of(g: str, k: str, v: float) -> float:
        f = floor.get(g, {}).get(k)
        return max(v, f) if f is not None and math.isfinite(f) else v
    unc = {g: {k: float(math.hypot(se_of(g, k, v),
                                   *(s.get(g, {}).get(k, 0.0) for s in spreads)))
               for k, v in d.items()}
           for g, d in est.se.items()}
    from motor_comp.workbench.library import context
    for n in est.spec.names:
        for p in TERMS[n].space(eng.summary, context(est.spec, D)):
            if p.profile and p.name in unc.get(n, {}):
                prof = profile_se(D, est.spec, est.model, n, p.name)
                if math.isfinite(prof):
                    unc[n][p.name] = max(unc[n][p.name], prof)
    return unc


def refit_linear(kin: Kinematics | Sequence[Kinematics], model: AxisModel) -> AxisModel:
    """Return the model with every parameter jointly refit (no effect added/removed)."""
    kins = [kin] if isinstance(kin, Kinematics) else list(kin)
    eng = sel.Engine(kins, model, folds=5, min_gain=0.1)
    return eng.h0(model).model


def add_effects(kin: Kinematics | Sequence[Kinematics], model: AxisModel,
                names: Sequence[str]) -> AxisModel:
    """Return ``model`` with the named effects added (nonlinear parameters searched)."""
    return fit(kin, model, add=names).model


__all__ = ['FitResult', 'FitStep', 'add_effects', 'fit', 'params_text', 'refit_linear',
           'significant_changes', 'model_scalars']
