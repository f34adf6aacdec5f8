"""``controller_node``: PID | adaptive sliding | N-PID with friction feedforward.

A thin adapter over :class:`motor_comp.control.controller.Controller`: each command is
``Controller.step`` — the same compiled ``controller_step`` the in-process simulator
loops over — on the reference (``<ns>/reference``: position [m], velocity [m/s],
effort = acceleration [m/s²]) and the measurement (``<ns>/joint_states``).  Publishes
the command [V] on ``<ns>/voltage``; saturation ±``<mode>.u_max`` is part of the law.

Timing.  Lockstep: the command for step k is computed when both the measurement and
the reference stamped t_k have arrived (in either order), exactly one command per
measurement.  Realtime: one command per measurement, on the latest reference.

Reliability (issue 8):

* stale data — if the reference or the measurement has not arrived for
  ``stale_timeout`` [s] of wall time the node commands 0 V with a warning until fresh
  data returns (lockstep: the waiting measurement is answered with 0 V so the plant is
  not left hanging, and later ones too until a reference arrives again);
* non-finite numbers in a message are ignored (never passed to the law, counted);
* ``mode`` and ``feedforward`` switch at run time bumplessly
  (``Controller.set_mode/set_feedforward``), adaptive estimates kept or reset according
  to ``keep_estimates``;
* every gain ``<mode>.<field>`` (units and ranges from the control module) is live
  tunable; an invalid value is rejected with the reason and nothing changes.
"""
from __future__ import annotations

import dataclasses
import math
import time
from typing import Any, Mapping

from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from motor_comp.control.controller import ControlMode, Feedforward, default_params, \
    make_controller
from motor_comp.errors import ParameterError
from motor_comp.nodes.common import DEFAULT_NAMESPACE, LOOP_QOS, Param, ParamNode, SUB_QOS, \
    TOPIC_JOINT_STATES, TOPIC_REFERENCE, TOPIC_VOLTAGE, Timing, run_node, stamp_to_ns
from motor_comp.physics.config import PlantConfig, load_plant

BASE_PARAMS = (
    Param('plant', 'pmlm', 'Nominal plant: pmlm, ballscrew, or a plant YAML file',
          read_only=True),
    Param('mode', 'pid', 'Control law', choices=tuple(m.label for m in ControlMode)),
    Param('feedforward', 'none', 'Friction feedforward from the reference velocity',
          choices=('none', 'static', 'gms', 'static+gms')),
    Param('keep_estimates', True, 'Keep the adaptive estimates when the mode changes'),
    Param('timing', 'lockstep', 'Timing mode', choices=('lockstep', 'realtime'),
          read_only=True),
    Param('control_rate', 1000.0, 'Control rate (the law uses dt = 1/rate)', 'Hz', 1.0,
          100_000.0, read_only=True),
    Param('stale_timeout', 0.5, 'Command 0 V when reference or measurement is older',
          's', 1e-3, 60.0),
)


def gain_params(plant: PlantConfig) -> tuple[Param, ...]:
    """``<mode>.<field>`` for every mode, with the plant's defaults, units and ranges."""
    out = []
    for mode in ControlMode:
        defaults = default_params(mode, plant)
        for f in defaults.fields_with_ranges():
            out.append(Param(f'{mode.label}.{f.name}', float(getattr(defaults, f.name)),
                             f'{mode.label}: {f.description}', f.unit, f.min, f.max))
    return tuple(out)


