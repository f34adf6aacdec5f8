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

Bounded laws: each estimate is projected onto a box ``[lo_i, hi_i]`` built around the
nominal model, ``hi = bound_factor·max(|nominal|, floor)``, which contains the truth when
the nominal is at least 1/bound_factor of it or the floor covers it (the floors admit
a nominally absent effect: a zero nominal, Tan's experiment); projection only removes update
components that point out of the box, where ``θ̃_i·θ̂̇_i`` would have been negative
anyway, so it never increases ``V̇``.

Robust modifications (why: measured on the default PMLM p2p run, 1 µm encoder at 1 kHz).
Tan's laws alone drift: after 60–100 s θ̂1 → 16.2 kg, fv → 45 N·s/m, k̂ → 30 N (their
box edges) and the axis hunts at every dwell (±3.5 mm/s, ≈ 8 000 velocity sign changes
per 30 s, dwell error 9 µm).  The proof above assumes what a sampled axis with an encoder
and stiction does not give, and each broken assumption has its own remedy:

1. *Balance condition* (Slotine & Li 1991, §7.2.3, the boundary layer follows the
   gain).  Inside the layer the robust term is a gain ``k̂/φ`` on ``s``, added to ``K``;
   the sampled PID part (GM 8.4 dB on the exact sampled loop) keeps no margin at 2.6·K,
   and with φ = 0.2 mm/s a k̂ of 10 N is 11·K: a limit cycle in the layer whose
   amplitude grows with k̂ (estimates exact and frozen, k̂ held at 30 N: ≈ 4 000 sign
   changes per 30 s of dwell).  The
   layer widens instead, ``φ_k = max(φ, k̂/K_φ)``, ``K_φ = layer_gain·K``.
2. *Dead zones* sized to the measurement noise of ``s`` (Peterson & Narendra 1982;
   :func:`noise_levels`).  ``k̂̇ = γ_k·|s_Δ|`` rectifies noise, so it grows without end
   under any noise: its law uses ``ε_k = max(φ, noise_margin·n̄)`` with n̄ from the
   quantisation and the random noise.  The θ̂ laws are linear in ``s_Δ``; their dead
   zone ``ε_θ`` covers the random noise only, whose square biases them (``s`` and
   ``ẍ_r`` share ``ė_f``: errors in variables).  The encoder's quantisation error is
   deterministic, bounded and averages out over a move; a dead zone of its size would
   stop the θ̂ laws at ≈ 5 µm of error (measured: the mass, fc, fv and ripple laws
   close 18–53 % instead of 60–99 % of their gaps in 10 s).
3. *Frozen at rest*: while ``|ẋ_d| <= v_rest = rest_counts·q/T`` (below one count per
   period the velocity is quantisation only) the friction is static — stiction holds
   any force up to f_s, not the sliding model — and ``d`` is not bounded by k*; there
   the laws integrated the integrator's holding force (legacy law, 10–30 s: B̂1 moved
   +46 N in the dwells and −39 N in the moves, k̂ grew in every dwell).
4. *σ-modification* (Ioannou & Kokotović 1983; Ioannou & Sun 1996, §8.4) towards the
   controller's nominal θ0 (:mod:`.nominal`, never the truth), ``−σ·(θ̂ − θ0)``, not
   on k̂.  Regressors ẋ and ẋ_d are
   nearly collinear (back-EMF vs viscous), ẍ_r is excited only during accelerations,
   and the Stribeck part of ``d`` correlates with ``sgn ẋ_d``: without leakage fĉ
   creeps to 17–20 N in 10 min and its step at every stop makes the axis stick-slip in
   the dwell.  The price is a bias towards a wrong nominal: measured 2–6 % of the
   mismatch after 60 s (fc, fv, A1 with the nominal 2–3× off).

Modified laws (all with the projection), applied while ``|ẋ_d| > v_rest``::

    u    = K·s + θ̂ᵀY + k̂·sat(s/φ_k),          φ_k = max(φ, k̂/K_φ)
    s_θ  = s − w_θ·sat(s/w_θ),  w_θ = max(ε_θ, φ_k);   s_k likewise with ε_k >= ε_θ
    θ̂̇_i = γ_i·s_θ·Y_i − σ·(θ̂_i − θ0_i),      k̂̇ = γ_k·|s_k|

