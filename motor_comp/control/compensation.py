"""Model-based compensation: a model's inverse dynamics as feedforward at the reference.

A fitted model file (DESIGN.md §6) says which forces the axis fights.  The compensation
adds them to the command, evaluated at the **reference** state — position ``r``,
velocity ``ṙ``, acceleration ``r̈``, and for the GMS pre-sliding elements a state
driven by the reference displacement, as the friction feedforward of Chiew et al.
(Fig. 9) is — so measurement noise never enters the feedforward.

Terms (:class:`CompensationTerms`, DESIGN.md §4):

* ``full`` (default): the model's whole inverse dynamics, the force balance of
  DESIGN.md §3 solved for the drive force at the reference,
  ``F = M·r̈ + damping·ṙ + Σ F_k(r, ṙ, z_ref)``, sent as the command that produces it
  through the model's own drive law ``F_in = input_gain·(u − back_emf·ẋ) − damping·ẋ``
  (:meth:`~motor_comp.physics.axis.AxisModel.input_force`):
  ``u_ff = F/input_gain + back_emf·ṙ`` — volts for a voltage drive; a current or
  force drive has ``back_emf = 0`` and the same formula gives amperes or newtons.  On a
  PID axis the inertia and the back-EMF, not the friction, make most of the tracking
  error (``bench/reproduce_papers.py``: a nominal inverse model cuts the PMLM's max
  error to 0.18× of PID's);
* ``effects``: only ``Σ F_k`` (the effects a model file lists), the behaviour before.

The reference state is taken where the command acts: a command computed at ``t_k`` is
held over ``[t_k, t_k + T)`` and reaches the axis after the model's dead time ``τ``
(``delay``), so the state is extrapolated by ``L = T/2 + τ`` along the reference,
``r + L·ṙ + ½L²·r̈``, ``ṙ + L·r̈`` (a Taylor step: the reference's jerk is not sent).
This is the "reference advanced by τ" that a dead time needs (a feedforward cannot be
delayed less than the plant delays it, only sent earlier); the feedback still sees the
delay.  Measured with the feedforward alone (no feedback) on the PMLM's rigid body,
20 mm at 1 Hz: 2.5 µm peak error with the T/2 lead, 64 µm without.  (In closed loop
under the PID the lead-free feedforward tracks the p2p task slightly better, 2.3 vs
3.3 µm RMS with the true model: the PID's derivative compares ``ṙ`` with a backward
difference half a period late, an extra ``Kd·T/2·r̈`` that partly stands in for the
missing lead — the feedback's business, not the model's.)

**Terms the controller law already carries are never counted twice** (the controller
packs them into ``K_CARRY_*`` from its mode and friction feedforward, see
:meth:`motor_comp.control.controller.Controller.set_compensation`); the compensation then
adds the model's force *minus the model's own value of each carried term*:

=====================  ==================================  ==============================
controller             carries (its own estimate / model)  the compensation adds
=====================  ==================================  ==============================
PID, N-PID, ff none    nothing                             everything
ff ``static``          static curve ``s(ṙ) + fv·ṙ``        GMS − ``s(ṙ)`` (pre-sliding
                                                           only), position terms, rigid
ff ``gms``             GMS elements (dry friction)         viscous, position terms, rigid
ff ``static+gms``      GMS elements + ``fv·ṙ``             position terms, rigid body
adaptive sliding       ``θ̂1·ẍ_r`` and ``θ̂2·ẋ`` (mass,    dry friction − ``fc·sgn ṙ``
(Tan eq. 15)           back-EMF and damping), ``fc·sgn    (Stribeck excess, pre-sliding),
                       ẋ_d``, ``fv·ẋ_d``, ripple          ripple harmonics ≥ 2 (all of
                       harmonic 1 at its own ω            them when the periods differ),
                                                           offset, spring, gravity,
                                                           asymmetry
=====================  ==================================  ==============================

(The adaptive law's robust term ``k̂·sat(s/φ)`` is a switching bound on the remainder,
not an estimate of the Stribeck force, so the Stribeck excess stays in the
compensation; it only leaves the robust term less to cover.  Its first ripple harmonic
is its own only when the model's period equals the law's within
:data:`RIPPLE_PERIOD_MATCH`; otherwise the law's regressor cannot represent the model's
ripple.  In every row, the rise of the dry level by load- and position-dependent
friction stays in the compensation: the carried terms are at the base level, below.)

**Load- and position-dependent friction** (``load_friction``, ``position_friction``;
issue 23) raise the model's dry-friction level by ``Δ = dfc(r) + mu·|F_in|`` [N], as
the plant kernel does (:func:`~motor_comp.physics.kernel.level_shift`): the Coulomb and
the break-away level alike, ``s(ṙ) → sgn(ṙ)·[fc + Δ + (fs − fc)·e^{−|ṙ/vs|^δ}]``.  With
``presliding`` the elements carry the level, and the shift enters where the plant puts
it: in the curve ``s(v)`` the elements slip at and relax towards (``α_i·s``), **shifted,
not scaled** — the element forces are never multiplied by ``(level + Δ)/level``.  Why:
while an element sticks it is a spring ``k_i·z_i`` whose stiffness no friction level
changes, so scaling the element forces would also scale the pre-sliding stiffness (and
the hysteresis after every reversal) by the level ratio, a law the plant does not
have; shifting the curve leaves the sticking springs alone and moves only the slip
limit and the sliding level, exactly as
:func:`~motor_comp.physics.effects.presliding.gms_trajectory_shifted` and the kernel do,
so in steady sliding the elements converge to ``s(v) + Δ·sgn v``.

``F_in`` is the model's drive force at the reference, its inverse dynamics
``M·r̈ + Σ F_k`` (every effect, inertia included) — with ``full`` and ``effects`` terms
alike, and whatever the controller carries: the screw's friction sees the force the
drive transmits, whichever part of the command (feedback, the law's own estimates or
this feedforward) produces it.  ``F_in`` appears on both sides (the friction grows with
the force that must overcome it), so it is solved: for the static curve in closed form
by :func:`~motor_comp.physics.effects.load_friction.load_friction_drive_force` (the
effect module's inverse); with GMS elements, whose force depends on the level through
the slip law's relaxation ``e^{−C·dt/|s(v)|}`` (no closed form), by a bracketing root
search on trial copies of the element state (:func:`_gms_drive_force`), started from
that closed form and converged to rounding.  The sum of the two shifts is ``Δ``; the
elements are then stepped once at that level.  A controller that carries dry friction
(its friction feedforward, the adaptive law's ``fc·sgn ẋ_d``) knows no shift: the
compensation removes the model's value of the carried term at the *unshifted* level,
so ``Δ·sgn ṙ`` (with GMS: the shifted elements less a second set of the model's
elements at the unshifted level) stays in the feedforward.

One implementation of each law: the forces are the effect modules' own compiled laws —
sliding friction (Coulomb + Stribeck + viscous, and the GMS elements) through
:func:`~motor_comp.control.feedforward.friction_feedforward`, which calls
:func:`~motor_comp.physics.effects.stribeck.stribeck_curve` and
:func:`~motor_comp.physics.effects.presliding.gms_step`;
:func:`~motor_comp.physics.effects.asymmetry.asymmetry_force`,
:func:`~motor_comp.physics.effects.ripple.ripple_sum`,
:func:`~motor_comp.physics.effects.gravity.gravity_torque`,
:func:`~motor_comp.physics.effects.position_friction.spline_sum` (``dfc``),
:func:`~motor_comp.physics.effects.load_friction.load_friction_level` and
:func:`~motor_comp.physics.effects.load_friction.load_friction_drive_force`; the offset
and spring laws ``f0`` and ``k·(x − x0)`` are read exactly as the plant kernel reads
them.  The same compiled step runs in the in-process simulator and in
``controller_node`` (it is part of :func:`~motor_comp.control.controller.controller_step`).

Effects a force feedforward cannot cancel are reported with the reason
(:data:`NOT_COMPENSABLE`): ``backlash`` (a gap in position, not a force).  Every other
effect of the vocabulary is compensated (:data:`COMPENSABLE`).

A **position table** (``motor-comp export-table``) holds the position-dependent part
only — ripple/cogging, gravity, spring, offset — over one period (or revolution) when
the part is periodic; the controller interpolates it linearly (periodically wrapped, or
clamped to its ends).  A table has no mass: its terms are its positions' forces.
``position_friction`` is not in it (:data:`TABLE_LEFT_OUT`): its force ``dfc(x)·sgn ẋ``
acts against the motion, so it is not a function of position alone; a table adds its
force whichever way the axis moves, and a tabulated ``dfc(x)`` would cancel the tight
spot going one way and double it coming back.  The model compensation, which knows the
reference's direction, carries it.

Packed layout.  The compensation travels inside the controller's packed vectors so the
compiled step stays one function: parameters ``Q[qb:]`` (after the controller's own
``Q_SIZE`` entries) and state ``C[cb:]``; offsets ``K_*`` and ``CS_*`` below are
relative to those starts.
"""
from __future__ import annotations

