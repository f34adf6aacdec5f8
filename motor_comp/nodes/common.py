"""Shared plumbing of the four nodes: parameter specs, QoS, stamps, the spin loop.

Nothing here is a control or physics law; the nodes convert messages to numbers and
call the core's step functions (DESIGN.md §2).  What lives here:

* :class:`Param` — one tunable with its unit, range and allowed values, turned into a
  ROS ``ParameterDescriptor`` (description with units, ``FloatingPointRange`` /
  ``IntegerRange``) and validated again in the node's ``on_set_parameters`` callback, so
  an invalid runtime update is rejected *with a reason* and the old value stays.
* :class:`Timing` — the two timing modes (lockstep on ``/clock``, realtime on wall timers).
* QoS profiles shared by publishers and subscribers so that they always match.
* :func:`run_node` — a spin loop with our own SIGINT/SIGTERM handling so that every node
  shuts down cleanly (and the recorder can flush) instead of dying inside a callback.
"""
from __future__ import annotations

import dataclasses
import enum
import gc
import math
import os
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import rclpy
import rclpy.exceptions
import rclpy.executors
from rclpy._rclpy_pybind11 import RCLError
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, \
    ParameterType, SetParametersResult
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.timer import Timer

from motor_comp.errors import MotorCompError, ParameterError

#: default namespace of the axis topics (DESIGN.md §5); override with ``-r __ns:=/x``
DEFAULT_NAMESPACE = 'axis'
#: topic names relative to the namespace; ``/clock`` is global by ROS convention
TOPIC_REFERENCE = 'reference'
TOPIC_JOINT_STATES = 'joint_states'
TOPIC_VOLTAGE = 'voltage'
TOPIC_CLOCK = '/clock'
JOINT_NAME = 'axis'


class Timing(enum.Enum):
    """How the loop is paced."""

    #: sim time on ``/clock``; the plant advances only when the step's command arrived
    LOCKSTEP = 'lockstep'
    #: wall-clock timers at the control rate
    REALTIME = 'realtime'


# Reliable, deep queues: in lockstep at most one message per topic is in flight, and in
# realtime a deep queue lets a briefly descheduled subscriber catch up instead of
# dropping samples the recorder must keep.  Publishers are transient-local (a late
# transient-local reader still gets the last sample); subscribers are volatile, which
# matches *any* publisher (``ros2 topic pub``, rosbag2, Foxglove use volatile writers
# by default, and a transient-local reader would not match them).  Start order is made
# safe by the plant waiting for its peers before step 0.
LOOP_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL)
SUB_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
#: what the recorder asks for: every sample (KEEP_ALL), reliable
RECORD_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)
#: ``/parameter_events`` is published volatile by every node
EVENTS_QOS = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1000,
                        reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)


