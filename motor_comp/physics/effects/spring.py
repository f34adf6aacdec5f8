"""Position-proportional force ``F = k·(x − x0)`` [N].

Cable carrier, flexure, or the ``C`` term of Chiew eq. 1.
"""
from __future__ import annotations

import dataclasses

import numpy as np

from motor_comp.errors import check_finite
from motor_comp.physics.effects.base import Effect


@dataclasses.dataclass(frozen=True)
class Spring(Effect):
    """Linear spring to a rest position.

    Parameters
    ----------
    k : float
        Stiffness [N/m] (finite; negative models a destabilising magnetic pull).
    x0 : float
        Rest position [m].
    """

    name = 'spring'
    title = 'spring (position-proportional force)'
    k: float = 0.0
    x0: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'k', check_finite('spring.k [N/m]', self.k))
        object.__setattr__(self, 'x0', check_finite('spring.x0 [m]', self.x0))

    def force(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Force [N] at positions ``x`` [m]."""
        return self.k * (np.asarray(x, dtype=float) - self.x0)

    def regressors(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Columns ``[x, 1]``; coefficients ``[k, −k·x0]``."""
        x = np.asarray(x, dtype=float)
        return np.stack([x, np.ones_like(x)], axis=1)
