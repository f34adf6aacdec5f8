"""Stribeck effect: friction rises from fc to fs as |ẋ| → 0.

``F = (fs − fc)·exp(−|ẋ/vs|^δ)·sgn(ẋ)``; together with Coulomb and viscous friction it
forms the static model ``[fc + (fs−fc)·e^{−|ẋ/vs|^δ}]·sgn(ẋ) + fv·ẋ`` of Chiew et al.
eq. 2 (the friction model of Tan 2002 §II too).  The signed Stribeck curve ``s(v)``
used by the GMS model (Lampaert 2003) is :func:`stribeck_curve`.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from motor_comp.errors import ParameterError, check_nonnegative, check_positive
from motor_comp.physics.effects.base import Effect


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
        return (stribeck_shape(v * (1.0 / self.vs), self.delta) * np.sign(v))[:, None]