def stamp_to_ns(stamp: Any) -> int:
    """Return a ``builtin_interfaces/Time`` as integer nanoseconds."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def set_stamp(stamp: Any, ns: int) -> None:
    """Write integer nanoseconds ``ns`` into a ``builtin_interfaces/Time`` in place."""
    stamp.sec, stamp.nanosec = divmod(int(ns), 1_000_000_000)


def period_ns(rate_hz: float) -> int:
    """Return the control period [ns] of ``rate_hz``, which must be a whole number of ns."""
    ns = 1e9 / rate_hz
    if abs(ns - round(ns)) > 1e-6:
        raise ParameterError(f'control_rate {rate_hz:g} Hz is not a whole number of ns')
    return int(round(ns))


@dataclasses.dataclass(frozen=True)
class Param:
    """One ROS parameter: default, unit, range/choices, and whether it may change live.

    Parameters
    ----------
    name : str
        Parameter name.
    default : bool, int, float, str or tuple of float
        Default value; its Python type fixes the ROS parameter type (a tuple is a
        ``double[]``).
    description : str
        What it is; the unit is appended in brackets.
    unit : str
        SI unit (``''`` for dimensionless or strings).
    low, high : float, optional
        Inclusive numeric range (``FloatingPointRange`` / ``IntegerRange``).
    choices : tuple of str, optional
        Allowed string values.
    read_only : bool
        Fixed after start (structure of the run, not a tuning knob).
    """

    name: str
    default: bool | int | float | str | tuple[float, ...]
    description: str
    unit: str = ''
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = False

    def descriptor(self) -> ParameterDescriptor:
        """Build the ROS descriptor: description with unit and choices, numeric range."""
        text = self.description + (f' [{self.unit}]' if self.unit else '')
        if self.choices:
            text += ' (one of: ' + ', '.join(self.choices) + ')'
        d = ParameterDescriptor(name=self.name, description=text, read_only=self.read_only)
        lo = -math.inf if self.low is None else self.low
        hi = math.inf if self.high is None else self.high
        if isinstance(self.default, bool):
            d.type = ParameterType.PARAMETER_BOOL
        elif isinstance(self.default, int):
            d.type = ParameterType.PARAMETER_INTEGER
            if self.low is not None or self.high is not None:
                d.integer_range = [IntegerRange(
                    from_value=int(max(lo, -2**62)), to_value=int(min(hi, 2**62)), step=0)]
        elif isinstance(self.default, float):
            d.type = ParameterType.PARAMETER_DOUBLE
            if self.low is not None or self.high is not None:
                d.floating_point_range = [FloatingPointRange(
                    from_value=lo, to_value=hi, step=0.0)]
        elif isinstance(self.default, tuple):
            d.type = ParameterType.PARAMETER_DOUBLE_ARRAY
        else:
            d.type = ParameterType.PARAMETER_STRING
        return d

    def convert(self, value: Any) -> Any:
        """Return the value in the spec's Python type (ROS arrays arrive as lists/arrays)."""
        if isinstance(self.default, tuple):
            try:
                return tuple(float(v) for v in value)
            except (TypeError, ValueError):
                raise ParameterError(f'{self.name}: expected a list of numbers, '
                                     f'got {value!r}') from None
        if isinstance(self.default, float) and isinstance(value, int) \
                and not isinstance(value, bool):
            return float(value)
        return value

    def check(self, value: Any) -> None:
        """Raise :class:`ParameterError` with a reason if ``value`` is not allowed."""
        value = self.convert(value)
        if isinstance(value, tuple):
            for i, v in enumerate(value):
                dataclasses.replace(self, name=f'{self.name}[{i}]',
                                    default=0.0).check(v)
            return
        kind = type(self.default)
        if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
            raise ParameterError(f'{self.name}: expected {kind.__name__}, '
                                 f'got {type(value).__name__} {value!r}')
        if kind is float and not math.isfinite(value) and not (
                value == math.inf and self.high == math.inf):   # e.g. u_max = inf: no limit
            raise ParameterError(f'{self.name}: must be finite, got {value!r}')
        if self.low is not None and value < self.low:
            raise ParameterError(f'{self.name}: {value!r} is below the minimum {self.low:g}'
                                 f'{" " + self.unit if self.unit else ""}')
        if self.high is not None and value > self.high:
            raise ParameterError(f'{self.name}: {value!r} is above the maximum {self.high:g}'
                                 f'{" " + self.unit if self.unit else ""}')
        if self.choices and value not in self.choices:
            raise ParameterError(f'{self.name}: {value!r} is not one of '
                                 f'{", ".join(self.choices)}')


#: shared by the realtime-capable nodes (plant, trajectory, controller)
REALTIME_PRIORITY = Param(
    'realtime_priority', 0, 'Realtime timing: SCHED_FIFO priority of the node process '
    '(all its threads, incl. DDS), as ros2_control does for its control thread; 0 = normal '
    'scheduling', '', 0, 98, read_only=True)


def set_realtime_priority(node: Node, priority: int) -> bool:
    """Run every thread of this process under ``SCHED_FIFO`` at ``priority`` (Linux).

    On a shared machine a normal-priority loop process is descheduled for 5–15 ms at a
    time; the PMLM loop has < 1.5 ms of delay margin (bench: a 1.5-period command delay
    destabilises PID and adaptive alike).  The node processes block in their wait sets
    between messages, so FIFO priority costs the machine only the loop's own CPU time,
    and the kernel's RT throttling (95 % by default) keeps the rest of the system alive.
    Returns False (with a warning, the node runs on) where not permitted.
    """
    if priority <= 0:
        return False
    try:
        tids = [int(t) for t in os.listdir('/proc/self/task')]
        for tid in tids:   # DDS threads already exist: each needs its own call
            os.sched_setscheduler(tid, os.SCHED_FIFO, os.sched_param(priority))
    except (OSError, AttributeError, ValueError) as exc:
        node.get_logger().warning(f'realtime_priority {priority}: not permitted here '
                                  f'({exc}); running with normal scheduling')
        return False
    node.get_logger().info(f'running SCHED_FIFO priority {priority} ({len(tids)} threads)')
    return True


