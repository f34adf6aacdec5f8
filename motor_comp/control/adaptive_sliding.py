r"""Adaptive sliding controller of Tan, Huang & Lee 2002 (PMLM friction and ripple).

Plant (Tan eq. 1–7, DESIGN.md §3), with ``g`` the input gain [N/V]::

    M·ẍ = g·(u − k_e·ẋ) − D·ẋ − F_fric(ẋ) − F_ripple(x) − F_load
    ⇔  θ1·ẍ = u − θ2·ẋ − F/g,    θ1 = M/g [V·s²/m],  θ2 = k_e + D/g [V·s/m]

Friction ``F_fric = fc·sgn ẋ + fv·ẋ + F_stribeck`` and ripple
``F_ripple = A1·sin ωx + B1·cos ωx`` (Tan eq. 9).  In volts the unknowns are
``θ = [θ1, θ2, fc/g, fv/g, A1/g, B1/g]``; the Stribeck part and the load form the
bounded remainder ``d`` with ``|d| <= k*``.

Errors (``e = x_d − x``, the sign of DESIGN.md §6), sliding surface (Tan eq. 12) and
boundary-layer metric (Slotine & Coetsee, Tan ref. [9])::

    s   = ė + λ1·e + λ2·∫e         (p² + λ1·p + λ2 Hurwitz)
    s_Δ = s − φ·sat(s/φ)

With ``ẍ_r = ẍ_d + λ1·ė + λ2·e`` we have ``ṡ = ẍ_r − ẍ``, hence
``θ1·ṡ = θ1·ẍ_r + θ2·ẋ + F/g − u = θᵀY + d − u`` with the regressor
``Y = [ẍ_r, ẋ, sgn ẋ_d, ẋ_d, sin ωx, cos ωx]``.  Control law (Tan eq. 15)::

    u = K·s + θ̂ᵀY + k̂·sat(s/φ)

``K·s = K·ė + K·λ1·e + K·λ2·∫e`` *is* a PID on ``e`` (Tan Remark 3.1), so the PID
baseline with ``Kp = K·λ1, Ki = K·λ2, Kd = K`` is the fair comparison.  The closed loop
is ``θ1·ṡ = −K·s − θ̃ᵀY − k̂·sat(s/φ) + d`` with ``θ̃ = θ̂ − θ``.

Lyapunov function (Tan eq. 25)::

    V = ½·θ1·s_Δ² + Σ_i θ̃_i²/(2γ_i) + (k̂ − k*)²/(2γ_k),     θ1 = 1/b

Outside the layer ``ṡ_Δ = ṡ`` and ``s_Δ·sat(s/φ) = |s_Δ|``; inside ``s_Δ = 0``.  So::

    V̇ = −K·s·s_Δ − s_Δ·θ̃ᵀY − k̂·|s_Δ| + d·s_Δ + Σ θ̃_i·θ̂̇_i/γ_i + (k̂ − k*)·k̂̇/γ_k

and the update laws (Tan eq. 18–24)::

    θ̂̇_i = γ_i·s_Δ·Y_i        (e.g. dÂ1/dt = γ_A·s_Δ·sin ωx)
    k̂̇   = γ_k·|s_Δ|           (grows with |s_Δ|)

give ``V̇ = −K·s·s_Δ − (k* − d·sgn s)·|s_Δ| <= −K·s_Δ² <= 0`` since ``s·s_Δ >= s_Δ²``;
Barbalat's lemma then gives ``s_Δ → 0``: the error enters the boundary layer.

Bounded laws: each estimate is projected onto a box ``[lo_i, hi_i]`` containing the
truth (``hi = bound_factor·max(|nominal|, floor)``); projection only removes update
components that point out of the box, where ``θ̃_i·θ̂̇_i`` would have been negative
anyway, so ``V̇ <= −K·s_Δ²`` still holds and no leakage is needed.

Practical choices (documented deviations): the Coulomb/viscous regressors use the
*desired* velocity ``ẋ_d`` (desired-compensation form, Sadegh & Horowitz 1990) because a
1 µm encoder at 1 kHz quantises velocity to 1 mm/s and ``sgn ẋ`` would chatter at rest;
the mismatch ``Y(ẋ) − Y(ẋ_d)`` is bounded and belongs to ``d``.  ``ė`` is the filtered
``ẋ_d − v_meas`` of the PID part (time constant ``tf``), and the back-EMF regressor is
``ẋ = ẋ_d − ė + (T + tf)·ẍ_d``: the velocity over the coming zero-order-hold interval,
predicted across the lag of the backward-difference measurement and the filter.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit

from motor_comp.control._jitcache import JIT_INLINE
from motor_comp.control.params import ParamsBase, spec
from motor_comp.physics.axis import AxisModel

#: names and units of the adaptive estimates (reported in physical units)
ESTIMATES = ('mass', 'back_emf', 'fc', 'fv', 'ripple_a', 'ripple_b', 'robust_gain')
N_THETA = 7
#: floors of the projection box in volt units (so an estimate of a nominally absent
#: effect can still move): θ1 [V·s²/m], θ2 [V·s/m], fc [V], fv [V·s/m], A1, B1, k [V]
_FLOORS = (0.1, 1.0, 0.5, 1.0, 0.5, 0.5, 0.5)


@dataclasses.dataclass(frozen=True)
class AdaptiveParams(ParamsBase):
    """Adaptive sliding tunables (defaults tuned on the PMLM of ``config/pmlm.yaml``)."""

    label = 'adaptive_sliding'
    k_s: float = spec(300.0, 'V·s/m', 'K, gain on s (the PID part: Kd = K)', 0.0, 1e7)
    lambda1: float = spec(160.0, '1/s', 'λ1 of s = ė + λ1·e + λ2·∫e', 0.0, 1e5)
    lambda2: float = spec(6400.0, '1/s²', 'λ2 of s = ė + λ1·e + λ2·∫e', 0.0, 1e10)
    phi: float = spec(2e-4, 'm/s', 'boundary-layer width φ of s', 1e-9, 10.0)
    tf: float = spec(3e-4, 's', 'filter time constant of ė', 0.0, 1.0)
    gamma_mass: float = spec(200.0, '-', 'adaptation rate γ of θ1',
                             0.0, 1e9)
    gamma_back_emf: float = spec(1e6, '-', 'adaptation rate γ of θ2', 0.0, 1e12)
    gamma_fc: float = spec(200.0, '-', 'adaptation rate γ of fc/g', 0.0, 1e12)
    gamma_fv: float = spec(1e4, '-', 'adaptation rate γ of fv/g', 0.0, 1e12)
    gamma_ripple: float = spec(1000.0, '-', 'adaptation rate γ of A1/g and B1/g', 0.0, 1e12)
    gamma_k: float = spec(20.0, '-', 'growth rate γ_k of the robust gain k̂', 0.0, 1e12)
    initial_fraction: float = spec(0.5, '-', 'initial estimates as a fraction of nominal',
                                   0.0, 2.0)
    bound_factor: float = spec(3.0, '-', 'projection box: |θ̂| <= factor·max(|nominal|, floor)',
                               1.0, 100.0)
    ripple_period: float = spec(0.0, 'm', 'ripple period of the regressor; 0 = from plant',
                                0.0, 10.0)
    u_max: float = spec(math.inf, 'V', 'output saturation ±u_max', 1e-6, math.inf)

    @property
    def pid_gains(self) -> tuple[float, float, float]:
        """(Kp, Ki, Kd) of the PID part K·(ė + λ1·e + λ2·∫e) (Tan Remark 3.1)."""
        return self.k_s * self.lambda1, self.k_s * self.lambda2, self.k_s


def nominal_theta(model: AxisModel, *, ripple_period: float = 0.0) -> tuple[np.ndarray, float]:
    """Return the true parameters in volts ``[θ1, θ2, fc/g, fv/g, A1/g, B1/g, k*]`` and ω.

    ``k*`` is the Stribeck excess ``fs − fc`` in volts (what the robust term must cover).
    """
    g = model.input_gain
    fc, fs, _, _ = model.stribeck_curve_params()
    rip = model.get('ripple')
    a1 = rip.harmonics[0][0] if rip is not None else 0.0
    b1 = rip.harmonics[0][1] if rip is not None else 0.0
    period = ripple_period or (rip.period if rip is not None else 0.02)
    theta = np.array([model.mass / g, model.back_emf + model.damping / g, fc / g,
                      model.fv / g, a1 / g, b1 / g, max(fs - fc, 0.0) / g])
    return theta, 2.0 * math.pi / period


def projection_box(theta: np.ndarray, bound_factor: float) -> tuple[np.ndarray, np.ndarray]:
    """Lower and upper bounds of each estimate (k̂ and the physical positives >= 0)."""
    hi = bound_factor * np.maximum(np.abs(theta), _FLOORS)
    lo = -hi.copy()
    for i in (0, 1, 2, 3, 6):  # mass, back-EMF, fc, fv and k̂ are non-negative
        lo[i] = 0.0
    return lo, hi


def estimates_in_units(theta: np.ndarray, input_gain: float) -> dict[str, float]:
    """Estimates in physical units: kg, V·s/m, N, N·s/m, N, N, N."""
    g = input_gain
    return {'mass': float(theta[0] * g), 'back_emf': float(theta[1]),
            'fc': float(theta[2] * g), 'fv': float(theta[3] * g),
            'ripple_a': float(theta[4] * g), 'ripple_b': float(theta[5] * g),
            'robust_gain': float(theta[6] * g)}


@njit(**JIT_INLINE)
def adaptive_output(th, i_th, q, i_gam, i_lo, i_hi, ks, lam1, lam2, phi, omega, tf, e, ed,
                    integ, ra, rv, y, dt, adapt):
    """Control [V] of Tan eq. 15 and, if ``adapt``, one Euler step of eq. 18–24 on ``th``.

    The vectors are the controller's packed state and parameters with offsets (no array
    views in the compiled loop).

    Parameters
    ----------
    th, i_th : ndarray, int
        Estimates ``[θ1, θ2, fc/g, fv/g, A1/g, B1/g, k̂]`` at ``th[i_th:i_th + 7]``
        (updated in place).
    q, i_gam, i_lo, i_hi : ndarray, int, int, int
        Adaptation rates and projection box at ``q[i_gam + i]``, ``q[i_lo + i]``,
        ``q[i_hi + i]``.
    ks, lam1, lam2, phi, omega : float
        K [V·s/m], λ1 [1/s], λ2 [1/s²], φ [m/s], ripple ω [rad/m].
    tf : float
        Time constant of the ė filter [s] (its lag is compensated in the ẋ regressor).
    e, ed, integ : float
        Error [m], filtered error rate [m/s], error integral [m·s].
    ra, rv, y : float
        Reference acceleration [m/s²], reference velocity [m/s], measured position [m].

    Returns
    -------
    (u [V], s [m/s])
    """
    s = ed + lam1 * e + lam2 * integ
    sat = s / phi
    if sat > 1.0:
        sat = 1.0
    elif sat < -1.0:
        sat = -1.0
    sd = s - phi * sat
    y0 = ra + lam1 * ed + lam2 * e       # ẍ_r
    # ẋ over the coming hold interval (centred at t + T/2), predicted from the filtered
    # measurement (centred at t − T/2 − tf): without the (T + tf)·ẍ_d lead the mass
    # estimate absorbs the lag of the back-EMF term (θ2·lag ≈ 1.5 kg on the PMLM)
    y1 = rv - ed + (dt + tf) * ra
    y2 = np.sign(rv)
    y3 = rv
    y4 = np.sin(omega * y)
    y5 = np.cos(omega * y)
    j = i_th
    u = ks * s + th[j] * y0 + th[j + 1] * y1 + th[j + 2] * y2 + th[j + 3] * y3 \
        + th[j + 4] * y4 + th[j + 5] * y5 + th[j + 6] * sat
    if adapt:
        reg = (y0, y1, y2, y3, y4, y5, abs(sd))
        for i in range(7):
            g = sd * reg[i] if i < 6 else reg[i]
            v = th[j + i] + dt * q[i_gam + i] * g
            if v < q[i_lo + i]:
                v = q[i_lo + i]
            elif v > q[i_hi + i]:
                v = q[i_hi + i]
            th[j + i] = v
    return u, s
