"""``trajectory_node``: publishes the desired motion on ``<ns>/reference``.

A thin adapter over :mod:`motor_comp.control.trajectories` (``Trajectory.at`` calls the
same compiled ``traj_eval`` the in-process simulator uses, so both drivers get
bit-identical references).  The message is a ``sensor_msgs/JointState`` named
``['axis']``: ``position`` = desired position [m], ``velocity`` = desired velocity
[m/s], and ``effort`` = desired *acceleration* [m/s²] — JointState has no acceleration
field and the adaptive controller's inertial feedforward needs it; carrying it here
keeps the ROS loop numerically identical to the simulator.

Lockstep: one reference per control tick, stamped with its time, published ahead of the
plant: on a ``/clock`` tick k (the plant publishes one every ``clock_every`` ticks) every
reference up to tick k + ``lookahead`` not yet sent (from tick k itself when the clock
restarts or repeats a tick).  The reference is a known function of time, so this takes
the node off the loop's critical path, and it may take the ticks in batches
(``batch_period``) instead of waking for each one: on two cores its wake-ups took CPU
from the plant and the controller.  A parameter change therefore reaches the loop within
``lookahead`` ticks.

Realtime: a wall-clock timer at ``control_rate``; trajectory time starts when the plant's
first measurement (stamped t0; the newest queued) arrives, at its reception time ``now₀``
on this node's clock (the start point r(0), stamped with the wall clock, is held until
then).  From then on each tick publishes the reference of the plant's sample grid
``t0 + k·T`` one period ahead (every grid point not yet published up to
``⌊(now − now₀)/T⌋ + 1``, at most ``CATCH_UP`` missed ones after a stall, counted and
logged at the end), stamped with its grid time, so the controller finds the reference of exactly
its measurement's stamp and a recording aligns reference and measurement without a hold
error (ṙ·T ≈ 150 µm at 0.15 m/s when they are stamped at unrelated instants).  The
plant's stamps may run on another clock than this node's (a drive on another machine, a
simulated plant whose sim time slipped behind the wall clock): only their grid is used.
With ``wait_for_command`` the trajectory time starts only with the first measurement
after a command was seen on ``voltage`` — the controller answering the held start point:
a drive publishes its measurements from power-on, before the controller reads them, and
a stress run of ``motor-comp autotune --external-plant`` lost the first 0.5 s of a table
that way, the axis standing while the reference moved.

End (``exit_at_end``, for a caller that runs one trajectory and waits for its end,
as ``motor-comp autotune`` does on a drive with its own clock): once the reference of
trajectory time ``duration`` has been published (realtime: at the grid point
``duration·rate``, stamped ``t0 + duration``), no later reference is published, every
reader is given the chance to acknowledge it and the process exits with status 0.  The
controller then sees no reference and commands 0 V after its ``stale_timeout``.

Start: the node joins the loop (subscribes ``/clock``, or starts its realtime timer)
only once ``expected_subscribers`` readers (controller + recorder) matched its
``reference`` writer, and the plant starts only once it sees that subscription: no
reader misses reference 0, whatever the order in which DDS discovery completes.

Parameters: ``trajectory`` (``sine | p2p | cv | chirp | table``) and ``<kind>.<field>``
for every field of each trajectory class; ``file``, the CSV ``t, x[, v, a]`` a
``table`` plays (DESIGN.md §4).  Changes are validated by building the new trajectory
(rejected with the reason if invalid) and take effect at the next tick.

``file`` is untrusted input (anyone on the graph may set it): it is read with
:mod:`motor_comp.param_files` — only inside the read-only ``model_dir`` directories
(``:``-separated; default the working directory and the package's ``config/``), only a
regular file under the size bound, never blocking — and a rejection names the rule or
the row, never the file's content.

Limits (issue 24): ``travel`` [min, max], ``vmax`` and ``amax`` (read-only, the same
parameters as the controller's; infinite = none).  A trajectory whose reference leaves
them anywhere on the control grid over ``duration`` (600 s when 0) is refused before it
is published (:func:`motor_comp.control.limits.check_reference`): at start a one-line
error and exit status 2, at run time a rejected parameter update (the old trajectory
goes on) — rather than a trip of the controller mid-run.  A table is checked the same
way, on its rows as played.
"""
from __future__ import annotations

