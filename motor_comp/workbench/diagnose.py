"""Which physical effect is the model missing?  Candidates ranked on held-out time blocks.

Every candidate of :mod:`~motor_comp.workbench.candidates` is fitted to the model's force
residual with blocked cross-validation: the sliding samples are cut into ``folds``
contiguous time blocks; each block in turn is held out while the candidate (including
its nonlinear parameters: period, Stribeck velocity, delay, GMS stiffness, gap) is
fitted on the others (the global part of a nonlinear search — spectral peak, grid —
chooses the basin once on all samples; every parameter is then refitted locally on the
training blocks of each fold).  ``explained`` is the fraction of the residual energy the
candidate removes on the held-out blocks, ``force_nrmse`` its held-out
``RMS(r)/RMS(F_in − mean)`` (DESIGN.md §6).  Contiguous blocks rather than shuffled
samples because the residual is smooth in time: a shuffled split would let the
neighbours of a test sample sit in the training set.

A candidate is *supported* when it pays for its parameters on held-out data: it
removes at least ``min_gain`` of the residual, lowers the held-out force NRMSE by at
least ``min_drop`` (a relevance floor: a third of a tiny residual is still tiny), and
improves a held-out BIC,
``n_eff·ln(SSE_cv/SSE_0) + p·ln(n_eff)``, with ``n_eff`` the number of independent
samples (samples / smoothing window).  Ranking uses the same per-parameter price, so
between two candidates that explain the same (offset vs asymmetry while sliding) the
simpler one is listed first.  Parameter uncertainties are delete-one-block jackknife
standard errors over the folds.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Sequence

import numpy as np

from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel
from motor_comp.workbench.candidates import FITTERS, MASS, CandidateFit, FitContext, \
    available_candidates
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.residual import Residual, residual

#: human wording of each candidate (the effects' ``title``, plus the mass refit)
TITLES = {'coulomb': 'Coulomb friction', 'viscous': 'viscous friction',
          'stribeck': 'Stribeck friction', 'presliding': 'pre-sliding hysteresis (GMS)',
          'ripple': 'force ripple', 'offset': 'constant force offset',
          'spring': 'spring (position-proportional force)',
          'asymmetry': 'direction-dependent friction', 'delay': 'input delay',
          'backlash': 'backlash', MASS: 'mass/inertia mismatch'}


@dataclasses.dataclass(frozen=True)
class CandidateResult:
    """One candidate's held-out score and its fit on all data.

    Parameters
    ----------
    effect : str
        Vocabulary name, or ``'mass'``.
    explained : float
        Held-out fraction of residual energy removed (can be < 0: it makes things worse).
    force_nrmse : float
        Held-out force NRMSE with the candidate.
    params : dict
        Physical parameters (model-file form, SI) fitted on all sliding samples.
    uncertainty : dict[str, float]
        Jackknife standard error of each scalar parameter (same units).
    scalars : dict[str, float]
        Flat parameter values for tables.
    n_params : int
        Parameters fitted.
    bic_delta : float
        Held-out BIC change (< 0 pays for the parameters).
    supported : bool
        Whether it pays for its parameters.
    fit : CandidateFit
        The fit on all data (model with the effect added, predicted force).
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
    fit: CandidateFit

    @property
    def title(self) -> str:
        """Human name of the candidate."""
        return TITLES.get(self.effect, self.effect)

    def sentence(self, *, rotary: bool = False) -> str:
        """Plain-language finding, e.g. 'force ripple, period 7.25 mm, … removes 83 %'.

        With ``rotary`` the position is an angle [rad]: periods are also given in
        cycles per revolution (and forces are torques in the model's input units).
        """
        s = self.scalars
        e = self.effect
        if e == 'ripple':
            p = s['period']
            per = (f'{p:.4g} rad ({2 * math.pi / p:.3g} cycles/rev)' if rotary else _mm(p))
            parts = [f'period {per}',
                     f'first harmonic {s["amplitude_1"]:.3g} N']
            nh = sum(1 for k in s if k.startswith('amplitude_'))
            if nh > 1:
                parts.append(f'{nh} harmonics')
        elif e == 'coulomb':
            parts = [f'fc {s["fc"]:.3g} N']
        elif e == 'viscous':
            parts = [f'fv {s["fv"]:.3g} N·s/m']
        elif e == 'stribeck':
            parts = [f'breakaway fs {s["fs"]:.3g} N', f'vs {s["vs"] * 1e3:.3g} mm/s',
                     f'δ {s["delta"]:.2g}']
        elif e == 'presliding':
            parts = [f'stiffness {s["stiffness"]:.3g} N/m', f'c {s["c"]:.3g} 1/s']
        elif e == 'offset':
            parts = [f'f0 {s["f0"]:.3g} N']
        elif e == 'spring':
            parts = [f'k {s["k"]:.3g} N/m', f'x0 {_mm(s["x0"])}']
        elif e == 'asymmetry':
            parts = [f'dfc {s["dfc"]:.3g} N', f'dfv {s["dfv"]:.3g} N·s/m']
        elif e == 'delay':
            parts = [f'tau {s["tau"] * 1e3:.3g} ms']
        elif e == 'backlash':
            parts = [f'width {s["width"] * 1e6:.3g} µm']
        else:
            parts = [f'mass {s["mass"]:.4g} kg']
        verdict = '' if self.supported else ' (not supported: does not pay for its ' \
                                            'parameters on held-out data)'
        return (f'{self.title}, {", ".join(parts)}, removes '
                f'{100 * self.explained:.0f} % of the residual{verdict}')

    def as_dict(self) -> dict[str, Any]:
        """JSON form (DESIGN.md §6 ``candidates`` entry)."""
        return {'effect': self.effect, 'title': self.title,
                'explained': float(self.explained), 'force_nrmse': float(self.force_nrmse),
                'params': self.params, 'uncertainty': self.uncertainty,
                'n_params': self.n_params, 'bic_delta': float(self.bic_delta),
                'supported': bool(self.supported), 'summary': self.sentence()}