class ParamNode(Node):
    """A node whose tunables are :class:`Param` specs, validated on every update.

    Subclasses call :meth:`declare_params` once, read ``self.p[name]``, and override
    :meth:`apply_params` to apply an accepted change (raise :class:`ParameterError` to
    reject it: the reason goes back to the caller and nothing changes).
    """

    #: subscriptions/timers on the loop's critical path, served by :class:`LeanLoop`
    hot_subscriptions: list
    hot_timers: list

    def mark_hot(self, entity: Any) -> Any:
        """Mark a subscription or timer as hot (served by the lean loop); return it."""
        if not hasattr(self, 'hot_subscriptions'):
            self.hot_subscriptions, self.hot_timers = [], []
        kind = self.hot_timers if isinstance(entity, Timer) else self.hot_subscriptions
        kind.append(entity)
        return entity

    def declare_params(self, specs: Sequence[Param]) -> None:
        """Declare ``specs`` (values from ``--params-file``/``-p`` override defaults).

        May be called more than once (e.g. gains whose defaults depend on an earlier
        parameter); validation covers every spec declared so far.
        """
        if not hasattr(self, 'specs'):
            self.specs: dict[str, Param] = {}
            self.p: dict[str, Any] = {}
            self.add_on_set_parameters_callback(self._on_set)
        self.specs.update({s.name: s for s in specs})
        declared = self.declare_parameters('', [(s.name, s.default, s.descriptor())
                                                for s in specs])
        for spec, par in zip(specs, declared):
            try:
                spec.check(par.value)
            except ParameterError as exc:
                raise ParameterError(f'{self.get_fully_qualified_name()}: {exc}') from None
            self.p[spec.name] = spec.convert(par.value)

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        new = dict(self.p)
        try:
            for par in params:
                spec = self.specs.get(par.name)
                if spec is None or par.name not in new:
                    continue   # rclpy's own (use_sim_time …): handled by rclpy
                if spec.read_only:
                    raise ParameterError(f'{par.name}: read-only while running')
                spec.check(par.value)
                new[par.name] = spec.convert(par.value)
            changed = {k: v for k, v in new.items() if v != self.p[k]}
            if changed:
                self.apply_params(changed, new)
        except (ParameterError, MotorCompError) as exc:
            self.get_logger().warning(f'rejected parameter update: {exc}')
            return SetParametersResult(successful=False, reason=str(exc))
        self.p = new
        return SetParametersResult(successful=True)

    def apply_params(self, changed: Mapping[str, Any], new: Mapping[str, Any]) -> None:
        """Apply accepted changes; raise :class:`ParameterError` to reject them."""

    def finish(self, executor: rclpy.executors.Executor | None) -> None:
        """Run once on shutdown before the node is destroyed (drain, flush files).

        ``executor`` is None after an error: do not spin, just release resources.
        """

    @property
    def done(self) -> bool:
        """True when the node has finished its job and the process may exit."""
        return False


class LeanLoop:
    """A wait-set loop over a node's hot subscriptions and timers.

    rclpy's executors rebuild their wait set, a generator and a task per callback:
    measured here, a bare two-process Float64 ping-pong does ≈ 3 000 round trips/s with
    ``SingleThreadedExecutor.spin_once`` and ≈ 10 000 with this loop (see
    ``bench/ros_loop.py``).  It takes messages and fires timers exactly like the
    executor does (``take_message`` / ``call_timer``, then the same callback), so a
    node's behaviour does not depend on which loop served it; everything else
    (parameter services, clients, other timers) stays with the executor, which
    :func:`run_node` spins without blocking between lean waits.
    """

    def __init__(self, node: ParamNode) -> None:
        self.node = node
        self._sizes = (-1, -1)
        self._ws = None

    def spin_once(self, timeout_ns: int) -> int:
        """Wait up to ``timeout_ns`` for hot entities; run their callbacks; how many ran."""
        subs = getattr(self.node, 'hot_subscriptions', ())
        timers = getattr(self.node, 'hot_timers', ())
        if (len(subs), len(timers)) != self._sizes:
            self._sizes = (len(subs), len(timers))
            self._ws = _rclpy.WaitSet(len(subs), 0, len(timers), 0, 0, 0,
                                      self.node.context.handle)
        ws = self._ws
        ws.clear_entities()
        for sub in subs:
            ws.add_subscription(sub.handle)
        for tmr in timers:
            ws.add_timer(tmr.handle)
        ws.wait(timeout_ns)
        ran = 0
        for i, sub in enumerate(subs):
            if ws.is_ready('subscription', i):
                taken = sub.handle.take_message(sub.msg_type, sub.raw)
                if taken is not None:
                    sub.callback(taken[0])
                    ran += 1
        for j, tmr in enumerate(timers):
            if ws.is_ready('timer', j) and tmr.handle.is_timer_ready():
                tmr.handle.call_timer()
                tmr.callback()
                ran += 1
        return ran


