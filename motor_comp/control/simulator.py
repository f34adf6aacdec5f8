"""In-process closed-loop simulator: trajectory → controller → plant, one compiled loop.

The loop composes the three step kernels the ROS nodes call one by one
(:func:`~motor_comp.control.trajectories.traj_eval`,
:func:`~motor_comp.control.controller.controller_step`,
:func:`~motor_comp.physics.kernel.plant_measure` /
:func:`~motor_comp.physics.kernel.plant_advance`).  ``engine='python'`` steps the Python
wrappers the nodes use (``trajectory.at``, ``Plant.measure``, ``Controller.step``,
``Plant.step``) and gives identical numbers.  A model-based compensation
(:mod:`motor_comp.control.compensation`) travels inside the controller's packed vectors,
so both engines run it with no change here.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.control._jitcache import JIT_OPTIONS
from motor_comp.control.adaptive_sliding import ESTIMATES, N_THETA
from motor_comp.control.controller import C_TH, Controller, controller_step
from motor_comp.control.trajectories import Trajectory, traj_eval
from motor_comp.errors import ParameterError, check_positive
from motor_comp.physics import kernel as K
from motor_comp.physics.config import PlantConfig
from motor_comp.physics.plant import Plant, StepLoad


#: longest run kept in memory (≈ 14 h at 1 kHz, ≈ 7 GB of recorded arrays)
MAX_STEPS = 50_000_000


@dataclasses.dataclass(frozen=True)
class SimResult:
    """Time series of a closed-loop run, one sample per control step (SI units).

    Attributes
    ----------
    t : ndarray
        Control instants t_k = k·T [s].
    reference, reference_velocity, reference_acceleration : ndarray
        r(t_k) [m], ṙ [m/s], r̈ [m/s²].
    position, velocity : ndarray
        Measured position [m] and backward-difference velocity [m/s] at t_k.
    voltage : ndarray
        Command u_k [V] held over [t_k, t_k + T).
    true_position, true_velocity : ndarray
        Plant state at the end of the period [m], [m/s].
    friction, ripple : ndarray
        Friction and ripple forces of the last physics step of the period [N].
    estimates : ndarray (n, 7)
        Adaptive estimates after step k in physical units (see ``ESTIMATES``).
    metadata : Mapping
        Run parameters.
    """

    t: np.ndarray
    reference: np.ndarray
    reference_velocity: np.ndarray
    reference_acceleration: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    voltage: np.ndarray
    true_position: np.ndarray
    true_velocity: np.ndarray
    friction: np.ndarray
    ripple: np.ndarray
    estimates: np.ndarray
    metadata: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def error(self) -> np.ndarray:
        """Tracking error e = r − y [m]."""
        return self.reference - self.position

    def estimate(self, name: str) -> np.ndarray:
        """One estimate's time series by name (``mass``, ``fc``, ``ripple_a`` …)."""
        try:
            return self.estimates[:, ESTIMATES.index(name)]
        except ValueError:
            raise ParameterError(f'unknown estimate {name!r} (known: '
                                 f'{", ".join(ESTIMATES)})') from None

    def to_run(self, name: str = 'sim') -> Any:
        """Return the run as a :class:`motor_comp.logs.run.Run` (measured signals and command)."""
        from motor_comp.logs.run import Run
        meta = {k: (v if isinstance(v, str) else str(v)) for k, v in self.metadata.items()}
        return Run(t=self.t, position=self.position, velocity=self.velocity,
                   reference=self.reference, reference_velocity=self.reference_velocity,
                   voltage=self.voltage, metadata=meta, name=name)


@njit(**JIT_OPTIONS)
def _loop(P, S, Q, C, TP, noise, n_steps, n_sub, T, load_force, load_t,
          out_r, out_rv, out_ra, out_y, out_vy, out_u, out_x, out_v, out_f, out_rip, out_th):
    """Run the compiled closed loop; the per-step order is that of :func:`simulate`."""
    for k in range(n_steps):
        t = k * T
        r, rv, ra = traj_eval(TP, t)
        y, vy = K.plant_measure(P, S, noise[k], T)
        u = controller_step(Q, C, r, rv, ra, y, vy, T)
        f = load_force if t >= load_t else 0.0
        K.plant_advance(P, S, u, f, n_sub)
        out_r[k], out_rv[k], out_ra[k] = r, rv, ra
        out_y[k], out_vy[k], out_u[k] = y, vy, u
        out_x[k], out_v[k] = S[K.S_X], S[K.S_V]
        out_f[k], out_rip[k] = S[K.S_FRICTION], S[K.S_RIPPLE]
        for i in range(out_th.shape[1]):
            out_th[k, i] = C[C_TH + i]


def _theta_to_units(th: np.ndarray, gain: float) -> np.ndarray:
    """Volt-unit estimates → physical units (columns as ``ESTIMATES``)."""
    out = th.copy()
    for i in (0, 2, 3, 4, 5, 6):
        out[:, i] *= gain
    return out


