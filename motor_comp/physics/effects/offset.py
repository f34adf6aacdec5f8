"""Constant force offset ``F = f0`` [N] (gravity on an inclined axis, cable drag, bias)."""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np

from motor_comp.errors import check_finite
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.identification import Column, Context, Shape, Term


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


def constant_column(ctx: Context, label: str, scale: float = 1.0) -> Column:
    """Return the constant force while the axis moves, a column several terms share.

    With stuck samples carrying the drive force (``ctx.sticks``) a constant force's
    column is 0 on them too, so an offset and a Coulomb asymmetry stay the same column
    at a turn, as they are physically (``../shared/IDENTIFICATION.md`` §1).
    """
    if ctx.sticks:
        return Column(label, ('not_stuck', scale), lambda p: scale * (1.0 - p.stuck),
                      basis='constant')
    return Column(label, ('ones', scale), lambda p: np.full(len(p.v), scale),
                  basis='constant')


class OffsetTerm(Term):
    """Identification of a constant force ``f0``: the constant column (needs both ways)."""

    name = 'offset'
    #: in a residual's scan: a force of one sign, the same everywhere
    shape = Shape(None, odd=False)
    effect = Offset
    both_directions = True
    force_scaled = (('offset', 'f0'),)

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return the ``f0`` column."""
        return [constant_column(ctx, 'f0')]

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted offset."""
        return [Offset(f0=float(values.get((self.name, 'f0'), 0.0)))]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return ``f0``."""
        return {'f0': model.get(self.name).f0}, {}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``f0`` [N]."""
        return {('offset', 'f0'): lambda v: float(v.get(('offset', 'f0'), 0.0))}


TERM = OffsetTerm()
