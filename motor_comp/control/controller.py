"""The controller: one compiled step for every mode, wrapped for Python drivers.

:func:`controller_step` (njit) is the single implementation of the control laws; the
in-process simulator calls it inside its compiled loop and :meth:`Controller.step`
calls it from Python (the ROS ``controller_node``), on the same packed parameter vector
``Q`` and state vector ``C``, so both drivers produce bit-identical commands.

Per step, at control period ``T`` (``e = r − y`` [m]):

1. ``ė_f`` ← filtered ``ṙ − v_meas``; ``I ← I + T·e``;
2. feedback by mode — PID ``Kp·e + Ki·I + Kd·ė_f``; N-PID ``k(e)·(…)`` (Chiew eq. 8);
   adaptive sliding ``K·s + θ̂ᵀY + k̂·sat(s/φ_k)`` with its update laws (Tan eq. 15–24,
   with the robust modifications of :mod:`.adaptive_sliding`: balance condition, dead
   zones, frozen at rest, σ-leakage; their settings are packed at ``Q_EPS_TH…Q_TH0``);
3. friction feedforward from the reference (Chiew Fig. 9), force / nominal input gain;
   model-based compensation (:mod:`.compensation`: a model's inverse dynamics at the
   reference, without the terms this law carries itself);
4. saturation ±u_max; conditional-integration anti-windup.
"""
from __future__ import annotations

import enum
import math
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.control._jitcache import JIT_INLINE
from motor_comp.control.adaptive_sliding import ESTIMATES, N_THETA, AdaptiveParams, \
    Robustness, adaptive_output, estimates_in_units, nominal_theta, projection_box, robustness
from motor_comp.control.compensation import CS_F, CS_SIZE, RIPPLE_PERIOD_MATCH, Carried, \
    CarriedDry, Compensation, CompensationKind, compensation_command
from motor_comp.control.feedforward import Feedforward, friction_feedforward
from motor_comp.control.npid import NPIDParams, npid_gain, popov_limit, sampled_loop
from motor_comp.control.params import ParamsBase
from motor_comp.control.pid import PIDParams, filter_derivative, pid_output
from motor_comp.errors import ParameterError, check_positive
from motor_comp.physics.config import PlantConfig, PlantKind
from motor_comp.physics.effects.presliding import MAX_ELEMENTS


class ControlMode(enum.IntEnum):
    """Controller mode (ROS parameter ``mode``)."""

    PID = 0
    ADAPTIVE_SLIDING = 1
    NPID = 2

    @property
    def label(self) -> str:
        """The CLI/ROS spelling."""
        return self.name.lower()

    @classmethod
    def parse(cls, value: 'str | ControlMode') -> 'ControlMode':
        """From ``pid | adaptive_sliding | npid``."""
        if isinstance(value, ControlMode):
            return value
        try:
            return cls[str(value).upper()]
        except KeyError:
            raise ParameterError(f'controller mode must be one of '
                                 f'{", ".join(m.label for m in cls)}, got {value!r}') from None


PARAMS: dict[ControlMode, type[ParamsBase]] = {
    ControlMode.PID: PIDParams, ControlMode.ADAPTIVE_SLIDING: AdaptiveParams,
    ControlMode.NPID: NPIDParams}

# ---- packed parameters Q ------------------------------------------------------------
Q_MODE, Q_FF, Q_KP, Q_KI, Q_KD, Q_TF, Q_UMAX = 0, 1, 2, 3, 4, 5, 6
Q_K0, Q_EMAX, Q_KMAX = 7, 8, 9
Q_LAM1, Q_LAM2, Q_PHI, Q_KS, Q_OMEGA, Q_ADAPT = 10, 11, 12, 13, 14, 15
Q_GAMMA = 16
Q_LO = Q_GAMMA + N_THETA
Q_HI = Q_LO + N_THETA
Q_GAIN = Q_HI + N_THETA
Q_FC, Q_FS, Q_VS, Q_DELTA, Q_FV = Q_GAIN + 1, Q_GAIN + 2, Q_GAIN + 3, Q_GAIN + 4, Q_GAIN + 5
Q_GMS_N, Q_GMS_C = Q_GAIN + 6, Q_GAIN + 7
Q_GMS_ALPHA = Q_GAIN + 8
Q_GMS_K = Q_GMS_ALPHA + MAX_ELEMENTS
Q_GMS_SIGMA = Q_GMS_K + MAX_ELEMENTS      # GMS micro-damping [N·s/m]; Q_GMS_C is C [N/s]
# robustness of the adaptive laws (dead zone, layer slope, rest speed, leakage, targets)
Q_EPS_TH = Q_GMS_SIGMA + MAX_ELEMENTS
Q_EPS_K, Q_KLAYER, Q_VREST, Q_SIGMA = Q_EPS_TH + 1, Q_EPS_TH + 2, Q_EPS_TH + 3, Q_EPS_TH + 4
Q_TH0 = Q_EPS_TH + 5
Q_SIZE = Q_TH0 + N_THETA

