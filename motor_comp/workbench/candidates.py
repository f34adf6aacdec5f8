"""Candidate effects fitted to a force residual, one fitter per vocabulary name.

Each fitter takes the residual ``r`` of the current model and a training mask (and
optionally a fit on all data to start its local search from, skipping the global one)
and returns the effect with physical parameters plus the force it removes from ``r`` on
every sample (so the caller can score it on held-out samples):

* linear in the parameters (``coulomb``, ``viscous``, ``offset``, ``spring``,
  ``asymmetry``, and the ``mass`` refit): least squares on the effect module's own
  ``regressors`` (smoothed like the residual);
* ``ripple``: the period from the peak of the residual's spatial spectrum (residual
  binned on a uniform position grid, then FFT), refined by a 1-D least-squares search
  with the amplitudes solved linearly at each trial period (variable projection);
* ``stribeck``: grid over ``(vs, δ)`` then Nelder–Mead, the level ``fs − fc`` linear;
* ``presliding`` (GMS, Chiew's 4-element shape): grid then Nelder–Mead over the total
  stiffness and the slip rate ``c``; the force is :meth:`Presliding.force_along`;
* ``delay``: 1-D search over ``τ`` of the drive force computed from ``u(t − τ)``;
* ``backlash``: 1-D search over the gap width, the residual recomputed from the
  reconstructed motor position (:func:`~motor_comp.workbench.residual.motor_position`).

``stribeck`` and ``presliding`` presuppose a ``coulomb`` effect in the model (their
laws are defined relative to ``fc``); they are not offered without one.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np
from scipy.optimize import minimize, minimize_scalar

from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import Asymmetry, Backlash, Coulomb, Delay, Offset, \
    Presliding, Ripple, Spring, Stribeck, Viscous
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.residual import Residual, residual

#: Chiew's 4-element GMS distribution (normalised slip limits and relative stiffness)
GMS_ALPHA = (0.45, 0.30, 0.15, 0.10)
GMS_K_SHAPE = tuple(k / 12.3e6 for k in (8e6, 3e6, 1e6, 3e5))

#: the refit of the moving mass/inertia is offered next to the effects
MASS = 'mass'

#: the widest gap the backlash effect accepts [m]
MAX_BACKLASH = 0.01

#: the largest number of ripple harmonics a candidate fits
MAX_RIPPLE_HARMONICS = 6


@dataclasses.dataclass(frozen=True)
class FitContext:
    """What every fitter needs: the run's kinematics, the model and its residual."""

    kin: Kinematics
    model: AxisModel
    res: Residual


@dataclasses.dataclass(frozen=True)
class CandidateFit:
    """One candidate fitted on a training set.

    Parameters
    ----------
    effect : str
        Vocabulary name (or ``'mass'``).
    params : dict
        Fitted physical parameters in model-file form (SI).
    scalars : dict[str, float]
        The same as flat named numbers (for uncertainties and reports).
    predicted : ndarray
        Force [N] the candidate removes from the residual, on every sample.
    n_params : int
        Number of fitted parameters.
    model : AxisModel
        The model with the candidate added (or the mass changed).
    """

    effect: str
    params: dict
    scalars: dict
    predicted: np.ndarray
    n_params: int
    model: AxisModel


def _lstsq(cols: np.ndarray, y: np.ndarray, rows: np.ndarray) -> np.ndarray:
    # normal equations by einsum (a handful of columns, well scaled): LAPACK/BLAS calls
    # cost milliseconds each on a loaded machine inside the nonlinear searches
    a = cols[rows]
    g = np.einsum('ij,ik->jk', a, a)
    b = np.einsum('ij,i->j', a, y[rows])
    try:
        return np.linalg.solve(g + 1e-12 * np.trace(g) * np.eye(len(b)), b)
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(a, y[rows], rcond=None)[0]


def _linear(ctx: FitContext, raw_cols: np.ndarray, train: np.ndarray,
            smooth: bool = True) -> tuple[np.ndarray, np.ndarray]:
    cols = ctx.kin.smooth(raw_cols) if smooth else raw_cols
    theta = _lstsq(cols, ctx.res.r, train)
    return theta, _matvec(cols, theta)