def simulate(plant: PlantConfig, controller: Controller, trajectory: Trajectory, *,
             duration: float, seed: int = 0, load: StepLoad | None = None,
             engine: str = 'jit', x0: float | None = None) -> SimResult:
    """Run the closed loop for ``duration`` [s] at ``plant.control_rate``.

    Per-step order (what a lockstep ROS run must reproduce), ``T = 1/control_rate``,
    at control step ``k = 0, 1, …, n−1`` with ``t_k = k·T``:

    1. reference ``r_k, ṙ_k, r̈_k = trajectory.at(t_k)``;
    2. measurement ``y_k = plant.measure(T)`` — encoder reading (noise sample, then
       quantisation) and velocity ``(y_k − y_{k−1})/T``; at ``k = 0`` the previous
       reading is the quantised start position, so the first velocity is 0 without noise;
    3. command ``u_k = controller.step(r_k, ṙ_k, r̈_k, y_k, v_k, T)``;
    4. ``plant.step(u_k, T, f_ext=load.at(t_k))`` — ``T·physics_rate`` physics steps.

    The plant starts at rest at ``x0`` (default: the reference at t = 0).  The
    controller is used as given (call ``controller.reset()`` for a fresh start); its
    state after the run is the final state of the loop.

    Parameters
    ----------
    engine : {'jit', 'python'}
        ``jit`` runs :func:`_loop` (one compiled function); ``python`` steps the Python
        wrappers the ROS nodes call.  Both give identical results.
    """
    duration = check_positive('duration [s]', duration)
    T = 1.0 / plant.control_rate
    n = int(round(duration * plant.control_rate))
    if n < 1:
        raise ParameterError(f'duration {duration:g} s is shorter than one control period')
    if n > MAX_STEPS:
        raise ParameterError(f'duration {duration:g} s is {n} control steps, more than the '
                             f'{MAX_STEPS} a run keeps in memory; split it into shorter runs')
    load = load or StepLoad()
    ref0 = trajectory.at(0.0)
    sim_plant = Plant(plant.model, sensors=plant.sensors, physics_rate=plant.physics_rate,
                      load=load, seed=seed, x0=ref0.position if x0 is None else float(x0))
    n_sub = sim_plant.substeps(T)
    outs = {k: np.empty(n) for k in ('r', 'rv', 'ra', 'y', 'vy', 'u', 'x', 'v', 'f', 'rip')}
    th = np.empty((n, N_THETA))
    if engine == 'jit':
        # noise drawn in one call from the plant's own generator: the same stream as n
        # successive Plant.noise_sample() calls (checked by the engine-equality test)
        sd = plant.sensors.noise_std
        noise = sim_plant._rng.normal(0.0, sd, n) if sd > 0 else np.zeros(n)
        _loop(sim_plant.params, sim_plant.state, controller.packed, controller.state,
              trajectory.packed(), noise, n, n_sub, T, load.force, load.t_start, outs['r'],
              outs['rv'], outs['ra'], outs['y'], outs['vy'], outs['u'], outs['x'],
              outs['v'], outs['f'], outs['rip'], th)
    elif engine == 'python':
        for k in range(n):
            t = k * T
            ref = trajectory.at(t)
            meas = sim_plant.measure(T)
            u = controller.step(ref.position, ref.velocity, ref.acceleration,
                                meas.position, meas.velocity, T)
            sim_plant.step(u, T, f_ext=load.at(t))
            outs['r'][k], outs['rv'][k], outs['ra'][k] = ref.position, ref.velocity, \
                ref.acceleration
            outs['y'][k], outs['vy'][k], outs['u'][k] = meas.position, meas.velocity, u
            outs['x'][k], outs['v'][k] = sim_plant.position, sim_plant.velocity
            outs['f'][k], outs['rip'][k] = sim_plant.friction_force, sim_plant.ripple_force
            th[k] = controller.state[C_TH:C_TH + N_THETA]
    else:
        raise ParameterError(f"engine must be 'jit' or 'python', got {engine!r}")
    meta = {'plant': plant.kind.value, 'plant_source': plant.source,
            'trajectory': trajectory.params(), 'duration_s': duration, 'seed': seed,
            'control_rate_hz': plant.control_rate, 'physics_rate_hz': plant.physics_rate,
            'load_force_N': load.force, 'load_t_start_s': load.t_start, 'engine': engine,
            **controller.describe()}
    return SimResult(t=np.arange(n) * T, reference=outs['r'], reference_velocity=outs['rv'],
                     reference_acceleration=outs['ra'], position=outs['y'],
                     velocity=outs['vy'], voltage=outs['u'], true_position=outs['x'],
                     true_velocity=outs['v'], friction=outs['f'], ripple=outs['rip'],
                     estimates=_theta_to_units(th, plant.model.input_gain), metadata=meta)
