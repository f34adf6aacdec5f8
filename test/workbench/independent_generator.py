"""An independent data generator for the workbench proof suite (issue 11 item 7).

Deliberately different from the project's simulator (``motor_comp.physics`` /
``motor_comp.control``, which this module never imports — ``test_workbench_independent``
checks it):

* **integrator** — velocity-level time stepping (Moreau–Jean, as in non-smooth contact
  dynamics): semi-implicit Euler with the viscous force and the sticking GMS springs
  implicit, and dry friction as a set-valued law solved per step (the axis sticks when
  the friction needed to stop it within the step lies inside the break-away band).
  The project uses RK4 with a Karnopp switch and event location;
* **controller** — a P / PI cascade (position P, velocity PI) with velocity, acceleration
  and back-EMF feedforward, on a filtered backward-difference velocity; the project
  uses a PID on position error;
* **its own law implementations** of every effect of DESIGN.md §3 (coulomb, viscous,
  Stribeck, GMS pre-sliding with 1–3 element shapes of its own, multi-harmonic ripple,
  offset, spring, asymmetry, dead time, backlash, gravity on rotary axes);
* **experiments** users run: time-ordered back-and-forth speed sweeps (slow → fast, a
  dwell at every reversal) and chirps; log rates 100 Hz – 2 kHz; quantised, noisy
  encoder; linear or rotary axes; input logged as a voltage command (ZOH), or as a
  measured current / force (sampled from a drive whose current loop has a lag, the
  controller running faster than the log).

The output is a :class:`motor_comp.logs.run.Run` (the project's run currency; the
:mod:`motor_comp.logs` writer turns it into MCAP) and the TRUE model as a model-file
mapping (DESIGN.md §6).  Laws, as the contract states them (sign: every effect force
is subtracted, ``M·ẍ = F_in − Σ F_k``):

* ``F_in = g·(u − k_e·ẋ)`` (voltage) or ``g·i`` (current, force);
* sliding friction in direction ``d``: ``fc_d + (fs_d − fc_d)·exp(−|v/vs|^δ)`` with
  ``fc_d = fc + d·dfc/2``, ``fs_d = fs + d·dfc/2``; viscous ``fv·v + dfv/2·|v|``;
* GMS (Lampaert, Al-Bender & Swevers 2003, the published form): element ``i`` sticks
  (``dF_i = k_i·dx``) until ``F_i`` reaches ``α_i·s(v)`` in the direction of motion, then
  slips, ``dF_i/dt = sgn(v)·C·(α_i − F_i/s(v))`` with ``C`` [N/s]; a reversal makes it
  stick again; the elements carry the whole dry friction (element micro-damping
  ``sigma`` is 0 here);
* ripple ``Σ a_h sin(hωx) + b_h cos(hωx)``; offset ``f0``; spring ``k·(x − x0)``;
  gravity ``mgl·sin(q − q0)``; dead time on the applied input; backlash: a massless
  load (where the encoder reads) follows the motor through a play of width ``w``.
"""
from __future__ import annotations

import dataclasses
import math
import zlib
from typing import Any, Mapping, Sequence

import numpy as np
from numba import njit

from motor_comp.logs.run import Run
from tolerances import TOLERANCE as _TOLERANCE

#: effect names of DESIGN.md §6 this generator implements
EFFECT_NAMES = ('coulomb', 'viscous', 'stribeck', 'presliding', 'ripple', 'offset', 'spring',
                'asymmetry', 'delay', 'backlash', 'gravity')

#: effects a case needs alongside another for the law to be physical (Stribeck and GMS
#: act on a dry-friction level; asymmetry splits existing Coulomb and viscous levels)
REQUIRES = {'stribeck': ('coulomb',), 'presliding': ('coulomb',),
            'asymmetry': ('coulomb', 'viscous')}

#: GMS element shapes (α, relative k) of this generator: 1 to 3 elements, none the
#: project's 4-element (0.45, 0.30, 0.15, 0.10) shape
GMS_SHAPES = (
    ((1.0,), (1.0,)),
    ((0.7, 0.3), (0.75, 0.25)),
    ((0.35, 0.65), (0.6, 0.4)),
    ((0.2, 0.5, 0.3), (0.55, 0.35, 0.10)),
)

# ---- packed parameter vector of the plant kernel ------------------------------------
(I_M, I_G, I_KE, I_FC, I_FS, I_VS, I_DELTA, I_FV, I_DFC, I_DFV, I_F0, I_KSP, I_X0, I_MGL,
 I_Q0, I_TAU, I_W, I_PER, I_NH, I_GMS_N, I_GMS_C, I_CURRENT, I_TAU_I) = range(23)
I_RA = 23          # ripple a_h, 8 slots
I_RB = I_RA + 8    # ripple b_h, 8 slots
I_ALPHA = I_RB + 8
I_K = I_ALPHA + 4
N_PAR = I_K + 4


