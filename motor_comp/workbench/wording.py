"""Plain words for the workbench's findings: units, parameter changes, separating experiments.

Every sentence a user reads about a fit is made here, in the axis units (mm, µm, ms; mrad
on a rotary axis), so ``diagnose``, ``fit`` and the reports say the same thing the same
way.  The experiments that separate two effects a run cannot tell apart
(``../shared/IDENTIFICATION.md`` §6) are words, not selection rules: nothing here
decides what is found.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Sequence

import numpy as np

from motor_comp.physics.axis import AxisKind, AxisModel, Units
from motor_comp.physics.effects import EFFECTS, TERMS

MASS = 'mass'
#: the candidate that stands for "the model's own parameters were wrong"
REFIT = 'refit'

#: human wording of each candidate: the effects' own titles
TITLES = {**{n: cls.title or n for n, cls in EFFECTS.items()},
          MASS: 'mass/inertia mismatch', REFIT: 'wrong model parameters'}

#: the experiment that separates two effects a run cannot tell apart (§6)
#: the experiment that tells load-dependent friction from the laws it equals otherwise
BRAKE = ('decelerate faster than friction alone would, so that the drive brakes (pushes '
         'against the motion) for a good share of the run, at several speeds')
SEPARATE = {
    frozenset(('offset', 'asymmetry')): 'move both directions at equal speeds and hold '
                                        'still between moves',
    frozenset(('coulomb', 'stribeck')): 'include motion slower than the Stribeck velocity',
    frozenset(('spring', 'gravity')): 'move over more than ±90° (±π/2 rad)',
    frozenset(('spring', 'offset')): 'use a longer stroke',
    frozenset(('offset', 'gravity')): 'move over more than ±90° (±π/2 rad)',
    frozenset(('coulomb', 'offset')): 'reverse the direction of motion several times',
    frozenset(('coulomb', 'viscous')): 'move at several clearly different speeds',
    frozenset(('mass', 'delay')): 'add fast reversals (high accelerations)',
    frozenset(('mass', 'viscous')): 'add accelerations, not only constant speeds',
    frozenset(('viscous', 'delay')): 'add fast reversals (high accelerations)',
    frozenset(('coulomb', 'asymmetry')): 'move both directions at equal speeds',
    frozenset(('viscous', 'asymmetry')): 'move both directions at equal speeds',
    frozenset(('ripple', 'spring')): 'move over at least two ripple periods',
    frozenset(('ripple', 'offset')): 'move over at least two ripple periods',
    frozenset(('ripple', 'gravity')): 'move over a whole revolution',
    frozenset(('coulomb', 'position_friction')): 'move over the whole travel at one speed',
    # while the drive pushes along the motion, |F_in| = (M·a + fc + fv·|v|)/(1 − mu):
    # load friction is then a larger mass, Coulomb and viscous level; braking tells
    frozenset(('coulomb', 'load_friction')): BRAKE,
    frozenset(('viscous', 'load_friction')): BRAKE,
    frozenset(('mass', 'load_friction')): BRAKE,
    frozenset(('viscous', 'time')): 'interleave the speeds instead of raising them over time',
}

LINEAR_UNITS = Units.of(AxisKind.LINEAR)
ROTARY_UNITS = Units.of(AxisKind.ROTARY)


def axis_units(model: AxisModel, rotary: bool = False) -> Units:
    """Return the units of ``model``'s axis (its ``axis`` key; ``rotary`` forces rotary)."""
    return ROTARY_UNITS if rotary else model.units


def unit_of(effect: str, key: str, u: Units) -> tuple[str, float]:
    """Return the display unit and scale of a reported parameter."""
    pos_mm = ('mm', 1e3) if not u.rotary else ('mrad', 1e3)
    table = {
        'fc': (u.force, 1.0), 'fs': (u.force, 1.0), 'f0': (u.force, 1.0),
        'dfc': (u.force, 1.0), 'mgl': ('N·m', 1.0), 'fv': (u.viscous, 1.0),
        'dfv': (u.viscous, 1.0), 'k': (u.spring, 1.0), 'stiffness': (u.spring, 1.0),
        'x0': pos_mm, 'vs': ('mm/s', 1e3) if not u.rotary else ('mrad/s', 1e3),
        'delta': ('', 1.0), 'c': ('1/s', 1.0), 'tau': ('ms', 1e3),
        'width': ('µm', 1e6) if not u.rotary else ('mrad', 1e3), 'q0': ('rad', 1.0),
        'mass': (u.mass, 1.0), 'period': pos_mm, 'mu': ('', 1.0), 'rise': (u.force, 1.0),
        'x_peak': pos_mm,
    }
    if key.startswith('amplitude_') or key.startswith('dfc_'):
        return u.force, 1.0
    return table.get(key, ('', 1.0))


def params_text(est: Any, name: str, units: Units) -> str:
    """Return one effect's fitted parameters with standard errors, in the axis units.

    ``est`` is an :class:`~.result.Estimate` (its ``scalars`` and ``se``).
    """
    vals = est.scalars.get(name, {})
    se = est.se.get(name, {})
    return ', '.join(fmt_param(name, k, v, se.get(k), units) for k, v in vals.items())


