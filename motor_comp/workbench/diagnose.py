"""Find what a model gets wrong: a missing physical effect or a wrong parameter.

The method of ``../shared/IDENTIFICATION.md`` on the joint regressor of
:mod:`~motor_comp.workbench.ident`:

1. **H0 is the current model refitted**: every linear parameter (mass/inertia and each
   effect's coefficients) jointly, the nonlinear ones re-searched.  When the refit
   pays (held-out gain, BIC) the first finding is the parameters that were wrong —
   ``fc is 10.0 ± 0.1 N, not 5.0 N`` — and when every parameter moved by one common
   factor, the input gain (or the mass it is measured against) is named instead.
2. Each absent effect is scored as *H0 + candidate, all linear parameters re-estimated
   together*, with its nonlinear parameters chosen inside each fold; ``explained`` is
   the held-out fraction of H0's residual energy it removes, ``force_nrmse`` the
   held-out ``RMS(r)/RMS(F_in − mean)`` (DESIGN.md §6).
3. A candidate is *supported* when it pays for its parameters on held-out data: it
   removes at least ``min_gain`` of the residual, lowers the held-out NRMSE by at
   least ``min_drop``, and improves the held-out BIC ``n_eff·ln(SSE₁/SSE₀) +
   Δp·ln(n_eff)`` (``n_eff`` = samples per smoothing window).
4. Standard errors are cluster-robust over the validation blocks; pairs of parameters
   whose estimates correlate beyond ±0.97 are named with the experiment that would
   separate them, and a run too poor to judge (no motion, too few reversals, one
   speed) says what the experiment lacks.

Several runs are one experiment: one model, blocks from every run.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

import numpy as np

from motor_comp.threads import single_threaded_blas
from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisKind, AxisModel, Units
from motor_comp.workbench import ident as idm
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.residual import Residual, residual, sliding_mask

MASS = idm.MASS
#: the candidate that stands for "the model's own parameters were wrong"
REFIT = 'refit'

#: human wording of each candidate
TITLES = {'coulomb': 'Coulomb friction', 'viscous': 'viscous friction',
          'stribeck': 'Stribeck friction', 'presliding': 'pre-sliding hysteresis (GMS)',
          'ripple': 'force ripple', 'offset': 'constant force offset',
          'spring': 'spring (position-proportional force)',
          'asymmetry': 'direction-dependent friction', 'delay': 'input delay',
          'backlash': 'backlash', 'gravity': 'gravity (unbalanced load)',
          MASS: 'mass/inertia mismatch', REFIT: 'wrong model parameters'}

#: the experiment that separates two effects this run cannot tell apart (§6)
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
}
#: effects told from the canonical friction (coulomb, viscous) only by the other direction
#: of motion: on a run that moves one way, asymmetry's columns copy coulomb/viscous and
#: a constant offset copies coulomb, so they are not identifiable there and not offered
#: (the constant force while sliding is named Coulomb friction; the notes say so)
NEED_BOTH_DIRECTIONS = ('offset', 'asymmetry')
#: the nonlinear parameter that sets each effect's shape: an effect whose force share is
#: small (a backlash gap, a dead time) still pays when it removes most of what the model
#: leaves and this parameter is pinned down by the run (see :meth:`Engine.resolved`)
SHAPE_PARAM = {'delay': 'tau', 'backlash': 'width', 'presliding': 'stiffness'}
#: "most of what the model leaves": least held-out share of the residual removed
RESOLVED_GAIN = 0.5
#: "pinned down": largest standard error of the shape parameter relative to its value.
#: A GMS's initial stiffness Σk is set by the first encoder counts after each reversal,
#: so it is looser than a delay or a gap (0.19 on the independent generator's
#: c+presliding+ripple seed 3, whose pre-sliding is half of what a Coulomb + ripple
#: model leaves); a GMS fitted to a stick from a different law has no stiffness at all
RESOLVED_REL_SE = {'delay': 0.05, 'backlash': 0.05, 'presliding': 0.25}


LINEAR_UNITS = Units.of(AxisKind.LINEAR)
ROTARY_UNITS = Units.of(AxisKind.ROTARY)


def axis_units(model: AxisModel, rotary: bool = False) -> Units:
    """Return the units of ``model``'s axis (its ``axis`` key; ``rotary`` forces rotary)."""
    return ROTARY_UNITS if rotary else model.units


