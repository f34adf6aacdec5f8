"""Input dead time ``u(t − τ)`` (Chiew eq. 1: ``e^{−τs}``, τ = 1.29 ms on the XY table)."""
from __future__ import annotations

import dataclasses

import numpy as np

from motor_comp.errors import ParameterError, check_nonnegative
from motor_comp.physics.effects.base import Effect, EffectKind

#: longest dead time the plant accepts [s]
MAX_DELAY_S = 0.1


@dataclasses.dataclass(frozen=True)
class Delay(Effect):
    """Pure input delay (amplifier, communication, computation).

    Parameters
    ----------
    tau : float
        Dead time [s], 0 <= tau <= 0.1.
    """

    name = 'delay'
    kind = EffectKind.INPUT
    title = 'input delay'
    tau: float = 0.0

    def __post_init__(self) -> None:
        tau = check_nonnegative('delay.tau [s]', self.tau)
        if tau > MAX_DELAY_S:
            raise ParameterError(f'delay.tau [s] must be <= {MAX_DELAY_S:g}, got {tau:g}')
        object.__setattr__(self, 'tau', tau)

    def apply(self, t: np.ndarray, u: np.ndarray) -> np.ndarray:
        """Delayed signal ``u(t − τ)`` by linear interpolation; held at ``u[0]`` before start."""
        t = np.asarray(t, dtype=float)
        return np.interp(t - self.tau, t, np.asarray(u, dtype=float))