@dataclasses.dataclass(frozen=True)
class Diagnosis:
    """Result of :func:`diagnose`: the baseline and the ranked candidates."""

    baseline_nrmse: float
    rms_residual: float
    n_samples: int
    n_sliding: int
    n_eff: float
    folds: int
    candidates: tuple
    residual: Residual
    kin: Kinematics
    model: AxisModel
    rotary: bool = False

    @property
    def best(self) -> CandidateResult | None:
        """The best supported candidate, or None when nothing pays."""
        for c in self.candidates:
            if c.supported:
                return c
        return None

    def summary(self) -> str:
        """Plain text for the terminal."""
        lines = [f'baseline: force NRMSE {100 * self.baseline_nrmse:.1f} % '
                 f'(RMS residual {self.rms_residual:.3g} N over {self.n_sliding} sliding '
                 f'samples, {self.folds} held-out blocks)']
        best = self.best
        if best is None:
            lines.append('no candidate effect pays for its parameters: nothing is missing '
                         'that this run can reveal')
        else:
            lines.append(f'missing: {best.sentence(rotary=self.rotary)}')
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
            'baseline': {'force_nrmse': float(self.baseline_nrmse),
                         'rms_residual': float(self.rms_residual),
                         'n_samples': int(self.n_samples), 'n_sliding': int(self.n_sliding),
                         'folds': int(self.folds), 'sample_rate': 1.0 / self.kin.dt,
                         'resampled': bool(self.kin.resampled)},
            'candidates': [c.as_dict() for c in self.candidates],
            'best': best.effect if best is not None else None,
            'summary': (best.sentence(rotary=self.rotary) if best is not None
                        else 'nothing missing'),
        }


def _mm(x: float) -> str:
    return f'{x * 1e3:.4g} mm'


def _param_text(c: CandidateResult) -> str:
    out = []
    for k, v in c.scalars.items():
        u = c.uncertainty.get(k)
        out.append(f'{k}={v:.4g}' + (f'±{u:.2g}' if u is not None and u > 0 else ''))
    return ' '.join(out)


def fold_masks(mask: np.ndarray, folds: int) -> list[np.ndarray]:
    """Split the True samples of ``mask`` into ``folds`` contiguous time blocks."""
    idx = np.flatnonzero(mask)
    out = []
    for part in np.array_split(idx, folds):
        m = np.zeros_like(mask)
        m[part] = True
        out.append(m)
    return out


def effective_samples(kin: Kinematics, n: int) -> float:
    """Independent samples in ``n`` smoothed samples (one per smoothing window)."""
    return max(n / kin.window, 2.0)


