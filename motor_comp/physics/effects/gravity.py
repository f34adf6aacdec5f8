"""Gravity torque of an unbalanced load on a rotary axis ``τ = mgl·sin(q − q0)`` [N·m].

DESIGN.md §3/§6 (issue 11 item 4): a load of mass ``m`` whose centre of mass sits at a
distance ``l`` from a horizontal joint axis.  ``q0`` [rad] is the joint angle where the
load hangs straight down (the stable equilibrium); the torque, subtracted like every
effect force (``J·q̈ = τ_in − Σ τ_k``), pulls the joint back towards ``q0``.  Rotary axes
only: on a linear axis (vertical or inclined) gravity is a constant and belongs in
``offset``.  The law is linear in ``(mgl·cos q0, −mgl·sin q0)`` on the columns
``(sin q, cos q)``, which is how an inverse-dynamic-model identification estimates it.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.errors import check_finite
from motor_comp.physics.effects.base import AxisKind, Effect
from motor_comp.physics.effects.identification import Column, Context, Term


@njit(cache=True, inline='always', error_model='numpy')
def gravity_torque(q, mgl, q0):
    """Gravity torque [N·m] at joint angle ``q`` [rad]: ``mgl·sin(q − q0)``.

    Parameters
    ----------
    q : float or ndarray
        Joint angle [rad].
    mgl : float
        Unbalance ``m·g·l`` [N·m] (load mass × g × distance of its centre of mass).
    q0 : float
        Angle [rad] where the load hangs straight down.
    """
    return mgl * np.sin(q - q0)


@dataclasses.dataclass(frozen=True)
class Gravity(Effect):
    """Unbalanced load on a rotary joint (rotary axes only).

    Parameters
    ----------
    mgl : float
        Gravity torque amplitude ``m·g·l`` [N·m] (finite; a negative value is the same
        load with ``q0`` shifted by π — kept as given, no normalisation).
    q0 : float
        Joint angle [rad] where the load hangs straight down.
    """

    name = 'gravity'
    position_dependent = True
    title = 'gravity (unbalanced load)'
    axes = frozenset({AxisKind.ROTARY})
    mgl: float = 0.0
    q0: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'mgl', check_finite('gravity.mgl [N·m]', self.mgl))
        object.__setattr__(self, 'q0', check_finite('gravity.q0 [rad]', self.q0))

    def force(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Torque [N·m] at joint angles ``x`` [rad]."""
        return gravity_torque(np.asarray(x, dtype=float), self.mgl, self.q0)

    def regressors(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Columns ``[sin q, cos q]``; coefficients ``[mgl·cos q0, −mgl·sin q0]``."""
        x = np.asarray(x, dtype=float)
        return np.stack([np.sin(x), np.cos(x)], axis=1)

    @staticmethod
    def from_coefficients(a: float, b: float) -> 'Gravity':
        """Gravity from the regressor coefficients ``a = mgl·cos q0``, ``b = −mgl·sin q0``.

        Returns ``mgl = hypot(a, b) >= 0`` and ``q0 = atan2(−b, a)`` in (−π, π].
        """
        return Gravity(mgl=float(np.hypot(a, b)), q0=float(np.arctan2(-b, a)))


class GravityTerm(Term):
    """Identify gravity: ``A = mgl·cos q0`` on ``sin q``, ``B = −mgl·sin q0`` on ``cos q``."""

    name = 'gravity'
    effect = Gravity
    force_scaled = (('gravity', 'mgl'),)

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return the ``A`` and ``B`` columns."""
        return [Column('A', ('sinq',), lambda p: np.sin(p.x)),
                Column('B', ('cosq',), lambda p: np.cos(p.x))]

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted gravity torque."""
        a = float(values.get((self.name, 'A'), 0.0))
        b = float(values.get((self.name, 'B'), 0.0))
        return [Gravity(mgl=math.hypot(a, b), q0=math.atan2(-b, a))]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return ``A`` and ``B``."""
        e = model.get(self.name)
        return {'A': e.mgl * math.cos(e.q0), 'B': -e.mgl * math.sin(e.q0)}, {}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``mgl`` [N·m] and ``q0`` [rad]."""
        def g(v: Mapping, k: str) -> float:
            return float(v.get(('gravity', k), 0.0))
        return {('gravity', 'mgl'): lambda v: math.hypot(g(v, 'A'), g(v, 'B')),
                ('gravity', 'q0'): lambda v: math.atan2(-g(v, 'B'), g(v, 'A'))}


TERM = GravityTerm()
