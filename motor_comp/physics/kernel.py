"""Compiled plant kernel: one fixed physics step of the composed axis.

This is the only implementation of the axis dynamics.  The in-process simulator's loop
and the ROS ``plant_node`` both call :func:`plant_advance` and :func:`plant_measure`
(DESIGN.md §2: one implementation of each law, two drivers).  The kernel reads a packed
parameter vector ``P`` and mutates a state vector ``S`` (layouts below, built by
:mod:`motor_comp.physics.plant`); the force laws are the effect modules' own functions.

Integration (DESIGN.md §3): the smooth part by classical RK4 with the friction
direction frozen over the step; GMS elements updated exactly per step (the published
slip law of Lampaert 2003, relaxation rate ``C/|s(v)|``; sticking elements act inside the
RK4 stages as springs with their micro-damping ``σ_i``); Coulomb/Stribeck
stick–slip by a Karnopp-style switch — an axis at rest stays at rest while the net drive
force lies inside the break-away band.  A velocity zero-crossing inside a step is an
event: the step is integrated up to it, and the rest of the step is spent at rest or, if
the net force exceeds the break-away level there, sliding the other way.  So the axis
neither chatters through zero nor dwells at a reversal it should pass (a frictionless
oscillator keeps its period).

Load- and position-dependent friction (issue 23) raise the dry-friction level — Coulomb,
the Stribeck break-away level, the Karnopp band at rest and the GMS curve ``s(v)`` — by
``Δ = mu·|F_in| + dfc(x)`` [N] (:func:`level_shift`), with
``F_in = input_gain·(u − back_emf·ẋ) − damping·ẋ`` of the applied (delayed) command and
``(x, ẋ)`` of each RK4 stage (of the step's end for ``s(v)``).

Speed (issue 7: ≥ 1000× real time in closed loop at 10 kHz): :func:`plant_advance` is
one compiled function — its helpers are inlined at numba-IR level and read the
per-advance constants from a tuple unpacked from ``P`` once, not from the arrays; the
ripple at the start of a step (RK4 stage 1) is the one computed at the end of the
previous step; ``1/M`` and ``1/vs`` are hoisted.  The exact special cases of the laws
(Stribeck δ = 1, 2; ripple harmonics by angle addition) live in the effect modules, so
the effects' own ``force`` methods use them too.  Run under ``NUMBA_DISABLE_JIT=1`` the
same code is the pure-Python reference (checked against the compiled kernel by the
tests).

The level shift must cost an axis without those effects nothing: an inlined shift in
the RK4 stages (even one behind a branch), or merely handing the array ``P`` to the
inlined helpers (reference counting), slowed the PMLM step by 10–30 %, and a copy of the
static step called behind a per-step branch by 2–4 % (``bench/sim_speed.py``'s loops).
So the helpers take a *shift source* ``src`` whose type selects the law while compiling
(:func:`_shift`): None, which adds ``NO_SHIFT`` (−0.0; ``x + (−0.0) = x`` lets LLVM fold
it away: the plain axis runs the code it ran before, bit for bit), or the array ``P``.
:func:`plant_advance` as the drivers call it is the None version; for a model with
``mu ≠ 0`` or knots it calls :data:`_advance_shifted`, the same function compiled a
second time with ``P`` as the source.  The price is compile time: the second copy
roughly doubles the kernel's first (uncached) compilation.
"""
from __future__ import annotations

from collections import namedtuple

import numpy as np
from numba import njit, types
from numba.extending import overload

from motor_comp.physics.effects.backlash import play
from motor_comp.physics.effects.gravity import gravity_torque
from motor_comp.physics.effects.load_friction import load_friction_level
from motor_comp.physics.effects.position_friction import MAX_KNOTS, spline_sum
from motor_comp.physics.effects.presliding import MAX_ELEMENTS, gms_slip_rate, gms_step
from motor_comp.physics.effects.ripple import MAX_HARMONICS, ripple_sum
from motor_comp.physics.effects.stribeck import stribeck_level

