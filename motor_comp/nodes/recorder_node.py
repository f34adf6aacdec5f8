"""``recorder_node``: records the axis topics to MCAP (ros2 profile, ros2msg, CDR).

Subscribes with ``raw=True`` and hands the serialized CDR bytes unchanged to
:class:`motor_comp.logs.McapRecorder` — no decode/encode round trip, so the file holds
exactly what was on the wire.  Topics: ``<ns>/reference``, ``<ns>/joint_states``,
``<ns>/voltage``, ``/clock`` (lockstep) and, when anything publishes it,
``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``: the monitor's verdicts, the
controller's limits; its channel is created with its first message, so a run without
diagnostics records exactly the loop's topics; ``record_diagnostics``).

Output rule (issue 24): ``output`` (read-only) must name a *new* file in an existing
directory.  It is created exclusively — an existing file or a symbolic link at the path
is refused — so the parameter cannot clobber anything; later segments
(``<stem>.<n>.mcap``) follow the same rule.  ``motor-comp run -o RUN.mcap`` lets the
recorder write a new file next to ``RUN.mcap`` and moves it there at the end.

Log times.  Stamped messages (JointState, Clock) are logged at their header stamp, so a
lockstep run is logged in sim time and the same run twice gives the same data.
``Float64`` has no stamp: in lockstep each command answers exactly one measurement, so
the k-th voltage is logged at the stamp of the k-th ``joint_states`` (deterministic,
whatever the arrival order at the recorder); in realtime the controller answers the
newest measurement it has, so a voltage is logged at the stamp of the newest
``joint_states`` received (1 ns later if that one already carries a command) — the
stamps are the plant's sim time on the wall clock's axis, which lags the wall clock
when the plant process slipped, so arrival times would misalign commands and samples
by the slip.  Voltages that arrive before the recorder has seen a measurement (the
controller's watchdog zeros, or u_0 overtaking sample 0) are held back and written just
before the first measurement's stamp (at their arrival time if no sample ever comes).

Run parameters (documented choice): the recorder *queries* the other nodes'
parameters through their standard parameter services (``nodes`` parameter: the node
names in the same namespace) as soon as they answer — asking again every
:data:`PARAM_RETRY_S` until they do, since a request lost in discovery is gone for
good — and writes one MCAP metadata record per node (``params:<node>``, values as
strings) immediately — so the record
survives even a SIGKILL of the recorder.  Runtime changes arrive on
``/parameter_events`` and are written at the end as ``parameter_changes``
(``<sim ns>:<node>.<param>`` → new value).  A ``run`` record states timing, counts and
the topics.  Once the plant, controller and trajectory nodes have answered, the
``motor_comp`` record (the one :func:`motor_comp.logs.read_run` returns as
``Run.metadata``) gets the keys ``motor-comp simulate -o`` writes — ``plant``,
``controller``, ``feedforward``, ``seed``, ``trajectory`` (JSON of
``Trajectory.params()``), ``control_rate_hz``, ``physics_rate_hz``, ``gains`` — plus
the finite gains as top-level keys, so ``motor-comp compare RUN --model M.yaml`` can
replay the closed loop of a ROS recording (:func:`scenario_metadata`).  They describe
the run as it started; runtime changes are in ``parameter_changes``.

Memory (issue 13; ``bench/soak.py``, lockstep ball-screw, 4 messages per step).  The
Python heap is flat (``trace_memory``: +0.0 MiB over 300 000 messages) except the MCAP
writer's chunk index, which mcap keeps as one object per chunk (≈ 0.6 KiB each, a chunk
per ≈ 0.7 s: 3–5 MiB per hour of recording); :class:`~motor_comp.logs.McapRecorder`
now spills it to a temporary file, so nothing grows with the number of chunks.  RSS
moves in steps, not a slope: in a 900 s run (3.6 M messages, every step recorded,
machine at load ≈ 15) it rose 2.4 MiB in the first 30 k messages (start-up), one
≈ 1 MiB step near 0.8 M messages (the control run with ``discard:=true``, without any
MCAP writer, had a similar +0.6 MiB step at 0.5 M: native, rmw/DDS or malloc
thresholds), then 0.14 ± 0.005
MiB per hour of 1 kHz recording over the last 2.8 M messages.
A lagging recorder no longer loses data or grows its DDS queues without bound: the
lockstep plant paces itself on its readers' acknowledgements
(:class:`~motor_comp.nodes.common.Pacer`).  ``memory_log_interval`` logs RSS during a
run; ``discard`` is the control (same subscriptions and callbacks, no file).

Lifecycle: see :class:`RecorderNode` (file opened on configure, written while active,
finalised on deactivate, cleanup, shutdown or SIGINT/SIGTERM; every configure or
re-activation after a finished file opens the next segment).

Shutdown: on SIGINT/SIGTERM the node keeps taking messages until the graph has been
quiet for ``drain_time``, then closes the file (summary and index written), so no
received message is lost.  After a SIGKILL the file is readable up to its last
complete chunk (``chunk_size`` bounds the loss).
"""
from __future__ import annotations

