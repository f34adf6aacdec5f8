"""Backlash: a dead band of width ``w`` [m] between motor and load (play operator).

The load (where the linear scale measures) follows the motor only once the gap is
closed: ``x_load ∈ [x_motor − w/2, x_motor + w/2]`` and moves only when pushed by an
edge.  The load is taken as massless, so friction acts on the motor side.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from motor_comp.errors import ParameterError, check_nonnegative
from motor_comp.physics.effects.base import Effect, EffectKind


@njit(cache=True)
def play(x_motor, x_load, width):
    """One play-operator update: the load position [m] after the motor moved to ``x_motor``."""
    half = 0.5 * width
    if x_motor - x_load > half:
        return x_motor - half
    if x_load - x_motor > half:
        return x_motor + half
    return x_load


@njit(cache=True)
def play_trajectory(x_motor, width, x_load0):
    """Load positions [m] along a motor trajectory (play operator applied per sample)."""
    out = np.empty_like(x_motor)
    xl = x_load0
    for j in range(x_motor.shape[0]):
        xl = play(x_motor[j], xl, width)
        out[j] = xl
    return out


@dataclasses.dataclass(frozen=True)
class Backlash(Effect):
    """Dead band between motor and measured load.

    Parameters
    ----------
    width : float
        Total play [m], 0 <= width <= 0.01.
    """

    name = 'backlash'
    kind = EffectKind.OUTPUT
    title = 'backlash'
    width: float = 0.0

    def __post_init__(self) -> None:
        w = check_nonnegative('backlash.width [m]', self.width)
        if w > 0.01:
            raise ParameterError(f'backlash.width [m] must be <= 0.01, got {w:g}')
        object.__setattr__(self, 'width', w)

    def apply(self, x_motor: np.ndarray, x_load0: float | None = None) -> np.ndarray:
        """Load positions [m] for motor positions ``x_motor`` [m]."""
        x = np.ascontiguousarray(x_motor, dtype=float)
        return play_trajectory(x, self.width, float(x[0] if x_load0 is None else x_load0))
