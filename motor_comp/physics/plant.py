"""The simulated plant: an :class:`AxisModel` packed for the compiled kernel, with sensors.

:class:`Plant` owns the parameter and state vectors of :mod:`motor_comp.physics.kernel`
and exposes the step functions both drivers use (the in-process simulator and the ROS
``plant_node``).  Sensor and actuator imperfections that are not forces live here:
encoder quantisation [m], measurement noise [m], command saturation [V], external load.
On a rotary axis (``AxisModel.axis``) read rad for m and N·m for N throughout.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from motor_comp.errors import ParameterError, check_finite, check_nonnegative, \
    check_positive
from motor_comp.physics import kernel as K
from motor_comp.physics.axis import AxisModel


@dataclasses.dataclass(frozen=True)
class Sensors:
    """Measurement and actuation imperfections.

    Parameters
    ----------
    encoder_resolution : float
        Encoder quantum [m]; 0 for an ideal sensor.
    noise_std : float
        Standard deviation of additive position noise [m] before quantisation.
    saturation : float
        Command limit ±[V]; ``inf`` for none.
    """

    encoder_resolution: float = 1e-6
    noise_std: float = 0.0
    saturation: float = math.inf

    def __post_init__(self) -> None:
        object.__setattr__(self, 'encoder_resolution', check_nonnegative(
            'encoder_resolution [m]', self.encoder_resolution))
        object.__setattr__(self, 'noise_std', check_nonnegative('noise_std [m]',
                                                                self.noise_std))
        try:
            sat = float(self.saturation)
        except (TypeError, ValueError):
            raise ParameterError(
                f'saturation [V] must be a number, got {self.saturation!r}') from None
        if not sat > 0.0:  # inf (no limit) is allowed, NaN is not
            raise ParameterError(f'saturation [V] must be > 0, got {sat:g}')
        object.__setattr__(self, 'saturation', sat)


@dataclasses.dataclass(frozen=True)
class StepLoad:
    """External load force switched on at a time: ``F(t) = force·[t ≥ t_start]``.

    Parameters
    ----------
    force : float
        Load force [N] (subtracted like every effect force).
    t_start : float
        Switch-on time [s].
    """

    force: float = 0.0
    t_start: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'force', check_finite('load.force [N]', self.force))
        object.__setattr__(self, 't_start', check_nonnegative('load.t_start [s]',
                                                              self.t_start))

    def at(self, t: float) -> float:
        """Load force [N] at time ``t`` [s]."""
        return self.force if t >= self.t_start else 0.0


def pack_params(model: AxisModel, sensors: Sensors, dt: float) -> np.ndarray:
    """Pack a model, its sensors and the physics step ``dt`` [s] into the kernel vector."""
    dt = check_positive('physics step [s]', dt)
    P = np.zeros(K.P_SIZE)
    P[K.P_MASS] = model.mass
    P[K.P_GAIN] = model.input_gain
    P[K.P_BEMF] = model.back_emf
    P[K.P_DAMP] = model.damping
    fc, fs, vs, delta = model.stribeck_curve_params()
    P[K.P_FC], P[K.P_FS], P[K.P_VS], P[K.P_DELTA] = fc, fs, vs, delta
    P[K.P_FV] = model.fv
    asym = model.get('asymmetry')
    if asym is not None:
        P[K.P_DFC], P[K.P_DFV] = asym.dfc, asym.dfv
    gms = model.get('presliding')
    if gms is not None:
        n = len(gms.alpha)
        P[K.P_GMS_ON] = 1.0
        P[K.P_GMS_N] = n
        P[K.P_GMS_C] = gms.C
        P[K.P_GMS_ALPHA:K.P_GMS_ALPHA + n] = gms.alpha
        P[K.P_GMS_K:K.P_GMS_K + n] = gms.k
        P[K.P_GMS_SIGMA:K.P_GMS_SIGMA + n] = gms.sigma
    rip = model.get('ripple')
    if rip is not None:
        nh = len(rip.harmonics)
        P[K.P_RIP_NH] = nh
        P[K.P_RIP_PERIOD] = rip.period
        P[K.P_RIP_A:K.P_RIP_A + nh] = rip.a
        P[K.P_RIP_B:K.P_RIP_B + nh] = rip.b
    else:
        P[K.P_RIP_PERIOD] = 1.0
    off = model.get('offset')
    if off is not None:
        P[K.P_F0] = off.f0
    spr = model.get('spring')
    if spr is not None:
        P[K.P_SPRING_K], P[K.P_SPRING_X0] = spr.k, spr.x0
    dly = model.get('delay')
    if dly is not None:
        P[K.P_DELAY_STEPS] = dly.tau / dt
    bl = model.get('backlash')
    if bl is not None:
        P[K.P_BACKLASH] = bl.width
    grav = model.get('gravity')
    if grav is not None:
        P[K.P_GRAV_MGL], P[K.P_GRAV_Q0] = grav.mgl, grav.q0
    lf = model.get('load_friction')
    if lf is not None:
        P[K.P_LF_MU] = lf.mu
    pf = model.get('position_friction')
    if pf is not None:
        n = len(pf.x)
        P[K.P_PF_N] = n
        P[K.P_PF_X:K.P_PF_X + n] = pf.knots
        P[K.P_PF_Y:K.P_PF_Y + n] = pf.values
        P[K.P_PF_M:K.P_PF_M + n] = pf.slopes
    P[K.P_UMAX] = sensors.saturation
    P[K.P_QUANT] = sensors.encoder_resolution
    P[K.P_DT] = dt
    return P


def _rk4_gain(z: complex) -> float:
    """|R(z)| of classical RK4, ``R(z) = 1 + z + z²/2 + z³/6 + z⁴/24``."""
    return abs(1.0 + z * (1.0 + z / 2.0 * (1.0 + z / 3.0 * (1.0 + z / 4.0))))


def stiffest_modes(model: AxisModel) -> np.ndarray:
    """Eigenvalues [1/s] of the axis linearised at rest with every GMS element stuck.

    ``M·ẍ + D·ẋ + K·x = 0`` with ``K = Σk_i (GMS) + spring.k`` [N/m] and
    ``D = damping + fv + Σσ_i + input_gain·back_emf`` [N·s/m]: the fastest motion the
    explicit RK4 step must resolve (the pre-sliding resonance and its micro-damping).
    """
    gms = model.get('presliding')
    spr = model.get('spring')
    k = (gms.stiffness if gms is not None else 0.0) + (spr.k if spr is not None else 0.0)
    d = model.damping + model.fv + model.input_gain * model.back_emf + (
        sum(gms.sigma) if gms is not None else 0.0)
    return np.roots([model.mass, d, k]) if k != 0.0 else np.array([-d / model.mass])


def check_step_stable(model: AxisModel, physics_rate: float) -> None:
    """Raise :class:`ParameterError` if RK4 at ``physics_rate`` [Hz] cannot hold the axis.

    The check is on the decaying :func:`stiffest_modes` (a growing one, e.g. of a
    negative spring, is the physics, not the integrator); the message names the rate
    that would do.
    """
    modes = [lam for lam in stiffest_modes(model) if lam.real <= 0.0]
    if all(_rk4_gain(lam / physics_rate) <= 1.0 + 1e-12 for lam in modes):
        return
    rate = physics_rate
    while not all(_rk4_gain(lam / rate) <= 1.0 + 1e-12 for lam in modes):
        rate *= 1.25
    fast = max(abs(lam) for lam in modes)
    raise ParameterError(
        f'physics_rate [Hz] {physics_rate:g} is too low for this axis: its stiffest mode '
        f'at rest (|λ| = {fast:.4g} 1/s, from GMS k/sigma, spring, damping and mass) '
        f'makes the RK4 step unstable; use physics_rate >= {math.ceil(rate):d} Hz')


def initial_state(P: np.ndarray, x0: float = 0.0) -> np.ndarray:
    """Return a state vector at rest at ``x0`` [m], sized for the packed dead time."""
    nbuf = int(math.ceil(P[K.P_DELAY_STEPS])) + 2 if P[K.P_DELAY_STEPS] > 0 else 0
    S = np.zeros(K.S_BASE + nbuf)
    S[K.S_X] = S[K.S_XL] = S[K.S_YPREV] = x0
    q = P[K.P_QUANT]
    if q > 0:
        S[K.S_YPREV] = q * np.round(x0 / q)
    S[K.S_STUCK] = 1.0
    return S


@dataclasses.dataclass(frozen=True)
class Measurement:
    """One encoder reading: position [m] and backward-difference velocity [m/s]."""

    position: float
    velocity: float


class Plant:
    """A stateful simulated axis driven at a control period with physics sub-steps.

    Parameters
    ----------
    model : AxisModel
        The true axis (effects included).
    sensors : Sensors
        Encoder, noise, saturation.
    physics_rate : float
        Physics rate [Hz], >= 1000 (DESIGN.md asks >= 10 kHz by default).
    load : StepLoad, optional
        External load profile.
    seed : int
        Seed of the measurement-noise generator (deterministic runs).
    x0 : float
        Initial position [m].
    """

    def __init__(self, model: AxisModel, *, sensors: Sensors | None = None,
                 physics_rate: float = 10_000.0, load: StepLoad | None = None,
                 seed: int = 0, x0: float = 0.0) -> None:
        physics_rate = check_positive('physics_rate [Hz]', physics_rate)
        if physics_rate < 1000.0:
            raise ParameterError(f'physics_rate [Hz] must be >= 1000, got {physics_rate:g}')
        check_step_stable(model, physics_rate)
        self.model = model
        self.sensors = sensors or Sensors()
        self.physics_rate = physics_rate
        self.load = load or StepLoad()
        self.seed = int(seed)
        self.params = pack_params(model, self.sensors, 1.0 / physics_rate)
        self.x0 = float(x0)
        self.reset()

    def reset(self) -> None:
        """Back to rest at ``x0`` with a fresh noise generator."""
        self.state = initial_state(self.params, self.x0)
        self._rng = np.random.default_rng(self.seed)

    def substeps(self, dt_control: float) -> int:
        """Physics steps per control period ``dt_control`` [s] (must divide evenly)."""
        n = dt_control * self.physics_rate
        ni = int(round(n))
        if ni < 1 or abs(n - ni) > 1e-6 * max(1.0, n):
            raise ParameterError(
                f'control period {dt_control:g} s is not a whole number of physics steps '
                f'at {self.physics_rate:g} Hz')
        return ni

    def step(self, u: float, dt_control: float, f_ext: float | None = None) -> None:
        """Hold command ``u`` [V] for ``dt_control`` [s]; load from ``self.load`` by default."""
        if not math.isfinite(u):
            raise ParameterError(f'plant command must be finite, got {u!r}')
        f = self.load.at(self.time) if f_ext is None else float(f_ext)
        K.plant_advance(self.params, self.state, float(u), f, self.substeps(dt_control))

    def noise_sample(self) -> float:
        """Draw the next measurement-noise sample [m] (0 without noise)."""
        sd = self.sensors.noise_std
        return float(self._rng.normal(0.0, sd)) if sd > 0 else 0.0

    def measure(self, dt_control: float) -> Measurement:
        """Read the encoder (load side) and the velocity over the last ``dt_control`` [s]."""
        y, vy = K.plant_measure(self.params, self.state, self.noise_sample(), dt_control)
        return Measurement(position=float(y), velocity=float(vy))

    # -- true state views ----------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated time [s]."""
        return float(self.state[K.S_T])

    @property
    def position(self) -> float:
        """True motor position [m]."""
        return float(self.state[K.S_X])

    @property
    def load_position(self) -> float:
        """True load position [m] (differs from the motor by backlash)."""
        return float(self.state[K.S_XL])

    @property
    def velocity(self) -> float:
        """True velocity [m/s]."""
        return float(self.state[K.S_V])

    @property
    def friction_force(self) -> float:
        """Friction force of the last step [N] (static-model or GMS, incl. asymmetry)."""
        return float(self.state[K.S_FRICTION])

    @property
    def ripple_force(self) -> float:
        """Ripple force at the current position [N]."""
        return float(self.state[K.S_RIPPLE])

    @property
    def applied_command(self) -> float:
        """Command actually applied after saturation and delay [V]."""
        return float(self.state[K.S_UEFF])

    @property
    def stuck(self) -> bool:
        """Whether the axis is held by static friction (static friction models only)."""
        return bool(self.state[K.S_STUCK] > 0.5)