import collections
import json
import math
import struct
import time
import tracemalloc
from pathlib import Path
from typing import Any, Callable, Mapping

from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.msg import ParameterEvent
from rclpy.parameter import parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from motor_comp.errors import InputFileError, MotorCompError
from motor_comp.logs import McapRecorder
from motor_comp.logs.mcap_io import METADATA_NAME
from motor_comp.nodes.common import DEFAULT_NAMESPACE, EVENTS_QOS, MODEL_DIR, LeanLoop, \
    ManagedNode, Param, RECORD_QOS, TOPIC_CLOCK, TOPIC_JOINT_STATES, TOPIC_REFERENCE, \
    TOPIC_VOLTAGE, Timing, rss_mib, run_node

PARAMS = (
    Param('output', 'run.mcap', 'MCAP file to create: a new file in an existing directory '
          '(an existing file or link at the path is refused, never overwritten)',
          read_only=True),
    Param('timing', 'lockstep', 'Timing mode (how voltages are time-stamped)',
          choices=('lockstep', 'realtime'), read_only=True),
    Param('record_clock', True, 'Also record /clock', read_only=True),
    Param('record_diagnostics', True, 'Also record /diagnostics (the channel is created with '
          'its first message)', read_only=True),
    Param('chunk_size', 262144, 'MCAP chunk size: the most a SIGKILL can lose', 'bytes',
          1024, 64 * 1024 * 1024, read_only=True),
    Param('drain_time', 0.3, 'On shutdown, stop after the topics were quiet this long', 's',
          0.0, 10.0),
    Param('batch_period', 0.002, 'Lockstep: take the queued messages in batches, pausing '
          'this long after each batch (fewer wake-ups: CPU left to the loop\'s own '
          'processes); 0 = wake for every message', 's', 0.0, 0.1, read_only=True),
    Param('match_timeout', 10.0, 'Wait this long for publishers on reference/voltage/clock '
          'before subscribing joint_states anyway', 's', 0.0, 600.0, read_only=True),
    Param('trace_memory', False, 'Diagnostics: trace Python allocations (tracemalloc) and '
          'log the largest growth sites at exit (slows recording about 2×)', read_only=True),
    Param('memory_log_interval', 0.0, 'Diagnostics: log RSS, traced heap and message '
          'count this often (0 = off)', 's', 0.0, 3600.0, read_only=True),
    Param('discard', False, 'Diagnostics: subscribe and count like a recording, but '
          'write no MCAP (the control run of a memory soak)', read_only=True),
    Param('nodes', 'plant_node,trajectory_node,controller_node',
          'Comma-separated node names (same namespace) whose parameters are stored as '
          'MCAP metadata', read_only=True),
    MODEL_DIR,
)

#: the optional topic recorded when present
TOPIC_DIAGNOSTICS = '/diagnostics'
#: ask a node for its parameters again if it has not answered this long after [s]: a
#: service request or response sent before the other side's endpoint was discovered
#: is lost (DDS does not resend it), and a lost one left the recorder waiting forever
PARAM_RETRY_S = 2.0


_STAMP = struct.Struct('<iI')   # header.stamp (sec, nanosec) right after the CDR header


