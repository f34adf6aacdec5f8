"""Input dead time ``u(t − τ)`` (Chiew eq. 1: ``e^{−τs}``, τ = 1.29 ms on the XY table)."""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np

from motor_comp.errors import ParameterError, check_nonnegative
from motor_comp.physics.effects.base import Effect, EffectKind
from motor_comp.physics.effects.identification import Context, Param, Summary, Term

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


class DelayTerm(Term):
    """Identification of an input dead time ``τ``: the drive force from ``u(t − τ)``.

    No column of its own (an input effect): the workbench computes the drive force with
    the trial delay.  Searched from 0 to 30 ms or a tenth of the shortest run, in half
    samples, then refined between grid points; inside each fold ±2 samples around the
    all-data value in sixteenths.
    """

    name = 'delay'
    effect = Delay
    params = ('tau',)
    null = ('tau', 0.0)

    def space(self, s: Summary, ctx: Context) -> tuple[Param, ...]:
        """Return ``tau`` [s]."""
        hi = min(0.03, 0.1 * s.duration)
        grid = tuple(np.arange(0.0, hi + 1e-12, max(0.5 * s.dt, hi / 60.0)))
        return (Param('tau', 0.0, hi, grid=grid,
                      steps=tuple(s.dt * np.linspace(-2.0, 2.0, 17)), tol=1e-3 * s.dt),)

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted delay."""
        return [Delay(tau=max(float(eta['tau']), 0.0))]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return no coefficient and ``tau``."""
        return {}, {'tau': model.get(self.name).tau}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``tau`` [s]."""
        return {('delay', 'tau'): lambda v: float(v.get(('delay', 'tau'), eta['tau']))}


TERM = DelayTerm()
