"""Nonlinear PID (Chiew et al. eq. 6–9) and the loop-shaping design of its base PID.

``u = k(e)·(Kp·e + Ki·∫e + Kd·ė)`` with the sector-bounded gain (eq. 6)::

    k(e) = cosh(k0·e)        for |e| <= e_max        (= (e^{k0 e} + e^{−k0 e})/2)
    k(e) = cosh(k0·e_max)    beyond,

``k0 = 15 /mm``, ``e_max = 0.1 mm`` (k(e_max) = cosh 1.5 ≈ 2.35), and the bound
``k(e_max) <= 1/|Re G_ol(jω*)|`` from the Popov plot (eq. 9; ≈ 2.9 in the paper).
:func:`popov_limit` computes that bound for our model and :func:`npid_gain` clamps to
it, so the gain is continuous, even in ``e`` and bounded in ``[1, k_max]``.

The base PID is designed by loop shaping on the linear ball-screw model with its dead
time, ``G(s) = A·e^{−τs}/(s² + B·s + C)`` (Chiew eq. 1), to the paper's Table IV
(GM 9.9 dB at 184 Hz, PM 54.2° at 64.9 Hz, bandwidth 38.5 Hz — the bandwidth is read
off the sensitivity function, Fig. 6, i.e. where |S| first reaches −3 dB, the
definition of Skogestad & Postlethwaite, Chiew ref. [16]).
"""
from __future__ import annotations

import dataclasses
import math

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
    k0: float = spec(15000.0, '1/m', 'rate of the nonlinear gain (Chiew: 15 /mm)', 0.0, 1e7)
    e_max: float = spec(1e-4, 'm', 'error range of the nonlinear gain (Chiew: 0.1 mm)',
                        1e-9, 1.0)
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


def popov_limit(L: np.ndarray, w: np.ndarray) -> float:
    """Largest sector gain ``k_max`` the Popov criterion admits for the loop ``L(jω)``.

    Popov plot ``(Re L, ω·Im L)``; for a line of slope ``1/q`` (q >= 0) the criterion
    ``Re L − q·ω·Im L > −1/k`` must hold at every ω, so ``1/k_max(q) = max_ω −(Re L −
    q·ω·Im L)``; the best q over a grid gives ``k_max`` (Chiew eq. 9 reads it off the
    real-axis crossing of the Popov line).  Only ω above the gain crossover is
    examined: below it the type-2 loop (integrator + double-integrating plant) is
    conditionally stable and a larger gain moves it away from instability.
    """
    mag = np.abs(L)
    gc = np.nonzero((mag[:-1] >= 1.0) & (mag[1:] < 1.0))[0]
    keep = slice(int(gc[-1]) if gc.size else 0, None)
    L, w = L[keep], w[keep]
    best = 0.0
    for q in np.concatenate(([0.0], np.logspace(-6, -1, 101))):
        worst = float(np.max(-(L.real - q * w * L.imag)))
        if worst > 0.0:
            best = max(best, 1.0 / worst)
    return best


@dataclasses.dataclass(frozen=True)
class PIDDesign:
    """A loop-shaping result: the gains and the margins they achieve."""

    params: NPIDParams
    margins: LoopMargins
    popov_limit: float


def design_pid(model: AxisModel, *, delay: float, gain_margin_db: float = 9.9,
               phase_margin_deg: float = 54.2, bandwidth_hz: float = 38.5,
               crossover_hz: float = 64.9) -> PIDDesign:
    """Loop-shape ``Kp, Ki, Kd, T_f`` to the target margins (Chiew Table IV) by least squares.

    Four targets (GM, PM, sensitivity bandwidth, crossover) for four gains; the residual
    is solved with ``scipy.optimize.least_squares`` from a derivative-dominant start that
    provides the ~85° of phase lead the delay and the double integrator demand.
    """
    from scipy.optimize import least_squares  # lazy: keeps CLI start-up small

    w = frequency_grid()
    g = linear_plant_response(model, w, delay=delay)

    def residual(p: np.ndarray) -> list[float]:
        kp, ki, kd, tf = np.exp(p)
        try:
            m = loop_margins(pid_response(kp, ki, kd, tf, w) * g, w)
        except ParameterError:
            return [10.0] * 4
        return [(m.gain_margin_db - gain_margin_db) / 0.5,
                (m.phase_margin_deg - phase_margin_deg) / 2.0,
                (m.bandwidth_hz - bandwidth_hz) / 2.0,
                (m.crossover_hz - crossover_hz) / 2.0]

    # start: |C·G| = 1 at the target crossover with ~85° of lead (derivative dominant)
    wc = 2 * math.pi * crossover_hz
    c_mag = 1.0 / abs(linear_plant_response(model, np.array([wc]), delay=delay)[0])
    best = None
    for ki_ratio in (1.0, 10.0, 100.0):
        for tf in (1e-5, 1e-4):
            x0 = np.log([c_mag * 0.1, c_mag * 0.1 * ki_ratio, c_mag / wc, tf])
            r = least_squares(residual, x0)
            if best is None or r.cost < best.cost:
                best = r
    kp, ki, kd, tf = (float(v) for v in np.exp(best.x))
    params = NPIDParams(kp=kp, ki=ki, kd=kd, tf=tf)
    L = pid_response(kp, ki, kd, tf, w) * g
    return PIDDesign(params=params, margins=loop_margins(L, w), popov_limit=popov_limit(L, w))


def sampled_loop(model: AxisModel, params: NPIDParams, *, delay: float,
                 control_period: float, w: np.ndarray | None = None) -> tuple:
    """``(w, L)`` of the loop as implemented at ``control_period`` T.

    The zero-order hold and the backward-difference velocity add about one period of
    dead time (T/2 each), so the sampled loop is the continuous one with ``τ + T``.
    """
    w = frequency_grid() if w is None else w
    L = pid_response(params.kp, params.ki, params.kd, params.tf, w) * \
        linear_plant_response(model, w, delay=delay + control_period)
    return w, L