def scenario_metadata(plant: Mapping[str, Any], controller: Mapping[str, Any],
                      trajectory: Mapping[str, Any], *, timing: str,
                      dirs: Any = None) -> dict[str, str]:
    """Describe the run like ``motor-comp simulate -o`` does, from the nodes' parameters.

    Parameters
    ----------
    plant, controller, trajectory : Mapping
        Parameter name → value of ``plant_node``, ``controller_node``,
        ``trajectory_node`` (as their parameter services return them).
    timing : str
        ``lockstep`` or ``realtime`` (a lockstep run is the simulator's run exactly).
    dirs : sequence of Path, optional
        Where a plant file the plant node names may be read (its physics rate); the
        default directories of :mod:`motor_comp.param_files` when None.

    Returns
    -------
    dict of str to str
        The ``motor_comp`` metadata record.
    """
    from motor_comp import param_files
    from motor_comp.control.trajectories import make_trajectory

    mode = str(controller['mode'])
    kind = str(trajectory['trajectory'])
    traj = make_trajectory(kind, **{k.split('.', 1)[1]: _plain(v)
                                    for k, v in trajectory.items()
                                    if k.startswith(kind + '.')})
    gains = {k.split('.', 1)[1]: float(v) for k, v in controller.items()
             if k.startswith(mode + '.')}
    # another node's parameter names this file: read under the same rules as our own
    cfg = param_files.load_plant('plant', str(plant['plant']),
                                 param_files.default_dirs() if dirs is None else dirs)
    meta = {'plant': str(plant['plant']), 'controller': mode,
            'feedforward': str(controller['feedforward']), 'seed': str(int(plant['seed'])),
            'trajectory': json.dumps(traj.params()),
            'gains': json.dumps({k: v if math.isfinite(v) else None
                                 for k, v in gains.items()}),
            'control_rate_hz': repr(float(plant['control_rate'])),
            'physics_rate_hz': repr(float(plant['physics_rate']) or cfg.physics_rate),
            'load_force_N': repr(float(plant['load_force'])),
            'load_start_s': repr(float(plant['load_start'])),
            'x0_m': repr(float(plant['x0'])),
            'settings': '{}', 'timing': timing,
            'generator': 'motor-comp run (ROS 2 nodes)'}
    # top level too (what compare's replay reads); inf (no limit) is the default anyway
    meta.update({k: repr(v) for k, v in gains.items() if math.isfinite(v)})
    return meta


def _plain(value: Any) -> Any:
    """ROS array parameters arrive as lists/arrays: make them tuples of float."""
    if isinstance(value, (list, tuple)) or hasattr(value, 'tolist'):
        return tuple(float(v) for v in value)
    return value


def cdr_stamp_ns(data: bytes) -> int:
    """Return the leading ``builtin_interfaces/Time`` of a CDR message (JointState, Clock) [ns].

    Both types start with a Time (``header.stamp`` / ``clock``): after the 4-byte
    encapsulation header, int32 sec and uint32 nanosec, little-endian for CDR_LE.
    """
    if len(data) < 12:
        raise ValueError('message shorter than its stamp')
    fmt = _STAMP if data[1] == 1 else struct.Struct('>iI')   # 0x0001 = CDR_LE
    sec, nsec = fmt.unpack_from(data, 4)
    return sec * 1_000_000_000 + nsec