def rows_name(stops: bool) -> str:
    """Return the name of the rows a figure is judged on (one wording in every command).

    A model with a term whose evidence is at the turns is judged on the rows that reach
    the stops, the others on the sliding rows (:func:`.library.processing_for`).
    """
    return 'the rows that reach the stops' if stops else 'the sliding rows'


def unresolved(value: float, se: float | None) -> bool:
    """Return whether a standard error is at least its value (no error bar).

    The run does not resolve the parameter, e.g. a GMS attraction rate on a run whose
    turns never leave pre-sliding slowly (± 2e+15 1/s).
    """
    return se is not None and not np.isnan(se) and se >= abs(value) > 0


def fmt_param(effect: str, key: str, value: float, se: float | None, u: Units) -> str:
    """Return ``'fc 10.0 ± 0.1 N'`` in the axis units."""
    unit, k = unit_of(effect, key, u)
    txt = f'{key} {value * k:.4g}'
    bad = unresolved(value, se)
    if se is not None and np.isfinite(se) and se > 0 and not bad:
        txt += f' ± {se * k:.2g}'
    if unit:
        txt += f' {unit}'
    if bad:
        txt += ' (not resolved by this run)'
    if effect == 'ripple' and key == 'period' and u.rotary and value > 0:
        txt += f' ({2 * math.pi / value:.3g} cycles/rev)'
    return txt


@dataclasses.dataclass(frozen=True)
class ParameterChange:
    """A parameter the refit moved significantly: ``fc is 10.0 ± 0.1 N, not 5.0 N``."""

    effect: str
    name: str
    given: float
    fitted: float
    se: float

    def sentence(self, u: Units) -> str:
        """Return the change in plain words in the axis units."""
        unit, k = unit_of(self.effect, self.name, u)
        se = f' ± {self.se * k:.2g}' if np.isfinite(self.se) and self.se > 0 else ''
        label = self.name if self.effect in (MASS, self.name) else f'{self.effect}.{self.name}'
        return (f'{label} is {self.fitted * k:.4g}{se} {unit}, not {self.given * k:.4g} '
                f'{unit}').replace('  ', ' ')

    def as_dict(self) -> dict[str, Any]:
        """Return the JSON form."""
        return {'effect': self.effect, 'param': self.name, 'given': self.given,
                'fitted': self.fitted, 'se': self.se}


def identifiability_notes(correlations: Sequence[tuple[str, str, float]]) -> list[str]:
    """Return sentences for pairs correlated beyond ±0.97, with the separating experiment."""
    out = []
    seen = set()
    for a, b, rho in correlations:
        ea, eb = a.split('.')[0], b.split('.')[0]
        key = frozenset((ea, eb))
        if key in seen:
            continue
        seen.add(key)
        how = SEPARATE.get(key, 'an experiment that excites them differently')
        out.append(f'{ea} and {eb} (correlation {rho:+.2f} of {a} and {b}): {how}')
    return out


def model_scalars(model: AxisModel, data: Any = None) -> dict[str, dict[str, float]]:
    """Return the reported parameters of ``model`` as :mod:`.uncertainty` names them."""
    from motor_comp.workbench.library import context, spec_of, theta_of, labels, values_of
    from motor_comp.workbench.uncertainty import reported
    spec = spec_of(model)
    ctx = context(spec)
    vals = values_of(spec, labels(spec, ctx), theta_of(model, spec, ctx))
    out: dict[str, dict[str, float]] = {}
    for (g, k), fn in reported(spec).items():
        out.setdefault(g, {})[k] = float(fn(vals))
    return out


def significant_changes(before: Mapping, after: Any, *, rel: float = 0.02) \
        -> list[ParameterChange]:
    """Return the parameters that moved by more than 2 SE and ``rel`` between two fits."""
    out = []
    for grp, vals in after.scalars.items():
        for k, new in vals.items():
            old = before.get(grp, {}).get(k)
            if old is None or not np.isfinite(new):
                continue
            se = after.se.get(grp, {}).get(k, float('nan'))
            se_ok = True if not np.isfinite(se) else abs(new - old) > 2.0 * se
            if se_ok and abs(new - old) > rel * max(abs(old), abs(new), 1e-12):
                out.append(ParameterChange(grp, k, float(old), float(new), float(se)))
    return out


def force_scaled() -> set[tuple[str, str]]:
    """Return the reported parameters that scale with the force (mass and the terms')."""
    out = {(MASS, 'mass')}
    for t in TERMS.values():
        out.update(t.force_scaled)
    out.add(('coulomb', 'fc'))
    return out