import csv
import dataclasses
import enum
import io
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.control._jitcache import JIT_INLINE, JIT_OPTIONS
from motor_comp.control.feedforward import friction_feedforward
from motor_comp.errors import InputFileError, ModelFileError, ParameterError, check_positive
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects.asymmetry import asymmetry_force
from motor_comp.physics.effects.gravity import gravity_torque
from motor_comp.physics.effects.load_friction import (load_friction_drive_force,
                                                      load_friction_level)
from motor_comp.physics.effects.position_friction import MAX_KNOTS, spline_sum
from motor_comp.physics.effects.presliding import MAX_ELEMENTS, gms_step
from motor_comp.physics.effects.ripple import MAX_HARMONICS, ripple_sum
from motor_comp.physics.effects.stribeck import stribeck_curve, stribeck_level

#: effects a force feedforward cannot cancel, with the reason shown to the user
NOT_COMPENSABLE: dict[str, str] = {
    'backlash': 'a dead band is a gap in position between motor and load, not a force; '
                'a force feedforward cannot close it (it needs a position-domain inverse)',
}
#: effects the feedforward cancels (``delay`` by sending the feedforward τ earlier)
COMPENSABLE = ('coulomb', 'viscous', 'stribeck', 'presliding', 'ripple', 'offset',
               'spring', 'asymmetry', 'gravity', 'delay', 'load_friction',
               'position_friction')
#: the position-dependent effects a position table holds
POSITION_EFFECTS = ('ripple', 'gravity', 'spring', 'offset')
#: effects that depend on position but that a position table cannot hold, with the reason
TABLE_LEFT_OUT: dict[str, str] = {
    'position_friction': 'its force dfc(x)·sgn(v) acts against the motion, so it is not a '
                         'function of position alone (a table would cancel it one way and '
                         'double it the other); the model compensation carries it',
}
#: friction effects (the controller's own friction feedforward carries some of them)
FRICTION_EFFECTS = ('coulomb', 'viscous', 'stribeck', 'presliding', 'asymmetry',
                    'load_friction', 'position_friction')
#: trial evaluations of the GMS elements at most in each phase (bracketing, then
#: Illinois) of the solve of the load-dependent level (:func:`_gms_drive_force`)
LOAD_SOLVE_ITER = 60
#: the adaptive law's first ripple harmonic is the model's when the periods agree this
#: closely (relative): then over 50 periods of travel the phases part by < 0.16 rad
RIPPLE_PERIOD_MATCH = 5e-4


class CompensationKind(enum.IntEnum):
    """What the packed block holds (``K_KIND``)."""

    MODEL = 1
    TABLE = 2


class CompensationTerms(enum.Enum):
    """Which terms of a model the compensation sends (CLI ``--compensation-terms``).

    ``FULL``: the inverse dynamics ``M·r̈ + damping·ṙ + Σ F_k`` and the back-EMF;
    ``EFFECTS``: ``Σ F_k`` only.
    """

    FULL = 'full'
    EFFECTS = 'effects'

    @classmethod
    def parse(cls, value: 'str | CompensationTerms') -> 'CompensationTerms':
        """From ``full | effects`` (or an existing member)."""
        if isinstance(value, CompensationTerms):
            return value
        try:
            return cls(str(value))
        except ValueError:
            raise ParameterError(f'compensation terms must be one of '
                                 f'{", ".join(t.value for t in cls)}, got {value!r}') from None


class CarriedDry(enum.IntEnum):
    """Dry friction the controller law carries itself (``K_CARRY_DRY``)."""

    NONE = 0
    COULOMB = 1        # adaptive sliding: fc·sgn(ẋ_d)
    STATIC = 2         # friction feedforward static: the Stribeck curve s(ṙ)
    ALL = 3            # friction feedforward with the GMS elements