def score_candidate(ctx: FitContext, name: str, folds: Sequence[np.ndarray], *,
                    min_gain: float, n_eff: float, min_drop: float = 0.01) \
        -> CandidateResult:
    """Blocked cross-validation of one candidate; the final fit on all sliding samples."""
    fitter = FITTERS[name]
    r = ctx.res.r
    mask = ctx.res.mask
    # the global search (spectrum, grids) picks the basin once on all sliding samples;
    # each fold then refits every parameter locally on its training blocks only
    full = fitter(ctx, mask)
    sse_cv = 0.0
    fold_scalars = []
    for held in folds:
        train = mask & ~held
        f = fitter(ctx, train, full)
        d = r[held] - f.predicted[held]
        sse_cv += float(np.einsum('i,i->', d, d))
        fold_scalars.append(f.scalars)
    sse0 = float(np.einsum('i,i->', r[mask], r[mask]))
    explained = 1.0 - sse_cv / sse0 if sse0 > 0 else 0.0
    f_in = ctx.res.f_in[mask]
    den = float(np.sum((f_in - f_in.mean()) ** 2))
    nrmse = math.sqrt(sse_cv / den) if den > 0 else float('inf')
    k = len(folds)
    unc = {}
    for key in full.scalars:
        vals = np.array([s[key] for s in fold_scalars if key in s])
        if len(vals) == k:
            unc[key] = float(np.sqrt((k - 1) / k * np.sum((vals - vals.mean()) ** 2)))
    ratio = max(sse_cv / sse0, 1e-300) if sse0 > 0 else 1.0
    bic = n_eff * math.log(ratio) + full.n_params * math.log(n_eff)
    base = math.sqrt(sse0 / den) if den > 0 else float('inf')
    supported = bool(explained >= min_gain and base - nrmse >= min_drop and bic < 0)
    return CandidateResult(effect=name, explained=explained, force_nrmse=nrmse,
                           params=full.params, uncertainty=unc, scalars=full.scalars,
                           n_params=full.n_params, bic_delta=bic, supported=supported,
                           fit=full)


def diagnose(kin: Kinematics, model: AxisModel, *, folds: int = 5, min_gain: float = 0.1,
             min_drop: float = 0.01, candidates: Sequence[str] | None = None,
             rotary: bool = False) -> Diagnosis:
    """Rank the candidate effects missing from ``model`` along ``kin``.

    Parameters
    ----------
    kin : Kinematics
        The run (see :func:`~motor_comp.workbench.derivatives.kinematics`).
    model : AxisModel
        The current model.
    folds : int
        Number of contiguous held-out time blocks (>= 2).
    min_gain : float
        Least held-out fraction of the residual a supported candidate removes (0–1).
    min_drop : float
        Least held-out force-NRMSE decrease of a supported candidate (0.01 = 1 % of
        the drive force).
    candidates : sequence of str, optional
        Restrict to these names (default: every candidate available for the model).
    rotary : bool
        The position is an angle [rad] (wording of the summary only).
    """
    if folds < 2:
        raise ParameterError(f'folds must be >= 2, got {folds}')
    if not 0.0 <= min_gain < 1.0:
        raise ParameterError(f'min_gain must be in [0, 1), got {min_gain}')
    res = residual(kin, model)
    mask = res.mask
    n_sliding = int(np.count_nonzero(mask))
    if n_sliding < folds * 2 * kin.window:
        raise ParameterError(f'{kin.name}: only {n_sliding} samples in motion, too few to '
                             f'diagnose (the axis barely moves?)')
    names = available_candidates(model) if candidates is None else list(candidates)
    for n in names:
        if n not in FITTERS:
            raise ParameterError(f'unknown candidate {n!r} (known: {", ".join(FITTERS)})')
    ctx = FitContext(kin=kin, model=model, res=res)
    blocks = fold_masks(mask, folds)
    n_eff = effective_samples(kin, n_sliding)
    results = [score_candidate(ctx, n, blocks, min_gain=min_gain, n_eff=n_eff,
                               min_drop=min_drop)
               for n in names]
    price = math.log(n_eff) / n_eff
    results.sort(key=lambda c: -(c.explained - price * c.n_params))
    return Diagnosis(baseline_nrmse=res.nrmse(), rms_residual=float(np.sqrt(np.mean(
        res.r[mask] ** 2))), n_samples=len(kin), n_sliding=n_sliding, n_eff=n_eff,
        folds=folds, candidates=tuple(results), residual=res, kin=kin, model=model,
        rotary=rotary)