#: numba options of the kernel functions: cached on disk; numpy error model (no
#: ZeroDivisionError branches: every divisor is validated > 0 when P is packed).
#: Helpers of the step are inlined into :func:`plant_advance` at numba-IR level
#: (``inline='always'``): a cached callee is linked as object code, which LLVM cannot
#: inline, and passing the arrays P/S into a callee costs atomic reference counting.
_JIT = {'cache': True, 'error_model': 'numpy'}
_INLINE = dict(_JIT, inline='always')

# ---- parameter vector P -----------------------------------------------------------
P_MASS, P_GAIN, P_BEMF, P_DAMP = 0, 1, 2, 3
P_FC, P_FS, P_VS, P_DELTA, P_FV = 4, 5, 6, 7, 8
P_DFC, P_DFV = 9, 10
P_GMS_ON, P_GMS_N, P_GMS_C = 11, 12, 13   # GMS on, element count, attraction C [N/s]
P_GMS_ALPHA = 14
P_GMS_K = P_GMS_ALPHA + MAX_ELEMENTS      # element stiffnesses [N/m]
P_GMS_SIGMA = P_GMS_K + MAX_ELEMENTS      # element micro-damping [N·s/m]
P_RIP_NH = P_GMS_SIGMA + MAX_ELEMENTS
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
P_GRAV_MGL, P_GRAV_Q0 = P_F0 + 8, P_F0 + 9   # gravity mgl [N·m], q0 [rad]; mgl 0 = none
P_LF_MU = P_F0 + 10               # load_friction mu [-]; 0 = none
P_PF_N = P_F0 + 11                # position_friction knot count; 0 = none
P_PF_X = P_PF_N + 1               # knots [m]
P_PF_Y = P_PF_X + MAX_KNOTS       # dfc at the knots [N]
P_PF_M = P_PF_Y + MAX_KNOTS       # spline slopes at the knots [N/m]
P_SIZE = P_PF_M + MAX_KNOTS

#: the level shift of an axis without load- or position-dependent friction (module
#: docstring): −0.0, so that adding it is the identity LLVM removes
NO_SHIFT = -0.0

# _axis below unpacks the ripple amplitudes as 16-tuples
assert MAX_HARMONICS == 16, 'update _axis() for the new MAX_HARMONICS'

# ---- state vector S ---------------------------------------------------------------
S_X, S_V, S_XL, S_STUCK, S_T = 0, 1, 2, 3, 4
S_FRICTION, S_RIPPLE, S_UEFF = 5, 6, 7   # last friction [N], ripple [N], applied command
S_YPREV = 8                               # previous measured position [m]
S_DHEAD = 9                               # delay ring-buffer head index
S_GMS_F = 10
S_GMS_SLIP = S_GMS_F + MAX_ELEMENTS
S_DBUF = S_GMS_SLIP + MAX_ELEMENTS        # delay ring buffer follows
S_BASE = S_DBUF


#: Per-advance constants unpacked from P once (scalars and fixed-size tuples are passed
#: by value, so the inner step functions touch no array); names as the P layout.
_Axis = namedtuple('_Axis', (
    'gain', 'bemf', 'c_v', 'inv_mass', 'fc', 'fs', 'inv_vs', 'delta', 'half_dfc', 'half_dfv',
    'nh', 'period', 'ra', 'rb', 'f0', 'k_spring', 'x0_spring', 'gms', 'dt', 'mgl', 'q0'))