# ---- packed parameters, relative to the block start qb ---------------------------------
K_KIND, K_INVGAIN = 0, 1
K_FRIC, K_FC, K_FS, K_VS, K_DELTA, K_FV, K_DFC, K_DFV = 2, 3, 4, 5, 6, 7, 8, 9
K_GMS_N, K_GMS_C = 10, 11
K_GMS_ALPHA = 12
K_GMS_K = K_GMS_ALPHA + MAX_ELEMENTS
K_GMS_SIGMA = K_GMS_K + MAX_ELEMENTS      # GMS micro-damping [N·s/m]; K_GMS_C is C [N/s]
K_RIP_NH = K_GMS_SIGMA + MAX_ELEMENTS
K_RIP_PERIOD = K_RIP_NH + 1
K_RIP_A = K_RIP_PERIOD + 1
K_RIP_B = K_RIP_A + MAX_HARMONICS
K_F0 = K_RIP_B + MAX_HARMONICS
K_SPRING_K, K_SPRING_X0, K_GRAV_MGL, K_GRAV_Q0 = K_F0 + 1, K_F0 + 2, K_F0 + 3, K_F0 + 4
# rigid body and drive (full terms): mass [kg], damping [N·s/m], back-EMF [V·s/m]
K_FULL, K_MASS, K_DAMP, K_BEMF = K_F0 + 5, K_F0 + 6, K_F0 + 7, K_F0 + 8
K_TAU = K_F0 + 9                  # the model's dead time [s] (the reference is advanced)
# terms the controller carries (written by the controller from its mode/feedforward)
K_CARRY_DRY, K_CARRY_VISC, K_CARRY_RIGID, K_CARRY_RIP1 = (K_F0 + 10, K_F0 + 11,
                                                          K_F0 + 12, K_F0 + 13)
# load- and position-dependent friction (issue 23): mu [-]; knot count, knots [m],
# values [N] and spline slopes [N/m] of dfc (the plant kernel's P_LF_MU, P_PF_*)
K_LF_MU, K_PF_N = K_F0 + 14, K_F0 + 15
K_PF_X = K_PF_N + 1
K_PF_Y = K_PF_X + MAX_KNOTS
K_PF_M = K_PF_Y + MAX_KNOTS
K_MODEL_SIZE = K_PF_M + MAX_KNOTS
# table: n points, period (0 = not periodic), then n positions and n forces
K_TAB_N, K_TAB_PERIOD, K_TAB_X = 2, 3, 4

# ---- state, relative to the block start cb -----------------------------------------------
CS_F, CS_U = 0, 1                      # last force [N] and command [V] of the compensation
CS_STARTED, CS_RE = 2, 3               # evaluated once; last evaluated position [m]
CS_GMS_F = 4
CS_GMS_SLIP = CS_GMS_F + MAX_ELEMENTS
# with a level shift: the model's elements at the unshifted level (the value of what a
# GMS friction feedforward carries), and trial copies for the solve of the load level
CS_GMS_F0 = CS_GMS_SLIP + MAX_ELEMENTS
CS_GMS_SLIP0 = CS_GMS_F0 + MAX_ELEMENTS
CS_GMS_TF = CS_GMS_SLIP0 + MAX_ELEMENTS
CS_GMS_TS = CS_GMS_TF + MAX_ELEMENTS
CS_SIZE = CS_GMS_TS + MAX_ELEMENTS


@njit(**JIT_INLINE)
def _table_force(Q, qb, x):
    """Linear interpolation of the table force [N] at ``x`` (wrapped or clamped)."""
    n = int(Q[qb + K_TAB_N])
    ix = qb + K_TAB_X
    iff = ix + n
    period = Q[qb + K_TAB_PERIOD]
    x0 = Q[ix]
    if period > 0.0:
        x = x0 + (x - x0) - period * np.floor((x - x0) / period)
    if x <= x0:
        return Q[iff]
    if x >= Q[ix + n - 1]:
        if period > 0.0:   # between the last point and the first one a period later
            x1 = Q[ix + n - 1]
            w = (x - x1) / (x0 + period - x1)
            return (1.0 - w) * Q[iff + n - 1] + w * Q[iff]
        return Q[iff + n - 1]
    lo = 0
    hi = n - 1
    while hi - lo > 1:     # bisection: a table may have any (increasing) spacing
        mid = (lo + hi) // 2
        if Q[ix + mid] <= x:
            lo = mid
        else:
            hi = mid
    w = (x - Q[ix + lo]) / (Q[ix + hi] - Q[ix + lo])
    return (1.0 - w) * Q[iff + lo] + w * Q[iff + hi]


@njit(**JIT_INLINE)
def _gms_trial(Q, qb, C, cb, rv, dx, dt, level):
    """GMS force [N] of the next step with the dry level raised by ``level`` [N].

    The element law :func:`~motor_comp.physics.effects.presliding.gms_step` applied to
    copies of the element state (``CS_GMS_TF``/``CS_GMS_TS``), so the elements are not
    stepped: the trial of one level in the solve of :func:`_load_level`.  The same
    arithmetic as the real step in :func:`friction_feedforward` (``s(ṙ)`` with
    ``fc + level``, ``fs + level``), so the solved force is the stepped one.
    """
    n = int(Q[qb + K_GMS_N])
    for i in range(n):
        C[cb + CS_GMS_TF + i] = C[cb + CS_GMS_F + i]
        C[cb + CS_GMS_TS + i] = C[cb + CS_GMS_SLIP + i]
    s_v = stribeck_curve(rv, Q[qb + K_FC] + level, Q[qb + K_FS] + level, Q[qb + K_VS],
                         Q[qb + K_DELTA])
    return gms_step(C, cb + CS_GMS_TF, C, cb + CS_GMS_TS, Q, qb + K_GMS_ALPHA, Q,
                    qb + K_GMS_K, Q, qb + K_GMS_SIGMA, n, Q[qb + K_GMS_C], dt, dx, rv, s_v)


@njit(**JIT_INLINE)
def _load_residual(Q, qb, C, cb, rv, dx, dt, f_rest, shift, mu, f):
    """Residual ``φ(F) = F − f_rest − D(shift + mu·|F|)`` [N] of a trial drive force ``F``."""
    return f - f_rest - _gms_trial(Q, qb, C, cb, rv, dx, dt, shift + load_friction_level(f, mu))


