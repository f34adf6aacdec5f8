"""``monitor_node``: a model's force residual online → ``/diagnostics``.

A thin adapter over :func:`motor_comp.workbench.monitor.window_health` (the workbench's
own inverse model, :mod:`motor_comp.workbench.residual`): subscribes
``<ns>/joint_states`` (measured position) and ``<ns>/voltage`` (the drive input), keeps
the last ``window`` seconds (stamps of the measurements; each command is paired with
the measurement it answers), and every ``update_period`` seconds of stamp time judges
the model file ``model`` on that window.  Publishes ``diagnostic_msgs/DiagnosticArray``
on ``/diagnostics`` (the ROS standard topic, read by ``rqt_robot_monitor``, the
diagnostic aggregator, Foxglove) with one ``DiagnosticStatus``:

* level OK / WARN / ERROR by the windowed force NRMSE against ``warn_nrmse`` /
  ``error_nrmse`` (STALE while the axis did not move enough to judge);
* key-values ``force_nrmse``, ``rms_residual_N`` (``rms_residual_N·m`` on a rotary
  axis), ``samples``, ``window_s``, ``window_end_s`` (stamp of the newest sample), and
  when not OK the ``candidate`` effect that would
  explain the residual (``changed`` or ``missing``), the share it ``explains`` and its
  fitted ``change``.

The array's header is stamped with ``window_end_s`` (the newest measurement's stamp:
sim time in lockstep), so a recording logs each verdict beside the samples it judged.

Every parameter but ``timing`` and ``model_dir`` is live: a new ``model`` is loaded and
validated (a bad file is rejected with the reason and the old model stays); thresholds
must keep ``0 < warn_nrmse < error_nrmse``.  Level changes are logged.  The model file
is read under :mod:`motor_comp.param_files`: only inside ``model_dir``, only a regular
file under a size bound, and a rejection reason (returned to the caller and logged, so
on ``/rosout``) never quotes the file.
"""
from __future__ import annotations

import collections
import json
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from motor_comp import param_files
from motor_comp.errors import ParameterError
from motor_comp.nodes.common import DEFAULT_NAMESPACE, DIAGNOSTICS_READERS, MODEL_DIR, \
    RECORD_QOS, TOPIC_JOINT_STATES, TOPIC_VOLTAGE, Param, ParamNode, run_node, set_stamp, \
    stamp_to_ns
from motor_comp.physics.axis import AxisModel
from motor_comp.workbench.monitor import Health, Level, check_thresholds, window_health

PARAMS = (
    Param('model', '', 'Model file (YAML, DESIGN.md §6) whose force residual is watched'),
    Param('window', 2.0, 'Sliding window of the residual (stamp time)', 's', 0.1, 600.0),
    Param('update_period', 0.5, 'A verdict every this much stamp time', 's', 0.01, 600.0),
    Param('warn_nrmse', 0.15, 'Force NRMSE from which the level is WARN', '', 1e-4, 100.0),
    Param('error_nrmse', 0.5, 'Force NRMSE from which the level is ERROR', '', 1e-4, 100.0),
    Param('timing', 'lockstep', 'How commands pair with measurements: lockstep (the k-th '
          'command answers the k-th measurement) or realtime (the newest one)',
          choices=('lockstep', 'realtime'), read_only=True),
    MODEL_DIR,
    DIAGNOSTICS_READERS,
)

#: how long the monitor waits for its /diagnostics readers before joining anyway [s]
MATCH_TIMEOUT = 10.0

#: /diagnostics: the ROS convention (reliable, volatile, shallow)
DIAG_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE)

_LEVEL_BYTES = {Level.OK: DiagnosticStatus.OK, Level.WARN: DiagnosticStatus.WARN,
                Level.ERROR: DiagnosticStatus.ERROR, Level.STALE: DiagnosticStatus.STALE}


def load_model(path: str, dirs: Sequence[Path]) -> AxisModel:
    """Load the watched model from inside ``dirs``; an empty path names the parameter."""
    if not path.strip():
        raise ParameterError('model: a model file (YAML) is required')
    return param_files.load_model('model', path, dirs)[1]


