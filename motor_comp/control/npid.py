"""Nonlinear PID (Chiew et al. eq. 6–9) and the loop-shaping design of its base PID.

``u = k(e)·(Kp·e + Ki·∫e + Kd·ė)`` with the sector-bounded gain (eq. 6)::

    k(e) = cosh(k0·e)        for |e| <= e_max        (= (e^{k0 e} + e^{−k0 e})/2)
    k(e) = cosh(k0·e_max)    beyond,

Chiew: ``k0 = 15 /mm``, ``e_max = 0.1 mm`` (k(e_max) = cosh 1.5 ≈ 2.35) on tracking
errors of 0.1–0.5 mm, and the bound ``k(e_max) <= 1/|Re G_ol(jω*)|`` from the Popov plot
(eq. 9; ≈ 2.9 in the paper).  Our defaults keep ``k0·e_max = 1.5`` but scale ``e_max``
to this plant's N-PID study, where the feedforward leaves peak errors of 35–55 µm:
``e_max = 40 µm``, ``k0 = 37.5 /mm`` (with the paper's values k(e) <= 1.27 there: the
N-PID would be the PID).  :func:`popov_limit` computes the bound on the *sampled* loop
and :func:`npid_gain` clamps to it, so the gain is continuous, even in ``e`` and bounded
in ``[1, k_max]``.

The base PID is designed by loop shaping on the linear ball-screw model with its dead
time, ``G(s) = A·e^{−τs}/(s² + B·s + C)`` (Chiew eq. 1), towards the paper's Table IV
(GM 9.9 dB at 184 Hz, PM 54.2° at 64.9 Hz, bandwidth 38.5 Hz — the bandwidth is read
off the sensitivity function, Fig. 6, i.e. where |S| first reaches −3 dB, the
definition of Skogestad & Postlethwaite, Chiew ref. [16]).  :func:`design_pid` does
it either on the continuous loop (the paper's design) or, as the defaults are made, on
the loop as it runs (:func:`sampled_loop`: zero-order hold, the 1.29 ms dead time,
discrete integrator, backward-difference velocity and a derivative filter of at least
T/2).  At 1 kHz the margins are met (GM 9.9 dB, PM 54.2°) but the bandwidth is 20.9 Hz,
not 38.5 Hz: the dead time plus the hold (1.79 ms) cost 20° of phase at 31 Hz, and with
a filtered derivative the PID's lead cannot buy back more.  No rate reaches 38.5 Hz with
GM 9.9 dB and PM 54° held (filter >= T/2): 2 kHz 25 Hz, 10 kHz 30 Hz, 100 kHz 34 Hz
(``bench/reproduce_papers.py``); the bandwidth saturates near 34 Hz as T → 0 because the
1.29 ms delay alone already costs 16° at 34 Hz.  Chiew's continuous design reaches
38.9 Hz only by giving up 0.6 dB of gain margin (GM 9.3 dB) with an unfiltered
derivative (T_f = 10 µs), i.e. Table IV's three figures are not simultaneously
reachable on this stand-in plant at any rate; at 1 kHz that design keeps 4.4 dB / 31°.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from numba import njit

from motor_comp.control._jitcache import JIT_INLINE
from motor_comp.control.params import spec
from motor_comp.control.pid import PIDParams
from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel


@dataclasses.dataclass(frozen=True)
class NPIDParams(PIDParams):
    """N-PID tunables: the base PID's (the ball-screw loop-shaping design) and k(e)."""

    label = 'npid'
    k0: float = spec(37500.0, '1/m', 'rate of the nonlinear gain (Chiew: 15 /mm at his '
                     '0.1 mm error scale; here 37.5 /mm)', 0.0, 1e7)
    e_max: float = spec(4e-5, 'm', 'error range of the nonlinear gain (Chiew: 0.1 mm; '
                        'here 0.04 mm)', 1e-9, 1.0)
    k_max: float = spec(0.0, '-', 'upper bound of k(e); 0 = Popov limit of the plant',
                        0.0, 100.0)


@njit(**JIT_INLINE)
def npid_gain(e, k0, e_max, k_max):
    """Nonlinear gain k(e) [-] of Chiew eq. 6, saturated at |e| = e_max and at ``k_max``."""
    a = abs(e)
    if a > e_max:
        a = e_max
    k = np.cosh(k0 * a)
    if k_max > 0.0 and k > k_max:
        k = k_max
    return k


