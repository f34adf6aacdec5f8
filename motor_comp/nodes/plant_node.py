"""``plant_node``: the simulated axis (PMLM or ball-screw) as a ROS 2 node.

A thin adapter over :class:`motor_comp.physics.plant.Plant` (the compiled kernel's
``plant_advance``/``plant_measure``, the same functions the in-process simulator loops
over).  Publishes ``<ns>/joint_states`` (measured position [m], velocity [m/s], effort =
actuator force [N]) and, in lockstep, ``/clock``; subscribes ``<ns>/voltage`` [V].

Lockstep protocol (the plant owns sim time)::

    plant:  /clock t_k, joint_states(t_k)  ->  trajectory: reference(t_k)
    controller: waits for reference(t_k) and joint_states(t_k), publishes voltage u_k
    plant:  on u_k, advances one control period, k += 1, publishes the next pair

so step k is applied exactly when its command arrived, whatever the speed of the
machine: the run is deterministic and as fast as the slowest process allows.  Before
step 0 the plant waits until the controller, the trajectory and ``expected_subscribers``
readers of ``joint_states`` (controller + recorder by default) are matched, so nodes can
start in any order.  With ``duration`` > 0 the node exits after that much sim time.

Realtime: after the same wait for peers, a wall-clock timer at ``control_rate``
measures and publishes, stamped ``t0 + k·T`` — the sim time of the sample on the wall
clock's axis (stamping the timer's late firing time instead would add the timer latency,
0.1–2 ms on a loaded machine, as jitter between the sample and its stamp); a command
takes effect when it arrives (zero-order hold from its arrival, at the physics-step
resolution), so the loop's delay is its real transport and computation time.  If the
*plant process* is descheduled for whole periods, the simulated world pauses with it
(sim time slips behind the wall clock, counted and logged) rather than running the
axis open-loop through the gap: a hiccup of the simulator is not a physical event, and
catching up (as before) turned a 19 ms stall into a 1.8 mm excursion of the
ball-screw.  A late *controller* is still physical: the plant runs on, holding the last
command, exactly as a drive does.

A non-finite command never reaches the physics: it is refused with a warning and the
step is taken at 0 V, so the loop goes on.

A ``plant`` YAML file is read under :mod:`motor_comp.param_files` (inside the read-only
``model_dir``, a regular file under a size bound, reasons that never quote it).
"""
from __future__ import annotations

import array
import math
import time
from typing import Any, Mapping

import numpy as np
from rclpy.duration import Duration
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from motor_comp import param_files
from motor_comp.errors import ParameterError
from motor_comp.nodes.common import DEFAULT_NAMESPACE, DELAY_BIN_NS, DELAY_BINS, JOINT_NAME, \
    LOOP_QOS, MODEL_DIR, REALTIME_PRIORITY, SUB_QOS, TOPIC_CLOCK, TOPIC_JOINT_STATES, \
    TOPIC_VOLTAGE, ManagedNode, Pacer, Param, Timing, format_delays, period_ns, \
    read_float64, run_node, set_realtime_priority, set_stamp
from motor_comp.physics import kernel as K
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.plant import Plant, StepLoad, pack_params

