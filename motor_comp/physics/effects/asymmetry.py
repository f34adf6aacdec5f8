"""Direction-dependent friction: ``fc± = fc ± dfc/2``, ``fv± = fv ± dfv/2`` (DESIGN.md §6).

Added to a symmetric Coulomb/viscous model, the extra force is
``dfc/2·|sgn(ẋ)| + dfv/2·|ẋ|`` [N]: the same sign in both directions, zero at rest.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from motor_comp.errors import check_finite
from motor_comp.physics.effects.base import Effect


@njit(cache=True)
def asymmetry_force(v, dfc, dfv):
    """Extra force [N] of direction-dependent Coulomb (dfc [N]) and viscous (dfv [N·s/m])."""
    return 0.5 * dfc * np.abs(np.sign(v)) + 0.5 * dfv * np.abs(v)


@dataclasses.dataclass(frozen=True)
class Asymmetry(Effect):
    """Direction-dependent friction.

    Parameters
    ----------
    dfc : float
        Coulomb difference fc+ − fc− [N].
    dfv : float
        Viscous difference fv+ − fv− [N·s/m].
    """

    name = 'asymmetry'
    title = 'direction-dependent friction'
    dfc: float = 0.0
    dfv: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'dfc', check_finite('asymmetry.dfc [N]', self.dfc))
        object.__setattr__(self, 'dfv', check_finite('asymmetry.dfv [N·s/m]', self.dfv))

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Extra force [N] at velocities ``v`` [m/s]."""
        return asymmetry_force(np.asarray(v, dtype=float), self.dfc, self.dfv)

    def regressors(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Columns ``[|sgn v|/2, |v|/2]``; coefficients ``[dfc, dfv]``."""
        v = np.asarray(v, dtype=float)
        return np.stack([0.5 * np.abs(np.sign(v)), 0.5 * np.abs(v)], axis=1)
