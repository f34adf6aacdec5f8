"""Direction-dependent friction: ``fc± = fc ± dfc/2``, ``fv± = fv ± dfv/2`` (DESIGN.md §6).

Added to a symmetric Coulomb/viscous model, the extra force is
``dfc/2·|sgn(ẋ)| + dfv/2·|ẋ|`` [N]: the same sign in both directions, zero at rest.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.errors import check_finite
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.identification import Column, Context, Term


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


class AsymmetryTerm(Term):
    """Identification of direction-dependent friction: ``dfc``, ``dfv``.

    While sliding ``dfc/2`` is a constant force like an offset (the same column,
    ``../shared/IDENTIFICATION.md`` §1): it is left to a present offset or spring.  It
    splits the friction levels, so it needs one (Coulomb or viscous) to split, and
    motion both ways.  Inside the estimator the Coulomb level stays a friction both
    ways, ``fc ± dfc/2 ≥ 0``; the viscous split is free (a slope that differs by
    direction is what an asymmetric drive or a velocity-dependent gain looks like).
    """

    name = 'asymmetry'
    effect = Asymmetry
    requires_any = ('coulomb', 'viscous')
    both_directions = True

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return the ``dfc`` (shared constant) and ``dfv`` columns."""
        sticks = bool(ctx.sticks)
        return [Column('dfc', ('moving_share', sticks),
                       lambda p: 0.5 * (p.fwd + p.bwd if sticks else p.fwd + p.bwd + p.stuck),
                       basis='constant'),
                Column('dfv', ('abs_v',), lambda p: 0.5 * np.abs(p.v))]

    def constraints(self, ctx: Context) -> list:
        """Keep ``fc ± dfc/2 ≥ 0`` when the Coulomb level is a column of its own."""
        if 'coulomb' not in ctx.present or 'presliding' in ctx.present:
            return []
        fc, dfc = ('coulomb', 'fc'), (self.name, 'dfc')
        return [({fc: 1.0, dfc: 0.5}, 0.0), ({fc: 1.0, dfc: -0.5}, 0.0)]

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted asymmetry."""
        return [Asymmetry(dfc=float(values.get((self.name, 'dfc'), 0.0)),
                          dfv=float(values.get((self.name, 'dfv'), 0.0)))]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return ``dfc`` and ``dfv``."""
        e = model.get(self.name)
        return {'dfc': e.dfc, 'dfv': e.dfv}, {}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``dfc`` [N] and ``dfv`` [N·s/m]."""
        return {('asymmetry', k): (lambda v, k=k: float(v.get(('asymmetry', k), 0.0)))
                for k in ('dfc', 'dfv')}


TERM = AsymmetryTerm()
