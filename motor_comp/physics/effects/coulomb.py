"""Coulomb friction ``F = fc·sgn(ẋ)`` [N] (DESIGN.md §3; Chiew et al. eq. 2, Tan 2002 eq. 5)."""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from motor_comp.errors import check_nonnegative
from motor_comp.physics.effects.base import Effect


@njit(cache=True)
def coulomb_force(v, fc):
    """Return the Coulomb force [N] opposing velocity ``v`` [m/s].

    Zero at rest: holding the axis there (stiction) is the integrator's job.
    """
    return fc * np.sign(v)


@dataclasses.dataclass(frozen=True)
class Coulomb(Effect):
    """Coulomb (dry sliding) friction.

    Parameters
    ----------
    fc : float
        Coulomb friction level [N], >= 0.
    """

    name = 'coulomb'
    title = 'Coulomb friction'
    fc: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'fc', check_nonnegative('coulomb.fc [N]', self.fc))

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Force [N] at positions ``x`` [m] and velocities ``v`` [m/s]."""
        return coulomb_force(np.asarray(v, dtype=float), self.fc)

    def regressors(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Columns whose coefficients are ``[fc]`` (the law is linear in fc)."""
        return np.sign(np.asarray(v, dtype=float))[:, None]