@njit(**JIT_OPTIONS)
def _gms_drive_force(Q, qb, C, cb, rv, dx, dt, f_rest, shift, f0):
    """Drive force [N] that the GMS elements at the load-raised level balance.

    The root of ``φ(F) = F − f_rest − D(shift + mu·|F|)`` (:func:`_load_residual`), ``D``
    the elements' force after the step at that level.  ``D`` stays bounded however high
    the level (a slipping element moves towards ``α_i·s`` by at most
    ``(α_i + |F_i|/|s|)·C·dt``, a sticking one never beyond its spring force
    ``F_i + k_i·Δx``), so ``φ`` changes sign: from ``f0`` [N] (the sliding closed form)
    the search steps the way ``φ`` says, doubling
    the step until the sign changes, then narrows the bracket by the Illinois variant of
    regula falsi to rounding.  ``φ`` need not be monotone — the slip law relaxes at the
    rate ``C/|s(v)|``, so a raised level slows its own decay — and then the root found
    is the first sign change from the sliding value.  Not inlined: it runs only for a
    model with both GMS elements and ``load_friction``.
    """
    mu = Q[qb + K_LF_MU]
    fa = f0
    pa = _load_residual(Q, qb, C, cb, rv, dx, dt, f_rest, shift, mu, fa)
    tol = 2e-15 * (abs(f0) + abs(f_rest) + abs(shift) + Q[qb + K_FS])
    if abs(pa) <= tol:
        return fa
    step = abs(pa)
    fb = fa - pa                     # a fixed-point step: D at the level of fa
    pb = _load_residual(Q, qb, C, cb, rv, dx, dt, f_rest, shift, mu, fb)
    for _ in range(LOAD_SOLVE_ITER):  # same sign: φ ≥ F − f_rest − max|D| grows beyond
        if (pa < 0.0) != (pb < 0.0) or pb == 0.0:
            break
        fa, pa = fb, pb
        step *= 2.0
        fb = fa + step if pa < 0.0 else fa - step
        pb = _load_residual(Q, qb, C, cb, rv, dx, dt, f_rest, shift, mu, fb)
    best_f, best_p = (fb, pb) if abs(pb) <= abs(pa) else (fa, pa)
    side = 0
    for _ in range(LOAD_SOLVE_ITER):
        if abs(best_p) <= tol or pa == pb:
            break
        fc_ = (fa * pb - fb * pa) / (pb - pa)
        if not (min(fa, fb) < fc_ < max(fa, fb)):   # the bracket is down to rounding
            break
        pc = _load_residual(Q, qb, C, cb, rv, dx, dt, f_rest, shift, mu, fc_)
        if abs(pc) < abs(best_p):
            best_f, best_p = fc_, pc
        if (pc < 0.0) == (pb < 0.0):   # c replaces b; twice in a row: halve φ(a)
            if side == -1:
                pa *= 0.5
            side = -1
        else:                          # the sign changed between b and c: a ← b
            fa, pa = fb, pb
            side = 1
        fb, pb = fc_, pc
    return best_f


@njit(**JIT_INLINE)
def _load_level(Q, qb, C, cb, rv, dx, dt, f_rest, shift):
    """Load-friction level ``mu·|F_in|`` [N] of the model's drive force at the reference.

    ``F_in`` solves the inverse dynamics with the dry friction ``D`` at the level raised
    by ``shift + mu·|F_in|`` (``shift`` [N] the position-dependent part ``dfc(r)``):
    ``F_in = f_rest + D(shift + mu·|F_in|)``, ``f_rest`` [N] the rest of it (inertia,
    viscous and position terms, asymmetry).  Static curve:
    ``D = sgn(ṙ)·(s-level + shift + mu·|F_in|)``, solved in closed form by
    :func:`load_friction_drive_force`; GMS elements: :func:`_gms_drive_force`, from that
    closed form.
    """
    mu = Q[qb + K_LF_MU]
    fc, fs, vs, delta = Q[qb + K_FC], Q[qb + K_FS], Q[qb + K_VS], Q[qb + K_DELTA]
    level = stribeck_level(abs(rv), fc, fs, 1.0 / vs, delta) + shift
    f_in = load_friction_drive_force(f_rest, np.sign(rv), level, mu)
    if int(Q[qb + K_GMS_N]) > 0:
        f_in = _gms_drive_force(Q, qb, C, cb, rv, dx, dt, f_rest, shift, f_in)
    return load_friction_level(f_in, mu)


@njit(**JIT_INLINE)
def _dry_friction(Q, qb, C, cb, r, rv, dx, dt, f_rest):
    """Dry and viscous friction [N] the compensation adds, less what the law carries.

    The model's dry friction is its GMS elements (when it has ``presliding``: they carry
    the Coulomb + Stribeck level and the pre-sliding hysteresis) or its Stribeck curve
    ``s(ṙ)``; the viscous part is ``fv·ṙ``.  ``K_CARRY_DRY`` / ``K_CARRY_VISC`` remove
    the model's own value of the terms the controller carries (module table).  The GMS
    elements are stepped every call, carried or not, so a switch is bumpless.

    Load- and position-dependent friction raise the dry level ``fc`` and ``fs`` by
    ``Δ = dfc(r) + mu·|F_in|`` before :func:`friction_feedforward` is called (module
    docstring): ``dfc`` from the model's spline at the evaluated position ``r``,
    ``mu·|F_in|`` from :func:`_load_level` with ``f_rest`` [N], the model's drive force
    less its dry friction.  The carried terms are removed at the unshifted level (a
    second set of elements, ``CS_GMS_F0``, when the model has GMS), so the shift stays.
    """
    mode = int(Q[qb + K_FRIC])
    if mode == 0:
        return 0.0
    fc, fs, vs, delta, fv = (Q[qb + K_FC], Q[qb + K_FS], Q[qb + K_VS], Q[qb + K_DELTA],
                             Q[qb + K_FV])
    n = int(Q[qb + K_GMS_N])
    npf = int(Q[qb + K_PF_N])
    shifted = npf > 0 or Q[qb + K_LF_MU] != 0.0
    shift = 0.0
    if npf > 0:
        shift = spline_sum(r, Q, qb + K_PF_X, Q, qb + K_PF_Y, Q, qb + K_PF_M, npf)
    if Q[qb + K_LF_MU] != 0.0:
        shift += _load_level(Q, qb, C, cb, rv, dx, dt, f_rest, shift)
    _, f_static, f_el = friction_feedforward(
        mode, rv, dx, dt, fc + shift, fs + shift, vs, delta, fv, C, cb + CS_GMS_F,
        cb + CS_GMS_SLIP, Q, qb + K_GMS_ALPHA, qb + K_GMS_K, qb + K_GMS_SIGMA, n,
        Q[qb + K_GMS_C])
    curve = f_static - fv * rv            # s(ṙ), the static curve without viscous
    dry = f_el if n > 0 else curve
    # the model's value of what a controller carries: at the level without the shift
    curve0, f_el0 = curve, f_el
    if shifted:
        curve0 = stribeck_curve(rv, fc, fs, vs, delta)
        f_el0 = curve0
        if n > 0:
            f_el0 = gms_step(C, cb + CS_GMS_F0, C, cb + CS_GMS_SLIP0, Q, qb + K_GMS_ALPHA,
                             Q, qb + K_GMS_K, Q, qb + K_GMS_SIGMA, n, Q[qb + K_GMS_C], dt,
                             dx, rv, curve0)
    carried = int(Q[qb + K_CARRY_DRY])
    if carried == 1:
        dry -= fc * np.sign(rv)
    elif carried == 2:
        dry -= curve0
    elif carried == 3:
        dry -= f_el0 if n > 0 else curve0
    if Q[qb + K_CARRY_VISC] == 0.0:
        dry += fv * rv
    return dry