def _sse(pred: np.ndarray, r: np.ndarray, rows: np.ndarray) -> float:
    d = r[rows] - pred[rows]
    # einsum, not BLAS: a threaded BLAS dot costs milliseconds on a loaded machine and
    # this runs thousands of times inside the nonlinear searches
    return float(np.einsum('i,i->', d, d))


def _matvec(cols: np.ndarray, theta: np.ndarray) -> np.ndarray:
    return np.einsum('ij,j->i', cols, theta)


def fit_mass(ctx: FitContext, train: np.ndarray,
             start: CandidateFit | None = None) -> CandidateFit:
    """Mass/inertia mismatch: a residual ∝ acceleration, ``r ≈ ΔM·ẍ``."""
    a = ctx.res.a[:, None]
    theta, pred = _linear(ctx, a, train, smooth=False)
    m0 = ctx.model.mass
    mass = m0 + float(theta[0])
    # a non-positive mass is no physical finding (the residual anti-correlates with the
    # acceleration for another reason), and beyond a factor 10 it is not a refinement
    # but an unexcited inertia: then the mass stays (same rule as the joint refit)
    if not 0.1 * m0 <= mass <= 10.0 * m0:
        mass = m0
    pred = (mass - ctx.model.mass) * ctx.res.a
    return CandidateFit(MASS, {'mass': mass}, {'mass': mass}, pred, 1,
                        ctx.model.replace(mass=mass))


def _fit_friction_level(ctx: FitContext, train: np.ndarray, cls: type, key: str
                        ) -> CandidateFit:
    """One non-negative friction coefficient ``key`` of ``cls`` from its regressor."""
    res = ctx.res
    theta, _ = _linear(ctx, cls().regressors(res.x, res.v), train)
    eff = cls(**{key: max(float(theta[0]), 0.0)})
    pred = ctx.kin.smooth(eff.force(res.x, res.v))
    return CandidateFit(eff.name, eff.params(), {key: getattr(eff, key)}, pred, 1,
                        ctx.model.with_effect(eff))


def fit_coulomb(ctx: FitContext, train: np.ndarray,
                start: CandidateFit | None = None) -> CandidateFit:
    """Coulomb level from the regressor ``sgn ẋ``."""
    return _fit_friction_level(ctx, train, Coulomb, 'fc')


def fit_viscous(ctx: FitContext, train: np.ndarray,
                start: CandidateFit | None = None) -> CandidateFit:
    """Viscous coefficient from the regressor ``ẋ``."""
    return _fit_friction_level(ctx, train, Viscous, 'fv')


def fit_offset(ctx: FitContext, train: np.ndarray,
               start: CandidateFit | None = None) -> CandidateFit:
    """Constant force."""
    res = ctx.res
    theta, pred = _linear(ctx, Offset().regressors(res.x), train, smooth=False)
    eff = Offset(f0=float(theta[0]))
    return CandidateFit('offset', eff.params(), {'f0': eff.f0}, pred, 1,
                        ctx.model.with_effect(eff))


def fit_spring(ctx: FitContext, train: np.ndarray,
               start: CandidateFit | None = None) -> CandidateFit:
    """Spring ``k·(x − x0)`` from the columns ``[x, 1]``."""
    res = ctx.res
    theta, pred = _linear(ctx, Spring().regressors(res.x), train)
    k = float(theta[0])
    # x0 is only defined for a non-negligible stiffness; the constant part stays in pred
    span = float(np.ptp(res.x[train])) or 1.0
    x0 = -float(theta[1]) / k if abs(k) * span > 1e-9 * max(abs(theta[1]), 1e-12) else 0.0
    x0 = float(np.clip(x0, -1e3, 1e3))
    eff = Spring(k=k, x0=x0)
    return CandidateFit('spring', eff.params(), {'k': k, 'x0': x0}, pred, 2,
                        ctx.model.with_effect(eff))