# ---- frequency-domain design --------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class LoopMargins:
    """Stability margins of an open loop ``L(jω)``.

    Attributes
    ----------
    gain_margin_db : float
        Gain margin [dB] at the phase crossover above the gain crossover.
    phase_margin_deg : float
        Phase margin [deg] at the (last) gain crossover.
    crossover_hz, phase_crossover_hz : float
        Gain and phase crossover frequencies [Hz].
    bandwidth_hz : float
        Frequency [Hz] where |S| = |1/(1+L)| first reaches 1/√2.
    """

    gain_margin_db: float
    phase_margin_deg: float
    crossover_hz: float
    phase_crossover_hz: float
    bandwidth_hz: float


def frequency_grid(w_min: float = 1.0, w_max: float = 1e5, n: int = 20000) -> np.ndarray:
    """Log-spaced angular frequencies [rad/s]."""
    return np.logspace(math.log10(w_min), math.log10(w_max), n)


def linear_plant_response(model: AxisModel, w: np.ndarray, *, delay: float) -> np.ndarray:
    """``G(jω)`` [m/V] of the linear axis ``g/M·e^{−τs}/(s² + B·s + C)`` (Chiew eq. 1).

    ``B = (damping + input_gain·back_emf)/M`` and ``C = spring.k/M``; friction is not
    part of the linear model (it is the disturbance the feedforward cancels).
    """
    s = 1j * np.asarray(w, dtype=float)
    m = model.mass
    b = (model.damping + model.input_gain * model.back_emf) / m
    spring = model.get('spring')
    c = spring.k / m if spring is not None else 0.0
    return model.input_gain / m * np.exp(-delay * s) / (s * s + b * s + c)


def pid_response(kp: float, ki: float, kd: float, tf: float, w: np.ndarray) -> np.ndarray:
    """``C(jω) = Kp + Ki/s + Kd·s/(T_f·s + 1)`` [V/m]."""
    s = 1j * np.asarray(w, dtype=float)
    return kp + ki / s + kd * s / (tf * s + 1.0)


def loop_margins(L: np.ndarray, w: np.ndarray) -> LoopMargins:
    """Margins of the sampled open loop ``L`` on the grid ``w`` [rad/s].

    Computed here with numpy because the design optimiser evaluates it thousands of
    times; the tests cross-check it against python-control's ``stability_margins``.
    """
    mag = np.abs(L)
    ph = np.degrees(np.unwrap(np.angle(L)))
    ph -= 360.0 * np.ceil(ph[0] / 360.0)  # low-frequency phase in (−360°, 0°]
    gc = np.nonzero((mag[:-1] >= 1.0) & (mag[1:] < 1.0))[0]
    if gc.size == 0:
        raise ParameterError('loop has no gain crossover in the frequency grid')
    i = gc[-1]
    pc = np.nonzero((ph[:-1] >= -180.0) & (ph[1:] < -180.0))[0]
    pc = pc[pc >= i]
    if pc.size:
        j = pc[0]
        gm = -20.0 * math.log10(mag[j])
        w180 = float(w[j])
    else:
        gm, w180 = math.inf, math.inf
    sens = np.abs(1.0 / (1.0 + L))
    b = np.nonzero(sens >= 1.0 / math.sqrt(2.0))[0]
    bw = float(w[b[0]]) if b.size else math.inf
    return LoopMargins(gain_margin_db=float(gm), phase_margin_deg=float(180.0 + ph[i]),
                       crossover_hz=float(w[i]) / (2 * math.pi),
                       phase_crossover_hz=w180 / (2 * math.pi),
                       bandwidth_hz=bw / (2 * math.pi))