@njit(**JIT_INLINE)
def compensation_force(Q, qb, C, cb, r, rv, ra, dt):
    """Compensation force [N] at the reference state; its state in ``C`` stepped.

    Parameters
    ----------
    Q, qb : ndarray, int
        Packed parameters and the start of the compensation block.
    C, cb : ndarray, int
        Controller state and the start of the compensation state (updated in place).
    r, rv, ra : float
        Reference position [m] (or [rad]), velocity [m/s] and acceleration [m/s²] at
        the control instant; the model block evaluates them ``T/2 + τ`` later
        (module docstring), the GMS elements driven by the displacement of that state.
    dt : float
        Control period T [s].

    Returns
    -------
    (force [N], velocity of the evaluated state [m/s]) — the velocity lets
    :func:`compensation_command` add the back-EMF at the same state.
    """
    kind = int(Q[qb + K_KIND])
    if kind == 2:   # a table knows no dead time: half the hold period ahead
        return _table_force(Q, qb, r + 0.5 * dt * rv), rv
    lead = 0.5 * dt + Q[qb + K_TAU]
    r = r + lead * (rv + 0.5 * lead * ra)
    rv = rv + lead * ra
    dx = r - C[cb + CS_RE] if C[cb + CS_STARTED] > 0.0 else 0.0
    C[cb + CS_STARTED] = 1.0
    C[cb + CS_RE] = r
    # the model's forces that do not depend on the dry level, all of them (the load
    # level needs the whole drive force); what the controller carries is removed below
    f_pos = 0.0
    if Q[qb + K_DFC] != 0.0 or Q[qb + K_DFV] != 0.0:
        f_pos += asymmetry_force(rv, Q[qb + K_DFC], Q[qb + K_DFV])
    carried_rip = 0.0
    nh = int(Q[qb + K_RIP_NH])
    if nh > 0:
        f_pos += ripple_sum(r, Q[qb + K_RIP_PERIOD], Q, qb + K_RIP_A, Q, qb + K_RIP_B, nh)
        if Q[qb + K_CARRY_RIP1] != 0.0:   # the adaptive law's own first harmonic
            th = 2.0 * np.pi / Q[qb + K_RIP_PERIOD] * r
            carried_rip = Q[qb + K_RIP_A] * np.sin(th) + Q[qb + K_RIP_B] * np.cos(th)
    f_pos += Q[qb + K_F0] + Q[qb + K_SPRING_K] * (r - Q[qb + K_SPRING_X0])
    if Q[qb + K_GRAV_MGL] != 0.0:
        f_pos += gravity_torque(r, Q[qb + K_GRAV_MGL], Q[qb + K_GRAV_Q0])
    rigid = Q[qb + K_MASS] * ra
    f = _dry_friction(Q, qb, C, cb, r, rv, dx, dt, rigid + Q[qb + K_FV] * rv + f_pos)
    f += f_pos - carried_rip
    if Q[qb + K_FULL] != 0.0 and Q[qb + K_CARRY_RIGID] == 0.0:
        f += rigid + Q[qb + K_DAMP] * rv
    return f, rv


@njit(**JIT_INLINE)
def compensation_command(Q, qb, C, cb, r, rv, ra, dt):
    """Compensation command [V]: the force through the model's drive law.

    ``u = F/input_gain + back_emf·ṙ`` (the back-EMF with the full terms, unless the
    controller carries it).  Zero when no compensation block follows the controller's
    parameters (``Q.shape[0] <= qb``).  The force and the command are kept in
    ``C[cb + CS_F]``, ``C[cb + CS_U]`` for drivers and diagnostics.
    """
    if Q.shape[0] <= qb:
        return 0.0
    f, ve = compensation_force(Q, qb, C, cb, r, rv, ra, dt)
    u = f * Q[qb + K_INVGAIN]
    if int(Q[qb + K_KIND]) == 1 and Q[qb + K_FULL] != 0.0 and Q[qb + K_CARRY_RIGID] == 0.0:
        u += Q[qb + K_BEMF] * ve
    C[cb + CS_F] = f
    C[cb + CS_U] = u
    return u


@njit(**JIT_OPTIONS)
def _force_along(Q, C, r, rv, ra, dt, out_f, out_u):
    """Compensation force and command along a reference (fresh state at the first sample)."""
    for k in range(r.shape[0]):
        out_u[k] = compensation_command(Q, 0, C, 0, r[k], rv[k], ra[k], dt)
        out_f[k] = C[CS_F]


@dataclasses.dataclass(frozen=True)
class Carried:
    """Terms of a model the controller law carries itself (module table).

    Attributes
    ----------
    dry : CarriedDry
        Dry friction the law carries.
    viscous : bool
        Whether it carries ``fv·ṙ``.
    rigid : bool
        Whether it carries the inertia, back-EMF and damping (the adaptive law).
    ripple_first : bool
        Whether it carries the model's first ripple harmonic.
    """

    dry: CarriedDry = CarriedDry.NONE
    viscous: bool = False
    rigid: bool = False
    ripple_first: bool = False

    def pack_into(self, K: np.ndarray, qb: int = 0) -> None:
        """Write the ``K_CARRY_*`` entries of a model block starting at ``qb``."""
        K[qb + K_CARRY_DRY] = float(self.dry)
        K[qb + K_CARRY_VISC] = float(self.viscous)
        K[qb + K_CARRY_RIGID] = float(self.rigid)
        K[qb + K_CARRY_RIP1] = float(self.ripple_first)

    def names(self, comp: 'Compensation') -> list[str]:
        """Return the terms of ``comp`` these leave to the controller, in words."""
        out = []
        if comp.terms is CompensationTerms.FULL and self.rigid:
            out.append('inertia, back-EMF and damping')
        has = set(comp.compensated)
        dry = {CarriedDry.COULOMB: 'coulomb' if 'coulomb' in has else '',
               CarriedDry.STATIC: 'sliding friction curve'
               if has & {'coulomb', 'stribeck', 'presliding'} else '',
               CarriedDry.ALL: 'dry friction'
               if has & {'coulomb', 'stribeck', 'presliding'} else ''}.get(self.dry, '')
        if dry and has & {'load_friction', 'position_friction'}:
            dry += ' at its base level'      # the load/position rise stays compensated
        if dry:
            out.append(dry)
        if self.viscous and 'viscous' in has:
            out.append('viscous')
        if self.ripple_first and 'ripple' in has:
            out.append('ripple harmonic 1')
        return out


