"""Viscous friction ``F = fv·ẋ`` [N] (DESIGN.md §3; σ in Chiew eq. 2 and GMS eq. 5)."""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from motor_comp.errors import check_nonnegative
from motor_comp.physics.effects.base import Effect


@njit(cache=True)
def viscous_force(v, fv):
    """Viscous force [N] = fv [N·s/m] · v [m/s]."""
    return fv * v


@dataclasses.dataclass(frozen=True)
class Viscous(Effect):
    """Viscous friction.

    Parameters
    ----------
    fv : float
        Viscous coefficient [N·s/m], >= 0.
    """

    name = 'viscous'
    title = 'viscous friction'
    fv: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'fv', check_nonnegative('viscous.fv [N·s/m]', self.fv))

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Force [N] at velocities ``v`` [m/s]."""
        return viscous_force(np.asarray(v, dtype=float), self.fv)

    def regressors(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Columns whose coefficients are ``[fv]``."""
        return np.asarray(v, dtype=float)[:, None]
