"""Position-proportional force ``F = k·(x − x0)`` [N].

Cable carrier, flexure, or the ``C`` term of Chiew eq. 1.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np

from motor_comp.errors import check_finite
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.identification import Column, Context, Summary, Term
from motor_comp.physics.effects.offset import constant_column


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
    position_dependent = True
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


class SpringTerm(Term):
    """Identification of a spring: ``k`` on the position, ``−k·x0`` on the constant.

    Declared bounds: on a rotary axis a spring acts within a revolution (a torsion
    spring, a cable), so a run that turns more than one cannot show one; and the rest
    position ``x0`` lies within the travel seen, widened by that travel on each side —
    farther out, the fitted force is a constant with a slight slope over the stroke,
    not a spring the run identifies (an offset by another name).
    """

    name = 'spring'
    effect = Spring
    force_scaled = (('spring', 'k'),)

    def applicable(self, s: Summary) -> str | None:
        """Refuse a rotary run over more than a revolution."""
        if s.rotary and s.travel > 2.0 * math.pi:
            return 'a spring acts within a revolution; these runs turn more than one'
        return super().applicable(s)

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return the ``k`` and constant columns."""
        return [Column('k', ('position',), lambda p: p.position),
                constant_column(ctx, 'c')]

    def admissible(self, values: Mapping, eta: Mapping, s: Summary) -> str | None:
        """Refuse a rest position far outside the travel seen."""
        k = float(values.get((self.name, 'k'), 0.0))
        c = values.get((self.name, 'c'))
        if c is None or k == 0.0:
            return None
        x0 = -float(c) / k
        lo, hi = s.span
        w = hi - lo
        if not lo - w <= x0 <= hi + w:
            return f'rest position {x0:.4g} far outside the travel [{lo:.4g}, {hi:.4g}]'
        return None

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted spring (``x0`` 0 when another term owns the constant)."""
        k = float(values.get((self.name, 'k'), 0.0))
        c = values.get((self.name, 'c'))
        x0 = -float(c) / k if c is not None and k != 0.0 else 0.0
        x0 = float(np.clip(x0, -1e3, 1e3)) if np.isfinite(x0) else 0.0
        return [Spring(k=k, x0=x0)]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return ``k`` and the constant ``−k·x0``."""
        e = model.get(self.name)
        return {'k': e.k, 'c': -e.k * e.x0}, {}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``k`` [N/m] and, when the spring owns the constant, ``x0`` [m]."""
        def k(v: Mapping) -> float:
            return float(v.get(('spring', 'k'), 0.0))

        def x0(v: Mapping) -> float:
            kk = k(v)
            return -float(v.get(('spring', 'c'), 0.0)) / kk if kk else 0.0
        out = {('spring', 'k'): k}
        if 'offset' not in ctx.present:
            out[('spring', 'x0')] = x0
        return out


TERM = SpringTerm()