# ---- state C --------------------------------------------------------------------------
C_I, C_ED, C_E, C_U, C_UFF, C_INIT, C_RPREV, C_S = 0, 1, 2, 3, 4, 5, 6, 7
C_RAL, C_YL = 8, 12  # last reference acceleration [m/s²] and measurement [m]
C_FSTAT, C_FGMS = 9, 10   # last static-model and GMS-element feedforward forces [N]
C_RVL = 11           # last reference velocity [m/s]
C_DTL = 13           # last control period [s]
C_TH = 14
C_GMS_F = C_TH + N_THETA
C_GMS_SLIP = C_GMS_F + MAX_ELEMENTS
C_SIZE = C_GMS_SLIP + MAX_ELEMENTS


@njit(**JIT_INLINE)
def feedback(Q, C, e, ed, integ, ra, rv, y, dt, adapt):
    """Feedback command [V] of the mode in ``Q`` and the sliding variable ``s`` [m/s].

    The adaptive estimates in ``C`` are updated in place when ``adapt`` is true.
    """
    mode = int(Q[Q_MODE])
    if mode == 1:
        return adaptive_output(C, C_TH, Q, Q_GAMMA, Q_LO, Q_HI, Q_TH0, Q[Q_KS], Q[Q_LAM1],
                               Q[Q_LAM2], Q[Q_PHI], Q[Q_OMEGA], Q[Q_TF], Q[Q_EPS_TH],
                               Q[Q_EPS_K], Q[Q_KLAYER], Q[Q_VREST], Q[Q_SIGMA], e, ed, integ,
                               ra, rv, y, dt, adapt)
    if mode == 2:
        k = npid_gain(e, Q[Q_K0], Q[Q_EMAX], Q[Q_KMAX])
        return k * pid_output(Q[Q_KP], Q[Q_KI], Q[Q_KD], e, integ, ed), 0.0
    return pid_output(Q[Q_KP], Q[Q_KI], Q[Q_KD], e, integ, ed), 0.0


@njit(**JIT_INLINE)
def controller_step(Q, C, r, rv, ra, y, vy, dt):
    """One control step: command [V] from reference (r, ṙ, r̈) and measurement (y, v).

    Parameters
    ----------
    Q : ndarray
        Packed parameters (module constants ``Q_*``).
    C : ndarray
        Controller state, updated in place.
    r, rv, ra : float
        Reference position [m], velocity [m/s], acceleration [m/s²].
    y, vy : float
        Measured position [m] and velocity [m/s].
    dt : float
        Control period [s].
    """
    e = r - y
    ed = filter_derivative(C[C_ED], rv - vy, Q[Q_TF], dt)
    integ = C[C_I] + dt * e
    # friction feedforward (GMS elements stepped every period so switching is bumpless)
    n = int(Q[Q_GMS_N])
    if C[C_INIT] == 0.0:
        C[C_INIT] = 1.0
        C[C_RPREV] = r
    dx = r - C[C_RPREV]
    C[C_RPREV] = r
    C[C_RVL] = rv
    f_ff, f_static, f_gms = friction_feedforward(
        int(Q[Q_FF]), rv, dx, dt, Q[Q_FC], Q[Q_FS], Q[Q_VS], Q[Q_DELTA], Q[Q_FV],
        C, C_GMS_F, C_GMS_SLIP, Q, Q_GMS_ALPHA, Q_GMS_K, Q_GMS_SIGMA, n, Q[Q_GMS_C])
    C[C_FSTAT] = f_static
    C[C_FGMS] = f_gms
    # model-based compensation (a block after Q_SIZE / C_SIZE, when one is loaded)
    u_ff = f_ff / Q[Q_GAIN] + compensation_command(Q, Q_SIZE, C, C_SIZE, r, rv, ra, dt)
    u_fb, s = feedback(Q, C, e, ed, integ, ra, rv, y, dt, Q[Q_ADAPT] > 0.5)
    C[C_S] = s
    C[C_RAL] = ra
    C[C_YL] = y
    C[C_DTL] = dt
    u = u_fb + u_ff
    umax = Q[Q_UMAX]
    u_sat = min(max(u, -umax), umax)
    if u_sat != u and e * (u - u_sat) > 0.0:
        integ = C[C_I]  # anti-windup: do not integrate further into the limit
    C[C_I] = integ
    C[C_ED] = ed
    C[C_E] = e
    C[C_U] = u_sat
    C[C_UFF] = u_ff
    return u_sat