def _unit_of(effect: str, key: str, u: Units) -> tuple[str, float]:
    """Display unit and scale of a scalar parameter."""
    pos_mm = ('mm', 1e3) if not u.rotary else ('mrad', 1e3)
    table = {
        'fc': (u.force, 1.0), 'fs': (u.force, 1.0), 'f0': (u.force, 1.0),
        'dfc': (u.force, 1.0), 'mgl': ('N·m', 1.0), 'fv': (u.viscous, 1.0),
        'dfv': (u.viscous, 1.0), 'k': (u.spring, 1.0), 'stiffness': (u.spring, 1.0),
        'x0': pos_mm, 'vs': ('mm/s', 1e3) if not u.rotary else ('mrad/s', 1e3),
        'delta': ('', 1.0), 'c': ('1/s', 1.0), 'tau': ('ms', 1e3),
        'width': ('µm', 1e6) if not u.rotary else ('mrad', 1e3), 'q0': ('rad', 1.0),
        'mass': (u.mass, 1.0), 'period': pos_mm,
    }
    if key.startswith('amplitude_'):
        return u.force, 1.0
    return table.get(key, ('', 1.0))


def fmt_param(effect: str, key: str, value: float, se: float | None, u: Units) -> str:
    """``'fc 10.0 ± 0.1 N'`` in the axis units."""
    unit, k = _unit_of(effect, key, u)
    v = value * k
    txt = f'{key} {v:.4g}'
    if se is not None and np.isfinite(se) and se > 0:
        txt += f' ± {se * k:.2g}'
    if unit:
        txt += f' {unit}'
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
        """Plain words in the axis units."""
        unit, k = _unit_of(self.effect, self.name, u)
        se = f' ± {self.se * k:.2g}' if np.isfinite(self.se) and self.se > 0 else ''
        label = self.name if self.effect in (MASS, self.name) else f'{self.effect}.{self.name}'
        return (f'{label} is {self.fitted * k:.4g}{se} {unit}, not {self.given * k:.4g} '
                f'{unit}').replace('  ', ' ')

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {'effect': self.effect, 'param': self.name, 'given': self.given,
                'fitted': self.fitted, 'se': self.se}


@dataclasses.dataclass(frozen=True)
class CandidateResult:
    """One candidate's held-out score and its joint fit on all data.

    Parameters
    ----------
    effect : str
        Vocabulary name, ``'mass'`` (only the mass was wrong) or ``'refit'``.
    explained : float
        Held-out fraction of the refitted baseline's residual energy removed (for the
        refit itself: of the given model's residual).
    force_nrmse : float
        Held-out force NRMSE with the candidate.
    params : dict
        Physical parameters of the effect (model-file form, SI); for ``mass``/``refit``
        the refitted model's ``mass`` and ``effects``.
    uncertainty : dict[str, float]
        Standard error of each scalar parameter (same units).
    scalars : dict[str, float]
        Flat parameter values for tables.
    n_params : int
        Parameters it adds.
    bic_delta : float
        Held-out BIC change (< 0 pays for the parameters).
    supported : bool
        Whether it pays for its parameters.
    model : AxisModel
        The jointly refitted model with the candidate.
    changes : tuple of ParameterChange
        Parameters of the model that moved significantly in the joint refit.
    units : Units
        Axis units for the wording.
    """

    effect: str
    explained: float
    force_nrmse: float
    params: dict
    uncertainty: dict
    scalars: dict
    n_params: int
    bic_delta: float
    supported: bool
    model: AxisModel
    changes: tuple = ()
    units: Units = LINEAR_UNITS
    correlations: tuple = ()
    spec: Any = None
    #: the fit put one of the candidate's own parameters at its physical bound
    at_bound: bool = False

    @property
    def title(self) -> str:
        """Human name of the candidate."""
        return TITLES.get(self.effect, self.effect)

    def sentence(self, *, rotary: bool | None = None) -> str:
        """Plain-language finding, e.g. 'force ripple, period 7.25 mm, … removes 83 %'."""
        u = ROTARY_UNITS if rotary else self.units
        if self.effect in (MASS, REFIT):
            what = '; '.join(c.sentence(u) for c in self.changes) or 'parameters refitted'
            body = f'{self.title}: {what}'
        else:
            parts = [fmt_param(self.effect, k, v, self.uncertainty.get(k), u)
                     for k, v in self.scalars.items()]
            if self.effect == 'asymmetry':
                parts.append(_directions(self.model, u))
            body = f'{self.title}, {", ".join(p for p in parts if p)}'
        verdict = '' if self.supported else ' (not supported: does not pay for its ' \
                                            'parameters on held-out data)'
        return f'{body}, removes {100 * self.explained:.0f} % of the residual{verdict}'

    def as_dict(self) -> dict[str, Any]:
        """JSON form (DESIGN.md §6 ``candidates`` entry)."""
        return {'effect': self.effect, 'title': self.title,
                'explained': float(self.explained), 'force_nrmse': float(self.force_nrmse),
                'params': self.params, 'uncertainty': self.uncertainty,
                'n_params': self.n_params, 'bic_delta': float(self.bic_delta),
                'supported': bool(self.supported), 'summary': self.sentence(),
                'changes': [c.as_dict() for c in self.changes],
                'model': self.model.to_dict()}


