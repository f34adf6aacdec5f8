"""Add effects to a model and refit all its parameters on a run; ``--auto`` loop.

The refit is the robotics inverse-model identification (``F_in = M·ẍ + Σ θ_j·φ_j``):
with the nonlinear parameters held (ripple period, Stribeck ``vs``/``δ``, delay, GMS
stiffness and rate, backlash width — taken from the candidate search), every parameter
that enters linearly is re-estimated jointly by least squares on the smoothed
regressors of the effect modules: the mass, ``fc``, ``fv``, ``fs − fc``, the ripple
amplitudes, ``f0``, the spring, the asymmetry, and a common scale of the GMS force.
``input_gain``, ``back_emf`` and ``damping`` stay fixed (they are the drive's data;
``damping`` and ``back_emf`` are collinear with ``fv``).

Held-out errors: each fit is repeated with one contiguous time block left out, and the
force NRMSE is evaluated on that block (the same blocks as :mod:`.diagnose`).
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable, Sequence

import numpy as np

from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import Asymmetry, Coulomb, Offset, Ripple, Spring, \
    Stribeck, Viscous
from motor_comp.workbench.candidates import FITTERS, MASS, FitContext, \
    available_candidates
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.diagnose import diagnose, fold_masks
from motor_comp.workbench.residual import force_nrmse, residual


def refit_linear(kin: Kinematics, model: AxisModel, train: np.ndarray | None = None) \
        -> AxisModel:
    """Joint least-squares refit of every linear parameter of ``model`` (see module doc)."""
    res = residual(kin, model)
    rows = res.mask if train is None else (train & res.mask)
    x, v = res.x, res.v
    cols: list[np.ndarray] = [res.a[:, None]]
    slots: list[tuple[str, int]] = [(MASS, 1)]
    gms = model.has('presliding')
    for e in model.effects:
        n = e.name
        if n in ('coulomb', 'stribeck') and gms:
            continue   # carried by the GMS elements, scaled through their column
        if n == 'presliding':
            c = res.forces['presliding'][:, None]
        elif n == 'offset':
            c = np.ones((len(kin), 1))
        elif n == 'spring':
            c = kin.smooth(e.regressors(x))
            if model.has('offset'):
                c = c[:, :1]   # the constant belongs to the offset
        elif n in ('coulomb', 'viscous', 'stribeck', 'ripple', 'asymmetry'):
            c = kin.smooth(e.regressors(x, v))
        else:
            continue   # delay, backlash: nonlinear only
        cols.append(c)
        slots.append((n, c.shape[1]))
    X = np.concatenate(cols, axis=1)
    theta, *_ = np.linalg.lstsq(X[rows], res.f_in[rows], rcond=None)
    if not 0.1 * model.mass <= theta[0] <= 10.0 * model.mass:
        # the run does not excite the inertia (e.g. constant speed): an estimate an
        # order of magnitude off is noise, so the mass is kept and the rest refit
        rest, *_ = np.linalg.lstsq(X[rows][:, 1:], (res.f_in - res.inertia)[rows],
                                   rcond=None)
        theta = np.concatenate([[model.mass], rest])
    coef: dict[str, np.ndarray] = {}
    i = 0
    for name, w in slots:
        coef[name] = theta[i:i + w]
        i += w
    out = model.replace(mass=max(float(coef[MASS][0]), 1e-3 * model.mass))
    fc_new = max(float(coef['coulomb'][0]), 0.0) if 'coulomb' in coef else model.fc
    for e in model.effects:
        n = e.name
        if n not in coef and n != 'stribeck':
            continue
        c = coef.get(n)
        if n == 'coulomb':
            new = Coulomb(fc=fc_new)
        elif n == 'viscous':
            new = Viscous(fv=max(float(c[0]), 0.0))
        elif n == 'stribeck':
            if c is None:       # scaled with the GMS below
                continue
            new = Stribeck(fs=fc_new + max(float(c[0]), 0.0), vs=e.vs, delta=e.delta)
        elif n == 'presliding':
            scale = max(float(c[0]), 1e-3)
            cou, st = model.get('coulomb'), model.get('stribeck')
            if cou is not None:
                out = out.with_effect(Coulomb(fc=cou.fc * scale))
            if st is not None:
                out = out.with_effect(Stribeck(fs=st.fs * scale, vs=st.vs, delta=st.delta))
            continue
        elif n == 'ripple':
            new = Ripple(period=e.period, harmonics=tuple(
                (float(c[2 * h]), float(c[2 * h + 1])) for h in range(len(c) // 2)))
        elif n == 'offset':
            f0 = float(c[0])
            if 'spring' in coef:
                sp = model.get('spring')
                f0 += float(coef['spring'][0]) * sp.x0
            new = Offset(f0=f0)
        elif n == 'spring':
            k = float(c[0])
            if len(c) > 1 and abs(k) > 0:
                x0 = float(np.clip(-float(c[1]) / k, -1e3, 1e3))
            else:
                x0 = e.x0
            new = Spring(k=k, x0=x0)
        elif n == 'asymmetry':
            new = Asymmetry(dfc=float(c[0]), dfv=float(c[1]))
        else:
            continue
        out = out.with_effect(new)
    return out


def add_effects(kin: Kinematics, model: AxisModel, names: Sequence[str],
                train: np.ndarray | None = None) -> AxisModel:
    """``model`` with the named effects added (nonlinear parameters searched), all refit."""
    for name in names:
        _check_addable(model, name)
        res = residual(kin, model)
        rows = res.mask if train is None else train & res.mask
        model = FITTERS[name](FitContext(kin=kin, model=model, res=res), rows).model
    return refit_linear(kin, model, train)


def heldout_nrmse(kin: Kinematics, procedure: Callable[[np.ndarray | None], AxisModel], *,
                  mask: np.ndarray, folds: int = 5) -> float:
    """Force NRMSE of ``procedure(train)`` on the blocks it did not see."""
    num = 0.0
    r_all = []
    f_all = []
    for held in fold_masks(mask, folds):
        m = procedure(mask & ~held)
        res = residual(kin, m, mask=mask)
        r_all.append(res.r[held])
        f_all.append(res.f_in[held])
    r = np.concatenate(r_all)
    num = force_nrmse(r, np.concatenate(f_all))
    return num


@dataclasses.dataclass(frozen=True)
class FitStep:
    """One step of a fit: the effect added (None = starting model) and its errors."""

    effect: str | None
    force_nrmse: float
    model: AxisModel
    summary: str = ''

    def as_dict(self) -> dict[str, Any]:
        """JSON form (DESIGN.md §6 ``steps`` entry)."""
        return {'effect': self.effect, 'force_nrmse': float(self.force_nrmse),
                'summary': self.summary}


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Steps from the starting model to the fitted one."""

    steps: tuple
    model: AxisModel

    def as_dict(self) -> dict[str, Any]:
        """JSON form of DESIGN.md §6 (``steps``, ``model``)."""
        return {'steps': [s.as_dict() for s in self.steps], 'model': self.model.to_dict()}


