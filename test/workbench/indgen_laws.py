"""The independent generator's effect laws and closed-loop kernel (numba).

Part of the independent data generator (:mod:`independent_generator` is the public
face).  Never imports ``motor_comp.physics`` / ``motor_comp.control``: every law here is
this generator's own implementation, written from the contract's words (DESIGN.md §3,
§6) or, for the effects the library does not have, from the physics named below.

Sign convention of the contract: every effect force is subtracted,
``M·ẍ = F_in − Σ F_k``; a positive friction opposes positive velocity.

Dry friction (sliding in direction ``d = ±1`` at speed ``|v|``; one magnitude, the
*level*, that every dry-friction effect adds to):

* Coulomb / Stribeck / asymmetry: ``fc_d + (fs_d − fc_d)·exp(−|v/vs|^δ)``,
  ``fc_d = fc + d·dfc/2``, ``fs_d = fs + d·dfc/2`` [N];
* ``load_friction`` (library, DESIGN.md §6): ``+ mu·|F_in|`` — the drive force loads the
  screw/gear contacts (efficiency of a screw or gear train: the friction torque grows
  with the transmitted torque, e.g. Olsson et al. 1998, "Friction models and friction
  compensation", §2 on load-dependent Coulomb friction).  It shifts the break-away
  level as well, so a stuck axis holds more under a large drive force;
* ``position_friction`` (library): ``+ dfc(x)``, a tight spot along the travel.  This
  generator's interpolation through the knots is a cubic Hermite spline with
  Catmull–Rom (centred-chord) tangents and zero end slopes (Catmull & Rom 1974), C¹ and
  constant beyond the end knots — not the library's interpolation, on purpose;
* ``friction_drift`` (out of library): warm-up of the lubricant, ``+ Δ·(e^{−t/τ} − ē)``
  with ``ē = τ/T·(1 − e^{−T/τ})`` the drift's mean over the run ``[0, T]``, so the
  model's ``coulomb.fc`` is the run's average level (the constant a complete in-library
  model fits) and the level falls (Δ > 0) or rises (Δ < 0) with time only;
* ``speed_dip`` (out of library): a lubrication regime in a speed band,
  ``− D·exp(−½((|v| − v_d)/w)²)`` — friction lower around ``v_d``, not monotone in speed
  (no Stribeck curve has it);
* ``reversal_transient`` (out of library): a lip seal flips over at a reversal and
  drags more until it has settled, ``+ R·exp(−s/λ)``, ``s`` the distance travelled
  since the last change of the direction of motion (a start from rest in the opposite
  direction is a reversal; so is the first motion of the run).  Millimetres, not the
  micrometres of pre-sliding, and a level that *decays* with distance where GMS rises.

Forces that are not friction (same sign in both directions of motion; explicit):

* offset ``f0``, spring ``k·(x − x0)``, gravity ``mgl·sin(q − q0)``, ripple
  ``Σ a_h sin(hωx) + b_h cos(hωx)``, the asymmetric viscous part ``dfv/2·|v|``;
* ``drag`` (out of library): hydrodynamic/aerodynamic drag ``c·v·|v|`` [N·s²/m²]
  (a part moving through oil or coolant, a fan or impeller on a rotary shaft) — odd in
  ``v`` but quadratic, not the library's linear viscous law;
* ``bump`` (out of library): a cable snag or a seal at one place of the travel,
  ``A·exp(−½((x − x_b)/w)²)`` [N] — one bump, not periodic, the same sign in both
  directions (a force, not a friction);
* ``disturbance`` (out of library): an unbalanced fan or pump on the machine frame,
  ``A·sin(2π·f·t + φ)`` [N] at a fixed *time* frequency, tied to neither position nor
  speed.

GMS pre-sliding (Lampaert, Al-Bender & Swevers 2003, the published form): element ``i``
sticks (``dF_i = k_i·dx``) until ``F_i`` reaches ``α_i·s(v)`` in the direction of motion,
then slips, ``dF_i/dt = sgn(v)·C·(α_i − F_i/s(v))``; ``s(v)`` is the whole dry level
above (so every dry-friction effect acts through the elements when GMS is present).
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

# ---- packed parameter vector of the plant kernel ------------------------------------
(I_M, I_G, I_KE, I_FC, I_FS, I_VS, I_DELTA, I_FV, I_DFC, I_DFV, I_F0, I_KSP, I_X0, I_MGL,
 I_Q0, I_TAU, I_W, I_PER, I_NH, I_GMS_N, I_GMS_C, I_CURRENT, I_TAU_I) = range(23)
I_RA = 23          # ripple a_h, 8 slots
I_RB = I_RA + 8    # ripple b_h, 8 slots
I_ALPHA = I_RB + 8
I_K = I_ALPHA + 4
# the two new library effects
I_MU = I_K + 4                 # load_friction mu [-]
I_PF_N = I_MU + 1              # position_friction: number of knots (0 = absent)
MAX_KNOTS = 32
I_PF_X = I_PF_N + 1            # knot positions [m | rad]
I_PF_D = I_PF_X + MAX_KNOTS    # knot values [N | N·m]
I_PF_M = I_PF_D + MAX_KNOTS    # Hermite tangents at the knots [N/m]
# effects no unit of the library models
I_DR_D = I_PF_M + MAX_KNOTS    # friction_drift Δ [N]
I_DR_TAU = I_DR_D + 1          # its time constant τ [s]
I_DR_MEAN = I_DR_D + 2         # ē, the mean of e^{−t/τ} over the run [-]
I_DI_A = I_DR_D + 3            # disturbance amplitude [N]
I_DI_F = I_DR_D + 4            # its frequency [Hz]
I_DI_PH = I_DR_D + 5           # its phase [rad]
I_DG_C = I_DR_D + 6            # drag c [N·s²/m²]
I_BU_A = I_DR_D + 7            # bump amplitude [N]
I_BU_X = I_DR_D + 8            # its centre [m]
I_BU_W = I_DR_D + 9            # its width (standard deviation) [m]
I_SD_D = I_DR_D + 10           # speed_dip depth [N]
I_SD_V = I_DR_D + 11           # its centre speed [m/s]
I_SD_W = I_DR_D + 12           # its width [m/s]
I_RT_R = I_DR_D + 13           # reversal_transient height [N]
I_RT_L = I_DR_D + 14           # its decay distance λ [m]
N_PAR = I_DR_D + 15

#: effects no unit of the library models, in the column order of the kernel's
#: ``out_extra`` record
EXTRA_NAMES = ('friction_drift', 'disturbance', 'drag', 'bump', 'speed_dip',
               'reversal_transient')
#: of those, the ones that change the dry-friction level (friction-like: they flip
#: with the direction of motion)
DRY_EXTRAS = ('friction_drift', 'speed_dip', 'reversal_transient')


def hermite_tangents(x: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Compute Catmull–Rom tangents [N/m] of the knots ``(x, d)``: centred chords, flat ends.

    Parameters
    ----------
    x : ndarray
        Strictly increasing knot positions [m] (or [rad]).
    d : ndarray
        Knot values [N] (or [N·m]).

    Returns
    -------
    ndarray
        ``m_j = (d_{j+1} − d_{j−1}) / (x_{j+1} − x_{j−1})`` inside, 0 at both ends (so the
        curve joins the constant continuation beyond the end knots with a continuous
        slope; Catmull & Rom 1974).
    """
    x = np.asarray(x, dtype=float)
    d = np.asarray(d, dtype=float)
    m = np.zeros_like(d)
    if len(x) > 2:
        m[1:-1] = (d[2:] - d[:-2]) / (x[2:] - x[:-2])
    return m