@njit(**_INLINE)
def _axis(P):
    """Unpack the smooth-force and friction parameters of ``P`` into an ``_Axis``."""
    i, j = P_RIP_A, P_RIP_B
    ra = (P[i], P[i + 1], P[i + 2], P[i + 3], P[i + 4], P[i + 5], P[i + 6], P[i + 7],
          P[i + 8], P[i + 9], P[i + 10], P[i + 11], P[i + 12], P[i + 13], P[i + 14],
          P[i + 15])
    rb = (P[j], P[j + 1], P[j + 2], P[j + 3], P[j + 4], P[j + 5], P[j + 6], P[j + 7],
          P[j + 8], P[j + 9], P[j + 10], P[j + 11], P[j + 12], P[j + 13], P[j + 14],
          P[j + 15])
    return _Axis(P[P_GAIN], P[P_BEMF], P[P_DAMP] + P[P_FV], 1.0 / P[P_MASS], P[P_FC],
                 P[P_FS], 1.0 / P[P_VS], P[P_DELTA], 0.5 * P[P_DFC], 0.5 * P[P_DFV],
                 int(P[P_RIP_NH]), P[P_RIP_PERIOD], ra, rb, P[P_F0], P[P_SPRING_K],
                 P[P_SPRING_X0], P[P_GMS_ON] > 0.5, P[P_DT], P[P_GRAV_MGL], P[P_GRAV_Q0])


@njit(**_JIT)
def level_shift(P, x, v, u):
    """Rise of the dry-friction level [N] at ``(x, v)`` under the applied command ``u``.

    ``mu·|F_in| + dfc(x)``: the load-dependent friction (``load_friction``, with the
    drive force ``F_in = gain·(u − bemf·v) − damping·v`` [N]) plus the position-dependent
    one (``position_friction``, the spline packed at ``P_PF_*``); 0 without both.

    Parameters
    ----------
    P : ndarray
        Packed parameters.
    x, v : float
        Position [m] and velocity [m/s].
    u : float
        Command after saturation and delay [V] (or the model's input unit).
    """
    shift = 0.0
    mu = P[P_LF_MU]
    if mu != 0.0:
        shift = load_friction_level(P[P_GAIN] * (u - P[P_BEMF] * v) - P[P_DAMP] * v, mu)
    npf = int(P[P_PF_N])
    if npf > 0:
        shift += spline_sum(x, P, P_PF_X, P, P_PF_Y, P, P_PF_M, npf)
    return shift


def _shift(src, x, v, u):
    """Level shift [N] from a shift source: :func:`level_shift` of ``P``, or ``NO_SHIFT``.

    ``src`` is the packed ``P``, or None for an axis without load- or position-dependent
    friction (and in the GMS stages, whose friction is the elements').  The pure-Python
    form (``NUMBA_DISABLE_JIT=1``); compiled, the overload below picks
    the law from the *type* of ``src`` while typing, so no branch is left in the code.
    """
    if isinstance(src, np.ndarray):
        return level_shift(src, x, v, u)
    return NO_SHIFT


@overload(_shift, jit_options=_JIT)   # not inlined at IR level: LLVM inlines it anyway
def _shift_compiled(src, x, v, u):
    """Compile :func:`_shift`: ``level_shift`` for an array source, −0.0 for None."""
    if isinstance(src, types.Array):
        return lambda src, x, v, u: level_shift(src, x, v, u)
    return lambda src, x, v, u: NO_SHIFT


@njit(**_INLINE)
def _ripple(A, x):
    """Position-periodic force [N] at ``x`` [m]: ripple plus gravity (0 without both).

    Gravity ``mgl·sin(x − q0)`` (rotary axes) is evaluated here, with the ripple, rather
    than in :func:`_drive_force`: like the ripple, its value at the step's start is
    reused for RK4 stage 1, and an axis without it pays one comparison (a branch in the
    stage loop cost ~10 % of a PMLM step).  ``S_RIPPLE`` stores the ripple share alone.
    """
    if A.mgl == 0.0:
        if A.nh > 0:
            return ripple_sum(x, A.period, A.ra, 0, A.rb, 0, A.nh)
        return 0.0
    f = gravity_torque(x, A.mgl, A.q0)
    if A.nh > 0:
        f += ripple_sum(x, A.period, A.ra, 0, A.rb, 0, A.nh)
    return f