class ControllerNode(ParamNode):
    """Computes one command per measurement with the core controller step."""

    def __init__(self) -> None:
        super().__init__('controller_node', namespace=DEFAULT_NAMESPACE)
        self.declare_params(BASE_PARAMS)
        cfg = load_plant(self.p['plant'])
        self.declare_params(gain_params(cfg))   # defaults depend on the plant
        self.cfg = dataclasses.replace(cfg, control_rate=self.p['control_rate'])
        self.timing = Timing(self.p['timing'])
        self.dt = 1.0 / self.p['control_rate']
        mode = self.p['mode']
        gains = {k.split('.', 1)[1]: v for k, v in self.p.items()
                 if k.startswith(mode + '.')}
        self.controller = make_controller(mode, plant=self.cfg,
                                          feedforward=self.p['feedforward'], **gains)
        for m in ControlMode:   # the other modes' gains, ready for a switch
            if m.label != mode:
                self.controller.update(mode=m, **{k.split('.', 1)[1]: v
                                                  for k, v in self.p.items()
                                                  if k.startswith(m.label + '.')})
        # load the compiled step now (numba cache), not inside the first control period
        make_controller(mode, plant=self.cfg, feedforward=self.p['feedforward'],
                        **gains).step(0.0, 0.0, 0.0, 0.0, 0.0, self.dt)
        self._refs: dict[int, tuple[float, float, float]] = {}
        self._ref_latest: tuple[float, float, float] | None = None
        self._meas: tuple[int, float, float] | None = None   # pending (lockstep)
        self._meas_since = 0.0
        now = time.monotonic()
        self._last_ref_rx = self._last_meas_rx = now
        self._stale = False
        self.ignored = 0
        self.steps = 0
        self._out = Float64()
        self.pub = self.create_publisher(Float64, TOPIC_VOLTAGE, LOOP_QOS)
        self._ref_sub = self.mark_hot(self.create_subscription(
            JointState, TOPIC_REFERENCE, self._on_reference, SUB_QOS))
        # measurements only once the trajectory matched: the plant starts when it sees
        # our joint_states reader, and reference 0 must not be missed
        self._since = now
        self._match_timer = self.create_timer(0.05, self._subscribe_measurements)
        self.create_timer(min(0.05, self.p['stale_timeout'] / 4), self._watchdog)
        self.get_logger().info(f'{self.timing.value} controller {self.controller.describe()}')

    def _subscribe_measurements(self) -> None:
        if self._ref_sub.get_publisher_count() < 1 and time.monotonic() - self._since < 10.0:
            return
        self._match_timer.cancel()
        self.mark_hot(self.create_subscription(JointState, TOPIC_JOINT_STATES,
                                               self._on_measurement, SUB_QOS))

    # -- messages --------------------------------------------------------------------
    def _finite(self, msg: JointState, what: str, n: int) -> tuple[float, ...] | None:
        try:
            vals = (float(msg.position[0]), float(msg.velocity[0]),
                    float(msg.effort[0]) if len(msg.effort) else 0.0)[:n]
        except IndexError:
            vals = ()
        if len(vals) == n and all(math.isfinite(v) for v in vals):
            return vals
        self.ignored += 1
        # one call site per kind: rclpy throttles per call site
        if what == 'reference':
            self.get_logger().warning('ignored reference with missing or non-finite values',
                                      throttle_duration_sec=1.0)
        else:
            self.get_logger().warning(f'ignored {what} with missing or non-finite values',
                                      throttle_duration_sec=1.0)
        return None

    def _on_reference(self, msg: JointState) -> None:
        vals = self._finite(msg, 'reference', 3)
        if vals is None:
            return
        self._last_ref_rx = time.monotonic()
        if self._stale and self.timing is Timing.LOCKSTEP:
            self._stale = False
            self.get_logger().info('reference is back: control resumes')
        self._ref_latest = vals
        if self.timing is Timing.REALTIME:
            return
        t_ns = stamp_to_ns(msg.header.stamp)
        self._refs[t_ns] = vals
        if self._meas is not None and self._meas[0] == t_ns:
            self._answer()

    def _on_measurement(self, msg: JointState) -> None:
        vals = self._finite(msg, 'measurement', 2)
        if vals is None:
            return
        self._last_meas_rx = time.monotonic()
        t_ns = stamp_to_ns(msg.header.stamp)
        self._meas = (t_ns, vals[0], vals[1])
        self._meas_since = self._last_meas_rx
        if self.timing is Timing.REALTIME:
            if self._ref_latest is not None and not self._stale:
                self._command(self._ref_latest)
            return
        if t_ns in self._refs:
            self._answer()
        elif self._stale:
            self._zero('no reference for this step')

    def _answer(self) -> None:
        """Lockstep: both halves of step k are here — compute and publish u_k."""
        t_ns = self._meas[0]
        ref = self._refs.pop(t_ns)
        for old in [k for k in self._refs if k < t_ns]:
            del self._refs[old]
        self._command(ref)

    def _command(self, ref: tuple[float, float, float]) -> None:
        _, y, vy = self._meas
        self._out.data = self.controller.step(ref[0], ref[1], ref[2], y, vy, self.dt)
        self.pub.publish(self._out)
        self._meas = None if self.timing is Timing.LOCKSTEP else self._meas
        self.steps += 1

    def _zero(self, why: str) -> None:
        self._out.data = 0.0
        self.pub.publish(self._out)
        self.get_logger().warning(f'stale data ({why}): commanding 0 V',
                                  throttle_duration_sec=1.0)
        if self.timing is Timing.LOCKSTEP:
            self._meas = None

    def _watchdog(self) -> None:
        now = time.monotonic()
        limit = self.p['stale_timeout']
        if self.timing is Timing.LOCKSTEP:
            # the plant is waiting on us: answer a measurement whose reference is late
            if self._meas is not None and now - self._meas_since > limit:
                self._stale = True
                self._zero(f'no reference for {limit:g} s')
            return
        ref_age, meas_age = now - self._last_ref_rx, now - self._last_meas_rx
        if ref_age > limit or meas_age > limit:
            self._stale = True
            what = 'reference' if ref_age > limit else 'measurement'
            self._zero(f'no {what} for {max(ref_age, meas_age):.3g} s')
        elif self._stale:
            self._stale = False
            self.get_logger().info('reference and measurement are back: control resumes')

    # -- parameters ------------------------------------------------------------------
    def apply_params(self, changed: Mapping[str, Any], new: Mapping[str, Any]) -> None:
        """Validate every change first, then apply (all or nothing)."""
        ctl = self.controller
        staged: dict[ControlMode, dict[str, float]] = {}
        for name, value in changed.items():
            if '.' in name:
                mode, field = name.split('.', 1)
                staged.setdefault(ControlMode.parse(mode), {})[field] = value
        for mode, fields in staged.items():
            ctl.params_of(mode).replace(**fields)   # raises ParameterError, nothing changed
        if 'feedforward' in changed:
            ff = Feedforward.parse(new['feedforward'])
            if ff & Feedforward.GMS and self.cfg.model.get('presliding') is None:
                raise ParameterError(f'feedforward {ff.label!r} needs a presliding (GMS) '
                                     f'effect in the nominal plant {self.cfg.source}')
        for mode, fields in staged.items():
            ctl.update(mode=mode, **fields)
        if 'mode' in changed:
            ctl.set_mode(new['mode'], keep_estimates=new['keep_estimates'])
        if 'feedforward' in changed:
            ctl.set_feedforward(new['feedforward'])
        if {'mode', 'feedforward'} & changed.keys():
            self.get_logger().info(f'now {ctl.mode.label} + {ctl.feedforward.label} '
                                   f'feedforward')


def main(args: list[str] | None = None) -> int:
    """Console entry point ``controller_node``."""
    return run_node(ControllerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
