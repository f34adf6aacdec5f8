"""Backlash: a dead band of width ``w`` [m] between motor and load (play operator).

The load (where the linear scale measures) follows the motor only once the gap is
closed: ``x_load ∈ [x_motor − w/2, x_motor + w/2]`` and moves only when pushed by an
edge.  The load is taken as massless, so friction acts on the motor side.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.errors import ParameterError, check_nonnegative
from motor_comp.physics.effects.base import Effect, EffectKind
from motor_comp.physics.effects.identification import Context, Evidence, Param, Summary, Term

#: widest gap the effect accepts [m]
MAX_WIDTH = 0.01


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
        if w > MAX_WIDTH:
            raise ParameterError(f'backlash.width [m] must be <= {MAX_WIDTH:g}, got {w:g}')
        object.__setattr__(self, 'width', w)

    def apply(self, x_motor: np.ndarray, x_load0: float | None = None) -> np.ndarray:
        """Load positions [m] for motor positions ``x_motor`` [m]."""
        x = np.ascontiguousarray(x_motor, dtype=float)
        return play_trajectory(x, self.width, float(x[0] if x_load0 is None else x_load0))


class BacklashTerm(Term):
    """Identification of a backlash gap: the motor motion reconstructed across it.

    An output effect: no column of its own; the workbench rebuilds the motor position
    from the measured load position for each trial width (the model's own dynamics
    across the gap) and every column follows that motion.  Searched log-spaced from
    ten times the position noise (a gap narrower is not told from stiction; a search
    from a few counts sat on too coarse a grid and missed a 39 µm gap) to 5 % of the
    travel (at most 10 mm).  Its evidence is at the reversals.  A gap's SSE profile
    is one-sided (a flight that ends too early leaves the load stuck under a drive
    force; one too late changes little), so its standard error comes from the
    profile (``profile = True`` on the parameter).
    """

    name = 'backlash'
    effect = Backlash
    evidence = Evidence.TURNS
    min_reversals = 4
    excludes = ('presliding',)
    params = ('width',)
    null = ('width', 0.0)

    def space(self, s: Summary, ctx: Context) -> tuple[Param, ...]:
        """Return ``width`` [m]."""
        lo = max(1e-7, 10.0 * s.noise)
        hi = min(MAX_WIDTH, 0.05 * s.travel)
        hi = min(max(hi, 4 * lo), MAX_WIDTH)
        lo = min(lo, 0.25 * hi)
        return (Param('width', lo, hi, grid=tuple(np.logspace(np.log10(lo), np.log10(hi), 8)),
                      log=True, steps=tuple(np.log((0.8, 0.9, 1.0, 1.1, 1.25))),
                      profile=True, resolved=True),)

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted gap."""
        return [Backlash(width=float(np.clip(eta['width'], 0.0, MAX_WIDTH)))]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return no coefficient and ``width``."""
        return {}, {'width': model.get(self.name).width}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``width`` [m]."""
        return {('backlash', 'width'):
                lambda v: float(v.get(('backlash', 'width'), eta['width']))}


TERM = BacklashTerm()