@dataclasses.dataclass(frozen=True)
class Compensation:
    """A packed compensation block and what it does.

    Attributes
    ----------
    kind : CompensationKind
        From a model file or from a position table.
    source : str
        File it came from.
    packed : ndarray
        Parameter block (layout ``K_*``), appended to the controller's parameters.
    input_gain : float
        Force per command unit [N/V] used for ``u = F/input_gain``.
    compensated : tuple of str
        Effects the feedforward cancels.
    not_compensated : Mapping[str, str]
        Effects of the model it cannot cancel, with the reason.
    units : Mapping[str, str]
        Position and force units (``m``/``N`` or ``rad``/``N·m``).
    terms : CompensationTerms
        Full inverse dynamics or the effects only (a table: its effects).
    model : AxisModel or None
        The model it was packed from (None for a table).
    """

    kind: CompensationKind
    source: str
    packed: np.ndarray
    input_gain: float
    compensated: tuple
    not_compensated: Mapping[str, str]
    units: Mapping[str, str]
    terms: CompensationTerms = CompensationTerms.EFFECTS
    model: AxisModel | None = None

    def with_terms(self, terms: 'str | CompensationTerms') -> 'Compensation':
        """Return the same compensation with other terms (a table keeps its own)."""
        terms = CompensationTerms.parse(terms)
        if self.kind is CompensationKind.TABLE or terms is self.terms:
            return self
        packed = self.packed.copy()
        packed[K_FULL] = float(terms is CompensationTerms.FULL)
        return dataclasses.replace(self, packed=packed, terms=terms)

    def carried_for(self, carried: Carried) -> np.ndarray:
        """Return the packed block with the controller's carried terms written in."""
        packed = self.packed.copy()
        if self.kind is CompensationKind.MODEL:
            carried.pack_into(packed)
        return packed

    def force_along(self, r: np.ndarray, rv: np.ndarray, dt: float, *,
                    ra: np.ndarray | None = None, advance: bool = True,
                    carried: Carried = Carried()) -> np.ndarray:
        """Force [N] the controller adds along a sampled reference (fresh state).

        Parameters
        ----------
        r, rv : ndarray
            Reference position [m] and velocity [m/s] at the control instants.
        dt : float
            Control period [s].
        ra : ndarray, optional
            Reference acceleration [m/s²] (zero when not given).
        advance : bool
            Evaluate ``T/2 + τ`` ahead as the controller does (module docstring);
            False: at the given samples exactly (the effect laws along a path).
        carried : Carried
            Terms left to the controller law.
        """
        return self._along(r, rv, dt, ra, advance, carried)[0]

    def command_along(self, r: np.ndarray, rv: np.ndarray, dt: float, *,
                      ra: np.ndarray | None = None,
                      carried: Carried = Carried()) -> np.ndarray:
        """Command [V] the controller adds along a sampled reference (fresh state)."""
        return self._along(r, rv, dt, ra, True, carried)[1]

    def _along(self, r: np.ndarray, rv: np.ndarray, dt: float, ra: np.ndarray | None,
               advance: bool, carried: Carried) -> tuple[np.ndarray, np.ndarray]:
        r = np.ascontiguousarray(r, dtype=float)
        rv = np.ascontiguousarray(rv, dtype=float)
        ra = np.zeros_like(r) if ra is None else np.ascontiguousarray(ra, dtype=float)
        if r.shape != rv.shape or r.shape != ra.shape:
            raise ParameterError('reference position, velocity and acceleration differ '
                                 'in length')
        packed = self.carried_for(carried)
        if not advance and self.kind is CompensationKind.MODEL:
            packed[K_TAU] = -0.5 * float(dt)     # lead T/2 + τ = 0
        elif not advance:                        # a table's force depends on r alone
            rv = np.zeros_like(r)
        out_f, out_u = np.empty(len(r)), np.empty(len(r))
        _force_along(packed, np.zeros(CS_SIZE), r, rv, ra, float(dt), out_f, out_u)
        return out_f, out_u

    def describe(self) -> dict[str, Any]:
        """Plain-value summary (node logs, run metadata, JSON)."""
        return {'compensation': self.source, 'compensation_kind': self.kind.name.lower(),
                'compensation_terms': self.terms.value,
                'compensated': list(self.compensated),
                'not_compensated': dict(self.not_compensated)}

    def summary(self) -> str:
        """One line: what is compensated and what is not (and why)."""
        what = ', '.join(self.compensated) or 'nothing'
        if self.kind is CompensationKind.MODEL and self.terms is CompensationTerms.FULL:
            what = f'inertia, back-EMF, damping, {what}'
        text = f'compensation from {self.source} ({self.terms.value}): {what}'
        for name, why in self.not_compensated.items():
            text += f'; {name} not compensated ({why})'
        return text


def _units(model: AxisModel) -> dict[str, str]:
    u = model.units
    return {'position': u.position, 'force': u.force}