@njit(cache=True)
def hermite_eval(xq, n, p):
    """Evaluate the position_friction level ``dfc(xq)`` [N] at packed knots (Hermite)."""
    x0 = p[I_PF_X]
    xn = p[I_PF_X + n - 1]
    if xq <= x0:
        return p[I_PF_D]
    if xq >= xn:
        return p[I_PF_D + n - 1]
    j = 0
    while p[I_PF_X + j + 1] < xq:
        j += 1
    h = p[I_PF_X + j + 1] - p[I_PF_X + j]
    s = (xq - p[I_PF_X + j]) / h
    s2 = s * s
    s3 = s2 * s
    return ((2.0 * s3 - 3.0 * s2 + 1.0) * p[I_PF_D + j]
            + (s3 - 2.0 * s2 + s) * h * p[I_PF_M + j]
            + (-2.0 * s3 + 3.0 * s2) * p[I_PF_D + j + 1]
            + (s3 - s2) * h * p[I_PF_M + j + 1])


@njit(cache=True)
def _dry_extra(speed, x, t, f_in, s_rev, p, out):
    """Sum the dry-level terms beyond Coulomb/Stribeck/asymmetry [N]; fill ``out``.

    ``out`` (3,) receives the friction_drift, speed_dip and reversal_transient parts
    (the out-of-library ones, for the record); the return value is their sum plus
    load_friction and position_friction.
    """
    add = 0.0
    if p[I_MU] != 0.0:
        add += p[I_MU] * abs(f_in)
    n = int(p[I_PF_N])
    if n > 0:
        add += hermite_eval(x, n, p)
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    if p[I_DR_D] != 0.0:
        out[0] = p[I_DR_D] * (math.exp(-t / p[I_DR_TAU]) - p[I_DR_MEAN])
    if p[I_SD_D] != 0.0:
        z = (speed - p[I_SD_V]) / p[I_SD_W]
        out[1] = -p[I_SD_D] * math.exp(-0.5 * z * z)
    if p[I_RT_R] != 0.0:
        out[2] = p[I_RT_R] * math.exp(-s_rev / p[I_RT_L])
    return add + out[0] + out[1] + out[2]