PARAMS = (
    Param('plant', 'pmlm', 'Plant: pmlm, ballscrew, or a plant YAML file', read_only=True),
    Param('timing', 'lockstep', 'Timing mode', choices=('lockstep', 'realtime'),
          read_only=True),
    Param('control_rate', 1000.0, 'Control (publish/step) rate', 'Hz', 1.0, 100_000.0,
          read_only=True),
    Param('physics_rate', 0.0, 'Physics rate (0 = the plant file value)', 'Hz', 0.0, 1e7,
          read_only=True),
    Param('duration', 0.0, 'Run length in sim time, then exit (0 = forever)', 's', 0.0,
          1e7, read_only=True),
    Param('seed', 0, 'Seed of the measurement-noise generator', '', 0, 2**31 - 1,
          read_only=True),
    Param('x0', 0.0, 'Initial position', 'm', -10.0, 10.0, read_only=True),
    Param('load_force', 0.0, 'External step load force (subtracted like friction)', 'N',
          -1e5, 1e5),
    Param('load_start', 0.0, 'Sim time the step load switches on', 's', 0.0, 1e7),
    Param('friction_scale', 1.0, 'Scale of the plant friction levels (coulomb fc, '
          'stribeck fs, viscous fv, load_friction mu, position_friction dfc): a worn, cold '
          'or re-lubricated axis, live', '', 0.0, 100.0),
    Param('expected_subscribers', 2,
          'Lockstep: readers of joint_states to wait for before step 0 '
          '(controller + recorder)', '', 0, 100, read_only=True),
    Param('expected_clock_subscribers', 2,
          'Lockstep: readers of /clock to wait for before step 0 (trajectory + recorder)',
          '', 0, 100, read_only=True),
    Param('clock_every', 10, 'Lockstep: publish /clock every this many control ticks (and '
          'at every start or resume); the trajectory node publishes its references '
          'ahead, so a sparser clock takes deliveries off each step (simulators publish '
          '/clock at a rate of their own too)', 'ticks', 1, 1000, read_only=True),
    Param('start_delay', 0.3, 'Lockstep: settle time after all peers matched', 's', 0.0,
          60.0, read_only=True),
    REALTIME_PRIORITY,
    MODEL_DIR,
)