def from_model(model: AxisModel, *, source: str = 'model',
               terms: 'str | CompensationTerms' = CompensationTerms.FULL) -> Compensation:
    """Pack ``model`` for the controller: its inverse dynamics or its effects (module doc).

    Parameters
    ----------
    model : AxisModel
        The (fitted) model.
    source : str
        Where it came from (reports).
    terms : {'full', 'effects'}
        The whole inverse dynamics (default) or ``Σ F_k`` only.
    """
    terms = CompensationTerms.parse(terms)
    K = np.zeros(K_MODEL_SIZE)
    K[K_KIND] = float(CompensationKind.MODEL)
    K[K_INVGAIN] = 1.0 / model.input_gain
    names = model.names
    gms = model.get('presliding')
    if any(n in names for n in ('coulomb', 'stribeck', 'viscous', 'presliding',
                                'load_friction', 'position_friction')):
        K[K_FRIC] = 3.0 if gms is not None else 1.0
    fc, fs, vs, delta = model.stribeck_curve_params()
    K[K_FC], K[K_FS], K[K_VS], K[K_DELTA], K[K_FV] = fc, fs, vs, delta, model.fv
    if gms is not None:
        n = len(gms.alpha)
        K[K_GMS_N], K[K_GMS_C] = n, gms.C
        K[K_GMS_ALPHA:K_GMS_ALPHA + n] = gms.alpha
        K[K_GMS_K:K_GMS_K + n] = gms.k
        K[K_GMS_SIGMA:K_GMS_SIGMA + n] = gms.sigma
    asym = model.get('asymmetry')
    if asym is not None:
        K[K_DFC], K[K_DFV] = asym.dfc, asym.dfv
    rip = model.get('ripple')
    if rip is not None:
        nh = len(rip.harmonics)
        K[K_RIP_NH], K[K_RIP_PERIOD] = nh, rip.period
        K[K_RIP_A:K_RIP_A + nh] = rip.a
        K[K_RIP_B:K_RIP_B + nh] = rip.b
    off = model.get('offset')
    if off is not None:
        K[K_F0] = off.f0
    spr = model.get('spring')
    if spr is not None:
        K[K_SPRING_K], K[K_SPRING_X0] = spr.k, spr.x0
    grav = model.get('gravity')
    if grav is not None:
        K[K_GRAV_MGL], K[K_GRAV_Q0] = grav.mgl, grav.q0
    lf = model.get('load_friction')
    if lf is not None:
        K[K_LF_MU] = lf.mu
    pf = model.get('position_friction')
    if pf is not None:
        nk = len(pf.x)
        K[K_PF_N] = nk
        K[K_PF_X:K_PF_X + nk] = pf.knots
        K[K_PF_Y:K_PF_Y + nk] = pf.values
        K[K_PF_M:K_PF_M + nk] = pf.slopes
    K[K_FULL] = float(terms is CompensationTerms.FULL)
    K[K_MASS], K[K_DAMP], K[K_BEMF] = model.mass, model.damping, model.back_emf
    dly = model.get('delay')
    K[K_TAU] = dly.tau if dly is not None else 0.0
    not_comp = {n: NOT_COMPENSABLE[n] for n in names if n not in COMPENSABLE}
    return Compensation(kind=CompensationKind.MODEL, source=source, packed=K,
                        input_gain=float(model.input_gain),
                        compensated=tuple(n for n in names if n in COMPENSABLE),
                        not_compensated=not_comp, units=_units(model), terms=terms,
                        model=model)


def load_model(path: str | Path, *,
               terms: 'str | CompensationTerms' = CompensationTerms.FULL) -> Compensation:
    """Compensation from a model YAML file (one-line :class:`ModelFileError` if bad)."""
    model = AxisModel.load(path)
    return from_model(model, source=str(path), terms=terms)


# ---- position tables -------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class PositionTable:
    """The position-dependent force of a model on a grid.

    Attributes
    ----------
    position : ndarray
        Grid [m] or [rad], increasing.
    force : ndarray
        Force [N] (torque [N·m]) to add at each position.
    command : ndarray
        The same in drive units, ``force / input_gain`` [V] (or [A], or [N]).
    period : float
        Period of the table [m]/[rad]; 0 when it is not periodic (clamped at its ends).
    input_gain : float
        Force per command unit of the model.
    units : Mapping[str, str]
        ``position``, ``force``, ``command`` unit strings.
    effects : tuple of str
        The effects the table holds.
    source : str
        Model file.
    left_out : Mapping[str, str]
        Position-dependent effects of the model the table cannot hold, with the reason
        (:data:`TABLE_LEFT_OUT`); empty for a table read from a file.
    """

    position: np.ndarray
    force: np.ndarray
    command: np.ndarray
    period: float
    input_gain: float
    units: Mapping[str, str]
    effects: tuple
    source: str
    left_out: Mapping[str, str] = dataclasses.field(default_factory=dict)


_COMMAND_UNIT = {'voltage': 'V', 'current': 'A', 'force': 'N'}


def table_period(model: AxisModel) -> float:
    """Period [m]/[rad] of the position-dependent part of ``model``, 0 if not periodic.

    Ripple alone: its period; gravity: one revolution (2π); both: one revolution when
    it holds a whole number of ripple periods.  A spring makes the part non-periodic.
    """
    if model.has('spring'):
        return 0.0
    rip, grav = model.get('ripple'), model.get('gravity')
    if grav is not None:
        if rip is not None:
            cycles = 2.0 * math.pi / rip.period
            if abs(cycles - round(cycles)) > 1e-6 * max(1.0, cycles):
                return 0.0
        return 2.0 * math.pi
    if rip is not None:
        return float(rip.period)
    return 0.0


def position_table(model: AxisModel, *, points: int = 1024,
                   span: tuple[float, float] | None = None,
                   source: str = 'model') -> PositionTable:
    """Tabulate the position-dependent effects of ``model`` (effects' own force laws).

    ``position_friction`` is left out and named in :attr:`PositionTable.left_out`
    (:data:`TABLE_LEFT_OUT`: it acts against the motion, module docstring).

    Parameters
    ----------
    points : int
        Grid points (>= 2).  A periodic table covers ``[0, period)`` (the point at
        ``period`` would repeat the first); otherwise ``span`` inclusive.
    span : (float, float), optional
        ``(x_min, x_max)`` [m]/[rad]; required when the part is not periodic (spring, or
        ripple and gravity that do not share a revolution); with a periodic part it
        replaces the one-period grid.
    """
    if not isinstance(points, (int, np.integer)) or isinstance(points, bool) or points < 2:
        raise ParameterError(f'--points must be an integer >= 2, got {points!r}')
    effects = tuple(n for n in model.names if n in POSITION_EFFECTS)
    left_out = {n: TABLE_LEFT_OUT[n] for n in model.names if n in TABLE_LEFT_OUT}
    if not effects:
        why = ''.join(f'; {n} is not tabulated: {r}' for n, r in left_out.items())
        raise ParameterError(f'{source}: the model has no position-dependent effect '
                             f'({", ".join(POSITION_EFFECTS)}); nothing to tabulate{why}')
    period = table_period(model)
    if span is not None:
        lo, hi = (float(s) for s in span)
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise ParameterError(f'--range must be two finite numbers MIN < MAX, got {span}')
        x = np.linspace(lo, hi, points)
        period = 0.0
    elif period > 0.0:
        x = np.arange(points) * (period / points)
    else:
        raise ParameterError(f'{source}: the position-dependent part '
                             f'({", ".join(effects)}) is not periodic; give the travel '
                             f'with --range MIN MAX')
    f = np.zeros(points)
    for name in effects:
        f += model.get(name).force(x, np.zeros(points))
    units = dict(_units(model))
    units['command'] = _COMMAND_UNIT[model.input.value]
    return PositionTable(position=x, force=f, command=f / model.input_gain, period=period,
                         input_gain=float(model.input_gain), units=units, effects=effects,
                         source=source, left_out=left_out)