@njit(cache=True)
def _dry_level(speed, d, p):
    """Dry-friction magnitude [N] sliding in direction ``d`` at ``speed`` (≥ 0)."""
    fc = p[I_FC] + 0.5 * d * p[I_DFC]
    fs = p[I_FS] + 0.5 * d * p[I_DFC]
    if fs != fc:
        return fc + (fs - fc) * math.exp(-(speed / p[I_VS]) ** p[I_DELTA])
    return fc


@njit(cache=True)
def _smooth_forces(x, v, p):
    """Every memoryless force except dry friction and the implicit ``fv·v`` [N]."""
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
def _closed_loop(p, c, ref, n_ctrl, n_sub, dt, noise_y, quantum, u_max,
                 out_y, out_u, out_i, out_x):
    """Run the loop: controller at ``dt·n_sub``, plant at ``dt``.

    ``c`` = [kp 1/s, kv 1/s, ki N/(m/s)/s, mass estimate, gain estimate, k_e estimate,
    velocity-filter coefficient]; ``ref`` (n_ctrl, 3) = position, velocity, acceleration.
    Fills, per control step, the measured position, the command, the drive current
    averaged over the step (current/force drives) and the motor position.
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
    integ = 0.0
    y_prev = xl
    v_hat = 0.0
    voltage = p[I_CURRENT] < 0.5
    lag = 1.0 - math.exp(-dt / p[I_TAU_I]) if p[I_TAU_I] > 0.0 else 1.0
    half_w = 0.5 * p[I_W]
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
        i_sum = 0.0
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
            f_other = _smooth_forces(x, v, p)
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
                s_v = d * _dry_level(abs(vn), d, p) if d != 0.0 else 0.0
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
                v = vn
            else:
                # set-valued dry friction: the force that would stop the axis in this
                # step, compared with the break-away band at the current speed
                f_req = m * v / dt + f_in - f_other
                up = _dry_level(abs(v), 1.0, p)
                dn = _dry_level(abs(v), -1.0, p)
                if up < 0.0:
                    up = 0.0
                if dn < 0.0:
                    dn = 0.0
                if -dn <= f_req <= up:
                    v = 0.0
                else:
                    d = 1.0 if f_req > 0.0 else -1.0
                    lvl = up if d > 0.0 else dn
                    v = (v + dt / m * (f_in - f_other - d * lvl)) / (1.0 + dt * p[I_FV] / m)
                    if v * d < 0.0:
                        v = 0.0
                dx = dt * v
            x += dx
            if half_w > 0.0:
                if x - xl > half_w:
                    xl = x - half_w
                elif xl - x > half_w:
                    xl = x + half_w
            else:
                xl = x
        out_i[k] = i_sum / n_sub


# ---- excitation ---------------------------------------------------------------------

def _trapezoid(p0: float, p1: float, vmax: float, amax: float, dt: float) \
        -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Samples (position, velocity, acceleration) of a trapezoidal move p0 → p1."""
    dist = abs(p1 - p0)
    sgn = 1.0 if p1 >= p0 else -1.0
    if dist == 0.0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    ta = vmax / amax
    if amax * ta * ta > dist:        # triangular profile
        ta = math.sqrt(dist / amax)
        vmax = amax * ta
    tc = (dist - amax * ta * ta) / vmax
    total = 2 * ta + tc
    t = np.arange(0.0, total, dt)
    s = np.where(t < ta, 0.5 * amax * t ** 2,
                 np.where(t < ta + tc, 0.5 * amax * ta ** 2 + vmax * (t - ta),
                          dist - 0.5 * amax * (total - t) ** 2))
    vel = np.where(t < ta, amax * t, np.where(t < ta + tc, vmax, amax * (total - t)))
    acc = np.where(t < ta, amax, np.where(t < ta + tc, 0.0, -amax))
    return p0 + sgn * s, sgn * vel, sgn * acc


def sweep_reference(*, speeds: Sequence[float], stroke: float, accel: float, dt: float,
                    duration: float, dwell: float = 0.1, min_time: float = 0.6,
                    cycles: int = 2, centre: float = 0.0) -> np.ndarray:
    """Back-and-forth strokes at each speed in time order (slow → fast), repeated.

    Each speed runs ``cycles`` forward/backward pairs over a stroke of at most
    ``stroke`` (shorter at slow speeds so a stroke takes about ``min_time`` at full
    speed), centred on ``centre``, with a ``dwell`` [s] at rest at every reversal.  The
    pattern repeats (alternately fast → slow) until ``duration``.  Returns (n, 3):
    position, velocity, acceleration at step ``dt``.
    """
    n = int(round(duration / dt))

    def half_stroke(sp: float) -> float:
        return 0.5 * min(stroke, max(sp * min_time, 6 * sp * sp / accel))

    # a short run makes one cycle per speed, so that it still reaches the full travel
    one = sum(2 * (2 * half_stroke(sp) / sp + sp / accel + dwell) for sp in speeds)
    if cycles > 1 and cycles * one > duration:
        cycles = 1
    parts = []
    total = 0
    order = list(speeds)
    pos = centre
    while total < n:
        for sp in order:
            half = half_stroke(sp)
            for _ in range(cycles):
                for target in (centre + half, centre - half):
                    seg = _trapezoid(pos, target, sp, accel, dt)
                    pos = target
                    rest = int(round(dwell / dt))
                    block = np.stack(seg, axis=1)
                    still = np.tile([pos, 0.0, 0.0], (rest, 1))
                    parts += [block, still]
                    total += block.shape[0] + rest
        order = order[::-1]
    out = np.concatenate(parts)[:n]
    return out


