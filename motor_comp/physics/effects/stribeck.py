"""Stribeck effect: friction rises from fc to fs as |ẋ| → 0.

``F = (fs − fc)·exp(−|ẋ/vs|^δ)·sgn(ẋ)``; together with Coulomb and viscous friction it
forms the static model ``[fc + (fs−fc)·e^{−|ẋ/vs|^δ}]·sgn(ẋ) + fv·ẋ`` of Chiew et al.
eq. 2 (the friction model of Tan 2002 §II too).  The signed Stribeck curve ``s(v)``
used by the GMS model (Lampaert 2003) is :func:`stribeck_curve`.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.errors import ParameterError, check_nonnegative, check_positive
from motor_comp.physics import aot
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.identification import Column, Context, Evidence, Param, \
    Shape, Summary, Term


@aot.ahead(aot.F8_1D, aot.F8)
@njit(cache=True, inline='always', error_model='numpy')
def stribeck_shape(z, delta):
    """Stribeck decay ``exp(−|z|^δ)`` [-] of the normalised speed ``z = v/vs``.

    The exponents of the papers, δ = 2 (Tan 2002, Gaussian) and δ = 1 (Chiew et al.,
    exponential), are evaluated as ``z·z`` and ``|z|``, without a ``pow`` call in the
    plant's inner loop: ``|z|`` is exactly the power, ``z·z`` the correctly rounded
    square (``pow`` may differ from it in the last bit).
    """
    if delta == 2.0:
        return np.exp(-(z * z))
    if delta == 1.0:
        return np.exp(-np.abs(z))
    return np.exp(-np.abs(z) ** delta)


@njit(cache=True, inline='always', error_model='numpy')
def stribeck_level(speed, fc, fs, inv_vs, delta):
    """Unsigned static friction level [N] at speed ``|v|`` [m/s], given ``1/vs`` [s/m].

    ``fc + (fs−fc)·e^{−|v/vs|^δ}``; the normalisation multiplies by the reciprocal of
    ``vs`` (which the plant kernel computes once per advance) rather than dividing in
    every RK4 stage.  Every Stribeck function below goes through this one.
    """
    return fc + (fs - fc) * stribeck_shape(speed * inv_vs, delta)


@njit(cache=True, inline='always', error_model='numpy')
def stribeck_magnitude(speed, fc, fs, vs, delta):
    """Unsigned static friction level [N] at speed ``|v|`` [m/s]: fc + (fs−fc)·e^{−|v/vs|^δ}."""
    return stribeck_level(speed, fc, fs, 1.0 / vs, delta)


@njit(cache=True, inline='always', error_model='numpy')
def stribeck_curve(v, fc, fs, vs, delta):
    """Signed Stribeck curve ``s(v) = sgn(v)·[fc + (fs−fc)·e^{−|v/vs|^δ}]`` [N]."""
    return np.sign(v) * stribeck_level(v, fc, fs, 1.0 / vs, delta)


@njit(cache=True, error_model='numpy')
def stribeck_force(v, fc, fs, vs, delta):
    """Return the Stribeck term alone, ``(fs−fc)·e^{−|v/vs|^δ}·sgn(v)`` [N]."""
    return (fs - fc) * stribeck_shape(v * (1.0 / vs), delta) * np.sign(v)


@dataclasses.dataclass(frozen=True)
class Stribeck(Effect):
    """Stribeck friction (breakaway above the Coulomb level at low speed).

    Parameters
    ----------
    fs : float
        Breakaway (static) friction [N], >= the model's Coulomb level fc.
    vs : float
        Stribeck velocity [m/s], > 0.
    delta : float
        Stribeck shape exponent [-], in (0, 10].
    """

    name = 'stribeck'
    title = 'Stribeck friction'
    fs: float = 0.0
    vs: float = 1e-3
    delta: float = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'fs', check_nonnegative('stribeck.fs [N]', self.fs))
        object.__setattr__(self, 'vs', check_positive('stribeck.vs [m/s]', self.vs))
        d = check_positive('stribeck.delta [-]', self.delta)
        if d > 10.0:
            raise ParameterError(f'stribeck.delta [-] must be <= 10, got {d:g}')
        object.__setattr__(self, 'delta', d)

    def force(self, x: np.ndarray, v: np.ndarray, *, fc: float = 0.0) -> np.ndarray:
        """Stribeck term [N] at velocities ``v`` [m/s] given the Coulomb level ``fc`` [N]."""
        if self.fs < fc:
            raise ParameterError(
                f'stribeck.fs [N] ({self.fs:g}) must be >= coulomb.fc ({fc:g})')
        return stribeck_force(np.asarray(v, dtype=float), fc, self.fs, self.vs, self.delta)

    def regressors(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Column whose coefficient is ``fs − fc`` for the current ``vs``, ``delta``."""
        v = np.asarray(v, dtype=float)
        return (stribeck_shape_entry(v * (1.0 / self.vs), self.delta) * np.sign(v))[:, None]