def fit_asymmetry(ctx: FitContext, train: np.ndarray,
                  start: CandidateFit | None = None) -> CandidateFit:
    """Direction-dependent Coulomb and viscous friction from ``[|sgn ẋ|/2, |ẋ|/2]``."""
    res = ctx.res
    theta, _ = _linear(ctx, Asymmetry().regressors(res.x, res.v), train)
    eff = Asymmetry(dfc=float(theta[0]), dfv=float(theta[1]))
    pred = ctx.kin.smooth(eff.force(res.x, res.v))
    return CandidateFit('asymmetry', eff.params(), {'dfc': eff.dfc, 'dfv': eff.dfv}, pred,
                        2, ctx.model.with_effect(eff))


# -- ripple ------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class SpatialSpectrum:
    """Amplitude spectrum of a force against position.

    Parameters
    ----------
    frequency : ndarray
        Spatial frequency [cycles/m] (or cycles/rad for a rotary axis).
    amplitude : ndarray
        Amplitude [N] of the sinusoid at each frequency.
    bin_width : float
        Position grid step [m].
    span : float
        Position range covered [m].
    """

    frequency: np.ndarray
    amplitude: np.ndarray
    bin_width: float
    span: float

    def peak_period(self, *, min_period: float, max_period: float) -> float:
        """Period [m] of the largest peak within the allowed range."""
        f = self.frequency
        ok = (f >= 1.0 / max_period) & (f <= 1.0 / min_period)
        if not np.any(ok):
            return float('nan')
        i = np.flatnonzero(ok)[np.argmax(self.amplitude[ok])]
        return 1.0 / float(f[i])

    def amplitude_at(self, freq: float) -> float:
        """Largest amplitude [N] within one resolution bin of ``freq``."""
        df = 1.0 / self.span
        m = np.abs(self.frequency - freq) <= df
        return float(np.max(self.amplitude[m])) if np.any(m) else 0.0