def chirp_reference(*, f0: float, f1: float, amplitude: float, vmax: float, dt: float,
                    duration: float, centre: float = 0.0) -> np.ndarray:
    """Linear chirp ``f0 → f1`` [Hz] with the amplitude limited to peak speed ``vmax``.

    The amplitude fades in and out over 1 s (no step in velocity).  Returns (n, 3).
    """
    n = int(round(duration / dt))
    t = np.arange(n) * dt
    rate = (f1 - f0) / duration
    phase = 2 * np.pi * (f0 * t + 0.5 * rate * t ** 2)
    f = f0 + rate * t
    amp = np.minimum(amplitude, vmax / (2 * np.pi * f))
    ramp = np.clip(np.minimum(t, duration - t) / 1.0, 0.0, 1.0)
    env = amp * 0.5 * (1 - np.cos(np.pi * ramp))
    x = centre + env * np.sin(phase)
    v = np.gradient(x, dt)
    a = np.gradient(v, dt)
    return np.stack([x, v, a], axis=1)


# ---- cases --------------------------------------------------------------------------

@dataclasses.dataclass(frozen=True)
class Rig:
    """The drive and sensor side of a generated axis (SI; rad on rotary axes).

    Parameters
    ----------
    axis : str
        ``linear`` or ``rotary``.
    input : str
        ``voltage`` (ZOH command logged), ``current`` or ``force`` (measured, sampled).
    input_gain : float
        N/V, N/A (force constant) or 1 [N per N]; N·m per unit on rotary axes.
    back_emf : float
        V·s/m (V·s/rad) for voltage drives, else 0.
    mass : float
        Moving mass [kg] or inertia [kg·m²].
    rate : float
        Log rate [Hz] (100 – 2000).
    control_rate : float
        Controller rate [Hz]; equals ``rate`` for voltage drives.
    encoder : float
        Encoder quantum [m] or [rad].
    noise : float
        Position noise std [m] or [rad] before quantisation.
    current_noise : float
        Std of the logged current/force relative to its RMS.
    current_lag : float
        Current-loop time constant [s] (current/force drives).
    u_max : float
        Command saturation (V, A or N).
    travel : float
        Usable stroke [m] or [rad].
    speeds : tuple
        Sweep speeds [m/s] or [rad/s], slow → fast.
    accel : float
        Sweep acceleration [m/s²] or [rad/s²].
    """

    axis: str = 'linear'
    input: str = 'voltage'
    input_gain: float = 20.0
    back_emf: float = 10.0
    mass: float = 4.0
    rate: float = 1000.0
    control_rate: float = 1000.0
    encoder: float = 1e-6
    noise: float = 3e-7
    current_noise: float = 0.003
    current_lag: float = 2e-4
    u_max: float = 1e9
    travel: float = 0.2
    speeds: tuple = (0.004, 0.01, 0.025, 0.06, 0.14, 0.3)
    accel: float = 3.0


def draw_rig(rng: np.random.Generator, *, axis: str = 'linear', input: str = 'voltage',
             rate: float = 1000.0) -> Rig:
    """A plausible drive for ``axis``/``input``/``rate`` with drawn constants."""
    if axis == 'linear':
        mass = float(rng.uniform(2.0, 12.0))
        kw: dict[str, Any] = dict(encoder=float(rng.choice([0.5e-6, 1e-6, 2e-6])),
                                  noise=float(rng.uniform(1e-7, 5e-7)), travel=0.2,
                                  speeds=(0.004, 0.01, 0.025, 0.06, 0.14, 0.3), accel=3.0)
        gains = {'voltage': float(rng.uniform(10.0, 40.0)), 'current':
                 float(rng.uniform(20.0, 90.0)), 'force': 1.0}
        bemf = float(rng.uniform(5.0, 25.0))
    else:
        mass = float(rng.uniform(0.005, 0.05))
        counts = int(rng.choice([2 ** 16, 2 ** 18, 2 ** 20]))
        kw = dict(encoder=2 * np.pi / counts, noise=float(rng.uniform(0.0, 1e-5)),
                  travel=3.6, speeds=(0.06, 0.15, 0.4, 1.0, 2.2, 4.5), accel=30.0)
        gains = {'voltage': float(rng.uniform(0.2, 1.0)), 'current':
                 float(rng.uniform(0.1, 0.8)), 'force': 1.0}
        bemf = float(rng.uniform(0.1, 0.6))
    # a voltage command is logged where it is computed; a current/force drive runs its
    # loop faster than the log (the logged value is a sample of the measured current)
    control = rate if input == 'voltage' else 4000.0
    return Rig(axis=axis, input=input, input_gain=gains[input],
               back_emf=bemf if input == 'voltage' else 0.0, mass=mass, rate=rate,
               control_rate=float(control), **kw)