class Controller:
    """A stateful controller: mode, feedforward, validated parameters, packed kernel data.

    Build it with :func:`make_controller`.  ``step`` is what the ROS controller node
    calls each period; :attr:`packed` / :attr:`state` are what the simulator's compiled
    loop uses, so both run exactly the same arithmetic.
    """

    def __init__(self, plant: PlantConfig, mode: ControlMode, feedforward: Feedforward,
                 params: Mapping[ControlMode, ParamsBase]) -> None:
        self.plant = plant
        self._mode = mode
        self._ff = feedforward
        self._params: dict[ControlMode, ParamsBase] = dict(params)
        model = plant.model
        self._gms = model.get('presliding')
        if feedforward & Feedforward.GMS and self._gms is None:
            raise ParameterError(f'feedforward {feedforward.label!r} needs a presliding '
                                 f'(GMS) effect in the nominal model {plant.source!r}')
        self.state = np.zeros(C_SIZE)
        self.packed = np.zeros(Q_SIZE)
        self._comp: Compensation | None = None
        self._pack()
        self.reset()

    # -- packing ---------------------------------------------------------------------
    def _pack(self) -> None:
        Q = np.zeros(Q_SIZE)
        model = self.plant.model
        mode, p = self._mode, self._params[self._mode]
        Q[Q_MODE] = float(mode)
        Q[Q_FF] = float(self._ff)
        Q[Q_UMAX] = p.u_max
        Q[Q_TF] = p.tf
        if mode is ControlMode.ADAPTIVE_SLIDING:
            Q[Q_KP], Q[Q_KI], Q[Q_KD] = p.pid_gains
            Q[Q_LAM1], Q[Q_LAM2], Q[Q_PHI], Q[Q_KS] = p.lambda1, p.lambda2, p.phi, p.k_s
            theta, omega = nominal_theta(model, ripple_period=p.ripple_period)
            Q[Q_OMEGA] = omega
            Q[Q_ADAPT] = 1.0
            Q[Q_GAMMA:Q_GAMMA + N_THETA] = (p.gamma_mass, p.gamma_back_emf, p.gamma_fc,
                                            p.gamma_fv, p.gamma_ripple, p.gamma_ripple,
                                            p.gamma_k)
            lo, hi = projection_box(theta, p.bound_factor)
            Q[Q_LO:Q_LO + N_THETA], Q[Q_HI:Q_HI + N_THETA] = lo, hi
            rob = self.robustness
            Q[Q_EPS_TH], Q[Q_EPS_K] = rob.deadzone_theta, rob.deadzone_k
            Q[Q_KLAYER] = rob.layer_slope
            Q[Q_VREST], Q[Q_SIGMA] = rob.rest_speed, rob.sigma
            Q[Q_TH0:Q_TH0 + N_THETA] = theta
        else:
            Q[Q_KP], Q[Q_KI], Q[Q_KD] = p.kp, p.ki, p.kd
        if mode is ControlMode.NPID:
            Q[Q_K0], Q[Q_EMAX] = p.k0, p.e_max
            Q[Q_KMAX] = p.k_max if p.k_max > 0 else self.popov_limit()
        Q[Q_GAIN] = model.input_gain
        fc, fs, vs, delta = model.stribeck_curve_params()
        Q[Q_FC], Q[Q_FS], Q[Q_VS], Q[Q_DELTA], Q[Q_FV] = fc, fs, vs, delta, model.fv
        if self._gms is not None:
            n = len(self._gms.alpha)
            Q[Q_GMS_N], Q[Q_GMS_C] = n, self._gms.C
            Q[Q_GMS_ALPHA:Q_GMS_ALPHA + n] = self._gms.alpha
            Q[Q_GMS_K:Q_GMS_K + n] = self._gms.k
            Q[Q_GMS_SIGMA:Q_GMS_SIGMA + n] = self._gms.sigma
        self.packed[:Q_SIZE] = Q
        if self._comp is not None:   # the terms this law now carries itself
            self.packed[Q_SIZE:] = self._comp.carried_for(self.carried)

    @property
    def carried(self) -> Carried:
        """Terms of a compensation model this law carries itself (never added twice).

        The friction feedforward carries its static curve and/or GMS elements (and
        ``fv·ṙ`` with ``static``); the adaptive law its inertial, back-EMF/damping,
        Coulomb and viscous estimates, and the first ripple harmonic when the model's
        ripple period is the law's (:mod:`.compensation`, module table).
        """
        ff = self._ff
        dry = CarriedDry.ALL if ff & Feedforward.GMS else \
            CarriedDry.STATIC if ff & Feedforward.STATIC else CarriedDry.NONE
        viscous = bool(ff & Feedforward.STATIC)
        if self._mode is not ControlMode.ADAPTIVE_SLIDING:
            return Carried(dry=dry, viscous=viscous)
        rip = self._comp.model.get('ripple') if self._comp is not None \
            and self._comp.model is not None else None
        law_period = 2.0 * math.pi / self.packed[Q_OMEGA]
        return Carried(dry=max(dry, CarriedDry.COULOMB), viscous=True, rigid=True,
                       ripple_first=rip is not None
                       and abs(rip.period / law_period - 1.0) < RIPPLE_PERIOD_MATCH)

    @property
    def robustness(self) -> Robustness:
        """Dead zone, layer slope, rest speed and leakage of the adaptive laws (SI)."""
        p = self._params.get(ControlMode.ADAPTIVE_SLIDING) or AdaptiveParams()
        sens = self.plant.sensors
        return robustness(p, encoder_resolution=sens.encoder_resolution,
                          noise_std=sens.noise_std, control_period=1.0 / self.plant.control_rate)

    def popov_limit(self) -> float:
        """Popov (Tsypkin) bound of k(e) for the sampled loop of the nominal plant.

        Chiew eq. 9 on the loop as implemented: ZOH, dead time, discrete PID at the
        control rate (:func:`~motor_comp.control.npid.sampled_loop`).
        """
        p = self._params.get(ControlMode.NPID, NPIDParams())
        dly = self.plant.model.get('delay')
        T = 1.0 / self.plant.control_rate
        w, L = sampled_loop(self.plant.model, p, delay=dly.tau if dly else 0.0,
                            control_period=T)
        return max(1.0, popov_limit(L, w, control_period=T))

    # -- the step ------------------------------------------------------------------
    def step(self, ref_pos: float, ref_vel: float, ref_acc: float, meas_pos: float,
             meas_vel: float, dt: float) -> float:
        """Command [V] for one control period ``dt`` [s] (same kernel as the simulator)."""
        return float(controller_step(self.packed, self.state, float(ref_pos),
                                     float(ref_vel), float(ref_acc), float(meas_pos),
                                     float(meas_vel), float(dt)))

    # -- run-time changes -----------------------------------------------------------
    @property
    def mode(self) -> ControlMode:
        """Current mode."""
        return self._mode

    @property
    def feedforward(self) -> Feedforward:
        """Current friction feedforward."""
        return self._ff

    @property
    def params(self) -> ParamsBase:
        """Parameters of the current mode."""
        return self._params[self._mode]

    def params_of(self, mode: 'str | ControlMode') -> ParamsBase:
        """Parameters of any mode (its defaults if it has not been used yet)."""
        m = ControlMode.parse(mode)
        return self._params.setdefault(m, default_params(m, self.plant))

    def _rebalance(self, target: float) -> None:
        """Set the integrator so that the last output would have been ``target`` [V].

        The current law is evaluated at the last step's inputs (estimates frozen); it is
        affine in the integral except for the adaptive ``sat(s/φ)``, so two secant steps
        settle it.
        """
        Q, C = self.packed, self.state
        # slope of the output in the integral: N-PID scales its PID by k(e) (up to
        # k_max ≈ 2.6: a secant step with slope Ki alone would diverge)
        k_e = npid_gain(C[C_E], Q[Q_K0], Q[Q_EMAX], Q[Q_KMAX])
        coef = {ControlMode.PID: Q[Q_KI], ControlMode.NPID: Q[Q_KI] * k_e,
                ControlMode.ADAPTIVE_SLIDING: Q[Q_KS] * Q[Q_LAM2]}[self._mode]
        if coef <= 0.0 or not math.isfinite(target):
            return
        for _ in range(2):
            u_fb, _s = feedback(Q, C.copy(), C[C_E], C[C_ED], C[C_I], C[C_RAL], C[C_RVL],
                                C[C_YL], C[C_DTL], False)
            C[C_I] += (target - C[C_UFF] - u_fb) / coef

    def _feedforward_at_last(self, *, state: np.ndarray | None = None) -> float:
        """Feedforward command [V] of the current settings at the last step's reference.

        The friction feedforward from its last forces, the compensation evaluated at the
        last reference (on ``state``, the controller state, when given: a compensation
        just loaded starts its own state there; otherwise on a copy, so nothing the run
        depends on is stepped twice).
        """
        C = self.state
        ff = self._ff
        f = {Feedforward.NONE: 0.0, Feedforward.STATIC: C[C_FSTAT],
             Feedforward.GMS: C[C_FGMS],
             Feedforward.STATIC_GMS: C[C_FGMS] + self.plant.model.fv * C[C_RVL]}[ff]
        u = f / self.plant.model.input_gain
        if self._comp is not None:
            work = C.copy() if state is None else state
            u += compensation_command(self.packed, Q_SIZE, work, C_SIZE, C[C_RPREV],
                                      C[C_RVL], C[C_RAL], C[C_DTL])
        return u

    def _bumpless(self, u_last: float) -> None:
        """After a change of law or feedforward: the next command continues from u_last."""
        self.state[C_UFF] = self._feedforward_at_last()
        self._rebalance(u_last)

    def set_mode(self, mode: 'str | ControlMode', *, keep_estimates: bool = True) -> None:
        """Switch mode bumplessly: the integrator is re-balanced to the last output."""
        mode = ControlMode.parse(mode)
        if mode not in self._params:
            self._params[mode] = default_params(mode, self.plant)
        u_last, started = self.state[C_U], self.state[C_INIT] > 0
        self._mode = mode
        self._pack()
        if not keep_estimates:
            self._reset_estimates()
        if started:
            self._bumpless(u_last)

    def set_feedforward(self, feedforward: 'str | Feedforward') -> None:
        """Switch the friction feedforward bumplessly (the integrator absorbs the step).

        A loaded compensation gives up the friction terms the feedforward now carries
        (:attr:`carried`), so nothing is counted twice.
        """
        ff = Feedforward.parse(feedforward)
        if ff & Feedforward.GMS and self._gms is None:
            raise ParameterError(f'feedforward {ff.label!r} needs a presliding (GMS) effect '
                                 f'in the nominal model')
        u_last, started = self.state[C_U], self.state[C_INIT] > 0
        self._ff = ff
        self._pack()
        if started:
            self._bumpless(u_last)

    def update(self, *, mode: 'str | ControlMode | None' = None, **params: Any) -> None:
        """Change parameters of ``mode`` (default: current), validated, all or nothing."""
        m = self._mode if mode is None else ControlMode.parse(mode)
        current = self._params.get(m) or default_params(m, self.plant)
        new = current.replace(**params)  # raises ParameterError naming the field
        self._params[m] = new
        if m is self._mode:
            try:
                self._pack()
            except Exception:
                self._params[m] = current   # all or nothing
                self._pack()
                raise

    @property
    def estimates(self) -> dict[str, float]:
        """Adaptive estimates in physical units (kg, V·s/m, N, N·s/m, N, N, N)."""
        return estimates_in_units(self.state[C_TH:C_TH + N_THETA],
                                  self.plant.model.input_gain)

    @property
    def nominal(self) -> dict[str, float]:
        """The nominal model's values of :attr:`estimates` (what the law was built from)."""
        theta, _ = nominal_theta(self.plant.model)
        return estimates_in_units(theta, self.plant.model.input_gain)

    def _reset_estimates(self) -> None:
        p = self._params.get(ControlMode.ADAPTIVE_SLIDING)
        frac = p.initial_fraction if p is not None else 0.5
        theta, _ = nominal_theta(self.plant.model,
                                 ripple_period=p.ripple_period if p is not None else 0.0)
        init = frac * theta
        init[6] = 0.0  # the robust gain starts at zero and grows with |s_Δ|
        self.state[C_TH:C_TH + N_THETA] = init

    def reset(self) -> None:
        """Back to the initial state (integrators, filters, feedforward, estimates)."""
        self.state[:] = 0.0
        self._reset_estimates()

    # -- model-based compensation (motor_comp.control.compensation) ------------------
    @property
    def compensation(self) -> Compensation | None:
        """The loaded compensation, or None."""
        return self._comp

    def set_compensation(self, comp: Compensation | None) -> None:
        """Load (or with None remove) a compensation; bumpless while running.

        The terms this law carries itself (:attr:`carried`: the friction feedforward's,
        the adaptive estimates) are left out of it, so nothing is counted twice; a
        mode or feedforward switch re-packs them.  While running, the integrator is
        re-balanced so the command does not jump: the new feedforward, evaluated at the
        last reference, replaces what the integral held.  The same model with other
        terms (:meth:`Compensation.with_terms`) keeps its GMS element state.
        """
        Q, C = self.packed, self.state
        started = C[C_INIT] > 0
        u_last = C[C_U]
        old = self._comp
        state = np.zeros(C_SIZE + (CS_SIZE if comp is not None else 0))
        state[:C_SIZE] = C[:C_SIZE]
        keep = (comp is not None and old is not None and comp.kind is CompensationKind.MODEL
                and old.model is not None and comp.model is old.model)
        if keep:
            state[C_SIZE:] = C[C_SIZE:]
        self._comp = comp
        self.packed = np.concatenate([Q[:Q_SIZE], comp.packed if comp is not None
                                      else np.zeros(0)])
        self._pack()
        self.state = state
        if started:
            # a new block starts its own state at the last reference (GMS relaxed)
            state[C_UFF] = self._feedforward_at_last(state=None if keep else state)
            self._rebalance(u_last)

    @property
    def compensation_force(self) -> float:
        """Force [N] the compensation added at the last step (0 without one)."""
        return float(self.state[C_SIZE + CS_F]) if self.state.shape[0] > C_SIZE else 0.0

    def describe(self) -> dict[str, Any]:
        """Mode, feedforward and parameters as plain values (run metadata)."""
        out = {'controller': self._mode.label, 'feedforward': self._ff.label,
               **{k: v for k, v in self.params.as_dict().items()}}
        if self._comp is not None:
            out.update(self._comp.describe())
            out['compensation_carried'] = self.carried.names(self._comp)
        return out