def _directions(model: AxisModel, u: Units) -> str:
    """Both directions' friction values of an asymmetric model."""
    a = model.get('asymmetry')
    if a is None:
        return ''
    fc, fv = model.fc, model.fv
    return (f'positive direction fc+ {fc + a.dfc / 2:.4g} {u.force}, fv+ {fv + a.dfv / 2:.4g} '
            f'{u.viscous}; negative direction fc− {fc - a.dfc / 2:.4g} {u.force}, '
            f'fv− {fv - a.dfv / 2:.4g} {u.viscous}')


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`: baseline, refit finding, ranked candidates, caveats."""

    baseline_nrmse: float
    refit_nrmse: float
    rms_residual: float
    n_samples: int
    n_sliding: int
    n_eff: float
    folds: int
    candidates: tuple
    residual: Residual
    kin: Kinematics
    model: AxisModel
    refit: CandidateResult | None = None
    experiment: tuple = ()
    identifiability: tuple = ()
    units: Units = LINEAR_UNITS
    runs: tuple = ()

    @property
    def rotary(self) -> bool:
        """Whether the axis is rotary."""
        return self.units.rotary

    @property
    def best(self) -> CandidateResult | None:
        """The first finding: the best supported candidate, else a paying refit."""
        for c in self.candidates:
            if c.supported:
                return c
        return None

    def summary(self) -> str:
        """Plain text for the terminal."""
        u = self.units
        lines = [f'baseline: force NRMSE {100 * self.baseline_nrmse:.1f} % as given, '
                 f'{100 * self.refit_nrmse:.1f} % with its own parameters refitted '
                 f'(held-out; RMS residual {self.rms_residual:.3g} {u.force} over '
                 f'{self.n_sliding} sliding samples, {self.folds} folds)']
        best = self.best
        if best is None:
            lines.append('no candidate effect pays for its parameters: nothing is missing '
                         'that this run can reveal')
        elif best.effect in (MASS, REFIT):
            lines.append(f'first finding: {best.sentence()}')
        else:
            lines.append(f'missing: {best.sentence()}')
            if best.changes:
                lines.append('  with, refitted jointly: '
                             + '; '.join(c.sentence(u) for c in best.changes))
        for note in self.identifiability:
            lines.append(f'cannot tell apart: {note}')
        for note in self.experiment:
            lines.append(f'experiment: {note}')
        lines.append('candidates (held-out):')
        for i, c in enumerate(self.candidates, start=1):
            flag = '+' if c.supported else ' '
            lines.append(f' {flag}{i:2d}. {c.effect:<10s} explained {100 * c.explained:6.1f} %'
                         f'  NRMSE {100 * c.force_nrmse:5.1f} %  {_param_text(c)}')
        return '\n'.join(lines)

    def as_dict(self) -> dict[str, Any]:
        """JSON form of DESIGN.md §6 (``baseline``, ``candidates`` best first)."""
        best = self.best
        return {
            'run': self.kin.name,
            'runs': list(self.runs),
            'axis': 'rotary' if self.rotary else 'linear',
            'units': {k: getattr(self.units, k) for k in ('position', 'velocity', 'force',
                                                          'mass', 'viscous', 'spring')},
            'baseline': {'force_nrmse': float(self.baseline_nrmse),
                         'refit_force_nrmse': float(self.refit_nrmse),
                         'rms_residual': float(self.rms_residual),
                         'n_samples': int(self.n_samples), 'n_sliding': int(self.n_sliding),
                         'folds': int(self.folds), 'sample_rate': 1.0 / self.kin.dt,
                         'resampled': bool(self.kin.resampled)},
            'refit': self.refit.as_dict() if self.refit is not None else None,
            'candidates': [c.as_dict() for c in self.candidates],
            'best': best.effect if best is not None else None,
            'summary': (best.sentence() if best is not None else 'nothing missing'),
            'identifiability': list(self.identifiability),
            'experiment': list(self.experiment),
        }


def _param_text(c: CandidateResult) -> str:
    out = []
    for k, v in c.scalars.items():
        s = c.uncertainty.get(k)
        out.append(f'{k}={v:.4g}' + (f'±{s:.2g}' if s is not None and np.isfinite(s)
                                     and s > 0 else ''))
    return ' '.join(out)


# ------------------------------------------------------------------------------------
def as_list(kin: Kinematics | Sequence[Kinematics]) -> list[Kinematics]:
    """One run or several (one experiment)."""
    return [kin] if isinstance(kin, Kinematics) else list(kin)


def experiment_notes(D: idm.Data, model: AxisModel) -> list[str]:
    """List what the experiment lacks for the method to judge (empty when nothing)."""
    notes = []
    v = D.gather(lambda p: p.v)
    u = axis_units(model)
    n_rev = reversal_count(D)
    if not both_directions(D):
        notes.append('the axis moves in one direction only: Coulomb friction cannot be told '
                     'from a constant offset, and direction-dependent friction (asymmetry) '
                     'is not identifiable on this run; move both directions at equal speeds '
                     '(add runs in the other direction or reversals)')
    elif n_rev < 4:
        notes.append(f'only {n_rev} reversal(s) within the runs: pre-sliding and backlash '
                     'cannot be judged (they act at reversals); add back-and-forth moves')
    speed = np.abs(v)
    lo, hi = np.percentile(speed, [10, 90])
    if hi < 2.0 * lo:
        notes.append(f'speeds span only {lo:.3g}–{hi:.3g} {u.velocity}: Coulomb and viscous '
                     'friction cannot be separated; move at several clearly different speeds')
    return notes


def identifiability_notes(correlations: Sequence[tuple[str, str, float]]) -> list[str]:
    """Sentences for parameter pairs correlated beyond ±0.97, with the separating experiment."""
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


def both_directions(D: idm.Data) -> bool:
    """Whether the runs slide both ways (``idm.MIN_DIRECTION_SHARE`` of samples each way)."""
    return D.direction == 0


def reversal_count(D: idm.Data) -> int:
    """Sign changes of the velocity within the runs' sliding rows."""
    return int(sum(np.count_nonzero(np.diff(np.sign(p.kin.v[p.rows])) != 0)
                   for p in D.parts))


def available(spec: idm.Spec, model: AxisModel, units: Units, *,
              reversals: int = 100, both_ways: bool = True) -> list[str]:
    """Candidate effects that can be added to ``spec``.

    Pre-sliding and backlash act at reversals: with fewer than 4 the run cannot
    judge them, so they are not offered (the experiment notes say why).  Effects
    told from coulomb/viscous only by the other direction of motion (``asymmetry``,
    ``offset``) are not offered when the run moves one way only (``both_ways``
    False): there their columns copy the canonical ones, so they are not identifiable.
    """
    out = []
    names = set(spec.names)
    for n in idm.ORDER:
        if n in names:
            continue
        if n in ('presliding', 'backlash') and reversals < 4:
            continue
        if n in NEED_BOTH_DIRECTIONS and not both_ways:
            continue
        if n in ('stribeck', 'presliding') and 'coulomb' not in names:
            continue
        if n == 'presliding' and 'backlash' in names:
            continue
        if n == 'gravity' and not units.rotary:
            continue
        out.append(n)
    return out


def significant_changes(before: dict, after: idm.Estimate, *, rel: float = 0.02) \
        -> list[ParameterChange]:
    """Parameters that moved by more than 2 SE and ``rel`` between two fits."""
    out = []
    for grp, vals in after.scalars.items():
        for k, new in vals.items():
            old = before.get(grp, {}).get(k)
            if old is None or not np.isfinite(new):
                continue
            se = after.se.get(grp, {}).get(k, float('nan'))
            if grp == 'ripple' and k == 'period':
                continue
            if not np.isfinite(se):
                se_ok = True
            else:
                se_ok = abs(new - old) > 2.0 * se
            if se_ok and abs(new - old) > rel * max(abs(old), abs(new), 1e-12):
                out.append(ParameterChange(grp, k, float(old), float(new), float(se)))
    return out


def model_scalars(model: AxisModel) -> dict[str, dict[str, float]]:
    """Flat scalars of a model, named as :func:`ident.decode` names them."""
    out: dict[str, dict[str, float]] = {MASS: {'mass': model.mass}}
    for e in model.effects:
        p = e.params()
        if e.name == 'presliding':
            out[e.name] = {'stiffness': e.stiffness, 'c': e.C / max(model.fc, 1e-6)}
        elif e.name == 'ripple':
            d = {'period': e.period}
            for h, a in enumerate(e.amplitudes, start=1):
                d[f'amplitude_{h}'] = float(a)
            out[e.name] = d
        else:
            out[e.name] = {k: float(v) for k, v in p.items() if isinstance(v, float)}
    return out


#: parameters that scale with the force (a gain error multiplies each by one factor)
FORCE_SCALED = {(MASS, 'mass'), ('coulomb', 'fc'), ('viscous', 'fv'), ('offset', 'f0'),
                ('stribeck', 'fs'), ('spring', 'k'), ('gravity', 'mgl'),
                ('presliding', 'stiffness'), ('ripple', 'amplitude_1')}


def common_scale(given: AxisModel, est: idm.Estimate) -> float | None:
    """Return the factor every force parameter of ``given`` moved by, if they all agree.

    The input gain converts the logged command into force, so a gain error ``g/s``
    multiplies the mass and every force coefficient by ``s``: indistinguishable from
    all of them being off by the same factor, except that one wrong number is far more
    likely than several wrong by exactly the same ratio.  Returns ``s`` when at least
    two force parameters (the mass and one effect) all moved by ``s`` (within 2 SE or
    5 %), ``s`` differing from 1 by more than 3 %; else None.
    """
    before = model_scalars(given)
    ratios = []
    for grp, key in FORCE_SCALED:
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
    for q, se in ratios:
        tol = max(0.05 * s, 2.0 * se if np.isfinite(se) else 0.0)
        if abs(q - s) > tol:
            return None
    return s


def scale_forces(model: AxisModel, s: float) -> AxisModel:
    """``model`` with the input gain and every force parameter divided by ``s``."""
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
    """Sentence for a common scale factor: the input gain is the likely culprit."""
    if s is None:
        return None
    return (f'every force parameter moved by ×{s:.3f}: the input gain is probably '
            f'{model.input_gain / s:.4g}, not {model.input_gain:.4g} (a gain error scales '
            f'every force; if instead the gain is right, all parameters are off by that '
            f'factor)')


class Engine:
    """Shared state of one diagnose/fit session: the data, H0 and the scoring rule."""

    def __init__(self, kins: Sequence[Kinematics], model: AxisModel, *, folds: int,
                 min_gain: float, min_drop: float, rotary: bool = False) -> None:
        if folds < 2:
            raise ParameterError(f'folds must be >= 2, got {folds}')
        if not 0.0 <= min_gain < 1.0:
            raise ParameterError(f'min_gain must be in [0, 1), got {min_gain}')
        if rotary and not model.units.rotary:
            model = model.replace(axis=AxisKind.ROTARY)   # --rotary on a plain model file
        self.kins = kins
        self.model = model
        self.units = axis_units(model, rotary)
        self.D = idm.Data(kins, model, folds=folds)
        D = self.D
        if D.n < folds * 8:
            raise ParameterError(f'{kins[0].name}: only {D.n} samples in motion, too few to '
                                 'identify anything: the axis barely moves; record motion '
                                 'over the travel at several speeds')
        self.min_gain, self.min_drop = float(min_gain), float(min_drop)
        self.reversals = reversal_count(D)
        x = D.gather(lambda p: p.x)
        #: positions the runs cover [m or rad]
        self.span = (float(x.min()), float(x.max()))
        self.both_ways = both_directions(D)
        self.den = D.f_in_scale()
        # the model as given, on the same rows and columns (no fitting)
        self.sse_given = idm.given_sse(D, model)
        # is the inertia excited at all?  (a property of the run, not of a fit)
        f = D.y(0.0)
        self.mass_excited = bool(model.mass * np.sqrt(np.mean(D.al() ** 2))
                                 > 0.01 * np.sqrt(np.mean((f - f.mean()) ** 2)))

    def nrmse(self, sse: float) -> float:
        """Force NRMSE of a sum of squared residuals over the rows."""
        return math.sqrt(sse / self.den) if self.den > 0 else float('inf')

    def pays(self, sse0: float, sse1: float, dp: int) -> tuple[bool, float, float]:
        """(supported, explained, BIC change) of going from ``sse0`` to ``sse1``."""
        n_eff = self.D.n_eff
        explained = 1.0 - sse1 / sse0 if sse0 > 0 else 0.0
        bic = n_eff * math.log(max(sse1, 1e-300) / max(sse0, 1e-300)) + dp * math.log(n_eff)
        ok = (explained >= self.min_gain and self.nrmse(sse0) - self.nrmse(sse1)
              >= self.min_drop and bic < 0)
        return bool(ok), float(explained), float(bic)

    def resolved(self, name: str, est: idm.Estimate, explained: float,
                 bic: float) -> bool:
        """Whether ``name`` pays although its force share is below ``min_drop``.

        ``min_drop`` asks an effect to matter for the force (1 % of the drive force by
        default), but a backlash gap or a dead time of a fraction of a millisecond
        matters for the motion and for the other parameters (an unmodelled delay biases
        the mass) while its force share is tiny.  Such an effect still pays when, on
        held-out data, it removes most of what the model leaves (``RESOLVED_GAIN``),
        the BIC improves, and the parameter that sets its shape is pinned down by the
        run (standard error within ``RESOLVED_REL_SE`` of the value): structure the
        model leaves from a slightly different law elsewhere (a stick at a reversal,
        an integrator's detail) is fitted by a shape the run does not determine.
        """
        key = SHAPE_PARAM.get(name)
        if key is None or not (explained >= max(RESOLVED_GAIN, self.min_gain) and bic < 0):
            return False
        if name == 'presliding' and not self._presliding_resolved(est):
            return False
        val = est.scalars.get(name, {}).get(key)
        se = est.se.get(name, {}).get(key)
        if val is None or se is None or not (np.isfinite(se) and se > 0 and val != 0):
            return False
        return bool(se <= RESOLVED_REL_SE[name] * abs(val))

    def _presliding_resolved(self, est: idm.Estimate) -> bool:
        """Whether the run's samples see the fitted pre-sliding curve being travelled.

        Leaving a reversal at the run's acceleration ``a`` (90th percentile), the axis
        covers ``½·a·(2·dt)²`` in two samples.  A GMS whose longest element distance is
        shorter is crossed within the first sample or two: no sample lies on its curve,
        and what it fits is how a stick ends between samples (on the independent
        generator's 100 Hz rotary runs, a set-valued stick fitted as a 1.4e-4 rad GMS).
        """
        dists = est.spec.eta.get('presliding', ((),))[0]
        if not dists:
            return False
        dt = max(k.dt for k in self.D.kins)
        a = float(np.percentile(np.abs(self.D.al()), 90))
        return bool(max(dists) >= 2.0 * a * dt * dt)

    def h0(self, model: AxisModel) -> idm.Estimate:
        """Refit the model's own effects, every parameter (nonlinear ones re-searched)."""
        spec = idm.spec_of(model)
        for n in spec.names:
            if n in idm.NONLINEAR and n != 'presliding':
                spec = spec.with_(n, idm.best_eta(self.D, spec, n, model))
        if not self.mass_excited:
            # the run does not excite the inertia: keep the given mass, refit the rest
            spec = dataclasses.replace(spec, mass_free=False, mass=model.mass)
        return idm.estimate(self.D, spec, model)

    def score(self, base: idm.Estimate, name: str) -> CandidateResult:
        """Score H0 + ``name``: all jointly refit, nonlinear parameters chosen in-fold."""
        sse, eta = idm.cv_candidate(self.D, base.spec, name, base.model,
                                    screen=0.5 * self.min_gain)
        spec = base.spec.with_(name, eta)
        est = idm.estimate(self.D, spec, base.model, cv=False)
        dp = idm.n_params(spec) - idm.n_params(base.spec)
        ok, explained, bic = self.pays(base.sse_cv, sse, dp)
        bound = bool(est.at_bound.get(name)) or _unphysical(
            name, est, self.span, rotary=self.units.rotary)
        if bound:
            # the fit wants the effect outside its physical range (a Stribeck peak below
            # the Coulomb level, a negative friction): the clipped effect in the model
            # is not what was scored, and the structure is not this effect
            ok = False
        elif not ok:
            ok = self.resolved(name, est, explained, bic)
        eff = est.model.get(name)
        scal = dict(est.scalars.get(name, {}))
        unc = {k: float(v) for k, v in est.se.get(name, {}).items()}
        before = {g: v for g, v in model_scalars(self.model).items() if g != name}
        changes = tuple(significant_changes(before, est))
        return CandidateResult(effect=name, explained=explained, force_nrmse=self.nrmse(sse),
                               params=eff.params() if eff is not None else {},
                               uncertainty=unc, scalars=scal, n_params=dp, bic_delta=bic,
                               supported=ok, model=est.model, changes=changes,
                               units=self.units, correlations=tuple(est.correlations),
                               spec=est.spec, at_bound=bound)

    def refit_result(self, est: idm.Estimate) -> CandidateResult:
        """Turn the refit of the given model into a finding (``mass`` or ``refit``)."""
        ok, explained, bic = self.pays(self.sse_given, est.sse_cv, est.n_params)
        changes = tuple(significant_changes(model_scalars(self.model), est))
        s = common_scale(self.model, est)
        if s is not None:
            # one wrong number (the gain) rather than every force parameter by one factor
            g = self.model.input_gain
            changes = (ParameterChange('input_gain', 'input_gain', g, g / s, float('nan')),)
            est = dataclasses.replace(est, model=scale_forces(est.model, s))
        only_mass = bool(changes) and all(c.effect == MASS for c in changes)
        name = MASS if only_mass else REFIT
        scal = {f'{c.effect}.{c.name}' if c.effect != MASS else 'mass': c.fitted
                for c in changes}
        unc = {f'{c.effect}.{c.name}' if c.effect != MASS else 'mass': c.se for c in changes}
        params = {'mass': est.model.mass,
                  'effects': {e.name: e.params() for e in est.model.effects}}
        return CandidateResult(effect=name, explained=explained,
                               force_nrmse=self.nrmse(est.sse_cv), params=params,
                               uncertainty=unc, scalars=scal, n_params=est.n_params,
                               bic_delta=bic, supported=ok and bool(changes),
                               model=est.model, changes=changes, units=self.units,
                               correlations=tuple(est.correlations), spec=est.spec)


def _unphysical(name: str, est: idm.Estimate, span: tuple[float, float], *,
                rotary: bool = False) -> bool:
    """Whether the fitted ``name`` lies clearly outside its physical range.

    A spring's rest position ``x0`` farther from the positions ``span`` covered than
    the span itself is a constant force with a slight slope over the travel (an offset
    by another name), not a spring the run can identify.  On a rotary axis that turns
    more than a revolution there is no spring at all (a torsion spring or a cable acts
    within a turn; the load's weight is ``gravity``, cogging is ``ripple``): a torque
    that grows with the angle over many turns is drift, or a direction-dependent
    friction seen through runs that each turn one way (the HSM150 runs: a spring with
    x0 = −4341 rad stood in for the asymmetry).  Direction-dependent friction
    splits the friction levels, ``fc± = fc ± dfc/2`` and ``fv± = fv ± dfv/2``: with
    neither level in the model there is nothing to split (its constant column is an
    offset), and the Coulomb level, when present, must stay a friction both ways
    (≥ 0, within two standard errors) — a larger split is a force that pushes one way
    whatever the direction of motion.  A level not in the model yet is not judged (the
    dry level may join later); the viscous split is left free (a slope that differs by
    direction is what an asymmetric drive or a velocity-dependent gain looks like).
    """
    if name == 'spring':
        x0 = est.model.get('spring').x0
        width = span[1] - span[0]
        if rotary and width > 2.0 * np.pi:
            return True
        return not span[0] - width <= x0 <= span[1] + width
    if name != 'asymmetry':
        return False
    a = est.model.get('asymmetry')
    se = est.se.get('asymmetry', {})
    if not (est.model.has('coulomb') or est.model.has('viscous')):
        return True
    if not est.model.has('coulomb'):
        return False
    s = se.get('dfc', float('nan'))
    slack = s if np.isfinite(s) else 0.0        # 2 SE of dfc/2 = SE of dfc
    return bool(abs(a.dfc) / 2 - est.model.fc > slack)


@single_threaded_blas()
def diagnose(kin: Kinematics | Sequence[Kinematics], model: AxisModel, *, folds: int = 5,
             min_gain: float = 0.1, min_drop: float = 0.01,
             candidates: Sequence[str] | None = None, rotary: bool = False) -> Diagnosis:
    """Rank what is wrong with ``model`` on one run or several (one experiment).

    Parameters
    ----------
    kin : Kinematics or sequence of Kinematics
        The run(s) (see :func:`~motor_comp.workbench.derivatives.kinematics`).
    model : AxisModel
        The current model.
    folds : int
        Number of folds the validation blocks are dealt to (>= 2).
    min_gain : float
        Least held-out fraction of the residual a supported candidate removes (0–1).
    min_drop : float
        Least held-out force-NRMSE decrease of a supported candidate (0.01 = 1 % of
        the drive force).
    candidates : sequence of str, optional
        Restrict to these effect names (default: every effect the model lacks).
    rotary : bool
        Treat the position as an angle [rad] even if the model file says linear.
    """
    kins = as_list(kin)
    eng = Engine(kins, model, folds=folds, min_gain=min_gain, min_drop=min_drop,
                 rotary=rotary)
    model = eng.model
    h0 = eng.h0(model)
    refit = eng.refit_result(h0)
    names = (available(h0.spec, model, eng.units, reversals=eng.reversals,
                       both_ways=eng.both_ways)
             if candidates is None else list(candidates))
    for n in names:
        if n not in idm.ORDER:
            raise ParameterError(f'unknown candidate {n!r} (known: {", ".join(idm.ORDER)})')
    results = [eng.score(h0, n) for n in names if n not in h0.spec.names]
    # supported first, then by held-out BIC (the per-parameter price included)
    results.sort(key=lambda c: (not c.supported, c.bic_delta))
    if not any(c.supported for c in results) and refit.supported:
        results.insert(0, refit)
    elif refit.supported:
        results.append(dataclasses.replace(refit, supported=False))
    res = residual(kins[0], model)
    best = next((c for c in results if c.supported), None)
    corr = best.correlations if best is not None else h0.correlations
    ident_notes = identifiability_notes(corr)
    exp = experiment_notes(eng.D, model)
    g = gain_note(common_scale(model, h0), model)
    if g:
        exp.insert(0, g)
    return Diagnosis(baseline_nrmse=eng.nrmse(eng.sse_given), refit_nrmse=h0.nrmse_cv,
                     rms_residual=math.sqrt(eng.sse_given / eng.D.n),
                     n_samples=sum(len(k) for k in kins),
                     n_sliding=int(sum(np.count_nonzero(sliding_mask(k)) for k in kins)),
                     n_eff=eng.D.n_eff,
                     folds=folds, candidates=tuple(results), residual=res, kin=kins[0],
                     model=model, refit=refit, experiment=tuple(exp),
                     identifiability=tuple(ident_notes), units=eng.units,
                     runs=tuple(k.name for k in kins))