import array
import dataclasses
import time
from typing import Any, Mapping

from rclpy.duration import Duration
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from motor_comp.control.limits import check_reference
from motor_comp.control.trajectories import TRAJECTORIES, Table, TableData, Trajectory, \
    make_trajectory, parse_table
from motor_comp.errors import ParameterError
from motor_comp.param_files import parse_untrusted, read_text
from motor_comp.nodes.common import DEFAULT_NAMESPACE, JOINT_NAME, LOOP_QOS, MODEL_DIR, \
    MOTION_LIMITS, REALTIME_PRIORITY, Pacer, Param, ParamNode, SUB_QOS, TOPIC_CLOCK, \
    TOPIC_JOINT_STATES, TOPIC_REFERENCE, TOPIC_VOLTAGE, Timing, limits_from, period_ns, \
    read_clock_ns, read_joint_state, run_node, set_realtime_priority, set_stamp, \
    take_newest

#: a sample's reception time (rmw's, on the system clock) is used as the start of
#: trajectory time when it is this recent [ns]; else (a middleware without it) now
RX_TRUST_NS = 1_000_000_000
#: SI units of the trajectory fields, for the parameter descriptions
_UNITS = {'amplitude': 'm', 'period': 's', 'offset': 'm', 'distance': 'm', 'move_time': 's',
          'dwell': 's', 'speeds': 'm/s', 'stroke': 'm', 'acceleration': 'm/s^2',
          'f_start': 'Hz', 'f_end': 'Hz', 'duration': 's', 'fade': 's'}


def _trajectory_params() -> tuple[Param, ...]:
    """One parameter per field of every trajectory class, named ``<kind>.<field>``."""
    out = []
    for kind, cls in TRAJECTORIES.items():
        if cls is Table:   # its one parameter is ``file`` (a path, read under model_dir)
            continue
        for f in dataclasses.fields(cls):
            default = f.default
            default = tuple(float(v) for v in default) if isinstance(default, tuple) \
                else float(default)
            out.append(Param(f'{kind}.{f.name}', default,
                             f'{cls.__name__} {f.name.replace("_", " ")}',
                             _UNITS.get(f.name, ''), -1e6, 1e6))
    return tuple(out)


#: realtime: how many grid points missed during a stall are still published (100 ms)
CATCH_UP = 100

PARAMS = (
    Param('trajectory', 'p2p', 'Reference trajectory', choices=tuple(TRAJECTORIES)),
    Param('timing', 'lockstep', 'Timing mode', choices=('lockstep', 'realtime'),
          read_only=True),
    Param('control_rate', 1000.0, 'Realtime publish rate', 'Hz', 1.0, 100_000.0,
          read_only=True),
    Param('expected_subscribers', 2, 'Readers of reference (controller + recorder) that '
          'must have matched this node\'s writer before it joins the loop, so none misses '
          'reference 0 (after 10 s it goes on with a warning)', '', 0, 100, read_only=True),
    Param('lookahead', 64, 'Lockstep: publish the reference this many control ticks ahead of '
          '/clock (at most half the loop writers\' history); a parameter change reaches '
          'the loop within this many ticks', 'ticks', 1, LOOP_QOS.depth // 2,
          read_only=True),
    Param('duration', 0.0, 'Run length in trajectory time (0 = no end); lockstep: no '
          'reference is published for a tick past it, so the recording ends with the run; '
          'with exit_at_end the node exits after it', 's', 0.0, 1e7, read_only=True),
    Param('wait_for_command', False, 'Realtime: start the trajectory time with the first '
          'measurement after a command was seen on voltage (the loop is closed), not with '
          'the first measurement: a drive measures from power-on, before its controller '
          'answers (the start point is held until then)', read_only=True),
    Param('exit_at_end', False, 'Exit (status 0) once the reference of trajectory time '
          'duration is published and acknowledged (realtime: a caller waits for the end of '
          'the trajectory; lockstep runs end with the plant\'s duration)', read_only=True),
    Param('batch_period', 0.002, 'Lockstep: take the queued /clock ticks in batches, pausing '
          'this long after each batch (0 = wake for every tick); keep it well below '
          'lookahead control periods of wall time', 's', 0.0, 0.05, read_only=True),
    Param('file', '', 'Table trajectory: CSV with the columns t, x[, v, a] (SI: s, m, m/s, '
          'm/s^2; v and a derived when absent) played when trajectory is table; read inside '
          'model_dir, re-read when set'),
    MODEL_DIR,
    REALTIME_PRIORITY,
) + MOTION_LIMITS + _trajectory_params()