def default_params(mode: ControlMode, plant: PlantConfig) -> ParamsBase:
    """Return the defaults of ``mode`` for ``plant``.

    Ball-screw: PID and N-PID share the loop-shaping design of :mod:`.npid`.  PMLM: PID
    and the N-PID base = the adaptive controller's PID part (Tan's fair baseline).
    """
    if mode is not ControlMode.ADAPTIVE_SLIDING and plant.kind is PlantKind.PMLM:
        kp, ki, kd = AdaptiveParams().pid_gains
        return PARAMS[mode]().replace(kp=kp, ki=ki, kd=kd, tf=AdaptiveParams().tf)
    return PARAMS[mode]()


def make_controller(mode: 'str | ControlMode', *, plant: PlantConfig,
                    feedforward: 'str | Feedforward' = 'none', **params: Any) -> Controller:
    """Build a controller for ``plant`` in ``mode`` with parameter overrides ``params``."""
    m = ControlMode.parse(mode)
    ff = Feedforward.parse(feedforward)
    check_positive('control_rate [Hz]', plant.control_rate)
    base = default_params(m, plant)
    return Controller(plant, m, ff, {m: base.replace(**params)})


__all__ = ['ControlMode', 'Controller', 'ESTIMATES', 'Feedforward', 'controller_step',
           'default_params', 'make_controller']