def common_scale(given: AxisModel, est: Any) -> float | None:
    """Return the factor every force parameter of ``given`` moved by, if they all agree.

    The input gain converts the logged command into force, so a gain error ``g/s``
    multiplies the mass and every force coefficient by ``s``: indistinguishable from all
    of them being off by the same factor, except that one wrong number is far more
    likely than several wrong by exactly the same ratio.  Each ratio is compared within
    its tolerance (2 SE or 5 %).  Returns ``s`` (the median ratio, off 1 by more than
    3 %) when every ratio agrees with ``s`` and at least two of them moved: differ from
    1 by more than their tolerance.  A ratio that agrees with ``s`` only because its
    own uncertainty is wide agrees with no move as well, and is no evidence of a common
    factor (on the tutorial's run a model missing its ripple refits fc ×1.04 at 1.8 SE,
    fv ×0.84 ± 0.10 and the mass ×1.13 ± 0.06: one move, not a gain).  Else None.
    """
    before = model_scalars(given)
    ratios = []
    for grp, key in force_scaled():
        old = before.get(grp, {}).get(key)
        new = est.scalars.get(grp, {}).get(key)
        if old is None or new is None or old == 0:
            continue
        ratios.append((new / old, est.se.get(grp, {}).get(key, float('nan')) / abs(old)))
    if len(ratios) < 2:
        return None
    r = np.array([q for q, _ in ratios])
    s = float(np.median(r))
    if not (np.all(r > 0) and abs(s - 1.0) > 0.03):
        return None
    moved = 0
    for q, se in ratios:
        tol = max(0.05 * s, 2.0 * se if np.isfinite(se) else 0.0)
        if abs(q - s) > tol:
            return None
        moved += abs(q - 1.0) > tol
    return s if moved >= 2 else None


def scale_forces(model: AxisModel, s: float) -> AxisModel:
    """Return ``model`` with the input gain and every force parameter divided by ``s``."""
    d = model.to_dict()
    d['input_gain'] = model.input_gain / s
    d['mass'] = model.mass / s
    d['damping'] = model.damping / s
    eff = {}
    for name, p in (d.get('effects') or {}).items():
        p = dict(p)
        for k in ('fc', 'fv', 'fs', 'f0', 'k', 'dfc', 'dfv', 'mgl'):
            if k in p:
                p[k] = [v / s for v in p[k]] if isinstance(p[k], list) else p[k] / s
        if name == 'ripple':
            p['harmonics'] = [[a / s, b / s] for a, b in p['harmonics']]
        eff[name] = p
    d['effects'] = eff
    return AxisModel.from_dict(d, source='scaled model')


def gain_note(s: float | None, model: AxisModel) -> str | None:
    """Return the sentence for a common scale factor: the input gain is the likely culprit."""
    if s is None:
        return None
    return (f'every force parameter moved by ×{s:.3f}: the input gain is probably '
            f'{model.input_gain / s:.4g}, not {model.input_gain:.4g} (a gain error scales '
            f'every force; if instead the gain is right, all parameters are off by that '
            f'factor)')


def directions(model: AxisModel, u: Units) -> str:
    """Return both directions' friction values of an asymmetric model."""
    a = model.get('asymmetry')
    if a is None:
        return ''
    fc, fv = model.fc, model.fv
    return (f'positive direction fc+ {fc + a.dfc / 2:.4g} {u.force}, fv+ {fv + a.dfv / 2:.4g} '
            f'{u.viscous}; negative direction fc− {fc - a.dfc / 2:.4g} {u.force}, '
            f'fv− {fv - a.dfv / 2:.4g} {u.viscous}')


def more_words(effect: str, model: AxisModel, u: Units) -> str:
    """Return what a finding says besides its parameters ('' for most effects)."""
    return directions(model, u) if effect == 'asymmetry' else ''


def experiment_notes(summary: Any, units: Units) -> list[str]:
    """Return what the experiment lacks for the method to judge (empty when nothing)."""
    notes = []
    if summary.direction:
        notes.append('the axis moves in one direction only: Coulomb friction cannot be told '
                     'from a constant offset, and direction-dependent friction (asymmetry) '
                     'is not identifiable on this run; move both directions at equal speeds '
                     '(add runs in the other direction or reversals)')
    elif summary.reversals < 4:
        notes.append(f'only {summary.reversals} reversal(s) within the runs: pre-sliding and '
                     'backlash cannot be judged (they act at reversals); add back-and-forth '
                     'moves')
    lo, hi = summary.speeds[10], summary.speeds[90]
    if hi < 2.0 * lo:
        notes.append(f'speeds span only {lo:.3g}–{hi:.3g} {units.velocity}: Coulomb and viscous '
                     'friction cannot be separated; move at several clearly different speeds')
    return notes


__all__ = ['BRAKE', 'LINEAR_UNITS', 'MASS', 'ParameterChange', 'REFIT', 'ROTARY_UNITS',
           'SEPARATE', 'TITLES', 'axis_units', 'common_scale', 'directions', 'experiment_notes',
           'fmt_param', 'force_scaled', 'gain_note', 'identifiability_notes',
           'model_scalars', 'more_words', 'params_text', 'rows_name', 'scale_forces',
           'significant_changes', 'unit_of', 'unresolved']
