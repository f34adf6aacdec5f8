"""Load-dependent dry friction: the level grows with the drive force, ``fc + mu·|F_in|``.

In a ball-screw, a gear mesh or a preloaded guideway the normal force in the sliding
contacts grows with the force the drive transmits, and so does the dry friction: a
screw or gear train of efficiency ``η`` loses about ``(1 − η)·|F_in|`` of the drive
force ``F_in``, i.e. ``mu = 1 − η`` [-] (DESIGN.md §6, issue 23).  The same load-dependent
Coulomb term — dry friction linear in the absolute transmitted force — is the one
Hamon, Gautier & Garrec identify on robot joints by inverse-dynamic-model least squares
(IEEE/RSJ IROS 2010, dry friction depending on load and velocity); Olsson et al. 1998
(Eur. J. Control 4(3)) recall the classical origin, friction proportional to the normal
load.

The law: the dry-friction level (Coulomb and, with ``stribeck``, the break-away level)
rises by ``mu·|F_in|`` [N], acting against the motion,

    ``F = [fc + mu·|F_in| + (fs − fc)·e^{−|ẋ/vs|^δ}]·sgn(ẋ)``,

with ``F_in = input_gain·(u − back_emf·ẋ) − damping·ẋ`` the model's drive force
(:meth:`AxisModel.input_force`; the delayed command when the model has a ``delay``).  At
rest the Karnopp band widens the same way, ``|F_net| <= fs + mu·|F_in|``: a stuck screw
under a large drive force holds more.  ``0 <= mu < 1``: with ``mu >= 1`` the friction
outgrows any drive force (driving alone, the axis breaks away once
``|F_in|·(1 − mu) > fs``) and the inverse dynamics (:func:`load_friction_drive_force`)
has no solution.  A model with ``load_friction`` needs ``coulomb`` (checked by
:class:`~motor_comp.physics.axis.AxisModel`).

Units: mu [-], forces [N]; on a rotary axis torques [N·m].
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.errors import ParameterError, check_nonnegative
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.identification import Column, Context, Shape, Term


@njit(cache=True, inline='always', error_model='numpy')
def load_friction_level(f_in, mu):
    """Rise of the dry-friction level ``mu·|F_in|`` [N] under the drive force ``f_in`` [N].

    Parameters
    ----------
    f_in : float or ndarray
        Drive force ``input_gain·(u − back_emf·ẋ) − damping·ẋ`` [N].
    mu : float
        Load-friction coefficient [-], ``0 <= mu < 1``.
    """
    return mu * np.abs(f_in)


@njit(cache=True, error_model='numpy')
def load_friction_force(v, f_in, mu):
    """Extra friction force ``mu·|F_in|·sgn(v)`` [N] at velocity ``v`` [m/s].

    Zero at rest (holding the axis there is the integrator's break-away band).
    """
    return load_friction_level(f_in, mu) * np.sign(v)


@njit(cache=True, error_model='numpy')
def load_friction_drive_force(f_other, d, level, mu):
    """Drive force ``F_in`` [N] that moves the axis in direction ``d`` against load friction.

    Solves ``F_in = f_other + d·(level + mu·|F_in|)`` — the inverse dynamics with the
    dry friction of the level ``level`` [N] (``fc`` plus whatever else raises it, >= 0)
    raised by the load term — for ``F_in``, with ``f_other`` [N] the rest of the force
    balance (inertia ``M·ẍ`` and every other effect force).  With ``g = f_other + d·level``
    the unique solution for ``0 <= mu < 1`` is ``F_in = g/(1 − d·mu·sgn(g))``: the drive
    pays ``mu`` on its own force when it pushes along the motion and less friction when
    it brakes.  ``d = 0`` (at rest) gives ``f_other``.

    Parameters
    ----------
    f_other : float
        Inertial and other effect forces [N].
    d : float
        Direction of motion, −1, 0 or +1.
    level : float
        Dry-friction level without the load term [N].
    mu : float
        Load-friction coefficient [-], ``0 <= mu < 1``.
    """
    g = f_other + d * level
    return g / (1.0 - d * mu * np.sign(g))


#: the coefficient must stay below this: at 1 the friction equals the drive force
MU_LIMIT = 1.0


@dataclasses.dataclass(frozen=True)
class LoadFriction(Effect):
    """Dry friction growing with the transmitted drive force (screw/gear efficiency).

    Parameters
    ----------
    mu : float
        Load-friction coefficient [-], ``0 <= mu < 1`` (``1 − η`` for a drive of
        efficiency ``η``).
    """

    name = 'load_friction'
    title = 'load-dependent friction'
    mu: float = 0.0

    def __post_init__(self) -> None:
        mu = check_nonnegative('load_friction.mu [-]', self.mu)
        if mu >= MU_LIMIT:
            raise ParameterError(f'load_friction.mu [-] must be < 1 (at 1 the friction '
                                 f'equals the drive force), got {mu:g}')
        object.__setattr__(self, 'mu', mu)

    def level(self, f_in: np.ndarray) -> np.ndarray:
        """Rise of the dry-friction level ``mu·|F_in|`` [N] under drive forces ``f_in`` [N]."""
        return load_friction_level(np.asarray(f_in, dtype=float), self.mu)

    def force(self, x: np.ndarray, v: np.ndarray, *, f_in: np.ndarray) -> np.ndarray:
        """Extra friction ``mu·|F_in|·sgn(v)`` [N] at velocities ``v`` [m/s].

        Parameters
        ----------
        x : ndarray
            Positions [m] (unused: the law does not depend on them).
        v : ndarray
            Velocities [m/s].
        f_in : ndarray
            Drive force at each sample [N] (:meth:`AxisModel.input_force` of the
            applied, delayed command).
        """
        v = np.asarray(v, dtype=float)
        f_in = np.broadcast_to(np.asarray(f_in, dtype=float), v.shape)
        return load_friction_force(np.ascontiguousarray(v), np.ascontiguousarray(f_in),
                                   self.mu)

    def regressors(self, x: np.ndarray, v: np.ndarray, *, f_in: np.ndarray) -> np.ndarray:
        """Column ``|F_in|·sgn(v)``; coefficient ``mu`` [-]."""
        v = np.asarray(v, dtype=float).ravel()
        return (np.abs(np.asarray(f_in, dtype=float).ravel()) * np.sign(v))[:, None]


#: the largest mu the identification fits (see :class:`LoadFrictionTerm`)
MU_FIT_LIMIT = 0.5


class LoadFrictionTerm(Term):
    """Identification of load-dependent friction: ``mu`` on ``|F_in|·sgn ẋ``.

    The column is the drive force the run transmits (the delayed command, after the
    back-EMF and damping), signed like the Coulomb column (the turn model's shares).
    ``0 ≤ mu ≤ 0.5`` inside the estimator: a drive that loses more than half its force
    to friction is self-locking, and a fit that wants more is making the friction carry
    the drive force (at ``mu → 1`` any force the model lacks is "friction").  While the
    drive pushes along the motion the law copies a larger mass, Coulomb and viscous
    level (``1/(1 − mu)``); only samples where the drive brakes the motion tell them
    apart, which the columns judge.
    """

    name = 'load_friction'
    #: in a residual's scan: a friction growing with the drive force
    shape = Shape('force', odd=True, trend=1)
    effect = LoadFriction
    requires = ('coulomb',)
    dry_friction = True
    force_scaled = ()

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return the ``mu`` column."""
        return [Column('mu', ('load_friction',), lambda p: np.abs(p.f_in) * (p.fwd - p.bwd),
                       lo=0.0, hi=MU_FIT_LIMIT, uses_input=True)]

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted load friction."""
        mu = float(values.get((self.name, 'mu'), 0.0))
        return [LoadFriction(mu=min(max(mu, 0.0), MU_FIT_LIMIT))]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return ``mu``."""
        return {'mu': model.get(self.name).mu}, {}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``mu`` [-]."""
        return {(self.name, 'mu'): lambda v: float(v.get((self.name, 'mu'), 0.0))}


TERM = LoadFrictionTerm()
