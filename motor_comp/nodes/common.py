"""Shared plumbing of the four nodes: parameter specs, QoS, stamps, the spin loop.

Nothing here is a control or physics law; the nodes convert messages to numbers and
call the core's step functions (DESIGN.md §2).  What lives here:

* :class:`Param` — one tunable with its unit, range and allowed values, turned into a
  ROS ``ParameterDescriptor`` (description with units, ``FloatingPointRange`` /
  ``IntegerRange``) and validated again in the node's ``on_set_parameters`` callback, so
  an invalid runtime update is rejected *with a reason* and the old value stays.
* :class:`Timing` — the two timing modes (lockstep on ``/clock``, realtime on wall timers).
* QoS profiles shared by publishers and subscribers so that they always match.
* :class:`ManagedNode` — the lifecycle (managed node) base of plant, controller and
  recorder: configure / activate / deactivate / cleanup / shutdown through the standard
  ``lifecycle_msgs`` services, ``autostart`` for ``ros2 run`` alone.
* :class:`LeanLoop` — the wait-set loop over the hot subscriptions and timers;
  :class:`Pacer` — lockstep publishing that never outruns a lagging reliable reader;
  :func:`read_joint_state` — stamp and values straight from JointState CDR bytes.
* :func:`run_node` — a spin loop with our own SIGINT/SIGTERM handling so that every node
  shuts down cleanly (and the recorder can flush) instead of dying inside a callback;
  every publisher's last samples are acknowledged before the process exits.
  ``MOTOR_COMP_PROFILE=DIR`` profiles the loop's CPU time (cProfile) per node.
"""
from __future__ import annotations

import dataclasses
import enum
import faulthandler
import gc
import math
import os
import signal
import struct
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
from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from rclpy.lifecycle.node import LifecycleNodeMixin
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.subscription import Subscription
from rclpy.timer import Timer

from motor_comp.errors import MotorCompError, ParameterError
from motor_comp.nodes import PARENT_ENV

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


_U32 = struct.Struct('<I')
_STAMP = struct.Struct('<iI')
_F64 = struct.Struct('<d')


#: JointState CDR layouts seen (one value per sequence), by message length: the value
#: offsets, the bytes around them that must match, one Struct for stamp + the three
#: values.  The loop's messages all share one layout; parsing it field by field cost
#: ≈ 25 µs per message (cProfile, controller node), the precompiled Struct ≈ 2 µs.
_JS_LAYOUTS: dict[int, tuple[Any, ...]] = {}


def _learn_layout(data: bytes, where: Sequence[int]) -> None:
    """Remember the layout of ``data`` whose three values start at ``where``."""
    p0, p1, p2 = where
    layout = struct.Struct(f'<iI{p0 - 12}xd{p1 - p0 - 8}xd{p2 - p1 - 8}xd')
    _JS_LAYOUTS[len(data)] = (p0, p1, p2, data[:4], data[12:p0], data[p0 + 8:p1],
                              data[p1 + 8:p2], layout)