def diagnostic_status(health: Health, *, name: str, hardware_id: str, window: float,
                      window_end: float, force_unit: str) -> DiagnosticStatus:
    """Build the ``DiagnosticStatus`` of one verdict (level, message, key-values)."""
    st = DiagnosticStatus()
    st.level = _LEVEL_BYTES[health.level]
    st.name = name
    st.hardware_id = hardware_id
    st.message = health.message
    kv = [('force_nrmse', f'{health.nrmse:.6g}'),
          (f'rms_residual_{force_unit}', f'{health.rms_residual:.6g}'),
          ('samples', str(health.samples)), ('window_s', f'{window:g}'),
          ('window_end_s', f'{window_end:.6f}')]
    c = health.candidate
    if c is not None:
        kv += [('candidate', c.effect), ('candidate_title', c.title),
               ('candidate_status', c.status), ('candidate_explains', f'{c.explained:.3f}'),
               ('candidate_change', json.dumps(c.change))]
    st.values = [KeyValue(key=k, value=v) for k, v in kv]
    return st


class MonitorNode(ParamNode):
    """Judges a model on the live axis over a sliding window."""

    def __init__(self) -> None:
        super().__init__('monitor_node', namespace=DEFAULT_NAMESPACE)
        self.declare_params(PARAMS)
        check_thresholds(self.p['warn_nrmse'], self.p['error_nrmse'])
        self.model = load_model(self.p['model'], self.file_dirs)
        self._samples: collections.deque = collections.deque()
        # lockstep: measurements waiting for their command and commands that overtook
        # their measurement (two writers: arrival order across topics is not defined)
        self._pending: collections.deque = collections.deque()
        self._early: collections.deque = collections.deque()
        self._lockstep = self.p['timing'] == 'lockstep'
        if not self._lockstep:   # pairs with the newest measurement taken: arrival order
            self.take_burst = 1
        self._last_eval: float | None = None
        self.level: Level | None = None
        self.verdicts = 0
        self.pub = self.create_publisher(DiagnosticArray, '/diagnostics', DIAG_QOS)
        ns = self.get_namespace().strip('/') or DEFAULT_NAMESPACE
        self.status_name = f'motor_comp/{ns}: model monitor'
        self.hardware_id = ns
        # compile/load the residual's kernels before subscribing: messages queued during
        # a long first compilation could overflow one topic's queue and not the other's
        t = np.arange(400) * 1e-3
        window_health(t, 0.01 * np.sin(2 * np.pi * t), np.zeros_like(t), self.model)
        # served by the nodes' lean loop (common.run_node), like the loop's own topics;
        # every sample, like the recorder (KEEP_ALL): a sample lost on one topic and not
        # on the other would shift the command/measurement pairing for good.  So, like
        # the recorder, joint_states is subscribed only once the controller's voltage
        # writer is matched: a lockstep plant waits for this reader, and its first
        # commands could otherwise go out before the voltage writer knows this node.
        self._volt_sub = self.mark_hot(self.create_subscription(
            Float64, TOPIC_VOLTAGE, self._on_command, RECORD_QOS))
        self._js_sub = None
        self._since = time.monotonic()
        self._match_timer = self.create_timer(0.05, self._subscribe_joint_states)
        self.get_logger().info(f'watching {self.p["model"]} over {self.p["window"]:g} s '
                               f'(WARN from NRMSE {self.p["warn_nrmse"]:g}, ERROR from '
                               f'{self.p["error_nrmse"]:g})')

    def _subscribe_joint_states(self) -> None:
        if self._volt_sub.get_publisher_count() < 1:
            return
        # our verdicts' readers (the recorder) too: the plant starts when it sees our
        # joint_states reader, and a volatile reader misses what came before its match
        need = self.p['diagnostics_readers']
        if self.pub.get_subscription_count() < need:
            if time.monotonic() - self._since < MATCH_TIMEOUT:
                return
            self.get_logger().warning(f'{self.pub.get_subscription_count()} of {need} '
                                      f'/diagnostics readers after {MATCH_TIMEOUT:g} s: '
                                      'joining the loop anyway')
        self.destroy_timer(self._match_timer)
        self._match_timer = None
        self._js_sub = self.mark_hot(self.create_subscription(
            JointState, TOPIC_JOINT_STATES, self._on_measurement, RECORD_QOS))

    # -- messages --------------------------------------------------------------------
    def _on_measurement(self, msg: JointState) -> None:
        if not len(msg.position):
            return
        y = float(msg.position[0])
        if not np.isfinite(y):
            return
        sample = (stamp_to_ns(msg.header.stamp) * 1e-9, y)
        if not self._lockstep:
            self._pending.clear()   # realtime: the controller answers the newest
        elif self._early:
            self._add(sample, self._early.popleft())
            return
        elif len(self._pending) > 1000:   # commands stopped: start over
            self._pending.clear()
        self._pending.append(sample)

    def _on_command(self, msg: Float64) -> None:
        # lockstep: the k-th command answers the k-th measurement (the recorder's rule);
        # realtime: the newest measurement, as the controller node answers it
        if not np.isfinite(msg.data):
            return
        if self._pending:
            self._add(self._pending.popleft(), float(msg.data))
        elif self._lockstep and len(self._early) < 1000:
            self._early.append(float(msg.data))

    def _add(self, sample: tuple[float, float], u: float) -> None:
        t, y = sample
        s = self._samples
        if s and t <= s[-1][0]:
            self.get_logger().warning(f'measurement stamp went back from {s[-1][0]:.6f} to '
                                      f'{t:.6f} s: a new run, window cleared')
            s.clear()
        elif self._lockstep and len(s) > 2 and t - s[-1][0] > 1.5 * (s[-1][0] - s[-2][0]):
            # a lost sample: which command answers which measurement is no longer known
            self.get_logger().warning(f'gap in the measurements ({s[-1][0]:.6f} -> {t:.6f} '
                                      f's): window and pairing restarted',
                                      throttle_duration_sec=1.0)
            s.clear()
            self._pending.clear()
            self._early.clear()
            return
        s.append((t, y, u))
        window = self.p['window']
        while s and s[0][0] < t - window:
            s.popleft()
        if self._last_eval is None or t < self._last_eval:
            self._last_eval = t
        if t - self._last_eval >= self.p['update_period']:
            self._last_eval = t
            self._judge()

    def _judge(self) -> None:
        data = np.array(self._samples)
        health = window_health(data[:, 0], data[:, 1], data[:, 2], self.model,
                               warn=self.p['warn_nrmse'], error=self.p['error_nrmse'])
        arr = DiagnosticArray()
        set_stamp(arr.header.stamp, int(round(data[-1, 0] * 1e9)))   # the window's end
        arr.status = [diagnostic_status(health, name=self.status_name,
                                        hardware_id=self.hardware_id,
                                        window=self.p['window'], window_end=data[-1, 0],
                                        force_unit=self.model.units.force)]
        self.pub.publish(arr)
        self.verdicts += 1
        if health.level != self.level:
            self.get_logger().info(f'level {self.level.name if self.level is not None else "-"}'
                                   f' -> {health.level.name} at t = {data[-1, 0]:.3f} s: '
                                   f'{health.message}')
            self.level = health.level

    # -- parameters ------------------------------------------------------------------
    def apply_params(self, changed: Mapping[str, Any], new: Mapping[str, Any]) -> None:
        """Validate thresholds and a new model file before anything changes."""
        check_thresholds(new['warn_nrmse'], new['error_nrmse'])
        if 'model' in changed:
            model = load_model(new['model'], self.file_dirs)   # bad: the old one stays
            self.model = model
            self.get_logger().info(f'now watching {new["model"]}')


def main(args: list[str] | None = None) -> int:
    """Console entry point ``monitor_node``."""
    return run_node(MonitorNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