#: the run's 95th-percentile speed over the largest ``vs`` searched: the Stribeck rise
#: (``delta = 1``) must decay to ``e⁻³`` within the run's speeds (0.1 lost the rotary
#: interleaved generator run's vs = 0.13·v95: NRMSE 2.2x the true model's)
VS_SEEN_DECAY = 3.0


class StribeckTerm(Term):
    """Identification of the Stribeck rise: ``fs − fc ≥ 0`` on the shaped signed share.

    ``vs`` is searched inside the speeds seen, up to a third of the high ones (a larger
    ``vs`` stretches the hump over the whole speed range, where it copies a negative
    viscous term instead of describing low-speed friction; :data:`VS_SEEN_DECAY`),
    ``δ`` over 0.3–5; both on their logarithms.  ``fs ≥ fc`` holds inside the estimator.
    """

    name = 'stribeck'
    #: in a residual's scan: a friction excess that falls with speed from the lowest
    shape = Shape('velocity', odd=True, trend=-1)
    effect = Stribeck
    requires = ('coulomb',)
    #: it acts while the axis slides slowly: around the turns
    evidence = Evidence.SLIDING | Evidence.SLOW
    dry_friction = True
    params = ('vs', 'delta')
    force_scaled = (('stribeck', 'fs'),)

    def space(self, s: Summary, ctx: Context) -> tuple[Param, ...]:
        """Return ``vs`` [m/s] and ``delta`` [-].

        ``vs`` at most a third of the run's 95th-percentile speed: at ``delta = 1`` the
        rise has then fallen to ``e⁻³`` (5 %) within the speeds the run holds; a wider
        curve is not told from a viscous slope over this run.
        """
        lo = max(float(s.speeds[1]), 1e-7)
        hi = max(float(s.speeds[95]) / VS_SEEN_DECAY, 2 * lo)
        grid = tuple(float(v) for v in np.exp(np.linspace(np.log(lo), np.log(hi), 8)))
        return (Param('vs', math.exp(-16.0), hi, grid=grid, log=True,
                      steps=tuple(np.log((0.7, 1.0, 1.4)))),
                Param('delta', 0.3, 5.0, grid=(0.5, 1.0, 2.0), log=True,
                      steps=tuple(np.log((0.8, 1.0, 1.25)))))

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return the ``dfs = fs − fc`` column."""
        vs, dl = float(eta['vs']), float(eta['delta'])
        return [Column('dfs', ('stribeck_shares', vs, dl),
                       lambda p: stribeck_shape_entry(p.v / vs, dl) * (p.fwd - p.bwd), lo=0.0)]

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted Stribeck effect (``fs = fc + dfs``)."""
        fc = max(float(values.get(('coulomb', 'fc'), 0.0)), 0.0)
        dfs = max(float(values.get((self.name, 'dfs'), 0.0)), 0.0)
        return [Stribeck(fs=fc + dfs, vs=float(eta['vs']), delta=float(eta['delta']))]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return ``dfs = fs − fc`` and ``(vs, delta)``."""
        e = model.get(self.name)
        return {'dfs': e.fs - model.fc}, {'vs': e.vs, 'delta': e.delta}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``fs`` [N], ``vs`` [m/s], ``delta``."""
        def g(v: Mapping, k: tuple, d: float = 0.0) -> float:
            return float(v.get(k, d))
        return {('stribeck', 'fs'): lambda v: g(v, ('coulomb', 'fc')) + g(v, ('stribeck', 'dfs')),
                ('stribeck', 'vs'): lambda v: g(v, ('stribeck', 'vs'), eta['vs']),
                ('stribeck', 'delta'): lambda v: g(v, ('stribeck', 'delta'), eta['delta'])}


TERM = StribeckTerm()


# Python calls the kernels above through their entries: compiled ahead of time where
# built (see motor_comp.physics.aot), else the JIT
stribeck_shape_entry = aot.entry(stribeck_shape)
