"""Find what a model gets wrong: a missing physical effect or a wrong parameter.

A front-end of :mod:`.selection` (``../shared/IDENTIFICATION.md``):

1. **H0 is the current model refitted**: every linear parameter jointly, the nonlinear
   ones re-searched.  When the refit pays the first finding is the parameters that were
   wrong — ``fc is 10.0 ± 0.1 N, not 5.0 N`` — and when every parameter moved by one
   common factor, the input gain instead.
2. Each effect the run can judge is scored as *H0 + candidate, all linear parameters
   re-estimated together*, its nonlinear parameters chosen inside each fold;
   ``explained`` is the held-out fraction of H0's residual energy it removes,
   ``force_nrmse`` the held-out ``RMS(r)/RMS(F_in − mean)`` (DESIGN.md §6).
3. Pairs of parameters whose estimates correlate beyond ±0.97 are named with the
   experiment that would separate them, and a run too poor to judge says what it lacks.

Several runs are one experiment: one model, blocks from every run.
"""
from __future__ import annotations

import dataclasses
import functools
import math
from typing import Any, Sequence

import numpy as np

from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel, Units
from motor_comp.threads import single_threaded_blas
from motor_comp.workbench import selection as sel
from motor_comp.workbench.aliases import ambiguities
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.library import ORDER
from motor_comp.workbench.residual import Residual, residual
from motor_comp.workbench.result import CandidateResult
from motor_comp.workbench.scan import scan
from motor_comp.workbench.wording import LINEAR_UNITS, MASS, REFIT, common_scale, \
    experiment_notes, gain_note, identifiability_notes, rows_name, unresolved


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
    kin: Kinematics
    model: AxisModel
    refit: CandidateResult | None = None
    experiment: tuple = ()
    identifiability: tuple = ()
    units: Units = LINEAR_UNITS
    runs: tuple = ()
    unexplained: Any = None
    #: whether the baseline is judged on the rows that reach the stops (see
    #: :attr:`CandidateResult.stops`)
    stops: bool = False

    @functools.cached_property
    def residual(self) -> Residual:
        """The given model's force residual along the first run (for the figures)."""
        return residual(self.kin, self.model)

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
        un = self.unexplained
        floor = (f'; noise floor {100 * un.noise_floor_nrmse:.2f} %'
                 if un is not None and math.isfinite(un.noise_floor_nrmse) else '')
        lines = [f'baseline: force NRMSE {100 * self.baseline_nrmse:.2f} % as given, '
                 f'{100 * self.refit_nrmse:.2f} % with its own parameters refitted '
                 f'(held-out{floor}; RMS residual {self.rms_residual:.3g} {u.force} over '
                 f'{self.n_sliding} sliding samples, {self.folds} folds)']
        best = self.best
        if best is None:
            if un is not None and un.features:
                lines.append('no effect of the library pays for its parameters, but the '
                             'residual still holds structure:')
                lines += [f'  {f.text}' for f in un.features]
            elif un is not None:
                lines.append(f'no candidate effect pays for its parameters; {un.summary}')
            else:
                lines.append('no candidate effect pays for its parameters')
        elif best.effect in (MASS, REFIT):
            lines.append(f'first finding: {best.sentence()}')
        else:
            lines.append(f'missing: {best.sentence()}')
            if best.changes:
                lines.append('  with, refitted jointly: '
                             + '; '.join(c.sentence(u) for c in best.changes))
        if best is not None and un is not None and un.features:
            lines.append('the residual of the model as refitted holds: '
                         + '; '.join(f.text for f in un.features))
        for note in self.identifiability:
            lines.append(f'cannot tell apart: {note}')
        for note in self.experiment:
            lines.append(f'experiment: {note}')
        lines.append('candidates (held-out):')
        for i, c in enumerate(self.candidates, start=1):
            flag = '+' if c.supported else ' '
            rows = ''
            if c.stops != self.stops and math.isfinite(c.base_nrmse):
                # its figures are on other rows than the baseline's: they compare only
                # with the model without it on the same rows
                rows = (f'  (on {rows_name(c.stops)}, where the model leaves '
                        f'{100 * c.base_nrmse:.1f} %)')
            lines.append(f' {flag}{i:2d}. {c.effect:<10s} explained {100 * c.explained:6.1f} %'
                         f'  NRMSE {100 * c.force_nrmse:5.1f} %  {_param_text(c)}{rows}')
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
            'unexplained': (self.unexplained.as_dict() if self.unexplained is not None
                            else None),
            'baseline': {'force_nrmse': float(self.baseline_nrmse),
                         'noise_floor_nrmse': (float(self.unexplained.noise_floor_nrmse)
                                               if self.unexplained is not None else None),
                         'refit_force_nrmse': float(self.refit_nrmse),
                         'rms_residual': float(self.rms_residual),
                         'n_samples': int(self.n_samples), 'n_sliding': int(self.n_sliding),
                         'folds': int(self.folds), 'sample_rate': 1.0 / self.kin.dt,
                         'resampled': bool(self.kin.resampled)},
            'refit': self.refit.as_dict() if self.refit is not None else None,
            'candidates': [c.as_dict() for c in self.candidates],
            'best': best.effect if best is not None else None,
            'summary': (best.sentence() if best is not None else
                        (self.unexplained.summary if self.unexplained is not None
                         else 'no candidate pays')),
            'identifiability': list(self.identifiability),
            'experiment': list(self.experiment),
        }