#: how long the node waits for its expected readers before it goes on with a warning [s]
MATCH_TIMEOUT = 10.0


class TrajectoryNode(ParamNode):
    """Publishes ``reference`` on each ``/clock`` tick (lockstep) or timer (realtime)."""

    def __init__(self) -> None:
        super().__init__('trajectory_node', namespace=DEFAULT_NAMESPACE)
        self.declare_params(PARAMS)
        self.timing = Timing(self.p['timing'])
        self.limits = limits_from(self.p)
        self.trajectory = self._build(self.p)
        self._check(self.trajectory)   # refused before anything is published
        self.trajectory.at(0.0)   # load the compiled evaluator before the first tick
        self.dt_ns = period_ns(self.p['control_rate'])
        self._next_k = -1
        self._sent_k = -1     # lockstep: the last tick whose reference was published
        # lockstep: the last tick with a reference (the plant's last measurement is at
        # n_steps − 1; its command answers it, the reference of tick n_steps closes the run)
        self._last_k = (round(self.p['duration'] * self.p['control_rate'])
                        if self.p['duration'] > 0 else None)
        # exit_at_end: the last grid point published before the node is done
        self._end_k = self._last_k if self.p['exit_at_end'] else None
        self._finished = False
        # realtime: ticks that found grid points already due (this process was late), and
        # the longest such delay [periods]
        self.late_ticks = 0
        self.late_max = 0
        if self.timing is Timing.LOCKSTEP:
            self.batch_pause = self.p['batch_period']
        self._msg = JointState(name=[JOINT_NAME], position=array.array('d', [0.0]),
                               velocity=array.array('d', [0.0]),
                               effort=array.array('d', [0.0]))
        self._msg.header.frame_id = JOINT_NAME
        self.pub = self.create_publisher(JointState, TOPIC_REFERENCE, LOOP_QOS)
        # lockstep: never outrun a lagging reader (the recorder) by the writer's history
        self._pub_out = Pacer(self.pub) if self.timing is Timing.LOCKSTEP else self.pub
        self._t0_ns: int | None = None
        self._t0_rx_ns = 0  # realtime: this process's clock when the first sample arrived
        self._held_ns = 0   # realtime: stamp of the last held start point
        self._js_sub = None   # realtime: the first measurement's reader, until t0
        self._u_sub = None    # realtime, wait_for_command: the command reader, until t0
        self._loop_closed = not self.p['wait_for_command']
        # the plant starts when it sees our /clock (lockstep) or joint_states (realtime)
        # reader: create it only once our reference writer matched its readers, so none
        # of them misses reference 0 (a reader that sees our writer may not yet be seen
        # by it: DDS discovery is not symmetric in time)
        self._since = time.monotonic()
        self._match_timer = self.create_timer(0.05, self._join_loop)
        self.get_logger().info(f'{self.timing.value} trajectory {self.trajectory.params()}')
        if self.timing is Timing.REALTIME:
            set_realtime_priority(self, self.p['realtime_priority'])

    def _join_loop(self) -> None:
        readers = self.pub.get_subscription_count()
        if readers < self.p['expected_subscribers']:
            if time.monotonic() - self._since < MATCH_TIMEOUT:
                return
            self.get_logger().warning(f'{readers} of {self.p["expected_subscribers"]} '
                                      f'reference readers after {MATCH_TIMEOUT:g} s: '
                                      f'starting anyway')
        self.destroy_timer(self._match_timer)
        self._match_timer = None
        if self.timing is Timing.LOCKSTEP:
            # raw CDR: the tick's time straight from the bytes (read_clock_ns)
            self.mark_hot(self.create_subscription(Clock, TOPIC_CLOCK, self._on_clock,
                                                   SUB_QOS, raw=True))
        else:
            # trajectory time starts with the plant's first measurement; until then the
            # start point r(0) is held so the controller has a reference from the start.
            # Hot (served by the lean loop at once): the executor serves other entities
            # only every EXECUTOR_PERIOD_NS (50 ms), and a first measurement seen 52 ms
            # late made the reference jump 0.48 mm ahead at the start (a stress run)
            self._js_sub = self.mark_hot(self.create_subscription(
                JointState, TOPIC_JOINT_STATES, self._on_first_measurement, SUB_QOS,
                raw=True))
            if self.p['wait_for_command']:
                # a drive measures from power-on: start when the loop is closed
                self._u_sub = self.mark_hot(self.create_subscription(
                    Float64, TOPIC_VOLTAGE, self._on_command, SUB_QOS, raw=True))
            self.mark_hot(self.create_timer(self.dt_ns * 1e-9, self._on_tick))

    def _build(self, values: Mapping[str, Any]) -> Trajectory:
        kind = values['trajectory']
        if kind == Table.name:
            return Table(file=values['file'], data=self._read_table(values['file']))
        prefix = kind + '.'
        params = {k[len(prefix):]: v for k, v in values.items() if k.startswith(prefix)}
        return make_trajectory(kind, **params)

    def _check(self, trajectory: Trajectory) -> None:
        """Refuse a reference beyond the limits (ParameterError naming where)."""
        check_reference(trajectory, self.limits, duration=self.p['duration'],
                        rate=self.p['control_rate'])

    def _read_table(self, path: str) -> TableData:
        """Read the table ``file`` names (param_files rules; reasons without content)."""
        if not path.strip():
            raise ParameterError('file: the table trajectory needs a file (a CSV t, x[, v, a])')
        real, text = read_text('file', path, self.file_dirs)

        def parse(body: str) -> TableData | str:
            # parse_table's reasons name a row or column, never a cell: passed on as
            # they are; anything else it might raise is reduced by parse_untrusted
            try:
                return parse_table(body, source=f'file: {real}')
            except ParameterError as exc:
                return str(exc)
        data = parse_untrusted('file', real, text, parse, what='trajectory table')
        if isinstance(data, str):
            raise ParameterError(data)
        return data

    def apply_params(self, changed: Mapping[str, Any], new: Mapping[str, Any]) -> None:
        """Rebuild the trajectory (raises ParameterError with the reason if invalid)."""
        trajectory = self._build(new)
        self._check(trajectory)   # beyond the limits: rejected, the old one goes on
        self.trajectory = trajectory

    def publish_at(self, t: float, stamp_ns: int) -> None:
        """Publish the reference at trajectory time ``t`` [s] stamped ``stamp_ns``."""
        ref = self.trajectory.at(t)
        msg = self._msg
        set_stamp(msg.header.stamp, stamp_ns)
        msg.position[0] = ref.position   # in place: the message's own arrays
        msg.velocity[0] = ref.velocity
        msg.effort[0] = ref.acceleration
        self._pub_out.publish(msg)

    def _on_clock(self, msg: Clock | bytes) -> None:
        """Publish the references up to ``lookahead`` ticks ahead of this tick.

        The controller then already holds r(t_{k+1}) when measurement k+1 arrives, so
        the node is off the loop's critical path (plant → controller → plant).  The plant
        publishes ``/clock`` only every few ticks (``clock_every``).  A tick that does
        not advance (tick 0 of a new run, a resume at a tick already seen) republishes
        from the tick itself.
        """
        t_ns = read_clock_ns(msg)
        k, rem = divmod(t_ns, self.dt_ns)
        if rem:   # not on the control grid (foreign clock): publish for the tick itself
            self.publish_at(t_ns * 1e-9, t_ns)
            return
        if k == 0 or k <= self._next_k - 1:
            self._sent_k = k - 1
        ahead = k + self.p['lookahead']
        if self._last_k is not None:
            ahead = min(ahead, self._last_k)
        for j in range(max(self._sent_k + 1, k), ahead + 1):
            self._publish_step(j)
        self._sent_k = max(self._sent_k, ahead)
        if self._end_k is not None and self._sent_k >= self._end_k:
            self._finished = True
        self._next_k = k + 1   # a later tick advances

    def _publish_step(self, k: int) -> None:
        # the simulator evaluates the trajectory at k·T with T = 1/rate: use the same
        # float (not ns·1e-9, which can differ in the last bit)
        self.publish_at(k * (1.0 / self.p['control_rate']), k * self.dt_ns)

    def _on_first_measurement(self, msg: JointState | bytes, info: Any = None) -> None:
        # the subscription is dropped by the next tick (not here: the lean loop is
        # still iterating its subscriptions)
        if self._t0_ns is None and self._loop_closed:
            # trajectory time counts on this process's clock from the sample's arrival, so
            # whatever delays it here puts every reference of the run as late (a drive
            # measures from power-on; 58–116 ms in 4 of 10 starts of autotune on a drive,
            # and a controller that sees the move start that late kicks the axis past its
            # acceleration limit): the newest sample, not the oldest queued, and its
            # reception time, not the time this process got round to it
            msg, info, skipped = take_newest(self._js_sub, msg, info)
            self._t0_ns = read_joint_state(msg)[0]
            now = self.get_clock().now().nanoseconds
            rx = info.get('received_timestamp', 0) if isinstance(info, dict) else 0
            self._t0_rx_ns = rx if 0 < now - rx < RX_TRUST_NS else now
            self.get_logger().info(
                f'trajectory time starts with the sample stamped {self._t0_ns * 1e-9:.6f} s'
                + (' (after the controller\'s first command)' if self.p['wait_for_command']
                   else '') + f', received {(now - self._t0_rx_ns) * 1e-6:.1f} ms ago'
                + (f', {skipped} older queued samples skipped' if skipped else ''))

    def _on_command(self, msg: Float64 | bytes) -> None:
        # the controller answered a measurement (with the held start point): the loop is
        # closed, the next measurement starts the trajectory
        self._loop_closed = True

    def _on_tick(self) -> None:
        now = self.get_clock().now().nanoseconds
        if self._t0_ns is None:
            self.publish_at(0.0, now)
            self._held_ns = now
            return
        for sub in (self._js_sub, self._u_sub):
            if sub is not None:
                self.hot_subscriptions.remove(sub)
                self.destroy_subscription(sub)
        self._js_sub = self._u_sub = None
        # trajectory time runs on this process's clock from the first sample's arrival: the
        # plant's stamps may be on another clock (a drive on another machine, a simulated
        # plant whose sim time slipped behind the wall clock), and counting from its stamp
        # had started a slipped plant's trajectory seconds in, mid-move (a 29 mm step)
        k_now = max(0, (now - self._t0_rx_ns) // self.dt_ns)
        # stamps only increase: the held start point may be stamped just after t0 (on the
        # same clock; across clocks the held points are on ours, the grid on the plant's)
        held = self._held_ns - self._t0_ns
        if 0 <= held <= CATCH_UP * self.dt_ns:
            self._next_k = max(self._next_k, held // self.dt_ns + 1)
        # grid points missed while this process was descheduled are published too (up to
        # CATCH_UP of them): a plant that slipped needs them, and a recording then holds
        # the reference of every sample instead of holding an older one over the gap
        last = k_now + 1 if self._end_k is None else min(k_now + 1, self._end_k)
        if self._next_k >= 0 and k_now - self._next_k >= 1:
            self.late_ticks += 1
            self.late_max = max(self.late_max, k_now - self._next_k + 1)
        for k in range(max(self._next_k, k_now - CATCH_UP), last + 1):
            self.publish_at(k * (1.0 / self.p['control_rate']), self._t0_ns + k * self.dt_ns)
        self._next_k = max(self._next_k, last + 1)
        if self._end_k is not None and self._next_k > self._end_k:
            self._finished = True

    def finish(self, executor: Any) -> None:
        """Give the readers the chance to acknowledge the last references (at most 2 s)."""
        if self.timing is Timing.REALTIME:
            self.get_logger().info(f'timing: {self.late_ticks} ticks found references already '
                                   f'due, the latest {self.late_max * self.dt_ns * 1e-6:.1f} '
                                   f'ms late')
        if executor is not None:
            self.pub.wait_for_all_acked(Duration(seconds=2.0))

    @property
    def done(self) -> bool:
        """With ``exit_at_end``: the reference of trajectory time ``duration`` is out."""
        return self._finished


def main(args: list[str] | None = None) -> int:
    """Console entry point ``trajectory_node``."""
    return run_node(TrajectoryNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