def _check_addable(model: AxisModel, name: str) -> None:
    """Raise :class:`ParameterError` if effect ``name`` cannot be added to ``model``."""
    if name != MASS and model.has(name):
        raise ParameterError(f'the model already has {name!r}; it is refit anyway')
    if name not in available_candidates(model):
        raise ParameterError(
            f'cannot add {name!r} to this model'
            + (' (add coulomb first)' if name in ('stribeck', 'presliding') else ''))


def _check_add_list(model: AxisModel, names: Sequence[str]) -> None:
    """Check a whole ``add`` list before any fitting, effect by effect in order.

    The rules of :func:`available_candidates` (no duplicates, coulomb before stribeck
    and presliding) applied to the names alone, so that a bad list fails at once
    instead of after its first, possibly long, fitting steps.
    """
    present = {e.name for e in model.effects}
    for name in names:
        if name == MASS:
            continue
        if name in present:
            raise ParameterError(f'the model already has {name!r}; it is refit anyway'
                                 if model.has(name) else f'{name!r} is added twice')
        if name in ('stribeck', 'presliding') and 'coulomb' not in present:
            raise ParameterError(f'cannot add {name!r} to this model (add coulomb first)')
        if name in ('coulomb', 'stribeck') and 'presliding' in present:
            raise ParameterError(f'cannot add {name!r} to this model')
        present.add(name)


def fit(kin: Kinematics, model: AxisModel, *, add: Sequence[str] = (), auto: bool = False,
        folds: int = 5, min_gain: float = 0.1, max_steps: int = 6,
        progress: Callable[[str], None] | None = None, rotary: bool = False) -> FitResult:
    """Add ``add`` (one step each) and, with ``auto``, repeat diagnose→add until none pays.

    Returns every step with its held-out force NRMSE; the first step is the starting
    model (``effect=None``, its NRMSE over all sliding samples since nothing is fitted).
    """
    say = progress or (lambda s: None)
    _check_add_list(model, add)
    mask = residual(kin, model).mask
    steps = [FitStep(None, residual(kin, model, mask=mask).nrmse(), model, 'starting model')]
    say(f'start: force NRMSE {100 * steps[0].force_nrmse:.1f} %')
    for name in add:
        model = _step(kin, model, name, mask, folds, steps, say)
    if not add and not auto:
        # a plain refit of the existing parameters
        start = model
        nrmse = heldout_nrmse(kin, lambda tr: refit_linear(kin, start, tr), mask=mask,
                              folds=folds)
        model = refit_linear(kin, model)
        steps.append(FitStep('refit', nrmse, model, 'refit of all linear parameters'))
        say(f'refit: force NRMSE {100 * nrmse:.1f} %')
    if auto:
        for _ in range(max_steps):
            d = diagnose(kin, model, folds=folds, min_gain=min_gain, rotary=rotary)
            best = d.best
            if best is None:
                say('nothing else pays for its parameters: done')
                break
            if best.effect == steps[-1].effect:
                say(f'{best.effect} again: the refit did not settle it; stopping')
                break
            say(f'diagnose: {best.sentence(rotary=rotary)}')
            model = _step(kin, model, best.effect, mask, folds, steps, say)
            if steps[-1].force_nrmse >= steps[-2].force_nrmse:
                say('the held-out error did not fall: keeping the previous model')
                steps.pop()
                model = steps[-1].model
                break
    return FitResult(steps=tuple(steps), model=model)


def _step(kin: Kinematics, model: AxisModel, name: str, mask: np.ndarray, folds: int,
          steps: list, say: Callable[[str], None]) -> AxisModel:
    start = model
    nrmse = heldout_nrmse(kin, lambda tr: add_effects(kin, start, [name], tr), mask=mask,
                          folds=folds)
    model = add_effects(kin, start, [name])
    params = model.get(name).params() if name != MASS else {'mass': model.mass}
    text = f'added {name} {_fmt(params)}'
    steps.append(FitStep(name, nrmse, model, text))
    say(f'{text}: force NRMSE {100 * nrmse:.1f} %')
    return model


def _fmt(params: dict) -> str:
    def one(v: Any) -> str:
        if isinstance(v, list):
            return '[' + ', '.join(one(e) for e in v) + ']'
        return f'{v:.4g}'
    return ', '.join(f'{k}={one(v)}' for k, v in params.items())
