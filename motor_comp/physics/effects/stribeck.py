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


@njit(cache=True)
def stribeck_magnitude(speed, fc, fs, vs, delta):
    """Unsigned static friction level [N] at speed ``|v|`` [m/s]: fc + (fs−fc)·e^{−|v/vs|^δ}."""
    return fc + (fs - fc) * np.exp(-np.abs(speed / vs) ** delta)


@njit(cache=True)
def stribeck_curve(v, fc, fs, vs, delta):
    """Signed Stribeck curve ``s(v) = sgn(v)·[fc + (fs−fc)·e^{−|v/vs|^δ}]`` [N]."""
    return np.sign(v) * stribeck_magnitude(v, fc, fs, vs, delta)


@njit(cache=True)
def stribeck_force(v, fc, fs, vs, delta):
    """Return the Stribeck term alone, ``(fs−fc)·e^{−|v/vs|^δ}·sgn(v)`` [N]."""
    return (fs - fc) * np.exp(-np.abs(v / vs) ** delta) * np.sign(v)


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
        return (np.exp(-np.abs(v / self.vs) ** self.delta) * np.sign(v))[:, None]