def popov_limit(L: np.ndarray, w: np.ndarray, *, control_period: float = 0.0) -> float:
    """Largest sector gain ``k_max`` the Popov (or, sampled, Tsypkin) criterion admits.

    Continuous loop (``control_period = 0``): the Popov multiplier ``1 + q·jω``; for a
    line of slope ``1/q`` (q >= 0) the criterion ``Re[(1 + q·jω)·L] > −1/k`` must hold at
    every ω, so ``1/k_max(q) = max_ω −Re[(1 + q·jω)·L]``; the best q over a grid gives
    ``k_max`` (Chiew eq. 9 reads it off the real-axis crossing of the Popov line).

    Sampled loop at period T (``L = L(e^{jωT})``, ω up to the Nyquist frequency): the
    discrete-time counterpart, Tsypkin's criterion for a monotone sector nonlinearity
    (Jury & Lee 1964), replaces ``jω`` by the backward difference ``(1 − e^{−jωT})/T``,
    i.e. the multiplier ``1 + q·(1 − e^{−jωT})``; ``q = 0`` is the circle criterion
    ``Re L > −1/k``, which also holds for a time-varying gain.

    Only ω above the gain crossover is examined: below it the type-2 loop (integrator +
    double-integrating plant) is conditionally stable and a larger gain moves it away
    from instability.
    """
    mag = np.abs(L)
    gc = np.nonzero((mag[:-1] >= 1.0) & (mag[1:] < 1.0))[0]
    keep = slice(int(gc[-1]) if gc.size else 0, None)
    L, w = L[keep], w[keep]
    if control_period > 0.0:
        mult = (1.0 - np.exp(-1j * w * control_period)) / control_period
    else:
        mult = 1j * w
    best = 0.0
    for q in np.concatenate(([0.0], np.logspace(-6, -1, 101))):
        worst = float(np.max(-((1.0 + q * mult) * L).real))
        if worst > 0.0:
            best = max(best, 1.0 / worst)
    return best


# ---- the loop as implemented: sampled, zero-order hold, dead time -------------------
def _hold_integrals(a: np.ndarray, b: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray]:
    """``(e^{A t}, ∫_0^t e^{A σ} dσ·B)`` from one matrix exponential (Van Loan)."""
    from scipy.linalg import expm  # lazy: keeps CLI start-up small
    n = a.shape[0]
    m = np.zeros((n + 1, n + 1))
    m[:n, :n], m[:n, n] = a, b
    e = expm(m * t)
    return e[:n, :n], e[:n, n]


@dataclasses.dataclass(frozen=True)
class SampledPlant:
    """The linear axis seen by a digital controller: ZOH input, dead time, sampled output.

    With the total dead time ``τ_tot = τ + n_c·T = d·T + τ'`` (0 <= τ' < T), integrating
    ``ẋ = A·x + B·u(t − τ_tot)`` over one period of the zero-order hold gives the exact
    (modified z-transform) model::

        x[k+1] = Φ·x[k] + Γ0·u[k−d] + Γ1·u[k−d−1],    y[k] = x1[k]
        Φ = e^{AT},  Γ0 = ∫_0^{T−τ'} e^{Aσ}dσ·B,  Γ1 = e^{A(T−τ')}·∫_0^{τ'} e^{Aσ}dσ·B

    Attributes
    ----------
    phi, gamma0, gamma1 : ndarray
        Φ (2×2), Γ0, Γ1 (2,) [m/V, m/(V·s)].
    periods : int
        d, whole periods of dead time.
    control_period : float
        T [s].
    """

    phi: np.ndarray
    gamma0: np.ndarray
    gamma1: np.ndarray
    periods: int
    control_period: float

    def response(self, w: np.ndarray) -> np.ndarray:
        """``H(e^{jωT})`` [m/V] at angular frequencies ``w`` [rad/s] (below Nyquist)."""
        z = np.exp(1j * np.asarray(w, dtype=float) * self.control_period)
        (a, b), (c, d) = self.phi
        # (zI − Φ)⁻¹ first row, closed form for 2×2: [z − d, b] / det
        det = (z - a) * (z - d) - b * c
        g = self.gamma0[None, :] + self.gamma1[None, :] / z[:, None]
        x1 = ((z - d) * g[:, 0] + b * g[:, 1]) / det
        return x1 * z ** (-self.periods)

    def to_control(self) -> Any:
        """Return the same model as a python-control discrete ``StateSpace`` (dt = T).

        States: the plant's two, then the ``d + 1`` past commands ``u[k−1] … u[k−d−1]``.
        """
        import control as ct  # lazy: optional at run time, used by tests and benches
        d = self.periods
        n = 2 + d + 1
        a = np.zeros((n, n))
        bm = np.zeros((n, 1))
        a[:2, :2] = self.phi
        # plant input of period k: Γ0·u[k−d] + Γ1·u[k−d−1]; u[k−j] is state 2 + j − 1
        if d == 0:
            bm[:2, 0] = self.gamma0
        else:
            a[:2, 2 + d - 1] = self.gamma0
        a[:2, 2 + d] = self.gamma1
        bm[2, 0] = 1.0
        for j in range(1, d + 1):
            a[2 + j, 2 + j - 1] = 1.0
        cm = np.zeros((1, n))
        cm[0, 0] = 1.0
        return ct.ss(a, bm, cm, np.zeros((1, 1)), self.control_period)


