"""PID baseline: filtered derivative, conditional-integration anti-windup, output limit.

Discrete law at control period ``T`` (error ``e = r − y`` [m], DESIGN.md §6 sign)::

    ė_f[k] = ė_f[k−1] + T/(T_f + T)·(ė[k] − ė_f[k−1])    ė = ṙ − v_meas  (backward Euler
                                                          of a first-order filter T_f)
    I[k]   = I[k−1] + T·e[k]
    u      = Kp·e + Ki·I + Kd·ė_f   (+ feedforward), clipped to ±u_max

Anti-windup by conditional integration (clamping): when the output saturates and the
error would drive it further into the limit, the integrator keeps its old value.  The
arithmetic lives in :func:`motor_comp.control.controller.controller_step`, shared by
every mode; this module holds the tunables and the per-plant defaults.
"""
from __future__ import annotations

import dataclasses
import math

from numba import njit

from motor_comp.control._jitcache import JIT_INLINE
from motor_comp.control.params import ParamsBase, spec


@dataclasses.dataclass(frozen=True)
class PIDParams(ParamsBase):
    """PID gains (defaults: the ball-screw loop-shaping design, see :mod:`.npid`).

    The defaults are :func:`~motor_comp.control.npid.design_pid` of the ball-screw's
    nominal model at its 1 kHz control rate (sampled loop, ZOH, τ = 1.29 ms): GM 9.9 dB,
    PM 54.2°, crossover 31.6 Hz, sensitivity bandwidth 20.9 Hz, derivative filter
    0.70 ms = 0.7·T (``test_control_npid`` re-runs the design).
    """

    label = 'pid'
    kp: float = spec(874.81, 'V/m', 'proportional gain', 0.0, 1e9)
    ki: float = spec(34958.8, 'V/(m·s)', 'integral gain', 0.0, 1e12)
    kd: float = spec(101.646, 'V·s/m', 'derivative gain', 0.0, 1e7)
    tf: float = spec(6.98e-4, 's', 'derivative filter time constant', 0.0, 1.0)
    u_max: float = spec(math.inf, 'V', 'output saturation ±u_max', 1e-6, math.inf)


@njit(**JIT_INLINE)
def filter_derivative(prev, raw, tf, dt):
    """First-order low-pass of the error rate (backward Euler), time constant ``tf`` [s]."""
    if tf <= 0.0:
        return raw
    return prev + dt / (tf + dt) * (raw - prev)


@njit(**JIT_INLINE)
def pid_output(kp, ki, kd, e, integ, ed):
    """``Kp·e + Ki·∫e + Kd·ė_f`` [V]."""
    return kp * e + ki * integ + kd * ed