@njit(**_INLINE)
def _drive_force(A, x, v, u, f_ext, rip):
    """Every force except friction [N], given ripple + gravity ``rip`` [N] at ``x``."""
    f = A.gain * (u - A.bemf * v) - A.c_v * v
    f -= rip
    f -= A.f0 + A.k_spring * (x - A.x0_spring) + f_ext
    f -= A.half_dfv * abs(v)
    return f


@njit(**_INLINE)
def _sliding_friction(A, v, d, shift):
    """Static-model sliding friction [N] in direction ``d`` (±1) at velocity ``v``.

    The levels ``fc±``/``fs±`` of the asymmetry, both raised by ``shift`` [N] (the load-
    and position-dependent friction, :func:`level_shift`; ``NO_SHIFT`` without them).
    """
    fc = A.fc + d * A.half_dfc + shift
    if A.fs == A.fc:
        # no rise (Coulomb alone): the level is fc, exactly what the formula gives; its
        # decay's exp was a third of a plain axis's step (the ball-screw's bare model
        # run anchored over 20 s: 13 ms without it, 20 ms with it)
        return d * fc
    fs = A.fs + d * A.half_dfc + shift
    return d * stribeck_level(abs(v), fc, fs, A.inv_vs, A.delta)


@njit(**_INLINE)
def _breakaway(A, src, x, u, f_ext, rip):
    """At rest at ``x``: direction (±1) in which the axis breaks away, or 0 if held.

    Returns ``(direction, net force [N])``; the break-away band is ``[−fs−, fs+]`` with
    the direction-dependent levels ``fs± = fs ± dfc/2``, both raised by the load- and
    position-dependent friction at rest (shift source ``src``: ``mu·|gain·u| + dfc(x)``,
    a stuck screw under a large drive force holds more).  A level below zero
    (|dfc| > 2·fs, which the workbench may fit) counts as zero: rest with no net force
    stays rest, as the force laws say at v = 0, instead of breaking away on its own.
    """
    f_net = _drive_force(A, x, 0.0, u, f_ext, rip)
    shift = _shift(src, x, 0.0, u)
    if f_net > max(A.fs + A.half_dfc + shift, 0.0):
        return 1.0, f_net
    if f_net < -max(A.fs - A.half_dfc + shift, 0.0):
        return -1.0, f_net
    return 0.0, f_net


@njit(**_INLINE)
def _friction_at(A, src, v, d, x, x0, u, gms_force, k_stick, c_stick):
    """Friction [N] inside a step: static model in frozen direction ``d``, or GMS.

    GMS elements that stick act as springs with their micro-damping during the step
    (``gms_force + k_stick·(x−x0) + c_stick·v``: ``ż_i = v`` while sticking); treating them
    as a frozen force instead would make the explicit scheme pump energy into the
    pre-sliding oscillation.  ``gms_force`` holds the spring forces and the (frozen)
    micro-damping of the slipping elements at the step's start.  ``src`` is the shift
    source of the static model's level at ``(x, v)`` under the command ``u``.
    """
    if A.gms:
        return gms_force + k_stick * (x - x0) + c_stick * v
    return _sliding_friction(A, v, d, _shift(src, x, v, u))


@njit(**_INLINE)
def _rk4_frozen(A, src, x, v, u, f_ext, d, gms_force, k_stick, c_stick, dt, rip):
    """RK4 step of (x, v) with the friction direction ``d`` or the GMS state frozen.

    ``src`` the shift source of the friction level (:func:`_shift`).
    ``rip`` is the ripple force at the start ``x``, which the caller already has.  The
    four stages run as a loop (one inlined copy of the force laws instead of four; LLVM
    unrolls it); the weighted sums accumulate in the order ``k1 + 2k2 + 2k3 + k4``.

    Returns
    -------
    (x [m], v [m/s], stage-averaged friction [N])
    """
    xs, vs, r = x, v, rip
    sum_x = 0.0
    sum_v = 0.0
    sum_f = 0.0
    for stage in range(4):
        if stage > 0:
            r = _ripple(A, xs)
        f = _friction_at(A, src, vs, d, xs, x, u, gms_force, k_stick, c_stick)
        a = (_drive_force(A, xs, vs, u, f_ext, r) - f) * A.inv_mass
        w = 1.0 if stage == 0 or stage == 3 else 2.0
        sum_x += w * vs
        sum_v += w * a
        sum_f += w * f
        h = dt if stage == 2 else 0.5 * dt
        xs, vs = x + h * vs, v + h * a
    return x + dt / 6.0 * sum_x, v + dt / 6.0 * sum_v, sum_f / 6.0


