"""Viscous friction ``F = fv·ẋ`` [N] (DESIGN.md §3; σ in Chiew eq. 2 and GMS eq. 5)."""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.errors import check_nonnegative
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.identification import Column, Context, Shape, Signal, Term


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


class ViscousTerm(Term):
    """Identification of viscous friction: ``fv ≥ 0`` on the velocity the stencil sees."""

    name = 'viscous'
    #: in a residual's scan: a friction growing with speed
    shape = Shape('velocity', odd=True, trend=1)
    effect = Viscous
    force_scaled = (('viscous', 'fv'),)

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return the ``fv`` column (the processed velocity)."""
        return [Column('fv', ('vl',), signal=Signal.VELOCITY, lo=0.0)]

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted viscous effect."""
        return [Viscous(fv=max(float(values.get((self.name, 'fv'), 0.0)), 0.0))]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return ``fv``."""
        return {'fv': model.get(self.name).fv}, {}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``fv`` [N·s/m]."""
        return {('viscous', 'fv'): lambda v: float(v.get(('viscous', 'fv'), 0.0))}


TERM = ViscousTerm()
