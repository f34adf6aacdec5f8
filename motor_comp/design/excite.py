"""``excite``: an identification trajectory chosen to minimise the predicted standard errors.

From a start model and the axis limits
(:class:`~motor_comp.control.excitation.ExcitationLimits`) the design
(``../shared/IDENTIFICATION.md`` §9) proceeds in four steps:

1. **Candidate parts** (:mod:`motor_comp.control.excitation`): passes at
   :data:`SPEED_LEVELS` speeds geometric from the creep speed to ``vmax`` (out and
   back: both directions; with a Stribeck effect also :data:`STRIBECK_SPEEDS` around
   its ``vs``), reversal bursts at amplitudes of 3–100 encoder counts (pre-sliding),
   and sweeps — a cruise with its speed modulated, no reversal — at :data:`SWEEPS`
   frequencies up to the bandwidth (accelerations for the mass and the dead time).
   Each is within the travel, ``vmax``, ``amax`` and the drive limits under the start
   model (a part whose inverse dynamics ask more than 90 % of ``fmax``/``umax`` is
   slowed or shrunk).  The creep speed is the slowest the loop holds steadily on the
   start model (:func:`creep_speed`: below it the axis stick-slips).
2. **Information of each part**: the part is simulated in closed loop on the start
   model (the project's simulator, the controller the run will use, the sensor's
   quantisation and noise), processed like any run
   (:func:`~motor_comp.workbench.derivatives.kinematics`), and the regressor columns of
   the start model's parameters are formed along it — ``∂F/∂θ`` of the inverse dynamics
   ``F = M·ẍ + Σ F_k(x, ẋ)``: ``ẍ`` (mass), ``sgn ẋ`` (Coulomb), ``ẋ`` (viscous),
   ``sin/cos hωx`` (ripple), … by central differences of the effects' own laws, and
   ``−input_gain·u̇`` for a dead time.  Its Fisher information per second is
   ``JᵀJ/T`` (up to the noise variance, which does not change the choice).
3. **D-optimal allocation** of the time (every part at least once, so every regime is
   there; the rest of ``duration`` shared out): the multiplicative algorithm of
   Silvey, Titterington & Torsney (1978), ``w_i ← w_i·tr(M⁻¹M_i)/p``, maximises
   ``log det M`` (the volume of the parameters' confidence ellipsoid shrinks fastest;
   invariant to the parameters' units, unlike an A-optimal trace).
4. **Assembly and prediction**: the parts are interleaved (speeds in a bit-reversed
   order: not rising in time, so a drift is not confounded with speed, §8), placed over
   the travel by a van der Corput sequence, joined by minimum-jerk moves and rests;
   then the whole table is simulated in closed loop on the start model and refitted by
   the workbench's public :func:`~motor_comp.workbench.fit.fit` (no ``add``):
   ``FitResult.uncertainty`` is the estimator's own standard error on the data the
   excitation will produce; its median over :data:`PREDICT_RUNS` noise draws is the
   prediction printed and returned.  It is as good as the start model: the loop's noise
   and the run's regimes (stick-slip below a Stribeck velocity, the closed loop's jitter)
   follow the plant's parameters, and so do the fit's errors.

The travel must cover two periods of every position-dependent effect (the model's
ripple and any ``periods`` hinted) and, for ``gravity``, half a revolution (sine and
cosine both varied, IDENTIFICATION.md §6); otherwise a one-line error says so.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Sequence

import numpy as np

from motor_comp.control.controller import Controller, make_controller
from motor_comp.control.excitation import Burst, ExcitationLimits, Pass, Peaks, Profile, \
    Sweep, assemble, check_limits, drive_along, peaks, van_der_corput
from motor_comp.control.nominal import derive_nominal
from motor_comp.control.simulator import simulate
from motor_comp.control.trajectories import Table, TableData, table_from_arrays
from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel, InputKind
from motor_comp.physics.config import PlantConfig, PlantKind, load_plant
from motor_comp.physics.plant import Sensors

#: number of speed levels, geometric from creep to vmax
SPEED_LEVELS = 8
#: extra pass speeds, as multiples of a Stribeck velocity of the start model
STRIBECK_SPEEDS = (0.6, 1.2, 2.4)
#: reversal amplitudes in encoder counts (pre-sliding lives over a few to tens of µm)
REVERSAL_COUNTS = (3.0, 10.0, 30.0, 100.0)
#: number of sweeps, at frequencies geometric from bandwidth/4 to the bandwidth
SWEEPS = 3
#: cycles of a reversal burst and of an acceleration burst
REVERSAL_CYCLES, SWEEP_CYCLES = 3.0, 3.0
#: one-way time of a slow pass (its stroke is speed × this, up to the travel) [s]
SLOW_PASS_TIME = 1.0
#: rest after each part [s]
REST = 0.2
#: share of the travel kept clear of each end
MARGIN = 0.01
#: a part may ask at most this share of fmax / umax under the start model
DRIVE_SHARE = 0.9
#: simulated runs whose fits' standard errors are summarised (median) as the prediction:
#: a fit's SE is itself a statistic of one run (its spread and noise re-measurements
#: vary by ±50 % from one noise draw to the next on a 60 s run)
PREDICT_RUNS = 5
#: longest excitation [s]: a 1 kHz table of it stays under the 16 MiB a node reads
MAX_DURATION = 240.0


# ---- how the run will be made ---------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Loop:
    """The closed loop the excitation will run in: axis, sensors, rates, controller.

    Attributes
    ----------
    plant : PlantConfig
        The axis as simulated: the start (or, for a recording, the true) model with the
        sensors and rates of the run.
    nominal : PlantConfig
        What the controller is built from.
    mode : str
        ``pid | npid | adaptive_sliding``.
    gains : dict
        The controller's parameters (empty: the defaults of ``nominal``).
    """

    plant: PlantConfig
    nominal: PlantConfig
    mode: str
    gains: dict

    def controller(self) -> Controller:
        """Build a fresh controller of this loop."""
        return make_controller(self.mode, plant=self.nominal, **self.gains)

    def with_model(self, model: AxisModel) -> 'Loop':
        """Return the same loop on another axis model (e.g. the true plant of a recording)."""
        return dataclasses.replace(self, plant=self.plant.with_model(model))

    def describe(self) -> dict[str, Any]:
        """Plain values: mode and parameters (JSON)."""
        return {'mode': self.mode, 'nominal': self.nominal.source or 'start model',
                **self.controller().params.as_dict()}


def pid_for(model: AxisModel, bandwidth_hz: float) -> dict[str, float]:
    """PID gains placing the rigid axis's closed-loop poles at ``−ω`` (triple), ω = 2π·bw.

    The rigid axis with its drive law is ``M·ẍ + c·ẋ = g·u``, ``c = damping +
    g·back_emf``; with ``u = Kp·e + Ki·∫e + Kd·ė`` the characteristic polynomial
    ``M·s³ + (c + g·Kd)·s² + g·Kp·s + g·Ki`` equals ``M·(s + ω)³`` for
    ``Kp = 3Mω²/g``, ``Ki = Mω³/g``, ``Kd = (3Mω − c)/g`` (0 when the drive damps
    more); the derivative filter is ``1/(10ω)``.
    """
    w = 2.0 * math.pi * bandwidth_hz
    g = model.input_gain
    c = model.damping + g * model.back_emf
    return {'kp': 3.0 * model.mass * w * w / g, 'ki': model.mass * w ** 3 / g,
            'kd': max(3.0 * model.mass * w - c, 0.0) / g, 'tf': 0.1 / w}


def loop_for(model: AxisModel, *, plant: str | None = None, mode: str | None = None,
             encoder: float | None = None, noise_std: float | None = None,
             loop_bandwidth: float | None = None, control_rate: float = 1000.0) -> Loop:
    """Build the loop of the run: a plant's controller, or a PID placed on ``model``.

    With ``plant`` (``pmlm``, ``ballscrew`` or a plant YAML) the controller is that
    plant's (its nominal model, default mode ``pid`` on the PMLM, ``npid`` on the
    ball-screw, default gains: what ``simulate``/``run`` use) and so are the sensors and
    rates; otherwise a PID placed by :func:`pid_for` at ``loop_bandwidth`` (default
    20 Hz, at most ``control_rate/25`` and ``0.03/τ`` with a dead time) on the start
    model, a 1 µm (or µrad) encoder and no noise.  ``encoder``/``noise_std`` override.
    """
    if plant is not None:
        cfg = load_plant(plant)
        nominal = derive_nominal(cfg)
        mode = mode or ('npid' if cfg.kind is PlantKind.BALLSCREW else 'pid')
        sensors = cfg.sensors
        gains: dict = {}
        base = cfg
    else:
        rate = control_rate
        dly = model.get('delay')
        bw = loop_bandwidth or 20.0
        bw = min(bw, rate / 25.0, 0.03 / dly.tau if dly is not None and dly.tau > 0 else bw)
        mode = mode or 'pid'
        if mode != 'pid':
            raise ParameterError('without --plant the loop is a PID placed on the start '
                                 'model; another --controller needs --plant')
        gains = pid_for(model, bw)
        sensors = Sensors(encoder_resolution=1e-6, noise_std=0.0)
        base = PlantConfig(kind=PlantKind.PMLM, model=model, sensors=sensors,
                           control_rate=rate, source='start model')
        nominal = base
    sensors = Sensors(encoder_resolution=sensors.encoder_resolution if encoder is None
                      else encoder,
                      noise_std=sensors.noise_std if noise_std is None else noise_std,
                      saturation=sensors.saturation)
    axis = dataclasses.replace(base, model=model, sensors=sensors)
    return Loop(plant=axis, nominal=dataclasses.replace(nominal, sensors=sensors),
                mode=mode, gains=gains)


def record(loop: Loop, data: TableData, *, seed: int, name: str = 'excitation') -> Any:
    """Simulate ``loop`` along the table; return the run (:class:`~motor_comp.logs.run.Run`)."""
    traj = Table(data=data)
    res = simulate(loop.plant, loop.controller(), traj, duration=data.duration, seed=seed)
    return res.to_run(name=name)


# ---- the regressor columns of a model's parameters ------------------------------------
#: the scalar parameters of each effect the information proxy differentiates
_PROXY_PARAMS = {'coulomb': ('fc',), 'viscous': ('fv',), 'stribeck': ('fs', 'vs', 'delta'),
                 'offset': ('f0',), 'spring': ('k', 'x0'), 'asymmetry': ('dfc', 'dfv'),
                 'gravity': ('mgl', 'q0'), 'presliding': ('k', 'C')}


def parameters(model: AxisModel) -> list[tuple[str, tuple]]:
    """Return ``(label, path into model.to_dict())`` of every parameter the proxy knows.

    The mass, each effect's scalars (:data:`_PROXY_PARAMS`), every ripple coefficient
    and its period; the GMS stiffness as one scale; a dead time.  ``backlash`` has no
    force law along a path and is left to the fit route.
    """
    out: list[tuple[str, tuple]] = [('mass', ('mass',))]
    for e in model.effects:
        if e.name == 'ripple':
            out.append(('ripple.period', ('effects', 'ripple', 'period')))
            for h in range(len(e.harmonics)):
                out.append((f'ripple.a{h + 1}', ('effects', 'ripple', 'harmonics', h, 0)))
                out.append((f'ripple.b{h + 1}', ('effects', 'ripple', 'harmonics', h, 1)))
        elif e.name == 'delay':
            out.append(('delay.tau', ('effects', 'delay', 'tau')))
        for p in _PROXY_PARAMS.get(e.name, ()):
            out.append((f'{e.name}.{p}', ('effects', e.name, p)))
    return out


def _get(d: Any, path: tuple) -> Any:
    for k in path:
        d = d[k]
    return d


def _set(d: Any, path: tuple, value: Any) -> None:
    for k in path[:-1]:
        d = d[k]
    d[path[-1]] = value


def _force(model: AxisModel, x: np.ndarray, v: np.ndarray, a: np.ndarray,
           dt: float) -> np.ndarray:
    return model.mass * a + sum(model.effect_forces(x, v, dt=dt).values(), np.zeros_like(x))


def columns(model: AxisModel, x: np.ndarray, v: np.ndarray, a: np.ndarray,
            du: np.ndarray, dt: float) -> tuple[list[str], np.ndarray]:
    """Regressor columns ``∂r/∂θ`` of the inverse-dynamics residual along a path.

    ``r = F_in(u(t − τ)) − M·a − Σ F_k(x, v)``: ``−∂F/∂θ`` by central differences of
    the effects' laws (exact for the linear parameters), and ``−input_gain·u̇`` for the
    dead time (``du`` = ``u̇``).  Returns the labels and the ``(n, p)`` matrix.
    """
    names, cols = [], []
    base = model.to_dict()
    for label, path in parameters(model):
        if label == 'delay.tau':
            cols.append(-model.input_gain * du)
            names.append(label)
            continue
        if path[-1] == 'k' and path[1] == 'presliding':
            ks = np.array(_get(base, path), dtype=float)
            value, setter = 1.0, (lambda d, s, ks=ks: _set(d, path, list(ks * s)))
        else:
            value = float(_get(base, path))
            setter = (lambda d, s, path=path: _set(d, path, s))
        h = 1e-6 * max(abs(value), 1e-3)
        f = []
        for s in (value + h, value - h):
            d = _copy(base)
            setter(d, s)
            f.append(_force(AxisModel.from_dict(d), x, v, a, dt))
        cols.append(-(f[0] - f[1]) / (2.0 * h))
        names.append(label)
    return names, np.column_stack(cols)


def _copy(d: Any) -> Any:
    if isinstance(d, dict):
        return {k: _copy(v) for k, v in d.items()}
    if isinstance(d, list):
        return [_copy(v) for v in d]
    return d


def information(model: AxisModel, run: Any, *, window: tuple[float, float],
                hold: Any) -> tuple[list[str], np.ndarray]:
    """Return the Fisher information per second, for unit noise, of the parameters.

    The run is processed like any identification run (zero-phase smoothing and
    derivatives, :func:`~motor_comp.workbench.derivatives.kinematics`); rows at rest
    carry no sliding-friction information (the fit leaves them out) and are dropped
    unless the model has pre-sliding, which lives there.
    """
    from motor_comp.workbench.derivatives import kinematics
    kin = kinematics(run, hold=hold)
    m = (kin.t >= window[0]) & (kin.t <= window[1])
    if not model.has('presliding'):
        q = max(float(np.median(np.abs(np.diff(kin.position)))), 1e-12)
        m &= np.abs(kin.v) > 2.0 * q / kin.dt
    du = np.gradient(kin.u, kin.dt)
    names, J = columns(model, kin.x[m], kin.v[m], kin.a[m], du[m], kin.dt)
    return names, J.T @ J / max(window[1] - window[0], kin.dt)


def d_optimal(infos: Sequence[np.ndarray], fixed: np.ndarray, free: float, *,
              iterations: int = 300) -> np.ndarray:
    """Seconds ``u_i`` of each part beyond its fixed share, maximising ``log det M``.

    ``M = Σ fixed_i·M_i + Σ u_i·M_i`` with ``Σ u_i = free``: the multiplicative
    algorithm ``u_i ← u_i·tr(M⁻¹M_i) / Σ_j u_j·tr(M⁻¹M_j)·free`` (Silvey, Titterington
    & Torsney 1978; monotone in ``log det M``).  The columns are scaled to unit
    information first (the criterion is scale invariant; the inverse is not).
    """
    n = len(infos)
    total = sum(infos)
    s = 1.0 / np.sqrt(np.maximum(np.diag(total), 1e-300))
    infos = [M * np.outer(s, s) for M in infos]
    base = sum(f * M for f, M in zip(fixed, infos))
    ridge = 1e-9 * np.trace(sum(infos)) / len(s) * np.eye(len(s))
    u = np.full(n, free / n)
    if free <= 0.0:
        return np.zeros(n)
    for _ in range(iterations):
        M = base + sum(ui * Mi for ui, Mi in zip(u, infos)) + ridge
        Minv = np.linalg.inv(M)
        d = np.array([np.sum(Minv * Mi) for Mi in infos])   # tr(M⁻¹·M_i), M_i symmetric
        u = u * d
        u *= free / np.sum(u)
    return u


def predicted_se(infos: Sequence[np.ndarray], seconds: np.ndarray, sigma: float) -> np.ndarray:
    """Proxy standard errors ``√diag((Σ T_i·M_i)⁻¹)·σ`` (white noise of std ``σ`` [N])."""
    M = sum(t * Mi for t, Mi in zip(seconds, infos))
    return np.sqrt(np.maximum(np.diag(np.linalg.pinv(M)), 0.0)) * sigma


# ---- the design ----------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Candidate:
    """One part of the design space and what it teaches."""

    kind: str             # 'pass' | 'reversal' | 'sweep'
    part: Any             # Pass | Burst | Sweep
    level: float          # speed [m/s], reversal amplitude [m] or frequency [Hz]
    seconds: float        # length with its join and rest [s]
    info: np.ndarray      # Fisher information per second


@dataclasses.dataclass(frozen=True)
class Design:
    """A designed excitation and its predicted standard errors.

    Attributes
    ----------
    table : TableData
        The trajectory (``t, x, v, a``).
    limits : ExcitationLimits
        The limits it keeps.
    peaks : Peaks
        Its peaks and the drive it needs under the start model.
    loop : Loop
        The loop it was simulated in.
    start : AxisModel
        The start model.
    predicted_se : dict
        ``{effect: {param: SE}}`` — the fit's own standard errors on the simulated run
        of this excitation (the fit route), in the units of the model file.
    refit : AxisModel
        The model refitted on that simulated run (a sanity check of the design).
    proxy_se : dict
        ``{label: SE}`` of the information proxy at the fit's residual level.
    parts : list
        ``{kind, level, count, seconds}`` of every candidate part.
    order : list
        ``(kind, level, t0, t1)`` of the parts in time order (their windows [s]).
    creep : float
        Slowest pass speed [m/s] (:func:`creep_speed`).
    stick_slip : float or None
        Fastest speed at which the start model stick-slips under the loop (None: none
        found on the ladder).
    se_draws : dict
        ``{effect: {param: [SE, …]}}`` — each of the :data:`PREDICT_RUNS` fits' SE, of
        which ``predicted_se`` is the median (their scatter says how steadily a fit
        reports the parameter on this excitation).
    """

    table: TableData
    limits: ExcitationLimits
    peaks: Peaks
    loop: Loop
    start: AxisModel
    predicted_se: dict
    refit: AxisModel
    proxy_se: dict
    parts: list
    order: list
    creep: float = math.nan
    stick_slip: float | None = None
    se_draws: dict = dataclasses.field(default_factory=dict)

    @property
    def speeds(self) -> list[float]:
        """Cruise speeds of the passes in time order [m/s]."""
        return [lv for k, lv, *_ in self.order if k == 'pass']

    def as_dict(self) -> dict[str, Any]:
        """JSON form (keys of ``motor-comp excite --json``)."""
        return {'duration': self.table.duration, 'rows': int(self.table.t.shape[0]),
                'limits': {'travel': list(self.limits.travel), 'vmax': self.limits.vmax,
                           'amax': self.limits.amax, 'bandwidth': self.limits.bandwidth,
                           'fmax': _finite(self.limits.fmax),
                           'umax': _finite(self.limits.umax)},
                'peaks': self.peaks.as_dict(), 'controller': self.loop.describe(),
                'predicted_se': self.predicted_se, 'se_draws': self.se_draws,
                'proxy_se': self.proxy_se,
                'refit': self.refit.to_dict(), 'parts': self.parts,
                'speeds_in_order': self.speeds, 'creep_speed': self.creep,
                'stick_slip_speed': self.stick_slip,
                'start_model': self.start.to_dict()}


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def check_periods(model: AxisModel, limits: ExcitationLimits, periods: Sequence[float]) -> None:
    """One-line error when the travel is too short for a position-dependent effect."""
    span = limits.span * (1.0 - 2.0 * MARGIN)
    unit = model.units.position
    rip = model.get('ripple')
    wanted = ([(rip.period, 'the model\'s ripple period')] if rip is not None else []) + \
        [(float(p), '--period') for p in periods]
    for p, what in wanted:
        if not (math.isfinite(p) and p > 0):
            raise ParameterError(f'--period must be > 0, got {p!r}')
        if span < 2.0 * p:
            raise ParameterError(f'travel too short: {span:.4g} {unit} usable covers '
                                 f'{span / p:.2f} periods of {what} {p:g} {unit}; at least '
                                 f'2 are needed')
    if model.has('gravity') and span < math.pi:
        raise ParameterError(f'travel too short: {span:.4g} rad usable; gravity needs at '
                             f'least half a revolution (π rad) to tell mgl from q0')


def _quantum(loop: Loop, limits: ExcitationLimits) -> float:
    q = loop.plant.sensors.encoder_resolution
    return q if q > 0 else 1e-5 * limits.span


def _drive_peak(part: Any, centre: float, model: AxisModel, dt: float) -> tuple[float, float]:
    """Peak drive force and command of ``part`` under ``model`` (inverse dynamics)."""
    prof = Profile(part.start(centre))
    part.add_to(prof)
    t, x, v, a = prof.sample(dt)
    f, u = drive_along(model, x, v, a, dt)
    return float(np.max(np.abs(f))), float(np.max(np.abs(u)))


def _within_drive(make: Callable[[float], Any], centre: Callable[[Any], float],
                  model: AxisModel, limits: ExcitationLimits, dt: float, what: str) -> Any:
    """Return the part at the largest scale (1, 0.8, …) whose drive keeps the limits."""
    scale = 1.0
    for _ in range(25):
        part = make(scale)
        f, u = _drive_peak(part, centre(part), model, dt)
        if f <= DRIVE_SHARE * limits.fmax and u <= DRIVE_SHARE * limits.umax:
            return part
        scale *= 0.8
    raise ParameterError(f'the drive limits (fmax {limits.fmax:g}, umax {limits.umax:g}) '
                         f'leave no room for {what}: even slowed 50-fold it asks '
                         f'{f:.4g} {model.units.force} and a command of {u:.4g} under the '
                         f'start model (its friction, offset or gravity)')


def _pass(s: float, model: AxisModel, limits: ExcitationLimits, dt: float) -> Pass:
    """Return the pass at speed ``s`` (a slow one over ``s·SLOW_PASS_TIME``), in limits."""
    usable = limits.span * (1.0 - 2.0 * MARGIN)
    stroke = min(usable, s * SLOW_PASS_TIME + math.pi * s * s / (2.0 * limits.amax))

    def make(scale: float) -> Pass:
        return Pass.within(s * scale, stroke, 1, limits)
    return _within_drive(make, lambda p: limits.centre, model, limits, dt,
                         f'a pass at {s:g} {model.units.velocity}')


def lowest_speed(limits: ExcitationLimits, loop: Loop) -> float:
    """Slowest speed worth a pass: vmax/300, and 30 encoder counts per second."""
    return min(max(limits.vmax / 300.0, 30.0 * _quantum(loop, limits)), limits.vmax)


def creep_speed(model: AxisModel, limits: ExcitationLimits, loop: Loop, *,
                seed: int = 0) -> tuple[float, float | None]:
    """Slowest speed the loop holds steadily on the start model, and the fastest that sticks.

    Below a Stribeck velocity whose falling friction outweighs the damping, an axis
    under feedback stick-slips: a "constant-speed" pass is then a limit cycle whose
    sticking events change from one noise draw to the next, and so does what a fit can
    learn from it (measured on the ball-screw, stick-slip below 0.4 mm/s: the fitted
    Stribeck parameters' SEs varied 10× over noise seeds).  The passes are simulated
    from :func:`lowest_speed` up the geometric ladder; the first whose measured-free
    velocity stays above half its speed through both cruises is the creep speed.
    Returns ``(creep, fastest stick-slipping speed or None)``.
    """
    dt = 1.0 / loop.plant.control_rate
    v_lo = lowest_speed(limits, loop)
    stuck = None
    for s in np.geomspace(v_lo, limits.vmax, SPEED_LEVELS):
        part = _pass(float(s), model, limits, dt)
        prof = Profile(limits.centre)
        prof.hold(REST)
        prof.move(part.start(limits.centre), vmax=limits.vmax, amax=limits.amax)
        t0 = prof.t
        part.add_to(prof)
        prof.hold(REST)
        t, x, v, a = prof.sample(dt)
        res = simulate(loop.plant, loop.controller(),
                       Table(data=table_from_arrays(t, x, v, a, source='creep')),
                       duration=t[-1], seed=seed)
        cruise = (part.stroke - part.speed * part.ramp) / part.speed
        steady = True
        for way, d in enumerate((part.direction, -part.direction)):
            c0 = t0 + way * (2 * part.ramp + cruise) + part.ramp
            m = (res.t >= c0 + 0.1 * cruise) & (res.t <= c0 + cruise)
            if np.any(d * res.true_velocity[m] < 0.5 * part.speed):
                steady = False
        if steady:
            return float(part.speed), stuck
        stuck = float(part.speed)
    return float(limits.vmax), stuck


def candidate_parts(model: AxisModel, limits: ExcitationLimits, loop: Loop, *,
                    creep: float | None = None) -> list[tuple[str, float, Any]]:
    """``(kind, level, part)`` of the design space, each within every limit.

    The passes run at :data:`SPEED_LEVELS` speeds geometric from ``creep`` (default
    :func:`lowest_speed`) to ``vmax``.
    """
    dt = 1.0 / loop.plant.control_rate
    usable = limits.span * (1.0 - 2.0 * MARGIN)
    q = _quantum(loop, limits)
    v_lo = lowest_speed(limits, loop) if creep is None else creep
    speeds = np.geomspace(v_lo, limits.vmax, SPEED_LEVELS) if v_lo < limits.vmax \
        else np.array([limits.vmax])
    st = model.get('stribeck')
    if st is not None:
        # the Stribeck curve bends around vs: its shape is seen at speeds of that order
        # (IDENTIFICATION.md §6, Coulomb vs Stribeck), which a ladder spanning 2–3
        # decades samples once or twice
        extra = [f * st.vs for f in STRIBECK_SPEEDS if v_lo < f * st.vs < limits.vmax]
        speeds = np.unique(np.concatenate([speeds, extra]))
    out: list[tuple[str, float, Any]] = []
    for s in speeds:
        part = _pass(float(s), model, limits, dt)
        out.append(('pass', float(part.speed), part))
    f_rev = min(2.0, 0.5 * limits.bandwidth)
    for c in REVERSAL_COUNTS:
        amp = min(c * q, 0.1 * usable)
        part = Burst.within(amp, f_rev, REVERSAL_CYCLES, limits)
        out.append(('reversal', float(part.amplitude), part))
    for f in np.geomspace(0.25 * limits.bandwidth, limits.bandwidth, SWEEPS):

        def make_s(scale: float, f: float = f) -> Sweep:
            return Sweep.within(f, SWEEP_CYCLES, limits, usable=usable * scale)
        part = _within_drive(make_s, lambda p: limits.centre, model, limits, dt,
                             f'a sweep at {f:g} Hz')
        out.append(('sweep', float(f), part))
    return out


def _centres(kind: str, part: Any, n: int, limits: ExcitationLimits, k0: int) -> list[float]:
    """Centres of ``n`` instances of ``part`` spread over the travel (van der Corput)."""
    lo, hi = limits.travel
    m = MARGIN * limits.span
    half = part.amplitude if kind == 'reversal' else 0.5 * part.stroke
    a, b = lo + m + half, hi - m - half
    if b <= a:
        return [limits.centre] * n
    u = van_der_corput(k0 + n)[k0:]
    return list(a + (b - a) * u)


def _order(counts: dict[int, int], kinds: Sequence[str]) -> list[int]:
    """Interleave the instances: each kind spread evenly in time, speeds bit-reversed.

    Each instance gets the key ``(j + ½)/n_kind`` (its place among its kind's ``n``
    instances); sorting by it spreads every kind over the run.  Within the passes the
    levels follow a bit-reversed order (0, 4, 2, 6, 1, 5, 3, 7 for 8 levels), so the
    speed never rises monotonically in time.
    """
    keyed = []
    for kind in dict.fromkeys(kinds):
        idx = [i for i in counts if kinds[i] == kind]
        if kind == 'pass':
            idx = [idx[j] for j in _bit_reversed(len(idx))]
        seq = []
        while any(counts[i] > seq.count(i) for i in idx):
            for i in idx:
                if counts[i] > seq.count(i):
                    seq.append(i)
        n = len(seq)
        keyed += [((j + 0.5) / n, kind, i) for j, i in enumerate(seq)]
    keyed.sort(key=lambda k: (k[0], k[1]))
    return [i for _, _, i in keyed]


def _bit_reversed(n: int) -> list[int]:
    bits = max(1, (n - 1).bit_length())
    order = sorted(range(2 ** bits), key=lambda i: int(f'{i:0{bits}b}'[::-1], 2))
    return [i for i in order if i < n]


def _place(scored: Sequence[Candidate], counts: dict[int, int], kinds: Sequence[str],
           model: AxisModel, limits: ExcitationLimits,
           dt: float) -> tuple[list[int], list, TableData, list]:
    """Order, place and assemble the parts; the joins as fast as the drive limits allow."""
    order = _order(counts, kinds)
    seen: dict[int, int] = {}
    placed = []
    for i in order:
        c = scored[i]
        k = seen.get(i, 0)
        seen[i] = k + 1
        part = c.part
        if c.kind != 'reversal' and k % 2 == 1:  # every other repetition: negative first
            part = dataclasses.replace(part, direction=-part.direction)
        centre = _centres(c.kind, part, 1, limits, k + 3 * i)[0]
        placed.append((part, centre))
    # the joining moves run at vmax/amax unless the drive limits need them slower
    move_scale = 1.0
    for _ in range(20):
        data, windows = assemble(placed, limits, dt=dt, rest=REST, start=limits.centre,
                                 move_scale=move_scale)
        if not peaks(data, model).violations(limits):
            break
        move_scale *= 0.8
    return order, placed, data, windows


def design(model: AxisModel, limits: ExcitationLimits, *, duration: float = 60.0,
           loop: Loop | None = None, periods: Sequence[float] = (), seed: int = 0,
           progress: Callable[[str], None] | None = None) -> Design:
    """Design an excitation for ``model`` within ``limits`` (module docstring).

    Parameters
    ----------
    model : AxisModel
        The start model: its effect set is what the run must identify.
    limits : ExcitationLimits
        Travel, speed, acceleration, bandwidth and drive limits.
    duration : float
        Length of the excitation [s] (the parts' minimum is checked).
    loop : Loop, optional
        The loop of the run (:func:`loop_for`; default: a PID placed on ``model``).
    periods : sequence of float
        Spatial periods the travel must cover twice besides the model's own.
    seed : int
        Noise seed of the simulated run that predicts the standard errors.
    progress : callable, optional
        Called with one line per step.
    """
    from motor_comp.workbench.fit import fit
    from motor_comp.workbench.derivatives import InputHold, kinematics
    say = progress or (lambda s: None)
    if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
        raise ParameterError(f'--duration must be a finite number > 0, got {duration!r}')
    if duration > MAX_DURATION:
        raise ParameterError(f'--duration {duration:g} s: at most {MAX_DURATION:g} s (the '
                             f'table a node reads is bounded); split the experiment into '
                             f'several excitations')
    check_periods(model, limits, periods)
    loop = loop or loop_for(model)
    dt = 1.0 / loop.plant.control_rate
    hold = InputHold.ZOH if model.input is InputKind.VOLTAGE else InputHold.SAMPLE
    creep, stuck = creep_speed(model, limits, loop, seed=seed)
    if stuck is not None:
        say(f'the start model stick-slips at {stuck:.3g} {model.units.velocity} under this '
            f'loop: the slowest pass is {creep:.3g} {model.units.velocity}')
    cands = candidate_parts(model, limits, loop, creep=creep)
    say(f'{len(cands)} candidate parts: {SPEED_LEVELS} speeds from {creep:.3g} '
        f'{model.units.velocity}, {len(REVERSAL_COUNTS)} reversal amplitudes, {SWEEPS} '
        f'sweeps')
    profiles = []
    for kind, level, part in cands:
        prof = Profile(limits.centre)
        prof.hold(REST)
        prof.move(part.start(limits.centre), vmax=limits.vmax, amax=limits.amax)
        window = prof.t
        part.add_to(prof)
        window = (window, prof.t)
        prof.hold(REST)
        profiles.append((prof, window))
    fixed = np.array([prof.t for prof, _ in profiles])
    free = duration - float(np.sum(fixed))
    if free < 0:
        raise ParameterError(f'--duration {duration:g} s is too short: every part once '
                             f'takes {np.sum(fixed):.0f} s (raise --duration, or the speeds '
                             f'and the travel)')
    scored: list[Candidate] = []
    names: list[str] = []
    for i, ((kind, level, part), (prof, window)) in enumerate(zip(cands, profiles)):
        t, x, v, a = prof.sample(dt)
        run = record(loop, table_from_arrays(t, x, v, a, source='candidate'), seed=seed + i)
        names, info = information(model, run, window=window, hold=hold)
        scored.append(Candidate(kind=kind, part=part, level=level, seconds=prof.t, info=info))
    extra = d_optimal([c.info for c in scored], np.ones(len(scored)), free)
    counts = {i: 1 + int(np.floor(extra[i] / c.seconds + 0.5)) for i, c in enumerate(scored)}
    while sum(counts[i] * c.seconds for i, c in enumerate(scored)) > duration * 1.02:
        worst = min((i for i in counts if counts[i] > 1),
                    key=lambda i: extra[i] / (counts[i] * scored[i].seconds))
        counts[worst] -= 1
    kinds = [c.kind for c in scored]
    while True:
        order, placed, data, windows = _place(scored, counts, kinds, model, limits, dt)
        if data.duration <= duration * 1.03 or all(n == 1 for n in counts.values()):
            break
        # the joins took longer than estimated: drop the repetition worth least
        worst = min((i for i in counts if counts[i] > 1),
                    key=lambda i: extra[i] / (counts[i] * scored[i].seconds))
        counts[worst] -= 1
    pk = check_limits(data, model, limits)
    say(f'assembled {len(placed)} parts, {data.duration:.1f} s; predicting the standard '
        f'errors ({PREDICT_RUNS} closed-loop runs of the start model, refitted)')
    draws: dict[str, dict[str, list[float]]] = {}
    result = None
    for j in range(PREDICT_RUNS):
        kin = kinematics(record(loop, data, seed=seed + j), hold=hold)
        result = fit(kin, model)
        for g, dd in result.uncertainty.items():
            for k, v in dd.items():
                draws.setdefault(g, {}).setdefault(k, []).append(float(v))
    predicted = {g: {k: float(np.median(v)) for k, v in dd.items()}
                 for g, dd in draws.items()}
    res_sigma = _residual_sigma(result.model, kin)
    total = [counts[i] * c.seconds for i, c in enumerate(scored)]
    proxy = predicted_se([c.info for c in scored], np.array(total), res_sigma)
    parts = [{'kind': c.kind, 'level': c.level, 'count': counts[i],
              'seconds': counts[i] * c.seconds} for i, c in enumerate(scored)]
    return Design(table=data, limits=limits, peaks=pk, loop=loop, start=model,
                  predicted_se=predicted, se_draws=draws, refit=result.model,
                  proxy_se={n: float(s) for n, s in zip(names, proxy)}, parts=parts,
                  order=[(scored[i].kind, scored[i].level, *w)
                         for i, w in zip(order, windows)], creep=creep,
                  stick_slip=stuck)


def _residual_sigma(model: AxisModel, kin: Any) -> float:
    """RMS of the inverse-dynamics residual of ``model`` along ``kin`` [N] (moving rows)."""
    m = np.abs(kin.v) > 0
    dly = model.get('delay')
    u = np.interp(kin.t - dly.tau, kin.t, kin.u) if dly is not None else kin.u
    r = model.input_force(u, kin.v) - _force(model, kin.x, kin.v, kin.a, kin.dt)
    return float(np.sqrt(np.mean(r[m] ** 2))) if np.any(m) else 0.0


__all__ = ['Candidate', 'Design', 'Loop', 'candidate_parts', 'check_periods', 'columns',
           'd_optimal', 'design', 'information', 'loop_for', 'parameters', 'pid_for',
           'predicted_se', 'record']
