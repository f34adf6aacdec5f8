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
        """Delayed signal ``u(t − τ)`` by linear interpolation; zero before the start.

        The one start-up convention of the project (issue 15 item 6), the same as the
        plant kernel's dead-time buffer: before the first sample the command was 0 (a
        drive at power-on), and between that zero, taken one sample period before
        ``t[0]``, and ``u[0]`` the signal is interpolated linearly like everywhere else.
        For uniform samples at the physics step this is exactly the command the kernel
        applies (``S_UEFF``).

        Parameters
        ----------
        t : ndarray
            Increasing sample times [s].
        u : ndarray
            Samples of the command at ``t``.
        """
        t = np.asarray(t, dtype=float)
        u = np.asarray(u, dtype=float)
        if t.size == 0:
            return u.copy()
        h = t[1] - t[0] if t.size > 1 else 0.0
        if h > 0.0:
            t = np.concatenate(([t[0] - h], t))
            u = np.concatenate(([0.0], u))
            return np.interp(np.asarray(t[1:]) - self.tau, t, u, left=0.0)
        return np.interp(t - self.tau, t, u, left=0.0)