def sampled_plant(model: AxisModel, *, delay: float, control_period: float,
                  computation_periods: int = 0) -> SampledPlant:
    """Exact discretisation of the linear axis (Chiew eq. 1) behind a zero-order hold.

    Parameters
    ----------
    model : AxisModel
        The (nominal) axis; ``A = [[0, 1], [−k/M, −B]]``, ``B = [0, g/M]`` with the
        damping ``B = (damping + g·back_emf)/M`` of :func:`linear_plant_response`.
    delay : float
        Plant dead time τ [s] (Chiew: 1.29 ms).
    control_period : float
        T [s].
    computation_periods : int
        Extra whole periods between reading ``y_k`` and applying ``u_k``.  The simulator
        and the lockstep ROS nodes apply ``u_k`` at ``t_k`` itself, so 0 is the loop as
        implemented; a drive that outputs ``u_k`` at ``t_{k+1}`` has 1.
    """
    T = float(control_period)
    m = model.mass
    spring = model.get('spring')
    a = np.array([[0.0, 1.0],
                  [-(spring.k / m if spring is not None else 0.0),
                   -(model.damping + model.input_gain * model.back_emf) / m]])
    b = np.array([0.0, model.input_gain / m])
    tau = float(delay) + int(computation_periods) * T
    d = int(math.floor(tau / T + 1e-9))
    frac = max(tau - d * T, 0.0)
    phi, _ = _hold_integrals(a, b, T)
    e0, g0 = _hold_integrals(a, b, T - frac)
    _, i1 = _hold_integrals(a, b, frac)
    return SampledPlant(phi=phi, gamma0=g0, gamma1=e0 @ i1, periods=d, control_period=T)


def discrete_pid_response(kp: float, ki: float, kd: float, tf: float, w: np.ndarray, *,
                          control_period: float) -> np.ndarray:
    """``C(e^{jωT})`` [V/m] of the PID exactly as :mod:`.pid` computes it from ``e = r − y``.

    ``I[k] = I[k−1] + T·e[k]`` gives ``Ki·T/(1 − z⁻¹)``; the derivative acts on the
    backward-difference velocity ``(1 − z⁻¹)/T`` through the backward-Euler filter
    ``α/(1 − (1 − α)·z⁻¹)``, ``α = T/(T + T_f)``.
    """
    T = float(control_period)
    zi = np.exp(-1j * np.asarray(w, dtype=float) * T)
    alpha = T / (T + tf)
    return kp + ki * T / (1.0 - zi) + kd * alpha / (1.0 - (1.0 - alpha) * zi) * (1.0 - zi) / T


def sampled_grid(control_period: float, n: int = 4000) -> np.ndarray:
    """Log-spaced angular frequencies [rad/s] from 1 rad/s to just below Nyquist π/T."""
    return np.logspace(0.0, math.log10(0.9999 * math.pi / control_period), n)