Modified Lyapunov result, ``V = ½·θ1·s_θ² + Σ θ̃_i²/(2γ_i) + (k̂ − k*)²/(2γ_k)``.  For
``|s| > w_θ``, ``sat(s/φ_k) = sgn s`` and ``ṡ_θ = ṡ − ẇ_θ·sgn s`` with ``ẇ_θ >= 0``
(k̂ never decreases, so the layer only widens, which only lowers V̇).  With
``|s_k| <= |s_θ|``, ``|s_θ| − |s_k| <= Δε = ε_k − ε_θ`` and
``−θ̃ᵀ(θ̂ − θ0) <= −½|θ̃|² + ½|θ − θ0|²``::

    V̇ <= −K·s_θ² − (σ/2)·Σ θ̃_i²/γ_i + (σ/2)·Σ (θ_i − θ0_i)²/γ_i + k*·Δε

(inside ``|s| <= w_θ`` the same bound holds with ``s_θ = 0``).  So instead of
``s_Δ → 0`` the result is *uniform ultimate boundedness*: ``s_θ`` and θ̃ enter the set
where ``K·s_θ² + (σ/2)·|θ̃|²_Γ <= (σ/2)·|θ − θ0|²_Γ + k*·Δε`` — small when the nominal
model is close and the noise small, exactly Tan's result for σ = 0, ε_k = ε_θ = φ.  In
frozen phases the estimates are constant and the loop is the PID part with a bounded
feedforward error, stable on its own.  ``noise_margin = layer_gain = rest_counts =
sigma = 0`` restores Tan's laws exactly (kept for comparison: ``test_control_adaptive``).

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
    """Adaptive sliding tunables (defaults tuned on the PMLM of ``config/pmlm.yaml``).

    The last four are the robust modifications of the module docstring (0 = off).
    """

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
    initial_fraction: float = spec(1.0, '-', 'initial estimates as a fraction of the nominal '
                                   'model (which is itself 50 % or 0 of the truth, '
                                   ':mod:`.nominal`)', 0.0, 2.0)
    bound_factor: float = spec(3.0, '-', 'projection box: |θ̂| <= factor·max(|nominal|, floor)',
                               1.0, 100.0)
    ripple_period: float = spec(0.0, 'm', 'ripple period of the regressor; 0 = from plant',
                                0.0, 10.0)
    u_max: float = spec(math.inf, 'V', 'output saturation ±u_max', 1e-6, math.inf)
    noise_margin: float = spec(1.0, '-', 'adaptation dead zone ε = max(φ, margin·n̄), n̄ the '
                               'encoder-noise bound of s; 0 = φ only', 0.0, 100.0)
    layer_gain: float = spec(0.25, '-', 'balance condition: robust-term slope k̂/φ_k <= '
                             'layer_gain·K inside its layer; 0 = fixed φ', 0.0, 100.0)
    rest_counts: float = spec(1.0, 'counts', 'freeze adaptation while |ẋ_d| <= '
                              'rest_counts·q/T (q encoder quantum); 0 = never', 0.0, 1e6)
    sigma: float = spec(0.02, '1/s', 'σ-modification: leakage rate of θ̂ towards the '
                        'nominal θ (not k̂)', 0.0, 1e3)

    @property
    def pid_gains(self) -> tuple[float, float, float]:
        """(Kp, Ki, Kd) of the PID part K·(ė + λ1·e + λ2·∫e) (Tan Remark 3.1)."""
        return self.k_s * self.lambda1, self.k_s * self.lambda2, self.k_s