#: delay histograms of the realtime nodes: 0.1 ms bins, the last one collects ≥ 20 ms
DELAY_BIN_NS = 100_000
DELAY_BINS = 200


def delay_percentiles(hist: Sequence[int]) -> dict[str, float]:
    """Return p50/p99/max [s] (bin tops) of a :data:`DELAY_BINS` + 1 bin histogram."""
    import numpy as np
    h = np.asarray(hist)
    n = int(h.sum())
    if n == 0:
        return {}
    cum = np.cumsum(h)
    top = DELAY_BIN_NS * 1e-9
    return {'p50': (int(np.searchsorted(cum, 0.5 * n)) + 1) * top,
            'p99': (int(np.searchsorted(cum, 0.99 * n)) + 1) * top,
            'max': (int(np.flatnonzero(h)[-1]) + 1) * top}


def format_delays(hist: Sequence[int]) -> str:
    """``p50 x ms, p99 y ms, max z ms`` of a delay histogram."""
    return ', '.join(f'{k} {v * 1e3:.1f} ms' for k, v in delay_percentiles(hist).items())


def rss_mib() -> float:
    """Resident set size of this process [MiB] (Linux ``/proc/self/statm``)."""
    try:
        with open('/proc/self/statm') as f:
            return int(f.read().split()[1]) * os.sysconf('SC_PAGE_SIZE') / 2**20
    except (OSError, ValueError, IndexError):
        return math.nan


class _Usage:
    """CPU time and memory of the node process: RSS 5 s after start and at the end.

    Logged as one ``resources:`` line at a clean exit; ``bench/soak.py`` reads it to
    report memory growth over a long run.
    """

    def __init__(self, node: ParamNode) -> None:
        self.node = node
        self.rss_start = math.nan
        self._timer = node.create_timer(5.0, self._sample)

    def _sample(self) -> None:
        self.rss_start = rss_mib()
        self._timer.cancel()

    def report(self) -> None:
        cpu = time.process_time()
        self.node.get_logger().info(f'resources: cpu_s={cpu:.3f} rss_start_mib='
                                    f'{self.rss_start:.2f} rss_end_mib={rss_mib():.2f}')


class _Stop:
    """Set by SIGINT/SIGTERM; the spin loop polls it between callbacks."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal = 0

    def __call__(self, signum: int, frame: Any) -> None:  # noqa: ARG002 - signal API
        self.signal = signum
        self.event.set()


def run_node(factory: Callable[[], ParamNode], argv: Iterable[str] | None = None) -> int:
    """Create a node, spin it until SIGINT/SIGTERM or ``node.done``, shut down cleanly.

    rclpy's own signal handler would tear the context down under our feet (then a
    recorder could not drain its queue); we install ours and stop the loop ourselves.
    Returns the process exit status: 0 on a clean stop, 2 on a user error (printed as
    one line naming the parameter), never a traceback.
    """
    stop = _Stop()
    prog = Path(sys.argv[0]).stem
    try:
        rclpy.init(args=list(sys.argv if argv is None else argv),
                   signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:   # e.g. a missing or malformed --params-file
        print(f'{prog}: error: {str(exc).split(", at ")[0]}', file=sys.stderr)
        return 2
    signal.signal(signal.SIGINT, stop)
    signal.signal(signal.SIGTERM, stop)
    node = None
    executor = None
    clean = False
    status = 0
    try:
        node = factory()
        executor = rclpy.executors.SingleThreadedExecutor()
        executor.add_node(node)
        usage = _Usage(node)
        # everything allocated so far (numba, scipy, rclpy, the node) is long-lived: keep
        # it out of the collector's full passes, which otherwise cost the loop ~ms pauses
        gc.freeze()
        lean = LeanLoop(node)
        last = 0.0
        while not stop.event.is_set() and not node.done:
            ran = lean.spin_once(5_000_000)
            now = time.monotonic()
            if not ran or now - last > 0.005:   # services, parameter events, timers
                executor.spin_once(timeout_sec=0.0)
                last = now
        clean = True
    except (MotorCompError, rclpy.exceptions.ParameterException) as exc:
        print(f'{prog}: error: {exc}', file=sys.stderr)
        status = 2
    finally:
        if node is not None:
            try:
                node.finish(executor if clean else None)
                if clean:
                    usage.report()
            finally:
                node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    return status