def _param_text(c: CandidateResult) -> str:
    out = []
    for k, v in c.scalars.items():
        s = c.uncertainty.get(k)
        if unresolved(v, s):
            out.append(f'{k}={v:.4g}(unresolved)')
        else:
            out.append(f'{k}={v:.4g}' + (f'±{s:.2g}' if s is not None and np.isfinite(s)
                                         and s > 0 else ''))
    return ' '.join(out)


def as_list(kin: Kinematics | Sequence[Kinematics]) -> list[Kinematics]:
    """Return one run or several (one experiment) as a list."""
    return [kin] if isinstance(kin, Kinematics) else list(kin)


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
        Least held-out force-NRMSE fall of a supported candidate (0.01 = 1 % of the
        drive force), or the noise floor's NRMSE when that is smaller.
    candidates : sequence of str, optional
        Restrict to these effect names (default: every effect the model lacks).
    rotary : bool
        Treat the position as an angle [rad] even if the model file says linear.
    """
    kins = as_list(kin)
    eng = sel.Engine(kins, model, folds=folds, min_gain=min_gain, min_drop=min_drop,
                     rotary=rotary)
    model = eng.model
    h0 = eng.h0(model)
    refit = eng.refit_result(h0)
    names = (sel.candidates(h0.spec, eng.data) if candidates is None else list(candidates))
    for n in names:
        if n not in ORDER:
            raise ParameterError(f'unknown candidate {n!r} (known: {", ".join(ORDER)})')
    results = [eng.score(h0, n) for n in names if n not in h0.spec.names]
    # supported first, then by held-out BIC (the per-parameter price included)
    results.sort(key=lambda c: (not c.supported, c.bic_delta))
    if not any(c.supported for c in results) and refit.supported:
        results.insert(0, refit)
    elif refit.supported:
        results.append(dataclasses.replace(refit, supported=False))
    un = scan(eng.data_for(h0.spec), h0, eng.floor(h0), units=eng.units,
              verdicts={c.effect: c for c in results})
    best = next((c for c in results if c.supported), None)
    corr = best.correlations if best is not None else h0.correlations
    final = best.estimate if best is not None and best.estimate is not None else h0
    aliases = ambiguities(eng.data_for(final.spec), final)
    ident_notes = [a.sentence() for a in aliases] + identifiability_notes(corr)
    if best is not None and any(a.effect == best.effect for a in aliases):
        # the finding is one of several readings of this run
        others = ', '.join(a.other for a in aliases if a.effect == best.effect)
        i = results.index(best)
        results[i] = dataclasses.replace(best, why_not=f'or {others}: cannot be told apart '
                                                       'on this run')
    exp = experiment_notes(eng.summary, eng.units)
    g = gain_note(common_scale(model, h0), model)
    if g:
        exp.insert(0, g)
    return Diagnosis(baseline_nrmse=eng.nrmse_given, refit_nrmse=h0.nrmse_cv,
                     rms_residual=math.sqrt(eng.sse_given / eng.given_data.n),
                     n_samples=sum(len(k) for k in kins),
                     n_sliding=int(sum(np.count_nonzero(m) for m in eng.data.masks)),
                     n_eff=eng.data.n_eff,
                     folds=folds, candidates=tuple(results), kin=kins[0],
                     model=model, refit=refit, experiment=tuple(exp),
                     identifiability=tuple(ident_notes), units=eng.units,
                     runs=tuple(k.name for k in kins), unexplained=un,
                     stops=eng.given_data.processing.turns)


__all__ = ['CandidateResult', 'Diagnosis', 'diagnose']