class RecorderNode(ManagedNode):
    """Writes every received message of the axis topics to one MCAP file.

    Managed node: ``configure`` opens the file (header, channels; the other nodes'
    parameters are stored as soon as they answer); ``activate`` subscribes the topics
    and writes what arrives; ``deactivate`` drains what is still arriving and closes
    the file (summary written: a complete, finalised MCAP); ``cleanup`` and
    ``shutdown`` close it too if it is open.  Activating again after a deactivate
    opens the next segment ``<output stem>.<n>.mcap`` (never overwriting a finished
    file).  While not active nothing is subscribed, so the plant waits for the
    recorder before it starts a run.
    """

    def __init__(self) -> None:
        super().__init__('recorder_node', namespace=DEFAULT_NAMESPACE)
        self.declare_params(PARAMS)
        self.timing = Timing(self.p['timing'])
        # lockstep: the loop never outruns the recorder by more than a writer's history
        # (Pacer), commands pair with measurements by count, so batches may be taken
        # topic by topic.  Realtime: a command is stamped with the newest measurement
        # taken, so messages are taken one per topic and wait, in arrival order.
        if self.timing is Timing.LOCKSTEP:
            self.batch_pause = self.p['batch_period']
        else:
            self.take_burst = 1
        self.path = Path(self.p['output'])
        self.writer: McapRecorder | None = None
        self._segment = 0
        self._opened = False
        self._closed = True
        self._subs: dict[str, Any] = {}
        self._optional_subs: dict[str, Any] = {}
        self._js_sub = self._match_timer = self._param_timer = None
        self._param_clients: dict[str, AsyncParameterClient] = {}
        self.counts = collections.Counter()
        ns = self.get_namespace().rstrip('/')
        self.topics = {'reference': f'{ns}/{TOPIC_REFERENCE}',
                       'joint_states': f'{ns}/{TOPIC_JOINT_STATES}',
                       'voltage': f'{ns}/{TOPIC_VOLTAGE}', 'clock': TOPIC_CLOCK}
        if self.timing is Timing.REALTIME or not self.p['record_clock']:
            del self.topics['clock']   # no /clock in realtime
        self._types = {'reference': JointState, 'joint_states': JointState,
                       'voltage': Float64, 'clock': Clock, 'diagnostics': DiagnosticArray}
        # recorded when present: not waited for, its channel made at its first message
        self.optional = ({'diagnostics': TOPIC_DIAGNOSTICS} if self.p['record_diagnostics']
                         else {})
        self.create_subscription(ParameterEvent, '/parameter_events', self._on_event,
                                 EVENTS_QOS)
        self._mem_base = None
        if self.p['trace_memory']:
            tracemalloc.start(1)   # one frame: deeper tracing slows the loop ~40×
            self._mem_timer = self.create_timer(5.0, self._memory_baseline)
        if self.p['memory_log_interval'] > 0:
            self.create_timer(self.p['memory_log_interval'], self._memory_sample)
        self.autostart()

    # -- lifecycle -------------------------------------------------------------------
    def _segment_path(self) -> Path:
        out = Path(self.p['output'])
        if self._segment == 0:
            return out
        return out.with_name(f'{out.stem}.{self._segment}{out.suffix or ".mcap"}')

    def configure(self) -> None:
        """Open the output file and start storing the other nodes' parameters."""
        self._open()

    def _open(self) -> None:
        if self._opened:   # this node wrote the current segment: the next one, never it
            self._segment += 1
        out = self._segment_path()
        if not out.parent.is_dir():
            raise InputFileError(f'output: directory {out.parent} does not exist')
        self.path = out
        try:
            self.writer = (McapRecorder(out, chunk_size=self.p['chunk_size'], exclusive=True)
                           if not self.p['discard'] else _NullWriter())
        except InputFileError as exc:
            raise InputFileError(f'output: {exc}') from None
        self._opened = True
        self._closed = False
        self._optional_channels: set[str] = set()
        for key, topic in self.topics.items():
            self.writer.add_channel(topic, _type_name(self._types[key]))
        self.counts = collections.Counter()
        self._js_stamps: collections.deque[int] = collections.deque()
        self._pending_voltage: collections.deque[bytes] = collections.deque()
        self._last_ns = 0
        self._last_pair_ns = -1
        self._last_volt_ns = -1
        self._early_voltage: list[tuple[int, bytes]] = []
        self._last_rx = time.monotonic()
        self._changes: dict[str, str] = {}
        ns = self.get_namespace().rstrip('/')
        names = [n.strip() for n in self.p['nodes'].split(',') if n.strip()]
        if not self._param_clients:
            self._param_clients = {n: AsyncParameterClient(self, f'{ns}/{n}')
                                   for n in names}
        #: when each node was last asked for its parameters (monotonic s)
        self._asked: dict[str, float] = {}
        self._raw_params: dict[str, dict[str, Any]] = {}
        self._scenario_done = False
        if self._param_timer is not None:
            self.destroy_timer(self._param_timer)
        self._param_timer = self.create_timer(0.2, self._query_parameters)
        self.get_logger().info(f'recording {", ".join(self.topics.values())} → {out}')

    def activate(self) -> None:
        """Subscribe the topics (``joint_states`` last) and write what arrives."""
        if self._closed:   # deactivated before: a new segment, never the finished file
            self._open()
        handlers = {'reference': self._on_stamped('reference'),
                    'joint_states': self._on_joint_states, 'voltage': self._on_voltage,
                    'clock': self._on_stamped('clock'),
                    'diagnostics': self._on_stamped('diagnostics')}
        for key, topic in self.topics.items():
            if key != 'joint_states':
                self._subs[key] = self.mark_hot(self.create_subscription(
                    self._types[key], topic, handlers[key], RECORD_QOS, raw=True))
        for key, topic in self.optional.items():   # not waited for (see _subscribe_…)
            self._optional_subs[key] = self.mark_hot(self.create_subscription(
                self._types[key], topic, handlers[key], RECORD_QOS, raw=True))
        # joint_states last: the plant starts when it sees this reader, and by then the
        # other topics' writers have matched us, so nothing of the run is missed
        self._js_args = (self._types['joint_states'], self.topics['joint_states'],
                         handlers['joint_states'])
        self._since = time.monotonic()
        self._match_timer = self.create_timer(0.05, self._subscribe_joint_states)

    def deactivate(self) -> None:
        """Stop subscribing, write what is still arriving, close the file (finalised)."""
        if self._subs or self._js_sub is not None:
            self._drain(LeanLoop(self).spin_once)
        for sub in [*self._subs.values(), *self._optional_subs.values(), self._js_sub]:
            self.destroy_hot(sub)
        if self._match_timer is not None:
            self.destroy_timer(self._match_timer)
        self._subs, self._optional_subs, self._js_sub, self._match_timer = {}, {}, None, None
        self._close()

    def cleanup(self) -> None:
        """Close the file if it is still open; the next configure opens the next segment."""
        self.deactivate()
        if self._param_timer is not None:
            self.destroy_timer(self._param_timer)
            self._param_timer = None

    def _params_pending(self) -> list[str]:
        """Nodes that are up but whose parameters are not recorded yet.

        Up: its parameter services answer, or it publishes one of the recorded topics.
        The second matters: DDS discovers a node's topics and its services' endpoints
        separately, and a plant seen on ``/clock`` whose services were not discovered
        yet was not waited for — its 1.5 s lockstep run ended (and the node with it)
        before the recorder asked (a stress run lost ``params:plant_node`` this way).
        A publisher whose node name is not known yet counts as every node not yet
        recorded.
        """
        up: set[str] = set()
        for topic in self.topics.values():
            for info in self.get_publishers_info_by_topic(topic):
                if info.node_name.startswith('_NODE_NAME_UNKNOWN_'):
                    up.update(self._param_clients)
                else:
                    up.add(info.node_name)
        return [n for n, c in self._param_clients.items()
                if n not in self._raw_params and (n in up or c.services_are_ready())]

    def _subscribe_joint_states(self) -> None:
        # also wait until the running nodes' parameters are stored: the plant starts
        # when it sees this reader, and a short lockstep run (1.5 s of sim time, 0.5 s
        # of wall time) had ended, and the plant's parameter service with it, before a
        # starved recorder got its answer (a stress run lost ``params:plant_node``)
        unmatched = [k for k, sub in self._subs.items() if sub.get_publisher_count() < 1]
        pending = self._params_pending()
        waited = time.monotonic() - self._since
        if (unmatched or pending) and waited < self.p['match_timeout']:
            return
        if unmatched:
            self.get_logger().warning(f'no publisher on {", ".join(unmatched)} after '
                                      f'{waited:.0f} s: recording without waiting')
        if pending:
            self.get_logger().warning(f'no parameters from {", ".join(pending)} after '
                                      f'{waited:.0f} s: recording without them')
        self.destroy_timer(self._match_timer)
        self._match_timer = None
        self._js_sub = self.mark_hot(self.create_subscription(*self._js_args, RECORD_QOS,
                                                              raw=True))

    # -- messages --------------------------------------------------------------------
    def _write(self, key: str, data: bytes, t_ns: int) -> None:
        topic = self.topics.get(key)
        if topic is None:   # an optional topic: its channel from its first message on
            topic = self.optional[key]
            if key not in self._optional_channels:
                self.writer.add_channel(topic, _type_name(self._types[key]))
                self._optional_channels.add(key)
        self.writer.write_cdr(topic, data, t_ns, t_ns)
        self.counts[key] += 1
        self._last_ns = max(self._last_ns, t_ns)
        self._last_rx = time.monotonic()

    def _on_stamped(self, key: str):
        def callback(data: bytes) -> None:
            self._write(key, data, cdr_stamp_ns(data))
        return callback

    def _on_joint_states(self, data: bytes) -> None:
        t_ns = cdr_stamp_ns(data)
        self._write('joint_states', data, t_ns)
        # only the loop's own, advancing stamps pair with commands: a stray message
        # (e.g. injected by hand) is recorded but cannot shift the pairing
        if self.timing is Timing.REALTIME:
            if self._last_pair_ns < 0:
                self._flush_early_voltage(t_ns)
            self._last_pair_ns = max(self._last_pair_ns, t_ns)
        elif t_ns > self._last_pair_ns:
            self._last_pair_ns = t_ns
            if self._pending_voltage:   # its command overtook it on the way here
                self._write('voltage', self._pending_voltage.popleft(), t_ns)
            else:
                self._js_stamps.append(t_ns)

    def _flush_early_voltage(self, first_ns: int | None) -> None:
        """Write the voltages held back before the first measurement (see module doc)."""
        n = len(self._early_voltage)
        for i, (arrival, data) in enumerate(self._early_voltage):
            t_ns = arrival if first_ns is None else min(arrival, first_ns - (n - i))
            self._write('voltage', data, t_ns)
        self._early_voltage.clear()

    def _on_voltage(self, data: bytes) -> None:
        if self.timing is Timing.REALTIME:
            if self._last_pair_ns < 0:
                self._early_voltage.append((self.get_clock().now().nanoseconds, data))
                return
            t_ns = max(self._last_pair_ns, self._last_volt_ns + 1)
            self._last_volt_ns = t_ns
            self._write('voltage', data, t_ns)
        elif self._js_stamps:
            self._write('voltage', data, self._js_stamps.popleft())
        else:
            self._pending_voltage.append(data)

    # -- run parameters --------------------------------------------------------------
    def _query_parameters(self) -> None:
        now = time.monotonic()
        for name, client in self._param_clients.items():
            if name in self._raw_params or not client.services_are_ready():
                continue
            if now - self._asked.get(name, -math.inf) < PARAM_RETRY_S:
                continue
            self._asked[name] = now
            client.list_parameters(callback=lambda fut, n=name: self._on_list(n, fut))
        if len(self._raw_params) == len(self._param_clients):
            self._param_timer.cancel()

    def _on_list(self, name: str, future: Any) -> None:
        if self._closed or name in self._raw_params:   # a retry's late twin
            return
        names = list(future.result().result.names)
        self._param_clients[name].get_parameters(
            names, callback=lambda fut: self._on_values(name, names, fut))

    def _on_values(self, name: str, names: list[str], future: Any) -> None:
        if self._closed or name in self._raw_params:   # a retry's late twin
            return
        values = future.result().values
        raw = {n: parameter_value_to_python(v) for n, v in zip(names, values)}
        data = {n: str(v) for n, v in raw.items()}
        self.writer.add_metadata(f'params:{name}', data)
        self.get_logger().info(f'stored {len(data)} parameters of {name}')
        self._raw_params[name] = raw
        self._write_scenario()

    def _write_scenario(self) -> None:
        """Write the ``motor_comp`` record once plant, controller and trajectory answered."""
        need = ('plant_node', 'controller_node', 'trajectory_node')
        if self._scenario_done or not all(n in self._raw_params for n in need):
            return
        self._scenario_done = True
        try:
            meta = scenario_metadata(*(self._raw_params[n] for n in need),
                                     timing=self.timing.value, dirs=self.file_dirs)
        except (KeyError, ValueError, TypeError, MotorCompError) as exc:
            # e.g. nodes of another version: the record is optional, the run is not
            self.get_logger().warning(f'run description not stored: {exc}')
            return
        self.writer.add_metadata(METADATA_NAME, meta)

    def _on_event(self, msg: ParameterEvent) -> None:
        node = msg.node.rsplit('/', 1)[-1]
        if node not in self._param_clients:
            return
        for p in msg.changed_parameters:   # new_parameters = declarations at start
            key = f'{self._last_ns}:{node}.{p.name}'
            self._changes[key] = str(parameter_value_to_python(p.value))

    # -- diagnostics -----------------------------------------------------------------
    def _memory_baseline(self) -> None:
        self._mem_timer.cancel()
        self._mem_base = (tracemalloc.take_snapshot(), rss_mib(), self._messages())

    def _messages(self) -> int:
        return self.writer.message_count if self.writer is not None else 0

    def _memory_sample(self) -> None:
        self.get_logger().info(f'memory: rss_mib={rss_mib():.2f} traced_mib='
                               f'{tracemalloc.get_traced_memory()[0] / 2**20:.2f} '
                               f'messages={self._messages()}')

    def _memory_report(self) -> None:
        """Log where the traced Python heap grew since the baseline (5 s after start)."""
        if self._mem_base is None:
            return
        base, rss0, n0 = self._mem_base
        now = tracemalloc.take_snapshot()
        diff = now.compare_to(base, 'lineno')
        total = sum(d.size_diff for d in diff)
        self.get_logger().info(
            f'memory: {self._messages() - n0} messages since baseline; RSS '
            f'{rss0:.2f} → {rss_mib():.2f} MiB; traced Python heap +{total / 2**20:.3f} MiB')
        for d in diff[:5]:
            where = ' < '.join(f'{Path(f.filename).name}:{f.lineno}'
                               for f in list(d.traceback)[-4:])
            self.get_logger().info(f'memory: +{d.size_diff / 1024:.1f} KiB in '
                                   f'{d.count_diff:+d} blocks at {where}')

    # -- shutdown --------------------------------------------------------------------
    def _drain(self, spin: Callable[[int], Any]) -> None:
        """Take messages until the topics were quiet for ``drain_time`` (10 s at most).

        In lockstep every measurement gets its command, so more than one measurement
        still waiting for its command while the controller's writer is on the graph
        means commands on their way: a starved recorder's lost samples come again only
        at the writer's next heartbeat (Fast DDS: every 3 s while its history is not
        full), after any quiet time.  Seen once in a loaded CI run: a lockstep run that
        tripped at step 481 recorded 209 commands of 534.  The wait ends when the
        commands arrive, the writer leaves, or at the 10 s bound.
        """
        deadline = time.monotonic() + 10.0
        self._last_rx = time.monotonic()
        voltage = self.topics['voltage']
        while time.monotonic() < deadline:
            if time.monotonic() - self._last_rx >= self.p['drain_time']:
                if not (self.timing is Timing.LOCKSTEP and len(self._js_stamps) > 1
                        and self.count_publishers(voltage) > 0):
                    break
            spin(20_000_000)

    def _close(self) -> None:
        """Write the held-back commands and the run metadata, close the file."""
        if self._closed:
            return
        self._flush_early_voltage(None)
        # a command without its measurement (should not happen): keep it, at the last time
        while self._pending_voltage:
            self._write('voltage', self._pending_voltage.popleft(), self._last_ns)
        if self._changes:
            self.writer.add_metadata('parameter_changes', dict(self._changes))
        topics = {**self.topics, **self.optional}
        self.writer.add_metadata('run', {
            'timing': self.timing.value, 'recorder': 'motor_comp recorder_node',
            **{f'count:{topics[k]}': str(v) for k, v in self.counts.items()}})
        self.writer.close()
        self._closed = True
        if self.p['trace_memory']:
            self._memory_report()
        self.get_logger().info(
            f'closed {self.path}: ' + ', '.join(f'{k} {v}' for k, v in self.counts.items()))

    def finish(self, executor: Any) -> None:
        """Drain what is still arriving, write the run metadata, close the file."""
        if self._closed:
            return
        if executor is not None:
            self._drain(lambda ns: executor.spin_once(timeout_sec=ns * 1e-9))
        self._close()


class _NullWriter:
    """Stands in for :class:`McapRecorder` with ``discard``: same calls, nothing kept."""

    message_count = 0

    def add_channel(self, topic: str, msgtype: str) -> None:
        """Accept a channel (nothing is written)."""

    def write_cdr(self, topic: str, data: bytes, log_time_ns: int,
                  publish_time_ns: int | None = None) -> None:
        """Count the message, drop it."""
        self.message_count += 1

    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """Drop the record."""

    def close(self) -> None:
        """Nothing to close."""


def _type_name(cls: type) -> str:
    """``pkg/msg/Type`` of a generated message class."""
    module = cls.__module__.split('.')
    return f'{module[0]}/msg/{cls.__name__}'


def main(args: list[str] | None = None) -> int:
    """Console entry point ``recorder_node``."""
    return run_node(RecorderNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
