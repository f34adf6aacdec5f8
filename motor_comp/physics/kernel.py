"""Compiled plant kernel: one fixed physics step of the composed axis.

This is the only implementation of the axis dynamics.  The in-process simulator's loop
and the ROS ``plant_node`` both call :func:`plant_advance` and :func:`plant_measure`
(DESIGN.md §2: one implementation of each law, two drivers).  The kernel reads a packed
parameter vector ``P`` and mutates a state vector ``S`` (layouts below, built by
:mod:`motor_comp.physics.plant`); the force laws are the effect modules' own functions.

Integration (DESIGN.md §3): the smooth part by classical RK4 with the friction
direction frozen over the step; GMS elements updated exactly per step; Coulomb/Stribeck
stick–slip by a Karnopp-style switch — an axis at rest stays at rest while the net drive
force lies inside the break-away band.  A velocity zero-crossing inside a step is an
event: the step is integrated up to it, and the rest of the step is spent at rest or, if
the net force exceeds the break-away level there, sliding the other way.  So the axis
neither chatters through zero nor dwells at a reversal it should pass (a frictionless
oscillator keeps its period).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from motor_comp.physics.effects.backlash import play
from motor_comp.physics.effects.presliding import MAX_ELEMENTS, gms_update
from motor_comp.physics.effects.ripple import MAX_HARMONICS, ripple_force
from motor_comp.physics.effects.stribeck import stribeck_magnitude

# ---- parameter vector P -----------------------------------------------------------
P_MASS, P_GAIN, P_BEMF, P_DAMP = 0, 1, 2, 3
P_FC, P_FS, P_VS, P_DELTA, P_FV = 4, 5, 6, 7, 8
P_DFC, P_DFV = 9, 10
P_GMS_ON, P_GMS_N, P_GMS_C = 11, 12, 13
P_GMS_ALPHA = 14
P_GMS_K = P_GMS_ALPHA + MAX_ELEMENTS
P_RIP_NH = P_GMS_K + MAX_ELEMENTS
P_RIP_PERIOD = P_RIP_NH + 1
P_RIP_A = P_RIP_PERIOD + 1
P_RIP_B = P_RIP_A + MAX_HARMONICS
P_F0 = P_RIP_B + MAX_HARMONICS
P_SPRING_K, P_SPRING_X0 = P_F0 + 1, P_F0 + 2
P_DELAY_STEPS = P_F0 + 3          # τ/dt as a real number of physics steps
P_BACKLASH = P_F0 + 4
P_UMAX = P_F0 + 5                 # command saturation [V]; inf = none
P_QUANT = P_F0 + 6                # encoder resolution [m]; 0 = ideal
P_DT = P_F0 + 7                   # physics step [s]
P_SIZE = P_F0 + 8

# ---- state vector S ---------------------------------------------------------------
S_X, S_V, S_XL, S_STUCK, S_T = 0, 1, 2, 3, 4
S_FRICTION, S_RIPPLE, S_UEFF = 5, 6, 7   # last friction [N], ripple [N], applied command
S_YPREV = 8                               # previous measured position [m]
S_DHEAD = 9                               # delay ring-buffer head index
S_GMS_F = 10
S_GMS_SLIP = S_GMS_F + MAX_ELEMENTS
S_DBUF = S_GMS_SLIP + MAX_ELEMENTS        # delay ring buffer follows
S_BASE = S_DBUF


@njit(cache=True)
def _drive_force(P, x, v, u, f_ext):
    """Every force except sliding friction [N]: drive minus smooth effects and load."""
    f = P[P_GAIN] * (u - P[P_BEMF] * v) - (P[P_DAMP] + P[P_FV]) * v
    nh = int(P[P_RIP_NH])
    if nh > 0:
        f -= ripple_force(x, P[P_RIP_PERIOD], P[P_RIP_A:P_RIP_A + nh], P[P_RIP_B:P_RIP_B + nh])
    f -= P[P_F0] + P[P_SPRING_K] * (x - P[P_SPRING_X0]) + f_ext
    f -= 0.5 * P[P_DFV] * abs(v)
    return f


@njit(cache=True)
def _sliding_friction(P, v, d):
    """Static-model sliding friction [N] in direction ``d`` (±1) at velocity ``v``."""
    shift = 0.5 * P[P_DFC]
    fc = P[P_FC] + d * shift
    fs = P[P_FS] + d * shift
    return d * stribeck_magnitude(abs(v), fc, fs, P[P_VS], P[P_DELTA])


@njit(cache=True)
def _breakaway(P, x, u, f_ext):
    """At rest at ``x``: direction (±1) in which the axis breaks away, or 0 if held.

    Returns ``(direction, net force [N])``; the break-away band is ``[−fs−, fs+]`` with
    the direction-dependent levels ``fs± = fs ± dfc/2``.  A level below zero (|dfc| > 2·fs,
    which the workbench may fit) counts as zero: rest with no net force stays rest, as
    the force laws say at v = 0, instead of breaking away on its own.
    """
    f_net = _drive_force(P, x, 0.0, u, f_ext)
    shift = 0.5 * P[P_DFC]
    if f_net > max(P[P_FS] + shift, 0.0):
        return 1.0, f_net
    if f_net < -max(P[P_FS] - shift, 0.0):
        return -1.0, f_net
    return 0.0, f_net


@njit(cache=True)
def _accel(P, x, v, u, f_ext, f_fric):
    return (_drive_force(P, x, v, u, f_ext) - f_fric) / P[P_MASS]


@njit(cache=True)
def _friction_at(P, v, d, x, x0, gms_force, k_stick):
    """Friction [N] inside a step: static model in frozen direction ``d``, or GMS.

    GMS elements that stick act as springs during the step (``gms_force + k_stick·(x−x0)``);
    treating them as a frozen force instead would make the explicit scheme pump energy
    into the pre-sliding oscillation.
    """
    if P[P_GMS_ON] > 0.5:
        return gms_force + k_stick * (x - x0)
    return _sliding_friction(P, v, d)


@njit(cache=True)
def _rk4_frozen(P, x, v, u, f_ext, d, gms_force, k_stick, dt):
    """RK4 step of (x, v) with the friction direction ``d`` or the GMS state frozen."""
    f1 = _friction_at(P, v, d, x, x, gms_force, k_stick)
    k1x, k1v = v, _accel(P, x, v, u, f_ext, f1)
    x2, v2 = x + 0.5 * dt * k1x, v + 0.5 * dt * k1v
    f2 = _friction_at(P, v2, d, x2, x, gms_force, k_stick)
    k2x, k2v = v2, _accel(P, x2, v2, u, f_ext, f2)
    x3, v3 = x + 0.5 * dt * k2x, v + 0.5 * dt * k2v
    f3 = _friction_at(P, v3, d, x3, x, gms_force, k_stick)
    k3x, k3v = v3, _accel(P, x3, v3, u, f_ext, f3)
    x4, v4 = x + dt * k3x, v + dt * k3v
    f4 = _friction_at(P, v4, d, x4, x, gms_force, k_stick)
    k4x, k4v = v4, _accel(P, x4, v4, u, f_ext, f4)
    xn = x + dt / 6.0 * (k1x + 2.0 * k2x + 2.0 * k3x + k4x)
    vn = v + dt / 6.0 * (k1v + 2.0 * k2v + 2.0 * k3v + k4v)
    return xn, vn, (f1 + 2.0 * f2 + 2.0 * f3 + f4) / 6.0


@njit(cache=True)
def _delayed_command(P, S, u):
    """Push ``u`` into the dead-time buffer and return ``u(t − τ)`` (linear interpolation)."""
    steps = P[P_DELAY_STEPS]
    nbuf = S.shape[0] - S_DBUF
    if steps <= 0.0 or nbuf < 2:
        return u
    head = int(S[S_DHEAD])
    head = (head + 1) % nbuf
    S[S_DBUF + head] = u
    S[S_DHEAD] = head
    n0 = int(np.floor(steps))
    frac = steps - n0
    a = S[S_DBUF + (head - n0) % nbuf]
    b = S[S_DBUF + (head - n0 - 1) % nbuf]
    return (1.0 - frac) * a + frac * b


@njit(cache=True)
def _static_friction_step(P, x, v, u, f_ext, dt):
    """One step of the static (Coulomb/Stribeck/viscous) friction model with stick–slip.

    Karnopp-style switch with event location: at rest the axis stays while the net force
    is inside the break-away band; while sliding, RK4 runs with the friction direction
    frozen, and if the velocity reaches zero inside the step the integration stops at the
    zero-crossing (located by linear interpolation of v, then integrated exactly up to
    it) and the remaining time is spent stuck or sliding the other way.

    Returns
    -------
    (x [m], v [m/s], step-averaged friction [N], stuck flag)
    """
    t_left = dt
    impulse = 0.0                 # ∫ friction dt over the parts of the step done so far
    d = np.sign(v)
    for _ in range(3):            # slide → rest → slide back; a third event ends at rest
        if d == 0.0:
            d, f_net = _breakaway(P, x, u, f_ext)
            if d == 0.0:          # static friction balances the net force
                return x, 0.0, (impulse + f_net * t_left) / dt, 1.0
        xn, vn, f = _rk4_frozen(P, x, v, u, f_ext, d, 0.0, 0.0, t_left)
        if vn * d > 0.0:
            return xn, vn, (impulse + f * t_left) / dt, 0.0
        tc = t_left * v / (v - vn) if v != vn else 0.0
        if tc > 0.0:
            xn, _, f = _rk4_frozen(P, x, v, u, f_ext, d, 0.0, 0.0, tc)
        impulse += f * tc
        x, v, d = xn, 0.0, 0.0
        t_left -= tc
    _, f_net = _breakaway(P, x, u, f_ext)
    return x, 0.0, (impulse + f_net * t_left) / dt, 1.0


@njit(cache=True)
def plant_substep(P, S, u, f_ext):
    """Advance the axis by one physics step ``P[P_DT]`` with command ``u`` and load ``f_ext``.

    Parameters
    ----------
    P : ndarray
        Packed parameters (see module constants).
    S : ndarray
        State, updated in place.
    u : float
        Command [V] (or the model's input unit) before saturation and delay.
    f_ext : float
        External load force [N], subtracted like every effect force.
    """
    dt = P[P_DT]
    umax = P[P_UMAX]
    if u > umax:
        u = umax
    elif u < -umax:
        u = -umax
    u = _delayed_command(P, S, u)
    S[S_UEFF] = u
    x = S[S_X]
    v = S[S_V]
    if P[P_GMS_ON] > 0.5:
        n = int(P[P_GMS_N])
        forces = S[S_GMS_F:S_GMS_F + n]
        slip = S[S_GMS_SLIP:S_GMS_SLIP + n]
        f_gms = np.sum(forces)
        k_stick = 0.0
        for i in range(n):
            if slip[i] == 0.0:
                k_stick += P[P_GMS_K + i]
        xn, vn, _ = _rk4_frozen(P, x, v, u, f_ext, 0.0, f_gms, k_stick, dt)
        # the elements follow the direction-dependent Stribeck curve (fc±, fs± of the
        # asymmetry effect), so asymmetry acts on the dynamics, not only on the report
        s_v = _sliding_friction(P, vn, np.sign(vn))
        f_fric = gms_update(forces, slip, P[P_GMS_ALPHA:P_GMS_ALPHA + n],
                            P[P_GMS_K:P_GMS_K + n], P[P_GMS_C], xn - x, vn, s_v, dt)
    else:
        xn, vn, f_fric, stuck = _static_friction_step(P, x, v, u, f_ext, dt)
        S[S_STUCK] = stuck
    S[S_X] = xn
    S[S_V] = vn
    S[S_FRICTION] = f_fric
    nh = int(P[P_RIP_NH])
    if nh > 0:
        S[S_RIPPLE] = ripple_force(xn, P[P_RIP_PERIOD], P[P_RIP_A:P_RIP_A + nh],
                                   P[P_RIP_B:P_RIP_B + nh])
    S[S_XL] = play(xn, S[S_XL], P[P_BACKLASH])
    S[S_T] += dt


@njit(cache=True)
def plant_advance(P, S, u, f_ext, n_sub):
    """Advance ``n_sub`` physics steps holding command ``u`` [V] and load ``f_ext`` [N]."""
    for _ in range(n_sub):
        plant_substep(P, S, u, f_ext)


@njit(cache=True)
def plant_measure(P, S, noise, dt_meas):
    """Read the encoder: load position and its backward-difference velocity.

    Parameters
    ----------
    noise : float
        Measurement noise sample [m] added before quantisation.
    dt_meas : float
        Time since the previous reading [s] (the control period).

    Returns
    -------
    (position [m], velocity [m/s])
    """
    y = S[S_XL] + noise
    q = P[P_QUANT]
    if q > 0.0:
        y = q * np.round(y / q)
    vy = (y - S[S_YPREV]) / dt_meas if dt_meas > 0.0 else 0.0
    S[S_YPREV] = y
    return y, vy