def read_joint_state(msg: Any) -> tuple[int, float | None, float | None, float | None]:
    """Stamp [ns] and the first position, velocity, effort of a ``JointState``.

    ``msg`` is a message object or its serialized CDR bytes (a ``raw=True``
    subscription): the bytes are read directly — rclpy's deserialization builds four
    Python objects per message (JointState, Header, Time, lists) and took ≈ 1/3 of the
    controller's CPU per lockstep step.  A missing entry is None.  Layout (XCDR1,
    alignment relative to the body after the 4-byte encapsulation header): stamp
    int32 + uint32, frame_id string, name sequence<string>, then three
    sequence<double>.  Big-endian CDR is deserialized the ordinary way.
    """
    if isinstance(msg, (bytes, bytearray, memoryview)):
        data = bytes(msg)
        known = _JS_LAYOUTS.get(len(data))
        if known is not None:
            p0, p1, p2, head, mid0, mid1, mid2, layout = known
            # same length and the same bytes outside the stamp and the three values
            # (encapsulation, frame_id, names, sequence lengths): same offsets
            if (data[:4] == head and data[12:p0] == mid0 and data[p0 + 8:p1] == mid1
                    and data[p1 + 8:p2] == mid2):
                sec, nsec, pos, vel, eff = layout.unpack_from(data, 4)
                return sec * 1_000_000_000 + nsec, pos, vel, eff
        if data[1] != 1:   # not CDR_LE: rare, let rclpy do it
            from rclpy.serialization import deserialize_message
            from sensor_msgs.msg import JointState
            return read_joint_state(deserialize_message(data, JointState))
        sec, nsec = _STAMP.unpack_from(data, 4)
        off = 12 + _U32.unpack_from(data, 12)[0] + 4          # after frame_id
        off = ((off - 4 + 3) & ~3) + 4
        count = _U32.unpack_from(data, off)[0]
        off += 4
        for _ in range(count):                                  # names
            off = ((off - 4 + 3) & ~3) + 4
            off += 4 + _U32.unpack_from(data, off)[0]
        first: list[float | None] = []
        where: list[int] = []
        ones = True
        for _ in range(3):                                      # position, velocity, effort
            off = ((off - 4 + 3) & ~3) + 4
            count = _U32.unpack_from(data, off)[0]
            ones = ones and count == 1
            off += 4
            if count:
                off = ((off - 4 + 7) & ~7) + 4
                first.append(_F64.unpack_from(data, off)[0])
                where.append(off)
                off += 8 * count
            else:
                first.append(None)
        if ones and off == len(data) and len(_JS_LAYOUTS) < 64:
            _learn_layout(data, where)
        return sec * 1_000_000_000 + nsec, first[0], first[1], first[2]
    pos, vel, eff = msg.position, msg.velocity, msg.effort
    return (stamp_to_ns(msg.header.stamp), float(pos[0]) if len(pos) else None,
            float(vel[0]) if len(vel) else None, float(eff[0]) if len(eff) else None)


def read_float64(msg: Any) -> float:
    """Return the value of a ``std_msgs/Float64``, from the message or its CDR bytes.

    A ``raw=True`` subscription skips rclpy's deserialization into a message object
    (≈ 15 µs per message in the plant's lockstep step); CDR_LE puts the double right
    after the 4-byte encapsulation header.
    """
    if isinstance(msg, (bytes, bytearray, memoryview)):
        data = bytes(msg)
        if len(data) >= 12 and data[1] == 1:
            return _F64.unpack_from(data, 4)[0]
        from rclpy.serialization import deserialize_message
        from std_msgs.msg import Float64
        return float(deserialize_message(data, Float64).data)
    return float(msg.data)