@njit(**_INLINE)
def _static_friction_step(A, src, x, v, u, f_ext, dt, rip):
    """One step of the static (Coulomb/Stribeck/viscous) friction model with stick–slip.

    Karnopp-style switch with event location: at rest the axis stays while the net force
    is inside the break-away band; while sliding, RK4 runs with the friction direction
    frozen, and if the velocity reaches zero inside the step the integration stops at the
    zero-crossing (located by linear interpolation of v, then integrated exactly up to
    it) and the remaining time is spent stuck or sliding the other way.  ``rip`` is the
    ripple force [N] at the start ``x``; ``src`` the shift source of the friction level
    (:func:`_shift`).

    Returns
    -------
    (x [m], v [m/s], step-averaged friction [N], stuck flag)
    """
    t_left = dt
    impulse = 0.0                 # ∫ friction dt over the parts of the step done so far
    d = np.sign(v)
    event = False                 # the next RK4 call integrates up to the zero crossing
    tc = 0.0
    rounds = 0
    while rounds < 3:             # slide → rest → slide back; a third event ends at rest
        if not event and d == 0.0:
            d, f_net = _breakaway(A, src, x, u, f_ext, rip)
            if d == 0.0:          # static friction balances the net force
                return x, 0.0, (impulse + f_net * t_left) / dt, 1.0
        # one call site for both spans keeps a single inlined copy of the RK4 stages
        xn, vn, f = _rk4_frozen(A, src, x, v, u, f_ext, d, 0.0, 0.0, 0.0,
                                tc if event else t_left, rip)
        if not event:
            if vn * d > 0.0:
                return xn, vn, (impulse + f * t_left) / dt, 0.0
            tc = t_left * v / (v - vn) if v != vn else 0.0
            if tc > 0.0:
                event = True
                continue
        event = False
        impulse += f * tc
        if xn != x:
            rip = _ripple(A, xn)
        x, v, d = xn, 0.0, 0.0
        t_left -= tc
        rounds += 1
    _, f_net = _breakaway(A, src, x, u, f_ext, rip)
    return x, 0.0, (impulse + f_net * t_left) / dt, 1.0


@njit(**_INLINE)
def _delayed_command(S, u, nbuf, n0, frac):
    """Push ``u`` into the dead-time ring buffer of ``S``; return ``u(t − τ)``.

    ``τ = (n0 + frac)`` physics steps, linearly interpolated between buffer entries.
    """
    head = (int(S[S_DHEAD]) + 1) % nbuf
    S[S_DBUF + head] = u
    S[S_DHEAD] = head
    a = S[S_DBUF + (head - n0) % nbuf]
    b = S[S_DBUF + (head - n0 - 1) % nbuf]
    return (1.0 - frac) * a + frac * b