@njit(cache=True)
def _dry_level(speed, d, p):
    """Return the Coulomb/Stribeck/asymmetry level [N] sliding in direction ``d`` at ``speed``."""
    fc = p[I_FC] + 0.5 * d * p[I_DFC]
    fs = p[I_FS] + 0.5 * d * p[I_DFC]
    if fs != fc:
        return fc + (fs - fc) * math.exp(-(speed / p[I_VS]) ** p[I_DELTA])
    return fc


@njit(cache=True)
def _smooth_forces(x, v, p):
    """Sum every memoryless in-library force except dry friction and the implicit ``fv·v``."""
    f = p[I_F0] + p[I_KSP] * (x - p[I_X0]) + 0.5 * p[I_DFV] * abs(v)
    if p[I_MGL] != 0.0:
        f += p[I_MGL] * math.sin(x - p[I_Q0])
    nh = int(p[I_NH])
    if nh > 0:
        w = 2.0 * math.pi / p[I_PER]
        for h in range(nh):
            f += p[I_RA + h] * math.sin((h + 1) * w * x) + p[I_RB + h] * math.cos((h + 1) * w * x)
    return f


@njit(cache=True)
def _smooth_extra(x, v, t, p, out):
    """Sum the out-of-library forces that are not friction [N]; fill ``out`` (3,).

    ``out`` = disturbance ``A·sin(2πft + φ)``, drag ``c·v·|v|``, bump
    ``A·exp(−½((x − x_b)/w)²)``; returns their sum.
    """
    out[0] = 0.0
    out[1] = 0.0
    out[2] = 0.0
    if p[I_DI_A] != 0.0:
        out[0] = p[I_DI_A] * math.sin(2.0 * math.pi * p[I_DI_F] * t + p[I_DI_PH])
    if p[I_DG_C] != 0.0:
        out[1] = p[I_DG_C] * v * abs(v)
    if p[I_BU_A] != 0.0:
        z = (x - p[I_BU_X]) / p[I_BU_W]
        out[2] = p[I_BU_A] * math.exp(-0.5 * z * z)
    return out[0] + out[1] + out[2]


