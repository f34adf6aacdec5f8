"""Coulomb friction ``F = fc·sgn(ẋ)`` [N] (DESIGN.md §3; Chiew et al. eq. 2, Tan 2002 eq. 5)."""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.errors import check_nonnegative
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.identification import Column, Context, Shape, Term


@njit(cache=True)
def coulomb_force(v, fc):
    """Return the Coulomb force [N] opposing velocity ``v`` [m/s].

    Zero at rest: holding the axis there (stiction) is the integrator's job.
    """
    return fc * np.sign(v)


@dataclasses.dataclass(frozen=True)
class Coulomb(Effect):
    """Coulomb (dry sliding) friction.

    Parameters
    ----------
    fc : float
        Coulomb friction level [N], >= 0.
    """

    name = 'coulomb'
    title = 'Coulomb friction'
    fc: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'fc', check_nonnegative('coulomb.fc [N]', self.fc))

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Force [N] at positions ``x`` [m] and velocities ``v`` [m/s]."""
        return coulomb_force(np.asarray(v, dtype=float), self.fc)

    def regressors(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Columns whose coefficients are ``[fc]`` (the law is linear in fc)."""
        return np.sign(np.asarray(v, dtype=float))[:, None]


class CoulombTerm(Term):
    """Identification of Coulomb friction: ``fc`` on the signed share of sliding.

    The column is not ``sgn ẋ`` of an estimated velocity but the share of each
    sample's acceleration kernel spent sliding forward minus backward (the turn model
    of the workbench places a reversal between samples); on a run that slides one way
    only it is that direction throughout.  ``fc ≥ 0`` inside the estimator.
    """

    name = 'coulomb'
    #: in a residual's scan: a friction level, the same at every speed
    shape = Shape(None, odd=True)
    effect = Coulomb
    dry_friction = True
    force_scaled = (('coulomb', 'fc'),)

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return the ``fc`` column."""
        if ctx.direction:
            d = float(ctx.direction)
            return [Column('fc', ('direction', d), lambda p, d=d: np.full(len(p.v), d),
                           lo=0.0)]
        return [Column('fc', ('sgn_shares',), lambda p: p.fwd - p.bwd, lo=0.0)]

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted Coulomb effect."""
        return [Coulomb(fc=max(float(values.get((self.name, 'fc'), 0.0)), 0.0))]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return ``fc``."""
        return {'fc': model.get(self.name).fc}, {}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``fc`` [N]."""
        return {('coulomb', 'fc'): lambda v: float(v.get(('coulomb', 'fc'), 0.0))}


TERM = CoulombTerm()