@njit(**_JIT)
def plant_advance(P, S, u, f_ext, n_sub, shift_source=None):
    """Advance ``n_sub`` physics steps ``P[P_DT]`` holding command ``u`` and load ``f_ext``.

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
    n_sub : int
        Number of physics steps.
    shift_source : None or ndarray
        Internal; drivers leave it out.  The shift source of the friction level
        (:func:`_shift`): left out, a model with load- or position-dependent friction
        is handed to :data:`_advance_shifted` (this function compiled a second time,
        with ``P`` as the source).  ``shift_source is None`` is decided while
        compiling, so each compiled version holds one law only.
    """
    if n_sub <= 0:
        return
    if shift_source is None:
        if P[P_LF_MU] != 0.0 or P[P_PF_N] > 0.0:
            _advance_shifted(P, S, u, f_ext, n_sub, P)
            return
    src = shift_source
    A = _axis(P)
    dt = A.dt
    umax = P[P_UMAX]
    if u > umax:
        u = umax
    elif u < -umax:
        u = -umax
    steps = P[P_DELAY_STEPS]
    nbuf = S.shape[0] - S_DBUF
    delayed = steps > 0.0 and nbuf >= 2
    n0 = int(np.floor(steps))
    frac = steps - n0
    n_gms = int(P[P_GMS_N])
    attraction = P[P_GMS_C]
    width = P[P_BACKLASH]
    x = S[S_X]
    v = S[S_V]
    xl = S[S_XL]
    t = S[S_T]
    stuck = S[S_STUCK]
    f_fric = S[S_FRICTION]
    ueff = u
    rip = _ripple(A, x)           # ripple at the step's start: stage 1 of every RK4 step
    # s(v) at the step's start (the end of the previous step, with the command applied
    # there): rate of slipping elements
    s_v = 0.0
    if A.gms:
        s_v = _sliding_friction(A, v, np.sign(v), _shift(src, x, v, S[S_UEFF]))
    for _ in range(n_sub):
        if delayed:
            ueff = _delayed_command(S, u, nbuf, n0, frac)
        if A.gms:
            f_gms = 0.0
            k_stick = 0.0
            c_stick = 0.0
            for i in range(n_gms):
                fi = S[S_GMS_F + i]
                f_gms += fi
                if S[S_GMS_SLIP + i] == 0.0:
                    k_stick += P[P_GMS_K + i]
                    c_stick += P[P_GMS_SIGMA + i]
                elif P[P_GMS_SIGMA + i] != 0.0:
                    # micro-damping of a slipping element, σ_i·ż_i = σ_i·Ḟ_i/k_i, frozen
                    # at the step's start (Ḟ_i from the published slip law)
                    f_gms += P[P_GMS_SIGMA + i] / P[P_GMS_K + i] * gms_slip_rate(
                        fi, P[P_GMS_ALPHA + i], attraction, s_v)
            # (GMS: the friction inside the step is the elements', no level to shift)
            xn, vn, _ = _rk4_frozen(A, None, x, v, ueff, f_ext, 0.0, f_gms, k_stick,
                                    c_stick, dt, rip)
            # the elements follow the direction-dependent Stribeck curve (fc±, fs± of the
            # asymmetry effect), so asymmetry acts on the dynamics, not only on the report;
            # load- and position-dependent friction raise it at the step's end
            s_v = _sliding_friction(A, vn, np.sign(vn), _shift(src, xn, vn, ueff))
            f_fric = gms_step(S, S_GMS_F, S, S_GMS_SLIP, P, P_GMS_ALPHA, P, P_GMS_K,
                              P, P_GMS_SIGMA, n_gms, attraction, dt, xn - x, vn, s_v)
        else:
            xn, vn, f_fric, stuck = _static_friction_step(A, src, x, v, ueff, f_ext, dt, rip)
        if xn != x:
            rip = _ripple(A, xn)
        x = xn
        v = vn
        xl = play(x, xl, width)
        t += dt
    S[S_X] = x
    S[S_V] = v
    S[S_XL] = xl
    S[S_T] = t
    S[S_STUCK] = stuck
    S[S_FRICTION] = f_fric
    if A.mgl != 0.0:              # the report is the ripple alone
        rip -= gravity_torque(x, A.mgl, A.q0)
    S[S_RIPPLE] = rip
    S[S_UEFF] = ueff


#: :func:`plant_advance` compiled on its own, called with ``shift_source = P``: the copy
#: of the step with load- and position-dependent friction (a second dispatcher, so the
#: plain version calls it without recursion)
_advance_shifted = njit(**_JIT)(getattr(plant_advance, 'py_func', plant_advance))


@njit(**_JIT)
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