class PlantNode(ManagedNode):
    """The axis: advances on each command (lockstep) or on a wall timer (realtime).

    Managed node: ``configure`` builds the plant (from ``plant``, ``seed``, ``x0`` …)
    and its publishers; ``activate`` subscribes ``voltage`` and starts the run once its
    peers are there (lockstep: at the current step, so deactivate/activate pauses and
    resumes the same run); ``deactivate`` unsubscribes and stops the timers (the axis
    holds still: no step is taken without a command); ``cleanup`` drops the plant (the
    next configure starts a new run at step 0).
    """

    def __init__(self) -> None:
        super().__init__('plant_node', namespace=DEFAULT_NAMESPACE)
        self.declare_params(PARAMS)
        self.timing = Timing(self.p['timing'])
        self.plant: Plant | None = None
        self.pub_js = self.pub_clock = None
        self._voltage_sub = self._peer_timer = self._tick_timer = None
        self._finished = False
        self.published = 0
        self.k = 0
        self.refused = 0
        self.autostart()

    def configure(self) -> None:
        """Build the plant from the parameters, its publishers; step 0, nothing sent yet."""
        p = self.p
        cfg = param_files.load_plant('plant', p['plant'], self.file_dirs)
        physics = p['physics_rate'] or cfg.physics_rate
        self._model0 = cfg.model
        try:
            plant = Plant(scale_friction(cfg.model, p['friction_scale']), sensors=cfg.sensors,
                          physics_rate=physics,
                          load=StepLoad(p['load_force'], p['load_start']), seed=p['seed'],
                          x0=p['x0'])
        except ValueError as exc:
            raise ParameterError(str(exc)) from None
        self.dt_ns = period_ns(p['control_rate'])
        self.dt = 1.0 / p['control_rate']   # the simulator's T, bit for bit
        plant.substeps(self.dt)   # validates rate compatibility up front
        # load the compiled kernels now (numba cache) rather than inside the first tick
        warm = Plant(cfg.model, sensors=cfg.sensors, physics_rate=physics)
        warm.measure(self.dt)
        warm.step(0.0, self.dt, f_ext=0.0)
        cfg.model.input_force(0.0, 0.0)
        self.plant = plant
        self.n_steps = int(round(p['duration'] / self.dt)) if p['duration'] > 0 else -1
        self.k = 0
        self.refused = 0
        self.published = 0
        self.late = 0
        self._t0_ns: int | None = None
        self._slip_ns = 0                   # realtime: sim time behind the wall clock
        # realtime: command arrival after the latest sample's publication (loop delay)
        self.delay_hist = np.zeros(DELAY_BINS + 1, dtype=np.int64)
        # realtime: |tick-to-tick interval − T|, the control period jitter
        self.jitter_hist = np.zeros(DELAY_BINS + 1, dtype=np.int64)
        self._tick_ns: int | None = None   # realtime: wall time of the last measurement
        self._sub_done = 0                  # realtime: physics steps done in this period
        self.n_sub = plant.substeps(self.dt)
        self.phys_ns = self.dt_ns // self.n_sub
        self._finished = False
        self._started = False
        self._u = 0.0            # realtime: latest command (zero-order hold)
        self._js = JointState(name=[JOINT_NAME], position=array.array('d', [0.0]),
                              velocity=array.array('d', [0.0]), effort=array.array('d', [0.0]))
        self._js.header.frame_id = JOINT_NAME
        # the message's own arrays (the setters copy): written in place each step
        self._pos, self._vel, self._eff = self._js.position, self._js.velocity, self._js.effort
        self._clock_msg = Clock()
        self.pub_js = self.create_publisher(JointState, TOPIC_JOINT_STATES, LOOP_QOS)
        self.pub_clock = (self.create_publisher(Clock, TOPIC_CLOCK, LOOP_QOS)
                          if self.timing is Timing.LOCKSTEP else None)
        # lockstep: never outrun a lagging reader (the recorder) by the writers' history.
        # Every loop writer is paced (acknowledgements are per writer: pacing joint_states
        # alone let the controller's voltage writer overwrite 51 commands a lagging
        # recorder had not received).  Once per history depth: a wait before the writer's
        # history is full lasts until Fast DDS's 3 s heartbeat (see Pacer), and pacing
        # every 250 messages had halved the rate
        self._js_out = (Pacer(self.pub_js) if self.pub_clock is not None else self.pub_js)
        self._clock_out = Pacer(self.pub_clock) if self.pub_clock is not None else None
        self.get_logger().info(
            f'{cfg.kind.value} plant from {cfg.source}, {self.timing.value}, '
            f'{p["control_rate"]:g} Hz control, {physics:g} Hz physics')
        if self.timing is Timing.REALTIME:
            set_realtime_priority(self, p['realtime_priority'])

    def activate(self) -> None:
        """Subscribe ``voltage``; (re)start the run once the peers matched."""
        self._voltage_sub = self.mark_hot(self.create_subscription(
            Float64, TOPIC_VOLTAGE, self._on_voltage, SUB_QOS, raw=True))
        # both modes wait for their peers, so no early sample goes unanswered
        self._started = False
        self._waiting_since = time.monotonic()
        self._peer_timer = self.create_timer(0.05, self._wait_for_peers)

    def deactivate(self) -> None:
        """Stop: no more samples or steps until activated again."""
        self.destroy_hot(self._voltage_sub)
        self.destroy_hot(self._tick_timer)
        if self._peer_timer is not None:
            self.destroy_timer(self._peer_timer)
        self._voltage_sub = self._tick_timer = self._peer_timer = None
        self._started = False
        self._tick_ns = None   # realtime: the pause is slip, not a long period

    def cleanup(self) -> None:
        """Drop the plant and its publishers (a new configure starts a new run)."""
        self.deactivate()
        for pub in (self.pub_js, self.pub_clock):
            if pub is not None:
                self.destroy_publisher(pub)
        self.pub_js = self.pub_clock = None
        self.plant = None

    # -- lockstep --------------------------------------------------------------------
    def _peers_ready(self) -> bool:
        ns = self.get_namespace().rstrip('/')
        return (self.pub_js.get_subscription_count() >= self.p['expected_subscribers']
                and self.count_publishers(f'{ns}/{TOPIC_VOLTAGE}') >= 1
                and self.count_publishers(f'{ns}/reference') >= 1
                and (self.pub_clock is None or self.pub_clock.get_subscription_count()
                     >= self.p['expected_clock_subscribers']))

    def _wait_for_peers(self) -> None:
        if not self._peers_ready():
            if time.monotonic() - self._waiting_since > 10.0:
                self.get_logger().info('waiting for controller/trajectory/recorder …',
                                       throttle_duration_sec=10.0)
            return
        self.destroy_timer(self._peer_timer)
        # DDS matching is not symmetric in time: give the peers' writers/readers a moment
        # to match us too before the first (transient-local) sample goes out.
        self._peer_timer = self.create_timer(self.p['start_delay'] + 1e-3, self._start)

    def _start(self) -> None:
        self.destroy_timer(self._peer_timer)
        self._peer_timer = None
        self._started = True
        how = 'starting' if self.k == 0 else f'resuming at step {self.k} of'
        self.get_logger().info(f'peers matched: {how} {self.timing.value} run')
        if self.timing is Timing.LOCKSTEP:
            self._publish_step(clock=True)
        else:
            self._tick_timer = self.mark_hot(self.create_timer(self.dt, self._on_tick))

    def _publish_step(self, *, clock: bool = False) -> None:
        """Publish the measurement of step ``k`` (stamp ``k·dt``), then ``/clock``.

        The measurement first: it is on the loop's critical path (the controller
        answers it), ``/clock`` is not (the trajectory publishes the references ahead).
        ``/clock`` goes out every ``clock_every`` ticks and whenever ``clock`` is set (a
        start or a resume, so the trajectory republishes from this tick): each publish
        and each delivery costs CPU the two cores share with the loop.
        """
        t_ns = self.k * self.dt_ns
        self._publish_measurement(t_ns)
        if clock or self.k % self.p['clock_every'] == 0:
            set_stamp(self._clock_msg.clock, t_ns)
            self._clock_out.publish(self._clock_msg)

    def _publish_measurement(self, t_ns: int) -> None:
        m = self.plant.measure(self.dt)
        js = self._js
        set_stamp(js.header.stamp, t_ns)
        # written in place: the message holds these arrays (no per-step list + setter)
        self._pos[0] = m.position
        self._vel[0] = m.velocity
        self._eff[0] = self.plant.model.input_force(self.plant.applied_command,
                                                    self.plant.velocity)
        self._js_out.publish(js)
        self.published += 1

    def _command(self, u: float) -> float:
        if math.isfinite(u):
            return u
        self.refused += 1
        self.get_logger().warning(f'refused non-finite command {u!r}: holding 0 V',
                                  throttle_duration_sec=1.0)
        return 0.0

    def _on_voltage(self, msg: Float64 | bytes) -> None:
        u = self._command(read_float64(msg))
        if self.timing is Timing.REALTIME:
            self._apply_realtime(u)
            return
        if not self._started or self._finished:
            return
        # load at t_k = k·T exactly as the simulator evaluates it
        self.plant.step(u, self.dt, f_ext=self.plant.load.at(self.k * self.dt))
        self.k += 1
        if self.k == self.n_steps:
            self._finished = True
            self.get_logger().info(f'run complete: {self.k} steps, '
                                   f'{self.k * self.dt:g} s sim time')
            return
        self._publish_step()

    # -- realtime --------------------------------------------------------------------
    def _on_tick(self) -> None:
        """Close the running period, measure and publish the next sample.

        Within a period the command in force is the latest received: a command that
        arrives d after the tick's measurement takes effect d into the period (at the
        physics-step resolution), so the loop's delay is the real transport and
        computation time, not a whole period.  A tick this process delayed by whole
        periods does not advance the axis through them: sim time slips (see the module
        docstring), so the samples stay consecutive and every period is a closed-loop one.
        """
        if self._finished:
            return
        now = self.get_clock().now().nanoseconds
        if self._t0_ns is None:
            self._t0_ns = now
        else:
            self._advance_substeps(self.n_sub - self._sub_done)
            self.k += 1
        behind = (now - self._t0_ns - self._slip_ns) // self.dt_ns - self.k
        if behind > 0:
            self._slip_ns += behind * self.dt_ns
            self.late += behind
        if 0 < self.n_steps <= self.k:
            self._finished = True
            self.get_logger().info(f'run complete: {self.k} steps in realtime, sim time '
                                   f'slipped {self.late} periods behind the wall clock; '
                                   f'command arrival after the last sample: '
                                   f'{format_delays(self.delay_hist)}; control period '
                                   f'jitter: {format_delays(self.jitter_hist)}')
            return
        self._publish_measurement(self._t0_ns + self.k * self.dt_ns)
        if self._tick_ns is not None:
            jitter = abs(now - self._tick_ns - self.dt_ns)
            self.jitter_hist[min(jitter // DELAY_BIN_NS, DELAY_BINS)] += 1
        self._tick_ns = now
        self._sub_done = 0

    def _apply_realtime(self, u: float) -> None:
        """Run the period up to now with the old command, then hold ``u``."""
        if self._tick_ns is not None and not self._finished:
            elapsed = self.get_clock().now().nanoseconds - self._tick_ns
            self.delay_hist[min(elapsed // DELAY_BIN_NS, DELAY_BINS)] += 1
            n = min(self.n_sub, int(elapsed // self.phys_ns))
            if n > self._sub_done:
                self._advance_substeps(n - self._sub_done)
                self._sub_done = n
        self._u = u

    def _advance_substeps(self, n: int) -> None:
        if n > 0:
            self.plant.step(self._u, n * self.dt / self.n_sub,
                            f_ext=self.plant.load.at(self.k * self.dt))

    # -- parameters ------------------------------------------------------------------
    def apply_params(self, changed: Mapping[str, Any], new: Mapping[str, Any]) -> None:
        """Live load changes (the rest is read-only)."""
        if {'load_force', 'load_start'} & changed.keys():
            try:
                load = StepLoad(new['load_force'], new['load_start'])
            except ValueError as exc:
                raise ParameterError(str(exc)) from None
            if self.plant is not None:   # unconfigured: configure reads the parameters
                self.plant.load = load
        if 'friction_scale' in changed and self.plant is not None:
            # same kernel layout, new friction levels; the state (GMS elements) carries on
            P = self.plant.params
            P[:] = pack_params(scale_friction(self._model0, new['friction_scale']),
                               self.plant.sensors, float(P[K.P_DT]))
            self.get_logger().info(f'friction x{new["friction_scale"]:g} from step {self.k}')

    def finish(self, executor: Any) -> None:
        """Make sure the last samples reached every reader, then report the count."""
        for pub in (self.pub_js, self.pub_clock):
            if pub is not None and executor is not None:
                pub.wait_for_all_acked(Duration(seconds=2.0))
        pacer = getattr(self, '_js_out', None)
        pacer = pacer if isinstance(pacer, Pacer) else None
        self.get_logger().info(
            f'stopped: {self.published} measurements published, {self.k} steps, '
            f'{self.refused} commands refused'
            + (f'; paced on the readers\' acknowledgements {pacer.paced} times, '
               f'{pacer.wait_s:.3f} s, {pacer.waits} waits timed out' if pacer else ''))

    @property
    def done(self) -> bool:
        """The requested duration has been simulated."""
        return self._finished


def scale_friction(model: AxisModel, scale: float) -> AxisModel:
    """Return ``model`` with its friction levels times ``scale``.

    Coulomb, Stribeck and viscous levels, and the load- and position-dependent rises of
    the dry level (``mu``, the knot values ``dfc``): the whole level
    ``fc + dfc(x) + mu·|F_in|`` scales, so it stays >= 0.  A ``mu`` scaled to 1 or more
    is refused by the effect (one-line ParameterError, the node keeps its old values).
    """
    field = {'coulomb': 'fc', 'stribeck': 'fs', 'viscous': 'fv', 'load_friction': 'mu'}
    effects = []
    for e in model.effects:
        if e.name in field:
            e = e.replace(**{field[e.name]: getattr(e, field[e.name]) * scale})
        elif e.name == 'position_friction':
            e = e.replace(dfc=tuple(scale * v for v in e.dfc))
        effects.append(e)
    return model.replace(effects=tuple(effects))


def main(args: list[str] | None = None) -> int:
    """Console entry point ``plant_node`` (``ros2 run motor_comp plant_node``)."""
    return run_node(PlantNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