def read_clock_ns(msg: Any) -> int:
    """Return the time of a ``rosgraph_msgs/Clock`` [ns], from the message or its CDR bytes."""
    if isinstance(msg, (bytes, bytearray, memoryview)):
        data = bytes(msg)
        if len(data) >= 12 and data[1] == 1:
            sec, nsec = _STAMP.unpack_from(data, 4)
            return sec * 1_000_000_000 + nsec
        from rclpy.serialization import deserialize_message
        from rosgraph_msgs.msg import Clock
        return stamp_to_ns(deserialize_message(data, Clock).clock)
    return stamp_to_ns(msg.clock)


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
    allow_inf : bool
        ``±inf`` is a value (a limit's "no limit"); NaN never is.
    """

    name: str
    default: bool | int | float | str | tuple[float, ...]
    description: str
    unit: str = ''
    low: float | None = None
    high: float | None = None
    choices: tuple[str, ...] = ()
    read_only: bool = False
    allow_inf: bool = False

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
                value == math.inf and self.high == math.inf) and not (
                self.allow_inf and not math.isnan(value)):   # e.g. u_max = inf: no limit
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


#: shared by the nodes that read files their parameters name (param_files rules)
MODEL_DIR = Param(
    'model_dir', '', 'Directories the file parameters of this node may name, '
    '":"-separated; a path outside them (symbolic links followed) is refused without '
    'being opened, and only regular files under 16 MiB are read. Empty = the working '
    'directory and the package config/', read_only=True)

#: the motion limits (:mod:`motor_comp.control.limits`), shared by the trajectory node
#: (which refuses a reference beyond them) and the controller (which trips on them).
#: Read-only: a safety limit is fixed when the node starts, never loosened from the graph
MOTION_LIMITS = (
    Param('travel', (-math.inf, math.inf), 'Travel limits [min, max] of the position '
          '(-inf/inf = none)', 'm or rad', read_only=True, allow_inf=True),
    Param('vmax', math.inf, 'Speed limit |v| (inf = none)', 'm/s or rad/s', 1e-12,
          math.inf, read_only=True),
    Param('amax', math.inf, 'Acceleration limit |a| (inf = none)', 'm/s^2 or rad/s^2',
          1e-12, math.inf, read_only=True),
)


#: nodes that publish on /diagnostics (monitor, controller with limits): who must hear
#: them before the loop starts (the recorder), as the loop's own writers wait for theirs
DIAGNOSTICS_READERS = Param(
    'diagnostics_readers', 0, 'Readers of /diagnostics (e.g. the recorder) that must have '
    'matched this node\'s status writer before it joins the loop, so none misses a status '
    '(after 10 s it goes on with a warning)', '', 0, 100, read_only=True)


def limits_from(p: Mapping[str, Any]) -> Any:
    """Return the :class:`~motor_comp.control.limits.Limits` of a node's parameters.

    Raises :class:`ParameterError` for an invalid travel (``min < max``) or bound.
    """
    from motor_comp.control.limits import Limits
    return Limits(travel=p['travel'], vmax=p['vmax'], amax=p['amax'],
                  umax=p.get('umax', math.inf), max_error=p.get('max_error', math.inf))


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
    #: a reader off the loop's critical path (the recorder) pauses this long [s] after
    #: each productive wait and then takes what queued meanwhile in one go (see run_node)
    batch_pause: float = 0.0
    #: most messages :class:`LeanLoop` takes from one subscription per wait; 1 keeps the
    #: arrival order across topics (a realtime recorder or monitor pairs a command with
    #: the newest measurement *taken*, so a burst of one topic first would shift it)
    take_burst: int = 64
    #: process exit status after a clean stop (0; the controller's limit trip: 3) and
    #: the one line :func:`run_node` prints with it (``<node>: error: <exit_reason>``)
    exit_status: int = 0
    exit_reason: str = ''

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

    @property
    def file_dirs(self) -> tuple[Path, ...]:
        """Return the directories the node's file parameters may name (``model_dir``)."""
        from motor_comp.param_files import parse_dirs
        dirs = getattr(self, '_file_dirs', None)
        if dirs is None:   # resolved once: a later chdir cannot widen them
            dirs = self._file_dirs = parse_dirs(self.p['model_dir'])
        return dirs

    def finish(self, executor: rclpy.executors.Executor | None) -> None:
        """Run once on shutdown before the node is destroyed (drain, flush files).

        ``executor`` is None after an error: do not spin, just release resources.
        """

    @property
    def done(self) -> bool:
        """True when the node has finished its job and the process may exit."""
        return False


#: shared by the managed nodes (plant, controller, recorder)
AUTOSTART = Param(
    'autostart', True, 'Managed node: configure and activate at start, so `ros2 run` '
    'alone runs the loop; false = wait in unconfigured for lifecycle transitions '
    '(<node>/change_state), as a lifecycle manager drives them', read_only=True)


class ManagedNode(ParamNode, LifecycleNode):
    """A :class:`ParamNode` that is a ROS 2 managed (lifecycle) node.

    unconfigured → ``configure`` → inactive → ``activate`` → active → ``deactivate`` →
    inactive → ``cleanup`` → unconfigured, and ``shutdown`` from any of them, through
    the standard ``lifecycle_msgs`` services ``<node>/change_state`` and
    ``<node>/get_state`` (as ros2_control hardware and Nav2 servers are driven).
    Subclasses implement :meth:`configure`, :meth:`activate`, :meth:`deactivate` and
    :meth:`cleanup`; raising :class:`MotorCompError` there fails the transition with
    the reason logged (the node stays in its state, or returns to unconfigured after a
    failed configure, as the lifecycle design says).  With ``autostart`` (default) the
    node configures and activates itself at start; a failure is then the process's
    one-line error (exit status 2).

    Parameters (and their validation) exist in every state; the loop's topics are
    subscribed only while active, so a plant waiting for its peers does not start a
    run that an inactive controller or recorder would miss.
    """

    def __init__(self, name: str, **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        self._transition_error: Exception | None = None

    def autostart(self) -> None:
        """Configure and activate now if ``autostart`` is set (call after declare_params)."""
        self.declare_params([AUTOSTART])
        if not self.p['autostart']:
            self.get_logger().info('managed node: unconfigured, waiting for lifecycle '
                                   'transitions (autostart false)')
            return
        for trigger in (self.trigger_configure, self.trigger_activate):
            if trigger() != TransitionCallbackReturn.SUCCESS:
                err = self._transition_error
                raise err if isinstance(err, MotorCompError) else MotorCompError(str(err))

    @property
    def lifecycle_state(self) -> str:
        """Label of the current lifecycle state (``unconfigured``, ``active`` …)."""
        return self._state_machine.current_state[1]

    @property
    def active(self) -> bool:
        """True in the ``active`` state."""
        return self._state_machine.current_state[1] == 'active'

    def _transition(self, name: str, step: Callable[[], None]) -> TransitionCallbackReturn:
        self._transition_error = None
        try:
            step()
        except (MotorCompError, rclpy.exceptions.ParameterException, OSError) as exc:
            self._transition_error = exc
            self.get_logger().error(f'{name} failed: {exc}')
            return TransitionCallbackReturn.FAILURE
        self.get_logger().info(f'lifecycle: {name} done')
        return TransitionCallbackReturn.SUCCESS

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Lifecycle callback: build what the node needs (see :meth:`configure`)."""
        return self._transition('configure', self.configure)

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Lifecycle callback: join the loop (see :meth:`activate`)."""
        LifecycleNode.on_activate(self, state)   # lifecycle publishers, if any
        return self._transition('activate', self.activate)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Lifecycle callback: leave the loop (see :meth:`deactivate`)."""
        LifecycleNode.on_deactivate(self, state)
        return self._transition('deactivate', self.deactivate)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Lifecycle callback: release what configure built (see :meth:`cleanup`)."""
        return self._transition('cleanup', self.cleanup)

    def on_shutdown(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Lifecycle callback: from any state, leave the loop and release everything."""
        def down() -> None:
            if state.label == 'active':
                self.deactivate()
            if state.label in ('active', 'inactive'):
                self.cleanup()
        return self._transition('shutdown', down)

    def on_error(self, state: LifecycleState) -> TransitionCallbackReturn:
        """Lifecycle callback after an exception in a transition: release, unconfigured."""
        self.get_logger().error(f'lifecycle error in {state.label}: releasing resources')
        try:
            self.deactivate()
            self.cleanup()
        except Exception as exc:  # noqa: BLE001 - best effort on the error path
            self.get_logger().error(f'cleanup after error failed: {exc}')
        return TransitionCallbackReturn.SUCCESS

    def _LifecycleNodeMixin__on_change_state(self, req: Any, resp: Any) -> Any:
        """``<node>/change_state``: an unavailable transition is refused, not a crash.

        rclpy raises from the service callback when the transition does not exist in
        the current state (e.g. ``activate`` while unconfigured), which would end the
        node's spin loop; here it is answered ``success: false`` with the reason logged.
        """
        available = self._state_machine.available_transitions
        label, tid = req.transition.label, req.transition.id
        if not any((t[1] == label) if label else (t[0] == tid) for t in available):
            self.get_logger().warning(
                f'refused lifecycle transition {label or f"id {tid}"}: not available in '
                f'state {self.lifecycle_state} (available: '
                f'{", ".join(t[1] for t in available) or "none"})')
            resp.success = False
            return resp
        try:
            return LifecycleNodeMixin._LifecycleNodeMixin__on_change_state(self, req, resp)
        except RCLError as exc:   # a race with a transition of our own
            self.get_logger().warning(f'refused lifecycle transition: {exc}')
            resp.success = False
            return resp

    def configure(self) -> None:
        """Build the node's state from its parameters (raise MotorCompError to refuse)."""

    def activate(self) -> None:
        """Subscribe the loop's topics and start working."""

    def deactivate(self) -> None:
        """Stop working: unsubscribe, stop timers (must be safe to call when inactive)."""

    def cleanup(self) -> None:
        """Release what :meth:`configure` built (must be safe to call when unconfigured)."""

    def destroy_hot(self, entity: Any) -> None:
        """Unmark and destroy a hot subscription or timer (None is ignored)."""
        if entity is None:
            return
        for kind in (getattr(self, 'hot_subscriptions', []), getattr(self, 'hot_timers', [])):
            if entity in kind:
                kind.remove(entity)
        if isinstance(entity, Timer):
            self.destroy_timer(entity)
        else:
            self.destroy_subscription(entity)


def take_newest(sub: Any, msg: Any, info: Any = None) -> tuple[Any, Any, int]:
    """Return the newest message queued behind ``msg`` on ``sub``, its info, how many skipped.

    A realtime reader wants the latest sample, not the oldest queued one: a lean loop
    takes one message per wake-up, so a backlog built up during a stall (a slow start)
    drains only as fast as new samples arrive — never, at a steady rate.  ``info`` is the
    message info of ``msg`` (reception time …), replaced by that of the newest.
    """
    skipped = 0
    while True:
        taken = sub.handle.take_message(sub.msg_type, sub.raw)
        if taken is None:
            return msg, info, skipped
        msg, info = taken[0], taken[1]
        skipped += 1


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

    @property
    def empty(self) -> bool:
        """True when the node has no hot entity (e.g. a managed node not yet active)."""
        return not (getattr(self.node, 'hot_subscriptions', None)
                    or getattr(self.node, 'hot_timers', None))

    def spin_once(self, timeout_ns: int) -> int:
        """Wait up to ``timeout_ns`` for hot entities; run their callbacks; how many ran.

        With no hot entity there is nothing to wait on: returns 0 at once.
        """
        subs = getattr(self.node, 'hot_subscriptions', ())
        timers = getattr(self.node, 'hot_timers', ())
        if not subs and not timers:
            return 0
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
        burst = getattr(self.node, 'take_burst', 1)
        for i, sub in enumerate(subs):
            if ws.is_ready('subscription', i):
                # everything queued (up to the node's take_burst), not one message per
                # wait: a reader that fell behind (the lockstep recorder on a loaded
                # machine) catches up without a wait-set round (clear, add, rcl_wait,
                # wake-up) per message.  Bounded, so the other entities and the
                # executor's services still get their turn.
                take, msg_type, raw, callback = (sub.handle.take_message, sub.msg_type,
                                                 sub.raw, sub.callback)
                # a callback with two parameters gets the message info too (source and
                # reception timestamps, sequence numbers), as the executor gives it
                info = sub._callback_type is Subscription.CallbackType.WithMessageInfo
                for _ in range(burst):
                    taken = take(msg_type, raw)
                    if taken is None:
                        break
                    if info:
                        callback(taken[0], taken[1])
                    else:
                        callback(taken[0])
                    ran += 1
                    if getattr(self.node, 'done', False):
                        # a node that finished runs no more callbacks: in lockstep the
                        # peer answers within the burst (a tripped controller published
                        # 10 commands past its hold on a loaded CI machine)
                        return ran
        for j, tmr in enumerate(timers):
            if ws.is_ready('timer', j) and tmr.handle.is_timer_ready():
                tmr.handle.call_timer()
                tmr.callback()
                ran += 1
        return ran


class Pacer:
    """Lockstep publishing that never outruns a reliable reader by a publisher's history.

    The loop's publishers keep the last :data:`LOOP_QOS` depth (1000) samples; a reader
    that falls further behind (the recorder, starved of CPU on a loaded machine) loses
    the oldest — measured: a 600 s lockstep soak with the machine at load 13 recorded
    591 502 of 600 000 steps.  Every ``every`` messages the publisher waits until every
    matched reader acknowledged what it has sent (``wait_for_all_acked``, at most
    ``timeout`` s, then it goes on: a reader that died is dropped by DDS later).  When
    the readers keep up the wait returns at once; when one lags, the lockstep loop runs
    at its pace instead of losing its data.  Not for realtime: a wall-clock loop must
    not wait for a recorder.

    ``every`` defaults to the history depth, which is both enough (a sample can only be
    overwritten once ``depth`` newer ones were published, and all older ones were
    acknowledged at the last wait) and fast: Fast DDS (2.14) readers acknowledge on the
    writer's heartbeats, and until its history is full a writer heartbeats only every
    3 s — measured (``wait_for_all_acked`` after N samples, one reader, depth 1000):
    2.5–3.0 s per wait before the history first fills, 1–5 ms once it is full (an
    overwrite announces itself at once).  With ``every`` = 500 the first wait of every
    run sat out its 1 s timeout: 1 s of a 3.4 s, 5000-step lockstep run.
    """

    def __init__(self, publisher: Any, *, every: int | None = None,
                 timeout: float = 1.0) -> None:
        from rclpy.duration import Duration
        self.publisher = publisher
        self.every = every if every is not None else publisher.qos_profile.depth
        self._timeout = Duration(nanoseconds=int(timeout * 1e9))
        self._n = 0
        self.waits = 0          # waits that ran into the timeout
        self.paced = 0          # waits
        self.wait_s = 0.0       # wall time spent waiting [s]

    def publish(self, msg: Any) -> None:
        """Publish; every ``every`` messages wait for the readers' acknowledgements."""
        self.publisher.publish(msg)
        self._n += 1
        if self._n % self.every == 0:
            t0 = time.perf_counter()
            if not self.publisher.wait_for_all_acked(self._timeout):
                self.waits += 1
            self.paced += 1
            self.wait_s += time.perf_counter() - t0


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
        #: CPU time [s] and hot callbacks since the first hot callback (the loop's cost,
        #: without start-up: imports and numba cache loads vary from start to start)
        self.loop_cpu0: float | None = None
        self.callbacks = 0

    def _sample(self) -> None:
        self.rss_start = rss_mib()
        self._timer.cancel()

    def report(self) -> None:
        cpu = time.process_time()
        loop = cpu - self.loop_cpu0 if self.loop_cpu0 is not None else 0.0
        self.node.get_logger().info(f'resources: cpu_s={cpu:.3f} rss_start_mib='
                                    f'{self.rss_start:.2f} rss_end_mib={rss_mib():.2f} '
                                    f'loop_cpu_s={loop:.3f} callbacks={self.callbacks}')


def _profiler(node: Node) -> Any:
    """Diagnostics: with ``MOTOR_COMP_PROFILE=DIR`` profile the spin loop (cProfile).

    The stats go to ``DIR/<node name>.prof`` at a clean exit (``bench/ros_loop.py
    --profile DIR`` prints where the loop's time goes).
    """
    where = os.environ.get('MOTOR_COMP_PROFILE')
    if not where:
        return None
    import cProfile
    profile = cProfile.Profile(time.process_time)   # CPU, not waiting
    profile.path = str(Path(where) / f'{node.get_name()}.prof')
    profile.enable()
    return profile


class _Stop:
    """Set by SIGINT/SIGTERM; the spin loop polls it between callbacks."""

    def __init__(self) -> None:
        self.event = threading.Event()
        self.signal = 0

    def __call__(self, signum: int, frame: Any) -> None:  # noqa: ARG002 - signal API
        self.signal = signum
        self.event.set()


def _parent_to_watch() -> int | None:
    try:
        return int(os.environ[PARENT_ENV])
    except (KeyError, ValueError):
        return None


def _orphaned(node: Node, parent: int | None) -> bool:
    """Whether the process that started this node (``PARENT_ENV``) is gone."""
    if parent is None or os.getppid() == parent:
        return False
    node.get_logger().warning(f'the process that started this node ({parent}) is gone: '
                              'stopping')
    return True


#: how often the spin loop lets rclpy's executor serve the non-hot entities (parameter
#: services, lifecycle services, start-up timers): their response time [ns]
EXECUTOR_PERIOD_NS = 50_000_000


def _wait_acked(node: Node, timeout: float = 4.0) -> None:
    """Let every reliable reader receive what this node published before it exits.

    A process that exits right after its last publish takes the samples its readers
    have not acknowledged with it: on a loaded machine a starved recorder then misses
    the controller's last commands (a realtime run recorded 934 of 1000 steps).  A
    sample a reader lost is sent again at the writer's next heartbeat, every 3 s in
    Fast DDS while its history is not full (:class:`Pacer`), so the wait outlasts one
    (it was 2 s: a lockstep run that tripped at step 481 recorded 209 of its 534
    commands, once, in a loaded CI run).
    """
    from rclpy.duration import Duration
    deadline = time.monotonic() + timeout
    for pub in list(node.publishers):
        left = deadline - time.monotonic()
        if left <= 0:
            break
        try:
            pub.wait_for_all_acked(Duration(nanoseconds=int(left * 1e9)))
        except (RCLError, rclpy.exceptions.InvalidHandle):
            pass   # a publisher destroyed by the node's own finish()


def run_node(factory: Callable[[], ParamNode], argv: Iterable[str] | None = None) -> int:
    """Create a node, spin it until SIGINT/SIGTERM or ``node.done``, shut down cleanly.

    rclpy's own signal handler would tear the context down under our feet (then a
    recorder could not drain its queue); we install ours and stop the loop ourselves.
    Returns the process exit status: 0 on a clean stop, 2 on a user error (printed as
    one line naming the parameter), the node's ``exit_status`` with its one-line
    ``exit_reason`` (a limit trip of the controller: 3), never a traceback.
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
    # a stop that hangs is diagnosable: NodeGroup.stop sends SIGABRT before SIGKILL,
    # and this prints every thread's Python stack to the node's log first
    faulthandler.enable()
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
        parent = _parent_to_watch()
        profile = _profiler(node)
        while not stop.event.is_set() and not node.done:
            if lean.empty:   # inactive managed node: only services and timers to serve
                executor.spin_once(timeout_sec=0.005)
                if _orphaned(node, parent):
                    stop.event.set()
                continue
            ran = lean.spin_once(EXECUTOR_PERIOD_NS)
            if ran:
                if usage.loop_cpu0 is None:
                    usage.loop_cpu0 = time.process_time()
                usage.callbacks += ran
                if node.batch_pause > 0.0:
                    # batches instead of a wake-up per message: on the 2-core machine the
                    # loop is CPU-bound across its processes, and each wake-up of a reader
                    # off the critical path takes CPU from the ones on it
                    stop.event.wait(node.batch_pause)
            now = time.monotonic()
            # services, parameter events, other timers: every EXECUTOR_PERIOD_NS, not
            # after each idle wait — a loaded machine makes the lean wait time out often,
            # and rclpy's spin_once (it rebuilds its wait set, tasks, generators) then
            # took half of a loop process's CPU (cProfile on CPU time, bench/ros_loop.py
            # --profile)
            if now - last > EXECUTOR_PERIOD_NS * 1e-9:
                executor.spin_once(timeout_sec=0.0)
                last = now
                if _orphaned(node, parent):
                    stop.event.set()
        clean = True
        why = (signal.Signals(stop.signal).name if stop.signal
               else 'parent gone' if stop.event.is_set() else 'done')
        node.get_logger().info(f'stopping ({why})')
        status = node.exit_status   # e.g. 3: a limit trip (its line is printed last)
        if profile is not None:
            profile.disable()
            try:
                profile.dump_stats(profile.path)
            except OSError as exc:
                print(f'{prog}: warning: MOTOR_COMP_PROFILE: cannot write {profile.path} '
                      f'({exc.strerror})', file=sys.stderr)
    except (MotorCompError, rclpy.exceptions.ParameterException) as exc:
        print(f'{prog}: error: {exc}', file=sys.stderr)
        status = 2
    finally:
        if node is not None:
            try:
                node.finish(executor if clean else None)
                if clean:
                    _wait_acked(node)
                    usage.report()
            finally:
                node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()
    if clean and status:
        print(f'{prog}: error: {node.exit_reason}', file=sys.stderr, flush=True)
    return status