def write_table(path: str | Path, table: PositionTable) -> None:
    """Write ``table`` as CSV with a ``#`` header stating units, period and source."""
    u = table.units
    lines = [
        '# motor-comp compensation table: position-dependent force to ADD to the command',
        f'# source_model: {table.source}',
        f'# effects: {" ".join(table.effects)}',
        f'# period: {table.period!r}' + ('  (0 = not periodic: clamped at both ends)'
                                         if table.period == 0.0 else
                                         f' {u["position"]} (wrapped)'),
        f'# input_gain: {table.input_gain!r} {u["force"]}/{u["command"]}',
        f'# units: position [{u["position"]}], force [{u["force"]}], '
        f'command [{u["command"]}] = force / input_gain',
    ]
    buf = io.StringIO()
    buf.write('\n'.join(lines) + '\n')
    w = csv.writer(buf, lineterminator='\n')
    w.writerow([f'position_{u["position"]}', f'force_{u["force"]}',
                f'command_{u["command"]}'])
    for x, f, c in zip(table.position, table.force, table.command):
        w.writerow([repr(float(x)), repr(float(f)), repr(float(c))])
    Path(path).write_text(buf.getvalue(), encoding='utf-8')


def read_table(path: str | Path) -> PositionTable:
    """Read a table written by :func:`write_table` (one-line error naming the problem)."""
    path = Path(path)
    try:
        text = path.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise InputFileError(f'{path}: no such compensation table') from None
    except IsADirectoryError:
        raise InputFileError(f'{path}: is a directory, expected a table CSV') from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(f'{path}: cannot read compensation table ({exc})') from None
    return table_from_text(text, source=str(path))


def table_from_text(text: str, *, source: str = 'table') -> PositionTable:
    """Parse the text of a table CSV (already read); errors name ``source``.

    The entry point for text read under rules of its own (``controller_node`` reads the
    file ``compensation_table`` names with :mod:`motor_comp.param_files`).
    """
    path = source
    header: dict[str, str] = {}
    rows: list[list[str]] = []
    for i, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        if line.startswith('#'):
            key, sep, value = line[1:].partition(':')
            if sep:
                header[key.strip()] = value.strip()
            continue
        rows.append([c.strip() for c in line.split(',')])
    if not rows:
        raise ModelFileError(f'{path}: empty compensation table')
    names = rows[0]
    if len(names) != 3 or not names[0].startswith('position') \
            or not names[1].startswith('force') or not names[2].startswith('command'):
        raise ModelFileError(f'{path}: expected columns position, force, command '
                             f'(motor-comp export-table), got {",".join(names)!r}')
    if any(len(r) != 3 for r in rows[1:]):
        bad = next(i for i, r in enumerate(rows[1:], 2) if len(r) != 3)
        raise ModelFileError(f'{path}: row {bad} does not have 3 columns')
    try:
        data = np.array([[float(c) for c in r] for r in rows[1:]], dtype=float)
    except ValueError as exc:
        raise ModelFileError(f'{path}: non-numeric value in the table ({exc})') from None
    if data.shape[0] < 2:
        raise ModelFileError(f'{path}: a table needs at least 2 rows, got {data.shape[0]}')
    if not np.all(np.isfinite(data)):
        raise ModelFileError(f'{path}: non-finite value in the table')
    x, f, c = data[:, 0], data[:, 1], data[:, 2]
    if np.any(np.diff(x) <= 0):
        raise ModelFileError(f'{path}: positions must be strictly increasing')
    try:
        period = float(header.get('period', '0').split()[0])
    except (ValueError, IndexError):
        raise ModelFileError(f'{path}: header period is not a number') from None
    if not (math.isfinite(period) and period >= 0.0):
        raise ModelFileError(f'{path}: header period must be >= 0, got {period!r}')
    if period > 0.0 and x[-1] - x[0] >= period:
        raise ModelFileError(f'{path}: positions span {x[-1] - x[0]:g}, more than one '
                             f'period ({period:g})')
    gain_text = header.get('input_gain')
    if gain_text is not None:
        try:
            gain = check_positive('input_gain', gain_text.split()[0])
        except (ParameterError, IndexError):
            raise ModelFileError(f'{path}: header input_gain must be a number > 0, got '
                                 f'{gain_text!r}') from None
    else:   # a hand-made table: the ratio of its own columns
        nz = np.abs(c) > 0
        if not np.any(nz):
            raise ModelFileError(f'{path}: no input_gain in the header and no non-zero '
                                 f'command to infer it from')
        gain = float(np.median(f[nz] / c[nz]))
        if not gain > 0:
            raise ModelFileError(f'{path}: force/command ratio is not positive')
    pos_unit = names[0].partition('_')[2] or 'm'
    force_unit = names[1].partition('_')[2] or 'N'
    cmd_unit = names[2].partition('_')[2] or 'V'
    return PositionTable(position=x, force=f, command=c, period=period, input_gain=gain,
                         units={'position': pos_unit, 'force': force_unit,
                                'command': cmd_unit},
                         effects=tuple(header.get('effects', '').split()),
                         source=header.get('source_model', source))


def from_table(table: PositionTable, *, source: str = 'table') -> Compensation:
    """Pack a position table for the controller (linear interpolation)."""
    n = len(table.position)
    K = np.zeros(K_TAB_X + 2 * n)
    K[K_KIND] = float(CompensationKind.TABLE)
    K[K_INVGAIN] = 1.0 / table.input_gain
    K[K_TAB_N] = n
    K[K_TAB_PERIOD] = table.period
    K[K_TAB_X:K_TAB_X + n] = table.position
    K[K_TAB_X + n:] = table.force
    return Compensation(kind=CompensationKind.TABLE, source=source, packed=K,
                        input_gain=float(table.input_gain),
                        compensated=table.effects or ('position table',),
                        not_compensated={}, units=dict(table.units))


def load_table(path: str | Path) -> Compensation:
    """Compensation from a table CSV (:func:`read_table`)."""
    return from_table(read_table(path), source=str(path))


def load(path: str | Path) -> Compensation:
    """Load a model YAML or a table CSV, by its suffix."""
    if Path(path).suffix.lower() == '.csv':
        return load_table(path)
    return load_model(path)


__all__ = ['COMPENSABLE', 'NOT_COMPENSABLE', 'POSITION_EFFECTS', 'TABLE_LEFT_OUT', 'Carried',
           'CarriedDry',
           'Compensation', 'CompensationKind', 'CompensationTerms', 'PositionTable',
           'compensation_command', 'compensation_force', 'from_model', 'from_table', 'load',
           'load_model', 'load_table', 'position_table', 'read_table', 'table_from_text',
           'table_period',
           'write_table']