def draw_effect(name: str, rng: np.random.Generator, rig: Rig,
                present: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """Parameters of effect ``name`` drawn from physical ranges (SI; rig's axis units).

    ``present`` holds the effects drawn so far (Stribeck needs the Coulomb level).
    Forces scale with the rig: linear ranges are in N, rotary ranges in N·m.
    """
    rot = rig.axis == 'rotary'
    fscale = 0.02 if rot else 1.0             # N·m per "N" of the linear ranges
    sign = 1.0 if rng.random() < 0.5 else -1.0
    if name == 'coulomb':
        return {'fc': fscale * float(rng.uniform(6.0, 30.0))}
    if name == 'viscous':
        if rot:
            return {'fv': float(rng.uniform(0.01, 0.06))}
        return {'fv': float(rng.uniform(25.0, 120.0))}
    if name == 'stribeck':
        fc = present['coulomb']['fc']
        vs = float(rng.uniform(0.2, 0.6)) if rot else float(rng.uniform(0.006, 0.02))
        return {'fs': fc * float(rng.uniform(1.5, 2.2)), 'vs': vs,
                'delta': float(rng.uniform(0.8, 2.0))}
    if name == 'presliding':
        alpha, kshape = GMS_SHAPES[int(rng.integers(len(GMS_SHAPES)))]
        ktot = float(rng.uniform(20.0, 120.0)) if rot else float(rng.uniform(1.5e5, 8e5))
        fc = present['coulomb']['fc']
        return {'alpha': list(alpha), 'k': [ktot * s for s in kshape],
                'C': fc * float(rng.uniform(300.0, 1500.0)), 'sigma': [0.0] * len(alpha)}
    if name == 'ripple':
        if rot:
            period = 2 * np.pi / int(rng.choice([6, 8, 12, 16]))
        else:
            period = float(rng.uniform(0.006, 0.03))
        nh = int(rng.integers(1, 4))
        a1 = fscale * float(rng.uniform(3.0, 9.0))
        harm = []
        for h in range(nh):
            amp = a1 * (1.0 if h == 0 else float(rng.uniform(0.25, 0.5)) ** h)
            ph = float(rng.uniform(0, 2 * np.pi))
            harm.append([amp * math.cos(ph), amp * math.sin(ph)])
        return {'period': period, 'harmonics': harm}
    if name == 'offset':
        return {'f0': sign * fscale * float(rng.uniform(4.0, 15.0))}
    if name == 'spring':
        if rot:
            return {'k': float(rng.uniform(0.05, 0.3)), 'x0': float(rng.uniform(-0.4, 0.4))}
        return {'k': float(rng.uniform(150.0, 600.0)), 'x0': float(rng.uniform(-0.03, 0.03))}
    if name == 'asymmetry':
        fc = present['coulomb']['fc']
        fv = present['viscous']['fv']
        return {'dfc': sign * fc * float(rng.uniform(0.25, 0.6)),
                'dfv': sign * fv * float(rng.uniform(0.3, 0.7))}
    if name == 'delay':
        return {'tau': float(rng.uniform(0.0005, 0.004))}
    if name == 'backlash':
        if rot:
            return {'width': float(rng.uniform(2e-3, 1e-2))}
        return {'width': float(rng.uniform(2e-5, 1.5e-4))}
    if name == 'gravity':
        if not rot:
            raise ValueError('gravity exists on rotary axes only (on a linear axis: offset)')
        return {'mgl': float(rng.uniform(0.1, 0.6)), 'q0': float(rng.uniform(-np.pi, np.pi))}
    raise KeyError(name)


def true_model(rig: Rig, effects: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """The model-file mapping (DESIGN.md §6) of the generated axis."""
    out: dict[str, Any] = {}
    if rig.axis == 'rotary':
        out['axis'] = 'rotary'
    out.update({'input': rig.input, 'input_gain': float(rig.input_gain),
                'back_emf': float(rig.back_emf), 'mass': float(rig.mass),
                'effects': {n: dict(effects[n]) for n in EFFECT_NAMES if n in effects}})
    return out


def draw_case(names: Sequence[str], *, seed: int, axis: str = 'linear',
              input: str = 'voltage', rate: float = 1000.0) -> tuple[Rig, dict[str, Any]]:
    """A rig and the true model with effects ``names`` (plus what they require)."""
    rng = np.random.default_rng(seed)
    rig = draw_rig(rng, axis=axis, input=input, rate=rate)
    wanted = []
    for n in names:
        for req in REQUIRES.get(n, ()):
            if req not in wanted:
                wanted.append(req)
        if n not in wanted:
            wanted.append(n)
    effects: dict[str, dict[str, Any]] = {}
    for n in sorted(wanted, key=EFFECT_NAMES.index):
        effects[n] = draw_effect(n, rng, rig, effects)
    return rig, true_model(rig, effects)


def _pack(model: Mapping[str, Any], rig: Rig) -> np.ndarray:
    p = np.zeros(N_PAR)
    e = model.get('effects') or {}
    p[I_M] = model['mass']
    p[I_G] = model['input_gain']
    p[I_KE] = model.get('back_emf', 0.0)
    p[I_CURRENT] = 0.0 if model.get('input', 'voltage') == 'voltage' else 1.0
    p[I_TAU_I] = rig.current_lag
    fc = e.get('coulomb', {}).get('fc', 0.0)
    p[I_FC] = fc
    st = e.get('stribeck')
    p[I_FS] = st['fs'] if st else fc
    p[I_VS] = st['vs'] if st else 1.0
    p[I_DELTA] = st['delta'] if st else 1.0
    p[I_FV] = e.get('viscous', {}).get('fv', 0.0)
    asym = e.get('asymmetry', {})
    p[I_DFC] = asym.get('dfc', 0.0)
    p[I_DFV] = asym.get('dfv', 0.0)
    p[I_F0] = e.get('offset', {}).get('f0', 0.0)
    sp = e.get('spring', {})
    p[I_KSP] = sp.get('k', 0.0)
    p[I_X0] = sp.get('x0', 0.0)
    g = e.get('gravity', {})
    p[I_MGL] = g.get('mgl', 0.0)
    p[I_Q0] = g.get('q0', 0.0)
    p[I_TAU] = e.get('delay', {}).get('tau', 0.0)
    p[I_W] = e.get('backlash', {}).get('width', 0.0)
    rip = e.get('ripple')
    if rip:
        harm = rip['harmonics']
        p[I_PER] = rip['period']
        p[I_NH] = len(harm)
        for h, (a, b) in enumerate(harm):
            p[I_RA + h], p[I_RB + h] = a, b
    else:
        p[I_PER] = 1.0
    gms = e.get('presliding')
    if gms:
        n = len(gms['alpha'])
        p[I_GMS_N] = n
        p[I_GMS_C] = gms['C']
        p[I_ALPHA:I_ALPHA + n] = gms['alpha']
        p[I_K:I_K + n] = gms['k']
    return p


@dataclasses.dataclass(frozen=True)
class Generated:
    """A generated run, its true model and what was hidden in it.

    Attributes
    ----------
    run : Run
        The logged signals (position, logged input, reference) at the log rate.
    truth : dict
        The true model-file mapping.
    rig : Rig
        The drive and sensors.
    motor_position : ndarray
        Motor-side position at the log stamps (before backlash, noise, quantisation).
    applied : ndarray
        The input actually applied (current state or command) at the log stamps.
    """

    run: Run
    truth: dict
    rig: Rig
    motor_position: np.ndarray
    applied: np.ndarray


def write(gen: Generated, directory: str, *, start: Mapping[str, Any] | None = None) -> None:
    """Write ``run.mcap`` (the project's MCAP writer), ``truth.yaml`` and ``start.yaml``."""
    from pathlib import Path

    import yaml

    from motor_comp.logs import write_run
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    write_run(out / 'run.mcap', gen.run)
    (out / 'truth.yaml').write_text(yaml.safe_dump(gen.truth, sort_keys=False),
                                    encoding='utf-8')
    if start is not None:
        (out / 'start.yaml').write_text(yaml.safe_dump(dict(start), sort_keys=False),
                                        encoding='utf-8')


def generate(truth: Mapping[str, Any], rig: Rig, *, excitation: str = 'sweep',
             duration: float = 30.0, seed: int = 0, physics_dt: float = 2e-5,
             name: str = 'indgen') -> Generated:
    """Simulate the closed loop of ``truth`` on ``rig`` and log it.

    Parameters
    ----------
    truth : mapping
        Model-file mapping (:func:`true_model`), linear or rotary.
    rig : Rig
        Drive, sensors, rates and sweep design.
    excitation : str
        ``sweep`` (time-ordered back-and-forth speed sweep, the usual identification
        experiment) or ``chirp`` (0.2 → 3 Hz, peak speed the rig's top sweep speed).
    duration : float
        Run length [s].
    seed : int
        Seed of the noise.
    physics_dt : float
        Plant step [s] (rounded so the control period is a whole number of steps).
    name : str
        Run label.
    """
    rng = np.random.default_rng(seed)
    T = 1.0 / rig.control_rate
    n_sub = max(1, int(round(T / physics_dt)))
    dt = T / n_sub
    log_every = max(1, int(round(rig.control_rate / rig.rate)))
    n_ctrl = int(round(duration / T))
    n_ctrl -= n_ctrl % log_every
    if excitation == 'sweep':
        ref = sweep_reference(speeds=rig.speeds, stroke=rig.travel, accel=rig.accel, dt=T,
                              duration=n_ctrl * T)
    elif excitation == 'chirp':
        ref = chirp_reference(f0=0.2, f1=3.0, amplitude=0.45 * rig.travel,
                              vmax=rig.speeds[-1], dt=T, duration=n_ctrl * T)
    else:
        raise ValueError(f'excitation must be sweep or chirp, got {excitation!r}')
    p = _pack(truth, rig)
    # controller: a rough idea of the axis (±20 % mass), its own bandwidth choice; the
    # velocity estimate is low-passed at 3× the loop bandwidth (encoder-count noise)
    tau = p[I_TAU]
    wv = min(2 * np.pi * 40.0, 2 * np.pi * rig.control_rate / 25.0)
    if tau > 0:
        wv = min(wv, 0.35 / tau)
    m_est = rig.mass * float(rng.uniform(0.8, 1.2))
    c = np.array([wv / 4.0, wv, m_est * wv * wv / 6.0, m_est, rig.input_gain,
                  rig.back_emf, 1.0 - math.exp(-3.0 * wv * T)])
    n_log = n_ctrl // log_every
    noise_y = rng.normal(0.0, rig.noise, n_ctrl)
    out_y, out_u = np.zeros(n_ctrl), np.zeros(n_ctrl)
    out_i, out_x = np.zeros(n_ctrl), np.zeros(n_ctrl)
    _closed_loop(p, c, np.ascontiguousarray(ref), n_ctrl, n_sub, dt, noise_y, rig.encoder,
                 rig.u_max, out_y, out_u, out_i, out_x)
    pick = slice(0, n_ctrl, log_every)
    if rig.input == 'voltage':
        logged = out_u[pick]
        applied = out_u[pick]
    else:
        # the drive reports its measured current averaged over a window centred on the
        # stamp (a zero-phase anti-alias filter), with measurement noise
        half = log_every // 2
        cs = np.concatenate([[0.0], np.cumsum(out_i)])
        k = np.arange(0, n_ctrl, log_every)
        lo = np.clip(k - half, 0, n_ctrl)
        hi = np.clip(k - half + log_every, 0, n_ctrl)
        applied = (cs[hi] - cs[lo]) / np.maximum(hi - lo, 1)
        logged = applied + rng.normal(0.0, 1.0, n_log) * rig.current_noise \
            * float(np.sqrt(np.mean(applied ** 2)))
    t = np.arange(n_log) * (T * log_every)
    r = ref[::log_every][:n_log]
    run = Run(t=t, position=out_y[pick], reference=r[:, 0], reference_velocity=r[:, 1],
              voltage=logged, name=name,
              metadata={'generator': 'test/workbench/independent_generator.py',
                        'excitation': excitation, 'seed': str(seed)})
    return Generated(run=run, truth=dict(truth), rig=rig, motor_position=out_x[pick],
                     applied=applied)


def start_model(truth: Mapping[str, Any], *, mass_factor: float = 2.0,
                keep_effects: bool = False, changes: Mapping[str, Any] | None = None) \
        -> dict[str, Any]:
    """The model a user starts from: bare (``effects: {}``) with a wrong mass.

    ``keep_effects`` keeps the true effects (for wrong-parameter cases); ``changes``
    maps ``'input_gain'`` or ``'effect.param'`` (``'ripple.amplitude'`` scales every
    harmonic) to a factor applied to the true value.
    """
    m = {k: (dict(v) if isinstance(v, dict) else v) for k, v in truth.items()}
    m['effects'] = {n: dict(p) for n, p in truth['effects'].items()} if keep_effects else {}
    m['mass'] = truth['mass'] * mass_factor
    for key, factor in (changes or {}).items():
        if '.' not in key:
            m[key] = m[key] * factor
            continue
        eff, par = key.split('.')
        if eff == 'ripple' and par == 'amplitude':
            m['effects']['ripple']['harmonics'] = [
                [a * factor, b * factor] for a, b in truth['effects']['ripple']['harmonics']]
        else:
            m['effects'][eff][par] = m['effects'][eff][par] * factor
    return m


# ---- the proof suite (issue 11 "Must show") -----------------------------------------

@dataclasses.dataclass(frozen=True)
class Case:
    """One suite case: the plant's effects, the rig, the experiment and the start model.

    Parameters
    ----------
    names : tuple of str
        Effects planted (their requirements, :data:`REQUIRES`, are added).
    axis, input : str
        Axis kind and logged input kind.
    rate : float
        Log rate [Hz].
    excitation : str
        ``sweep`` or ``chirp``.
    mass_factor : float
        Start model's mass as a multiple of the true one.
    changes : tuple of (key, factor)
        Wrong-parameter case: the start model keeps the true effects with these
        parameters scaled (see :func:`start_model`); empty = bare start model.
    """

    names: tuple
    axis: str = 'linear'
    input: str = 'voltage'
    rate: float = 1000.0
    excitation: str = 'sweep'
    mass_factor: float = 2.0
    changes: tuple = ()

    @property
    def label(self) -> str:
        """Short name for tables and test ids."""
        what = '+'.join(self.names)
        if self.changes:
            what += ' ' + ','.join(f'{k}x{f:g}' for k, f in self.changes)
        return (f'{what} [{self.axis[:3]} {self.input[:3]} {self.rate:g}Hz '
                f'{self.excitation} m{self.mass_factor:g}]')

    def draw(self, seed: int) -> tuple[Rig, dict[str, Any]]:
        """Rig and true model of this case for ``seed`` (different rigs across cases)."""
        salt = zlib.crc32(self.label.encode()) % 100000
        return draw_case(self.names, seed=100000 * seed + salt, axis=self.axis,
                         input=self.input, rate=self.rate)

    def start(self, truth: Mapping[str, Any]) -> dict[str, Any]:
        """The start model handed to the workbench."""
        return start_model(truth, mass_factor=self.mass_factor,
                           keep_effects=bool(self.changes), changes=dict(self.changes))


def _c(names: str, axis: str = 'linear', input: str = 'voltage', rate: float = 1000.0,
       excitation: str = 'sweep', mass_factor: float = 2.0, changes: tuple = ()) -> Case:
    return Case(tuple(names.split('+')), axis, input, rate, excitation, mass_factor, changes)


#: every effect alone (with what its law requires), from ``effects: {}`` and a wrong mass
ALONE = (
    _c('coulomb'),
    _c('viscous', input='current', rate=500.0, mass_factor=0.6),
    _c('stribeck'),
    _c('presliding', rate=2000.0, mass_factor=0.6),
    _c('ripple', input='force', excitation='chirp'),
    _c('offset', rate=200.0, mass_factor=0.6),
    _c('spring', input='current'),
    _c('asymmetry', mass_factor=0.6),
    _c('delay', excitation='chirp'),
    _c('backlash', rate=2000.0, mass_factor=0.6),
    _c('gravity', axis='rotary', input='current', rate=100.0),
)

#: combinations of 2–4 effects (linear and rotary, every input kind, 100 Hz – 2 kHz).
#: Never ``spring`` with ``offset``: ``k·(x − x0) + f0`` has one constant term, so only
#: ``f0 − k·x0`` is identifiable (the pair is one effect, not two); nor ``offset`` with
#: ``asymmetry`` alone (``dfc/2`` is a constant while sliding).
COMBOS = (
    _c('coulomb+viscous'),
    _c('coulomb+viscous+ripple', mass_factor=0.6),
    _c('coulomb+viscous+offset', input='current', rate=500.0),
    _c('coulomb+viscous+spring', excitation='chirp', mass_factor=0.6),
    _c('coulomb+viscous+delay'),
    _c('coulomb+viscous+backlash', rate=2000.0, mass_factor=0.6),
    _c('coulomb+viscous+stribeck'),
    _c('coulomb+viscous+presliding', rate=2000.0, mass_factor=0.6),
    _c('coulomb+viscous+asymmetry+ripple', input='force'),
    _c('coulomb+viscous+gravity', axis='rotary', input='current', rate=100.0,
       mass_factor=0.6),
    _c('coulomb+viscous+gravity+ripple', axis='rotary', input='current', rate=500.0),
    _c('coulomb+viscous+gravity+offset', axis='rotary', mass_factor=0.6),
    _c('ripple+offset', input='force', rate=2000.0, excitation='chirp'),
    _c('viscous+spring', input='current', rate=200.0, mass_factor=0.6),
    _c('coulomb+ripple+delay', excitation='chirp'),
    _c('coulomb+viscous+stribeck+ripple', input='current', mass_factor=0.6),
    _c('coulomb+viscous+spring+ripple', rate=500.0),
    _c('coulomb+backlash+ripple', rate=2000.0, mass_factor=0.6),
    _c('viscous+delay+offset'),
    _c('coulomb+viscous+ripple', axis='rotary', rate=2000.0, excitation='chirp',
       mass_factor=0.6),
    _c('coulomb+viscous+spring+gravity', axis='rotary', input='current', rate=200.0),
    _c('coulomb+presliding+ripple', rate=2000.0, mass_factor=0.6),
    _c('coulomb+viscous+stribeck+delay'),
)

#: wrong parameters in a model with the right effects: the finding is the parameter
WRONG = (
    _c('coulomb+viscous', mass_factor=1.0, changes=(('coulomb.fc', 1.4),)),
    _c('coulomb+viscous+offset', input='current', mass_factor=1.0,
       changes=(('viscous.fv', 0.6),)),
    _c('coulomb+viscous', mass_factor=1.0, changes=(('input_gain', 1.3),)),
    _c('coulomb+viscous+ripple', input='force', mass_factor=1.0,
       changes=(('ripple.amplitude', 0.7),)),
    _c('coulomb+viscous+gravity', axis='rotary', input='current', rate=500.0,
       mass_factor=1.0, changes=(('coulomb.fc', 0.6),)),
)

#: the whole suite
CASES = ALONE + COMBOS + WRONG

#: relative tolerance on each effect's main parameters: those of the project's
#: hidden-effect test (:mod:`tolerances`)
TOLERANCE = _TOLERANCE

#: absolute tolerances [SI] (delay to 0.1 ms; rotary x0/q0 in rad)
ABS_TOLERANCE = {
    'delay': {'tau': 1e-4},
    'spring': {'x0': 2e-3},
    'stribeck': {'delta': 0.7},
    'gravity': {'q0': 0.05},
}
ABS_TOLERANCE_ROTARY = {'spring': {'x0': 0.05}}
#: mass / inertia and input gain
MASS_TOLERANCE = 0.03


def main_params(name: str, params: Mapping[str, Any]) -> dict[str, float]:
    """Scalar main parameters of an effect's model-file params (names of TOLERANCE)."""
    if name == 'presliding':
        return {'stiffness': float(sum(params['k']))}
    if name == 'ripple':
        a, b = params['harmonics'][0]
        return {'period': float(params['period']), 'amplitude_1': float(math.hypot(a, b))}
    return {k: float(v) for k, v in params.items() if isinstance(v, (int, float))}


def parameter_errors(truth: Mapping[str, Any], fitted: Mapping[str, Any]) \
        -> list[tuple[str, str, float, float, float, bool]]:
    """``(effect, param, true, fitted, error, within tolerance)`` of every main parameter.

    The error is relative where :data:`TOLERANCE` is, absolute where
    :data:`ABS_TOLERANCE` is; effects missing from ``fitted`` are skipped (the effect
    set is judged separately).  Includes ``mass`` and ``input_gain``.
    """
    out = []
    for key in ('mass', 'input_gain'):
        err = fitted[key] / truth[key] - 1.0
        out.append(('', key, truth[key], fitted[key], err, abs(err) <= MASS_TOLERANCE))
    rot = truth.get('axis') == 'rotary'
    fe = fitted.get('effects') or {}
    for name, tp in (truth.get('effects') or {}).items():
        if name not in fe:
            continue
        t, f = main_params(name, tp), main_params(name, fe[name])
        for key, rel in TOLERANCE.get(name, {}).items():
            err = f[key] / t[key] - 1.0
            out.append((name, key, t[key], f[key], err, abs(err) <= rel))
        absol = dict(ABS_TOLERANCE.get(name, {}))
        if rot:
            absol.update(ABS_TOLERANCE_ROTARY.get(name, {}))
        for key, tol in absol.items():
            err = f[key] - t[key]
            if name == 'gravity' and key == 'q0':
                err = math.remainder(err, 2 * math.pi)
            out.append((name, key, t[key], f[key], err, abs(err) <= tol))
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """Write one suite case as files: ``python independent_generator.py LABEL-PREFIX -o DIR``.

    Then e.g. ``motor-comp fit DIR/run.mcap --model DIR/start.yaml --auto``.
    """
    import argparse
    p = argparse.ArgumentParser(description=main.__doc__.splitlines()[0])
    p.add_argument('case', help='start of a case label, e.g. "coulomb+viscous [" (or "list")')
    p.add_argument('--seed', type=int, default=1)
    p.add_argument('--duration', type=float, default=20.0)
    p.add_argument('-o', '--out', default='indgen_case')
    a = p.parse_args(argv)
    if a.case == 'list':
        print('\n'.join(c.label for c in CASES))
        return 0
    hits = [c for c in CASES if c.label.startswith(a.case)]
    if not hits:
        p.error(f'no case label starts with {a.case!r} (try "list")')
    case = hits[0]
    rig, truth = case.draw(a.seed)
    gen = generate(truth, rig, excitation=case.excitation, duration=a.duration, seed=a.seed,
                   name=case.label)
    write(gen, a.out, start=case.start(truth))
    print(f'{case.label} seed {a.seed}: {a.out}/run.mcap, truth.yaml, start.yaml')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