def sampled_loop(model: AxisModel, params: PIDParams, *, delay: float,
                 control_period: float, computation_periods: int = 0,
                 w: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(w, L(e^{jωT}))`` of the loop as implemented at period ``control_period`` T.

    The exact sampled loop (:func:`sampled_plant` × :func:`discrete_pid_response`): the
    zero-order hold, the dead time and the backward-difference velocity are all in it.
    ``w`` defaults to :func:`sampled_grid` (up to the Nyquist frequency).
    """
    w = sampled_grid(control_period) if w is None else np.asarray(w, dtype=float)
    H = sampled_plant(model, delay=delay, control_period=control_period,
                      computation_periods=computation_periods).response(w)
    C = discrete_pid_response(params.kp, params.ki, params.kd, params.tf, w,
                              control_period=control_period)
    return w, C * H


@dataclasses.dataclass(frozen=True)
class PIDDesign:
    """A loop-shaping result: the gains and the margins they achieve.

    ``popov_limit`` is the Popov bound (continuous design) or the Tsypkin bound of the
    sampled loop (discrete design) for ``k(e)``; ``control_period`` is 0 for the
    continuous design.
    """

    params: NPIDParams
    margins: LoopMargins
    popov_limit: float
    control_period: float = 0.0


def design_pid(model: AxisModel, *, delay: float, control_period: float = 0.0,
               computation_periods: int = 0, gain_margin_db: float = 9.9,
               phase_margin_deg: float = 54.2, bandwidth_hz: float = 38.5,
               crossover_hz: float | None = None, min_filter_periods: float = 0.5,
               integral_ratio: float = 5.0) -> PIDDesign:
    """Loop-shape ``Kp, Ki, Kd, T_f`` to the target margins (Chiew Table IV) by least squares.

    ``control_period = 0``: Chiew's continuous design on ``G(s)·e^{−τs}`` with four
    targets (GM, PM, sensitivity bandwidth and the crossover, 64.9 Hz by default).

    ``control_period = T > 0``: the design of the loop as it runs (:func:`sampled_loop`:
    ZOH, dead time τ plus ``computation_periods``, backward-difference velocity, discrete
    integrator and filter), with the derivative filter kept meaningful, ``T_f >=
    min_filter_periods·T`` (a filter far below T filters nothing) and the integral
    corner ``Ki/Kp >= ω_c/integral_ratio`` (integral action that still removes the
    friction offset within a few crossover periods, as in the continuous design where
    ``Ki/Kp ≈ ω_c/4``; without it the optimiser trades the integrator away for
    bandwidth).  GM and PM are hard
    targets (weights 0.3 dB, 1°), the bandwidth a soft one (10 Hz): with τ = 1.29 ms plus
    the hold, 38.5 Hz at 54° of phase margin needs more phase lead than a PID has, so the
    design returns the widest bandwidth that keeps the margins (the bench
    ``reproduce_papers.py`` prints it against the rate).
    """
    from scipy.optimize import least_squares  # lazy: keeps CLI start-up small

    T = float(control_period)
    if T > 0.0:
        w = sampled_grid(T, 3000)
        g = sampled_plant(model, delay=delay, control_period=T,
                          computation_periods=computation_periods).response(w)

        def loop(kp: float, ki: float, kd: float, tf: float) -> np.ndarray:
            return discrete_pid_response(kp, ki, kd, tf, w, control_period=T) * g
    else:
        w = frequency_grid()
        g = linear_plant_response(model, w, delay=delay)
        crossover_hz = 64.9 if crossover_hz is None else crossover_hz

        def loop(kp: float, ki: float, kd: float, tf: float) -> np.ndarray:
            return pid_response(kp, ki, kd, tf, w) * g

    def residual(p: np.ndarray) -> list[float]:
        kp, ki, kd, tf = np.exp(p)
        try:
            m = loop_margins(loop(kp, ki, kd, tf), w)
        except ParameterError:
            return [10.0] * 4
        if T > 0.0:
            return [(m.gain_margin_db - gain_margin_db) / 0.3,
                    (m.phase_margin_deg - phase_margin_deg) / 1.0,
                    (m.bandwidth_hz - bandwidth_hz) / 10.0,
                    3.0 * max(0.0, math.log(min_filter_periods * T / tf))
                    + 3.0 * max(0.0, math.log(2 * math.pi * m.crossover_hz
                                              / (integral_ratio * ki / kp)))]
        return [(m.gain_margin_db - gain_margin_db) / 0.5,
                (m.phase_margin_deg - phase_margin_deg) / 2.0,
                (m.bandwidth_hz - bandwidth_hz) / 2.0,
                (m.crossover_hz - crossover_hz) / 2.0]

    # start: |C·G| = 1 at a crossover with ~85° of lead (derivative dominant)
    wc = 2 * math.pi * (crossover_hz if crossover_hz else 0.8 * bandwidth_hz)
    c_mag = 1.0 / abs(linear_plant_response(model, np.array([wc]), delay=delay)[0])
    best = None
    for ki_ratio in (1.0, 10.0, 100.0):
        for tf in ((1e-5, 1e-4) if T == 0.0 else (T, 2.0 * T)):
            x0 = np.log([c_mag * 0.1, c_mag * 0.1 * ki_ratio, c_mag / wc, tf])
            r = least_squares(residual, x0)
            if best is None or r.cost < best.cost:
                best = r
    kp, ki, kd, tf = (float(v) for v in np.exp(best.x))
    params = NPIDParams(kp=kp, ki=ki, kd=kd, tf=tf)
    L = loop(kp, ki, kd, tf)
    return PIDDesign(params=params, margins=loop_margins(L, w),
                     popov_limit=popov_limit(L, w, control_period=T), control_period=T)