@njit(cache=True)
def closed_loop(p, c, ref, n_ctrl, n_sub, dt, noise_y, quantum, u_max,
                out_y, out_u, out_i, out_x, out_v, out_fin, out_fric, out_extra):
    """Run the loop: controller at ``dt·n_sub``, plant at ``dt`` (velocity-level stepping).

    ``c`` = [kp 1/s, kv 1/s, ki N/(m/s)/s, mass estimate, gain estimate, k_e estimate,
    velocity-filter coefficient]; ``ref`` (n_ctrl, 3) = position, velocity, acceleration.
    Fills, per control step: the measured position, the command, the drive current
    averaged over the step (current/force drives) and the motor position and velocity at
    the step's start; the drive force, the dry-friction force and each out-of-library
    force (columns of :data:`EXTRA_NAMES`) averaged over the step [N].
    """
    T = dt * n_sub
    x = 0.0 + ref[0, 0]
    v = 0.0
    xl = x
    cur = 0.0
    n_el = int(p[I_GMS_N])
    gf = np.zeros(4)            # GMS element forces [N]
    gslip = np.zeros(4)         # 0 stick, ±1 slipping in that direction
    u_hist = np.zeros(n_ctrl)
    dry_parts = np.zeros(3)     # out-of-library dry-level terms of the current step
    smooth_parts = np.zeros(3)  # out-of-library forces of the current step
    integ = 0.0
    y_prev = xl
    v_hat = 0.0
    voltage = p[I_CURRENT] < 0.5
    lag = 1.0 - math.exp(-dt / p[I_TAU_I]) if p[I_TAU_I] > 0.0 else 1.0
    half_w = 0.5 * p[I_W]
    last_dir = 0.0              # direction of the last motion (reversal_transient)
    s_rev = 0.0                 # distance travelled since that direction began [m]
    for k in range(n_ctrl):
        # -- measure (encoder on the load side), estimate velocity ------------------
        y = xl + noise_y[k]
        if quantum > 0.0:
            y = quantum * math.floor(y / quantum + 0.5)
        if k > 0:
            v_hat += c[6] * ((y - y_prev) / T - v_hat)
        y_prev = y
        # -- P / PI cascade with feedforward --------------------------------------
        e = ref[k, 0] - y
        ev = ref[k, 1] + c[0] * e - v_hat
        force = c[3] * (ref[k, 2] + c[1] * ev) + integ
        u = force / c[4]
        if voltage:
            u += c[5] * ref[k, 1]
        if u > u_max:
            u = u_max
        elif u < -u_max:
            u = -u_max
        else:
            integ += c[2] * ev * T          # conditional integration (anti-windup)
        u_hist[k] = u
        out_y[k] = y
        out_u[k] = u
        out_x[k] = x
        out_v[k] = v
        i_sum = 0.0
        fin_sum = 0.0
        fric_sum = 0.0
        for j in range(6):
            out_extra[k, j] = 0.0
        # -- plant: n_sub steps of velocity-level time stepping ---------------------
        for s in range(n_sub):
            t_mid = k * T + (s + 0.5) * dt - p[I_TAU]
            if t_mid < 0.0:
                u_app = 0.0
            else:
                idx = int(t_mid / T)
                u_app = u_hist[idx] if idx <= k else u_hist[k]
            if voltage:
                f_in = p[I_G] * (u_app - p[I_KE] * v)
            else:
                cur += lag * (u_app - cur)
                i_sum += cur
                f_in = p[I_G] * cur
            t_now = k * T + (s + 0.5) * dt
            f_other = _smooth_forces(x, v, p) + _smooth_extra(x, v, t_now, p, smooth_parts)
            m = p[I_M]
            if n_el > 0:
                # GMS: sticking elements are springs, taken implicitly with fv
                fg = 0.0
                ks = 0.0
                for i in range(n_el):
                    fg += gf[i]
                    if gslip[i] == 0.0:
                        ks += p[I_K + i]
                vn = (v + dt / m * (f_in - f_other - fg)) / (1.0 + dt * p[I_FV] / m
                                                             + dt * dt * ks / m)
                dx = dt * vn
                d = 1.0 if vn > 0.0 else (-1.0 if vn < 0.0 else 0.0)
                s_v = 0.0
                if d != 0.0:
                    sr = s_rev if d == last_dir else 0.0
                    lvl = _dry_level(abs(vn), d, p) + _dry_extra(abs(vn), x, t_now, f_in,
                                                                 sr, p, dry_parts)
                    s_v = d * lvl
                for i in range(n_el):
                    if gslip[i] != 0.0 and gslip[i] != d:
                        gslip[i] = 0.0
                    if gslip[i] == 0.0:
                        fi = gf[i] + p[I_K + i] * dx
                        lim = p[I_ALPHA + i] * abs(s_v)
                        if d != 0.0 and abs(fi) >= lim and fi * d > 0.0:
                            fi = d * lim
                            gslip[i] = d
                        gf[i] = fi
                    else:
                        # published slip law dF/dt = sgn(v)·C·(α − F/s(v)): exact at
                        # constant v, its rate follows the Stribeck curve
                        tgt = p[I_ALPHA + i] * s_v
                        gf[i] = tgt - (tgt - gf[i]) * math.exp(-p[I_GMS_C] * dt / abs(s_v))
                fric = 0.0
                for i in range(n_el):
                    fric += gf[i]
                v = vn
            else:
                # set-valued dry friction: the force that would stop the axis in this
                # step, compared with the break-away band at the current speed
                f_req = m * v / dt + f_in - f_other
                sr_up = s_rev if last_dir == 1.0 else 0.0
                sr_dn = s_rev if last_dir == -1.0 else 0.0
                up = _dry_level(abs(v), 1.0, p) + _dry_extra(abs(v), x, t_now, f_in, sr_up,
                                                             p, dry_parts)
                dn = _dry_level(abs(v), -1.0, p) + _dry_extra(abs(v), x, t_now, f_in,
                                                              sr_dn, p, dry_parts)
                if up < 0.0:
                    up = 0.0
                if dn < 0.0:
                    dn = 0.0
                d = 0.0
                if -dn <= f_req <= up:
                    v = 0.0
                    fric = f_req
                else:
                    d = 1.0 if f_req > 0.0 else -1.0
                    lvl = up if d > 0.0 else dn
                    if d > 0.0:
                        # the record needs the parts of the direction taken
                        _dry_extra(abs(v), x, t_now, f_in, sr_up, p, dry_parts)
                    v = (v + dt / m * (f_in - f_other - d * lvl)) / (1.0 + dt * p[I_FV] / m)
                    fric = d * lvl
                    if v * d < 0.0:
                        v = 0.0
                        fric = f_req
                        d = 0.0
                dx = dt * v
            # -- the record: drive force, dry friction, out-of-library forces -------
            fin_sum += f_in
            fric_sum += fric
            out_extra[k, 1] += smooth_parts[0]
            out_extra[k, 2] += smooth_parts[1]
            out_extra[k, 3] += smooth_parts[2]
            if d != 0.0 and v != 0.0:
                out_extra[k, 0] += d * dry_parts[0]
                out_extra[k, 4] += d * dry_parts[1]
                out_extra[k, 5] += d * dry_parts[2]
            # -- reversal memory: distance since the direction of motion last changed
            if v != 0.0:
                dnow = 1.0 if v > 0.0 else -1.0
                if dnow != last_dir:
                    last_dir = dnow
                    s_rev = 0.0
                s_rev += abs(dx)
            x += dx
            if half_w > 0.0:
                if x - xl > half_w:
                    xl = x - half_w
                elif xl - x > half_w:
                    xl = x + half_w
            else:
                xl = x
        out_i[k] = i_sum / n_sub
        out_fin[k] = fin_sum / n_sub
        out_fric[k] = fric_sum / n_sub
        for j in range(6):
            out_extra[k, j] /= n_sub