def spatial_spectrum(x: np.ndarray, r: np.ndarray, *, n_bins: int | None = None) \
        -> SpatialSpectrum:
    """Spectrum of ``r`` against position ``x`` (binned means, padded FFT).

    The axis travels the same positions many times at different speeds; averaging the
    residual in position bins keeps what is periodic in position and averages out what
    is not, and a uniform position grid makes the FFT applicable (the samples
    themselves are uniform in time, not in position).
    """
    lo, hi = float(np.min(x)), float(np.max(x))
    span = hi - lo
    if n_bins is None:
        n_bins = int(np.clip(len(x) // 8, 64, 8192))
    width = span / n_bins if span > 0 else 1.0
    idx = np.clip(((x - lo) / width).astype(int), 0, n_bins - 1)
    counts = np.bincount(idx, minlength=n_bins)
    sums = np.bincount(idx, weights=r, minlength=n_bins)
    filled = counts > 0
    centers = lo + (np.arange(n_bins) + 0.5) * width
    prof = np.interp(centers, centers[filled], sums[filled] / counts[filled])
    prof = prof - np.polyval(np.polyfit(centers, prof, 1), centers)
    nfft = 1 << int(math.ceil(math.log2(4 * n_bins)))
    spec = np.fft.rfft(prof * np.hanning(n_bins), nfft)
    # amplitude of a sinusoid: 2|X|/Σw for a Hann window
    amp = 2.0 * np.abs(spec) / np.sum(np.hanning(n_bins))
    freq = np.fft.rfftfreq(nfft, width)
    return SpatialSpectrum(frequency=freq, amplitude=amp, bin_width=width, span=span)


def _ripple_cols(x: np.ndarray, period: float, nh: int) -> np.ndarray:
    return Ripple(period=period, harmonics=((0.0, 0.0),) * nh).regressors(x)


def fit_ripple(ctx: FitContext, train: np.ndarray, start: CandidateFit | None = None, *,
               max_harmonics: int = 0) -> CandidateFit:
    """Force ripple: period from the spatial spectrum, refined; harmonics as significant."""
    res, kin = ctx.res, ctx.kin
    rows = train & res.mask
    x, r = res.x, res.r
    if start is not None:
        return _ripple_refine(ctx, rows, start.scalars['period'],
                              len(start.params['harmonics']), float(np.ptp(x[rows])))
    spec = spatial_spectrum(x[rows], r[rows])
    # at least 3 periods in the travel and 4 bins per period of the highest harmonic
    min_p = max(8 * spec.bin_width, 4.0 * kin.dt * float(np.percentile(np.abs(res.v), 90)))
    max_p = spec.span / 3.0
    p0 = spec.peak_period(min_period=min_p, max_period=max_p)
    if not np.isfinite(p0):
        p0 = max_p
    max_h = max_harmonics or MAX_RIPPLE_HARMONICS
    # harmonics present in the spectrum: amplitude above 15 % of the fundamental and
    # above four times the median spectral floor
    a1 = spec.amplitude_at(1.0 / p0)
    floor = float(np.median(spec.amplitude))
    nh = 1
    for h in range(2, max_h + 1):
        if h / p0 > 1.0 / min_p:
            break
        ah = spec.amplitude_at(h / p0)
        if ah > 0.15 * a1 and ah > 4 * floor:
            nh = h

    return _ripple_refine(ctx, rows, p0, nh, spec.span)


def _ripple_refine(ctx: FitContext, rows: np.ndarray, p0: float, nh: int, span: float) \
        -> CandidateFit:
    kin, x, r = ctx.kin, ctx.res.x, ctx.res.r

    def sse(period: float) -> float:
        # unsmoothed columns in the search (smoothing a slow sinusoid barely changes it)
        cols = _ripple_cols(x, period, nh)
        theta = _lstsq(cols, r, rows)
        return _sse(_matvec(cols, theta), r, rows)

    # the spectral peak is within one resolution bin: search ±1.5 bins around it
    dp = 1.5 * p0 * p0 / span
    opt = minimize_scalar(sse, bounds=(max(p0 - dp, 0.5 * p0), p0 + dp), method='bounded',
                          options={'xatol': 1e-6 * p0})
    period = float(opt.x)
    cols = kin.smooth(_ripple_cols(x, period, nh))
    theta = _lstsq(cols, r, rows)
    harm = tuple((float(theta[2 * h]), float(theta[2 * h + 1])) for h in range(nh))
    eff = Ripple(period=period, harmonics=harm)
    scalars = {'period': period}
    for h, amp in enumerate(eff.amplitudes, start=1):
        scalars[f'amplitude_{h}'] = float(amp)
    return CandidateFit('ripple', eff.params(), scalars, _matvec(cols, theta), 1 + 2 * nh,
                        ctx.model.with_effect(eff))


# -- stribeck ----------------------------------------------------------------------
def _speed_range(res: Residual, rows: np.ndarray) -> tuple[float, float]:
    speed = np.abs(res.v[rows])
    return float(np.min(speed)), float(np.percentile(speed, 95))


def fit_stribeck(ctx: FitContext, train: np.ndarray,
                 start: CandidateFit | None = None) -> CandidateFit:
    """Stribeck hump ``(fs − fc)·e^{−|v/vs|^δ}·sgn v``: grid, then Nelder–Mead."""
    res, kin = ctx.res, ctx.kin
    rows = train & res.mask
    fc = ctx.model.fc
    v_lo, v_hi = _speed_range(res, rows)
    # vs must lie inside the observed speeds, below 30 % of the high speeds: a larger vs
    # would make the hump a copy of the Coulomb level (not identifiable)
    vs_lo, vs_hi = max(v_lo, 1e-7), max(0.3 * v_hi, 2 * max(v_lo, 1e-7))

    def solve(log_vs: float, delta: float) -> tuple[float, np.ndarray, float]:
        vs = float(np.exp(log_vs))
        col = kin.smooth(Stribeck(fs=fc, vs=vs, delta=delta).regressors(res.x, res.v))
        theta = _lstsq(col, res.r, rows)
        level = max(float(theta[0]), 0.0)
        pred = col[:, 0] * level
        return level, pred, _sse(pred, res.r, rows)

    best = None
    if start is not None:
        best = (solve(np.log(start.scalars['vs']), start.scalars['delta'])[2],
                np.log(start.scalars['vs']), start.scalars['delta'])
    else:
        for delta in (0.5, 1.0, 2.0):
            for lv in np.linspace(np.log(vs_lo), np.log(vs_hi), 12):
                s = solve(lv, delta)[2]
                if best is None or s < best[0]:
                    best = (s, lv, delta)
    lo_b, hi_b = np.log(vs_lo), np.log(vs_hi)

    def cost(p: np.ndarray) -> float:
        lv = float(np.clip(p[0], lo_b, hi_b))
        d = float(np.clip(p[1], 0.3, 5.0))
        return solve(lv, d)[2]

    opt = minimize(cost, np.array([best[1], best[2]]), method='Nelder-Mead',
                   options={'xatol': 1e-3, 'fatol': 1e-9 * best[0],
                            'maxiter': 40 if start is not None else 100})
    lv = float(np.clip(opt.x[0], lo_b, hi_b))
    delta = float(np.clip(opt.x[1], 0.3, 5.0))
    level, pred, _ = solve(lv, delta)
    eff = Stribeck(fs=fc + level, vs=float(np.exp(lv)), delta=delta)
    return CandidateFit('stribeck', eff.params(),
                        {'fs': eff.fs, 'vs': eff.vs, 'delta': eff.delta}, pred, 3,
                        ctx.model.with_effect(eff))


# -- presliding --------------------------------------------------------------------
def gms_effect(stiffness: float, c: float, fc: float = 1.0) -> Presliding:
    """Chiew's 4-element GMS shape: total stiffness [N/m], slip rate ``c`` [1/s] at ``fc``.

    ``c`` is the relaxation rate at sliding speeds (|s| = fc): attraction ``C = c·fc``.
    """
    return Presliding(alpha=GMS_ALPHA, k=tuple(s * stiffness for s in GMS_K_SHAPE),
                      C=c * max(fc, 1e-9))


def fit_presliding(ctx: FitContext, train: np.ndarray,
                   start: CandidateFit | None = None) -> CandidateFit:
    """GMS pre-sliding in place of the static Coulomb/Stribeck curve near reversals."""
    res, kin = ctx.res, ctx.kin
    rows = train & res.mask
    static = sum((res.forces[n] for n in ('coulomb', 'stribeck') if n in res.forces),
                 np.zeros(len(kin)))
    fc, fs, vs, delta = ctx.model.stribeck_curve_params()

    def predicted(log_k: float, log_c: float) -> np.ndarray:
        eff = gms_effect(float(np.exp(log_k)), float(np.exp(log_c)), fc)
        f = eff.force_along(res.x, kin.dt, fc=fc, fs=fs, vs=vs, delta=delta)
        # the GMS force replaces the static curve: the change is what it explains
        return kin.smooth(f) - static

    # stiffness so that the pre-sliding distance fc/K spans ~1/10 encoder count ... 10 cm
    best = None
    if start is not None:
        lk, lc = np.log(start.scalars['stiffness']), np.log(start.scalars['c'])
        best = (_sse(predicted(lk, lc), res.r, rows), lk, lc)
    else:
        for lk in np.log(np.logspace(3, 9, 13)):
            for lc in np.log((1e2, 1e3, 1e4)):
                s = _sse(predicted(lk, lc), res.r, rows)
                if best is None or s < best[0]:
                    best = (s, lk, lc)

    def cost(p: np.ndarray) -> float:
        return _sse(predicted(float(np.clip(p[0], np.log(1e2), np.log(1e10))),
                              float(np.clip(p[1], np.log(1.0), np.log(1e6)))), res.r, rows)

    opt = minimize(cost, np.array(best[1:]), method='Nelder-Mead',
                   options={'xatol': 1e-3, 'fatol': 1e-9 * best[0],
                            'maxiter': 30 if start is not None else 60})
    lk = float(np.clip(opt.x[0], np.log(1e2), np.log(1e10)))
    lc = float(np.clip(opt.x[1], np.log(1.0), np.log(1e6)))
    eff = gms_effect(float(np.exp(lk)), float(np.exp(lc)), fc)
    return CandidateFit('presliding', eff.params(),
                        {'stiffness': eff.stiffness, 'c': float(np.exp(lc))},
                        predicted(lk, lc), 2,
                        ctx.model.with_effect(eff))


# -- delay -------------------------------------------------------------------------
def fit_delay(ctx: FitContext, train: np.ndarray, start: CandidateFit | None = None, *,
              max_tau: float = 0.03) -> CandidateFit:
    """Input dead time: the drive force recomputed from ``u(t − τ)``; 1-D search over τ."""
    res, kin, model = ctx.res, ctx.kin, ctx.model
    rows = train & res.mask
    gain = model.input_gain
    tau0 = model.get('delay').tau if model.has('delay') else 0.0
    u0 = kin.smooth(kin.input_at(tau0))

    def predicted(tau: float) -> np.ndarray:
        # F_in(τ0) − F_in(τ): only the command term depends on τ
        return gain * (u0 - kin.smooth(kin.input_at(tau)))

    hi = min(max_tau, 0.1, 0.25 * kin.duration)
    if start is not None:
        t0 = start.scalars['tau']
        grid = np.array([max(t0 - kin.dt, 0.0), t0, t0 + kin.dt])
    else:
        grid = np.arange(0.0, hi + 1e-12, 0.5 * kin.dt)
    costs = [_sse(predicted(tau), res.r, rows) for tau in grid]
    i = int(np.argmin(costs))
    lo_b, hi_b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    if hi_b > lo_b:
        opt = minimize_scalar(lambda s: _sse(predicted(s), res.r, rows), bounds=(lo_b, hi_b),
                              method='bounded', options={'xatol': 1e-3 * kin.dt})
        tau = float(opt.x)
    else:
        tau = float(grid[i])
    eff = Delay(tau=tau)
    return CandidateFit('delay', eff.params(), {'tau': tau}, predicted(tau), 1,
                        model.with_effect(eff))


# -- backlash ----------------------------------------------------------------------
def fit_backlash(ctx: FitContext, train: np.ndarray,
                 start: CandidateFit | None = None) -> CandidateFit:
    """Backlash gap width: residual recomputed from the reconstructed motor position."""
    res, kin, model = ctx.res, ctx.kin, ctx.model
    rows = train & res.mask

    def predicted(width: float) -> np.ndarray:
        m = model.with_effect(Backlash(width=width))
        return res.r - residual(kin, m, mask=res.mask).r

    span = float(np.ptp(kin.x))
    hi = min(MAX_BACKLASH, 0.05 * span)
    # from ten noise σ (what the joint fit's gap search uses, ``ident.backlash_grid``)
    lo = max(1e-7, 10.0 * kin.noise_std())
    hi = min(max(hi, 4 * lo), MAX_BACKLASH)
    lo = min(lo, 0.25 * hi)
    if start is not None:
        w0 = start.scalars['width']
        grid = np.array([max(0.7 * w0, lo), w0, min(1.4 * w0, MAX_BACKLASH)])
    else:
        grid = np.logspace(np.log10(lo), np.log10(hi), 14)
    costs = [_sse(predicted(w), res.r, rows) for w in grid]
    i = int(np.argmin(costs))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    opt = minimize_scalar(lambda lw: _sse(predicted(float(np.exp(lw))), res.r, rows),
                          bounds=(np.log(a), np.log(b)), method='bounded',
                          options={'xatol': 0.01})
    width = float(np.exp(opt.x))
    eff = Backlash(width=width)
    return CandidateFit('backlash', eff.params(), {'width': width}, predicted(width), 1,
                        model.with_effect(eff))


#: the fitter of each candidate name
FITTERS: dict[str, Callable[..., CandidateFit]] = {
    'coulomb': fit_coulomb,
    'viscous': fit_viscous,
    'stribeck': fit_stribeck,
    'presliding': fit_presliding,
    'ripple': fit_ripple,
    'offset': fit_offset,
    'spring': fit_spring,
    'asymmetry': fit_asymmetry,
    'delay': fit_delay,
    'backlash': fit_backlash,
    MASS: fit_mass,
}


def available_candidates(model: AxisModel) -> list[str]:
    """Candidate names for ``model``: absent effects (with their prerequisites) + mass."""
    out = []
    for name in FITTERS:
        if name == MASS:
            out.append(name)
            continue
        if model.has(name):
            continue
        if name in ('stribeck', 'presliding') and not model.has('coulomb'):
            continue
        if name in ('coulomb', 'stribeck') and model.has('presliding'):
            continue
        out.append(name)
    return out