def nominal_theta(model: AxisModel, *, ripple_period: float = 0.0) -> tuple[np.ndarray, float]:
    """Return the parameters of ``model`` in volts ``[θ1, θ2, fc/g, fv/g, A1/g, B1/g, k*]`` and ω.

    ``model`` is the controller's *nominal* model (:mod:`.nominal`), so this is what the
    controller believes, never the truth: the initial estimates, the σ-leakage target θ0
    and the projection box are built from it.  ``k*`` is the Stribeck excess ``fs − fc``
    in volts (what the robust term must cover).  ω [rad/m] comes from ``ripple_period``
    [m] if given, else from the nominal ripple period (the magnet pitch, which a user
    knows), else 0.02 m.
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


@dataclasses.dataclass(frozen=True)
class Robustness:
    """Robustness modifications of the update laws, in the units the kernel uses.

    Attributes
    ----------
    quantisation_noise, random_noise : float
        Bounds [m/s] of the encoder-quantisation and of the random-noise (3σ) parts of
        the measured ``s`` (:func:`noise_levels`).
    deadzone_theta : float
        ε_θ [m/s] = max(φ, noise_margin·random_noise): the θ̂ laws stop while
        ``|s| <= max(ε_θ, φ_k)``.
    deadzone_k : float
        ε_k [m/s] = max(φ, noise_margin·(quantisation + random noise)): k̂ stops growing
        while ``|s| <= max(ε_k, φ_k)``.
    layer_slope : float
        K_φ [V·s/m] = layer_gain·K, bound of the robust term's slope (0 = fixed φ).
    rest_speed : float
        v_rest [m/s]: adaptation is frozen while ``|ẋ_d| <= v_rest``; −1 = never.
    sigma : float
        σ [1/s], leakage rate of θ̂ towards the nominal θ.
    """

    quantisation_noise: float
    random_noise: float
    deadzone_theta: float
    deadzone_k: float
    layer_slope: float
    rest_speed: float
    sigma: float


def noise_levels(params: AdaptiveParams, *, encoder_resolution: float, noise_std: float,
                 control_period: float) -> tuple[float, float]:
    """Bounds [m/s] of the quantisation and random-noise parts of the measured ``s``.

    A reading error ``w`` [m] enters ``s = ė_f + λ1·e + λ2·∫e`` as follows: the
    backward difference makes the velocity err by ``(w_k − w_{k−1})/T``; through the
    backward-Euler filter ``ė_f ← ė_f + α·(ė − ė_f)``, ``α = T/(T + t_f)``, summation by
    parts bounds that by ``2·α·|w|max/T``; ``λ1·e`` adds ``λ1·|w|max``.  (The integral
    term sums ``w``, which the closed loop keeps zero-mean; it is left out.)  Hence
    ``n̄ = (2α/T + λ1)·w̄`` with ``w̄ = q/2`` for an encoder quantum ``q`` [m] and
    ``w̄ = 3·σ_n`` for random noise of standard deviation ``σ_n`` [m].  PMLM defaults
    (1 µm, 1 kHz, t_f = 0.3 ms, λ1 = 160/s): 0.85 mm/s from quantisation, ≈ 4·φ.
    """
    alpha = control_period / (control_period + params.tf)
    gain = 2.0 * alpha / control_period + params.lambda1
    return gain * 0.5 * encoder_resolution, gain * 3.0 * noise_std


def robustness(params: AdaptiveParams, *, encoder_resolution: float, noise_std: float,
               control_period: float) -> Robustness:
    """Derive the dead zones, layer slope, rest speed and leakage from the tunables."""
    nq, nr = noise_levels(params, encoder_resolution=encoder_resolution, noise_std=noise_std,
                          control_period=control_period)
    rest = (params.rest_counts * encoder_resolution / control_period
            if params.rest_counts > 0.0 else -1.0)
    m = params.noise_margin
    return Robustness(quantisation_noise=nq, random_noise=nr,
                      deadzone_theta=max(params.phi, m * nr),
                      deadzone_k=max(params.phi, m * (nq + nr)),
                      layer_slope=params.layer_gain * params.k_s, rest_speed=rest,
                      sigma=params.sigma)


@njit(**JIT_INLINE)
def dead_zone(s, width):
    """``s − width·sat(s/width)``, exactly 0 inside (no rounding residue to integrate)."""
    if s > width:
        return s - width
    if s < -width:
        return s + width
    return 0.0


@njit(**JIT_INLINE)
def adaptive_output(th, i_th, q, i_gam, i_lo, i_hi, i_th0, ks, lam1, lam2, phi, omega, tf,
                    eps_th, eps_k, k_layer, v_rest, sigma, e, ed, integ, ra, rv, y, dt, adapt):
    """Control [V] of Tan eq. 15 and, if ``adapt``, one Euler step of eq. 18–24 on ``th``.

    The vectors are the controller's packed state and parameters with offsets (no array
    views in the compiled loop).

    Parameters
    ----------
    th, i_th : ndarray, int
        Estimates ``[θ1, θ2, fc/g, fv/g, A1/g, B1/g, k̂]`` at ``th[i_th:i_th + 7]``
        (updated in place).
    q, i_gam, i_lo, i_hi, i_th0 : ndarray, int, int, int, int
        Adaptation rates, projection box and leakage targets (nominal θ) at
        ``q[i_gam + i]``, ``q[i_lo + i]``, ``q[i_hi + i]``, ``q[i_th0 + i]``.
    ks, lam1, lam2, phi, omega : float
        K [V·s/m], λ1 [1/s], λ2 [1/s²], minimum boundary layer φ [m/s], ripple ω [rad/m].
    tf : float
        Time constant of the ė filter [s] (its lag is compensated in the ẋ regressor).
    eps_th, eps_k : float
        Dead zones ε_θ, ε_k [m/s] of ``s`` for the θ̂ laws and the k̂ law (>= φ).
    k_layer : float
        Largest slope k̂/φ_k of the robust term inside its layer [V·s/m]; 0 = fixed φ.
    v_rest : float
        Adaptation is frozen while ``|ẋ_d| <= v_rest`` [m/s] (−1: never).
    sigma : float
        Leakage rate σ [1/s] of θ̂ towards the nominal θ0.
    e, ed, integ : float
        Error [m], filtered error rate [m/s], error integral [m·s].
    ra, rv, y : float
        Reference acceleration [m/s²], reference velocity [m/s], measured position [m].

    Returns
    -------
    (u [V], s [m/s])
    """
    j = i_th
    s = ed + lam1 * e + lam2 * integ
    phik = phi
    if k_layer > 0.0 and th[j + 6] > phik * k_layer:
        phik = th[j + 6] / k_layer          # balance condition: slope k̂/φ_k <= k_layer
    sat = min(max(s / phik, -1.0), 1.0)
    y0 = ra + lam1 * ed + lam2 * e       # ẍ_r
    # ẋ over the coming hold interval (centred at t + T/2), predicted from the filtered
    # measurement (centred at t − T/2 − tf): without the (T + tf)·ẍ_d lead the mass
    # estimate absorbs the lag of the back-EMF term (θ2·lag ≈ 1.5 kg on the PMLM)
    y1 = rv - ed + (dt + tf) * ra
    y2 = np.sign(rv)
    y3 = rv
    y4 = np.sin(omega * y)
    y5 = np.cos(omega * y)
    u = ks * s + th[j] * y0 + th[j + 1] * y1 + th[j + 2] * y2 + th[j + 3] * y3 \
        + th[j + 4] * y4 + th[j + 5] * y5 + th[j + 6] * sat
    if adapt and abs(rv) > v_rest:
        sd = dead_zone(s, max(eps_th, phik))     # s_θ of the θ̂ laws
        se = dead_zone(s, max(eps_k, phik))      # s_k of the k̂ law
        reg = (y0, y1, y2, y3, y4, y5)
        for i in range(7):
            if i < 6:
                rate = q[i_gam + i] * sd * reg[i] - sigma * (th[j + i] - q[i_th0 + i])
            else:
                rate = q[i_gam + i] * abs(se)
            v = th[j + i] + dt * rate
            if v < q[i_lo + i]:
                v = q[i_lo + i]
            elif v > q[i_hi + i]:
                v = q[i_hi + i]
            th[j + i] = v
    return u, s
