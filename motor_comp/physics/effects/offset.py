"""Constant force offset ``F = f0`` [N] (gravity on an inclined axis, cable drag, bias)."""
from __future__ import annotations

import dataclasses

import numpy as np

from motor_comp.errors import check_finite
from motor_comp.physics.effects.base import Effect


@dataclasses.dataclass(frozen=True)
class Offset(Effect):
    """Constant force opposing positive motion when f0 > 0.

    Parameters
    ----------
    f0 : float
        Constant force [N] (any sign).
    """

    name = 'offset'
    title = 'constant force offset'
    f0: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'f0', check_finite('offset.f0 [N]', self.f0))

    def force(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Force [N], the same at every sample."""
        return np.full(np.shape(x), self.f0)

    def regressors(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Column of ones; coefficient ``[f0]``."""
        return np.ones((np.shape(x)[0], 1))
