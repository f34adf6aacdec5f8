"""``controller_node``: PID | adaptive sliding | N-PID with friction feedforward.

A thin adapter over :class:`motor_comp.control.controller.Controller`: each command is
``Controller.step`` — the same compiled ``controller_step`` the in-process simulator
loops over — on the reference (``<ns>/reference``: position [m], velocity [m/s],
effort = acceleration [m/s²]) and the measurement (``<ns>/joint_states``).  Publishes
the command [V] on ``<ns>/voltage``; saturation ±``<mode>.u_max`` is part of the law.

Timing.  Lockstep: the command for step k is computed when both the measurement and
the reference stamped t_k have arrived (in either order), exactly one command per
measurement, with the nominal period ``dt = 1/control_rate`` (exactly the simulator).
Realtime: one command per *new* measurement, as a real drive does it:

* the reference is the one stamped exactly like the measurement (the trajectory node
  publishes on the plant's sample grid, one period ahead); if it is missing (the
  trajectory process was late), the latest reference (stamped t_r, with velocity and
  acceleration) is extrapolated to the measurement stamp t_m,
  ``r + ṙ·Δ + ½·r̈·Δ²`` with ``Δ = t_m − t_r``.  Using whatever reference came last
  (as before) put ``ṙ·Δ`` into the error with Δ = 0.1–2 ms (≈ 60 µm at 0.1 m/s), noise
  correlated with the regressors of the adaptive law (``s_Δ·λ2·e`` has a positive mean
  ∝ E[Δ²]): the PMLM mass estimate reached 10 kg after 90 ms (4.6 kg in lockstep) and
  the loop diverged to 1e50 m within 0.15 s;
* only the newest queued measurement is answered: when the process was descheduled
  (a 2-core machine shared with other work stalls it for 5–20 ms) the queue holds a
  backlog, and answering each old sample in turn applies commands computed from
  positions many periods old.  The skipped samples are counted;
* a measurement whose stamp does not advance (duplicate, or reordered) is not fed to
  the law: the plant holds the last command (counted, warned);
* ``dt_source`` chooses the period passed to the law: ``nominal`` (default, 1/rate) or
  ``stamps`` (difference of the measurement stamps, nominal after a gap longer than
  ``stale_timeout``).  Measured on the PMLM + adaptive sliding, 3 s realtime runs on
  the loaded 2-core machine without realtime priority: ``stamps`` diverged in 3 of 3
  runs, ``nominal`` stayed bounded in 3 of 3 (rms 9–29 µm).  A gap follows a stall in
  which the error grew under the held command, so weighting that one end-of-gap sample
  by the whole gap over-counts it in the integral and the adaptation (≈ 3× for an error
  growing ∝ t²) and kicks the estimates; with ``realtime_priority`` both give the
  lockstep figures (rms 5.0 µm, max 20 µm);
* the sample age at command time (``now − stamp``, logged as percentiles at exit)
  includes the plant's sim-time slip, if it slipped (its log says how many periods);
* ``realtime_priority`` > 0 runs the process under SCHED_FIFO
  (:func:`~motor_comp.nodes.common.set_realtime_priority`): sample age at command
  p99 0.5 ms, max 1.5 ms instead of p99 2–4 ms, max 20 ms.

Start: ``joint_states`` is subscribed only once a reference publisher is seen and
``expected_subscribers`` readers (plant + recorder) matched this node's ``voltage``
writer; the plant starts when it sees that subscription, so no reader of the loop misses
command 0 (a volatile reader gets only what is published after the writer matched it,
and a reader that sees the writer may not yet be seen by it).

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
  tunable; an invalid value is rejected with the reason and nothing changes;
* ``compensation_model`` (a model YAML) or ``compensation_table`` (a position table
  CSV of ``motor-comp export-table``) adds that model's inverse dynamics (or, with
  ``compensation_terms: effects``, its effects only) as feedforward at the reference
  state in any mode, less the terms the law carries itself
  (:mod:`motor_comp.control.compensation`; the reference acceleration is the reference
  message's effort); set at run time the file is loaded and validated first — a bad
  file is rejected with the reason and the old compensation stays — and switched in
  bumplessly (the integrator re-balanced); ``compensation_terms`` switches alike.
  The files (and a ``plant`` YAML) are read under :mod:`motor_comp.param_files`: only
  inside ``model_dir`` (read-only), only regular files under a size bound, and a
  rejection reason never quotes the file.

Limits (issue 24, :mod:`motor_comp.control.limits`): ``travel`` [min, max], ``vmax``,
``amax``, ``umax`` and ``max_error`` (read-only; infinite = none, the default).  Every
command is checked by a :class:`~motor_comp.control.limits.Guard` against the
reference, the measurement and the law's command; the first break is a *trip*: from
that command on the node commands 0 V (latched until it is configured again — lifecycle
cleanup + configure — or restarted), logs one error line with the cause and the values,
publishes an ERROR ``DiagnosticStatus`` (``motor_comp/<ns>: limits``, stamped with the
measurement that broke the limit; an OK one with the limits at the first command) on
``/diagnostics`` (the reason's time ``t`` is sim time in lockstep, the time since the
first sample answered in realtime, whose stamps are wall-clock based), and exits with
status 3 and the cause as its last line — after ``trip_hold`` more seconds of 0 V with
``exit_on_trip`` (as ``motor-comp run`` starts it), else when it is stopped.
"""
from __future__ import annotations

import dataclasses
import math
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from motor_comp import param_files
from motor_comp.control import compensation
from motor_comp.control.controller import ControlMode, Feedforward, default_params, \
    make_controller
from motor_comp.control.limits import Guard, Trip
from motor_comp.errors import ParameterError
from motor_comp.nodes.common import DEFAULT_NAMESPACE, DELAY_BIN_NS, DELAY_BINS, \
    DIAGNOSTICS_READERS, LOOP_QOS, MODEL_DIR, MOTION_LIMITS, REALTIME_PRIORITY, SUB_QOS, \
    TOPIC_JOINT_STATES, TOPIC_REFERENCE, TOPIC_VOLTAGE, ManagedNode, Pacer, Param, Timing, \
    format_delays, limits_from, read_joint_state, run_node, set_realtime_priority, set_stamp, \
    take_newest
from motor_comp.control.nominal import derive_nominal
from motor_comp.physics.config import PlantConfig

#: exit status of a node process whose controller tripped a limit (distinct from 2, a
#: user error); ``motor-comp run`` turns it into its one-line error
TRIP_EXIT_STATUS = 3

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
    Param('dt_source', 'nominal', 'Realtime: period passed to the law, the nominal '
          '1/control_rate or the difference of the measurement stamps',
          choices=('nominal', 'stamps')),
    Param('compensation_model', '', 'Model file (YAML) whose effects are added as '
          'feedforward at the reference state, in any mode (empty = none); reloaded when '
          'set, a bad file is rejected and the old compensation stays'),
    Param('compensation_table', '', 'Position compensation table (CSV of motor-comp '
          'export-table), interpolated (empty = none; exclusive with compensation_model)'),
    Param('compensation_terms', 'full', 'Terms of compensation_model sent: the full inverse '
          'dynamics (inertia, back-EMF, damping and effects) or its effects only; switched '
          'bumplessly', choices=('full', 'effects')),
    Param('expected_subscribers', 2, 'Readers of voltage (plant + recorder) that must have '
          'matched this node\'s writer before it subscribes joint_states, so no reader '
          'misses the first commands (after 10 s it goes on with a warning)', '', 0, 100,
          read_only=True),
    REALTIME_PRIORITY,
    MODEL_DIR,
) + MOTION_LIMITS + (
    Param('umax', math.inf, 'Voltage limit: a command of the law beyond ±umax trips (inf = '
          'none; <mode>.u_max is the law\'s own saturation)', 'V', 1e-12, math.inf,
          read_only=True),
    Param('max_error', math.inf, 'Tracking-error limit |x_ref - x| (inf = none)',
          'm or rad', 1e-12, math.inf, read_only=True),
    Param('accel_window', 0.01, 'The measured acceleration checked against amax is the '
          'velocity change over this window', 's', 1e-4, 1.0, read_only=True),
    Param('exit_on_trip', False, 'After a limit trip, command 0 V for trip_hold more and '
          'exit with status 3 (false: command 0 V until configured again or stopped)',
          read_only=True),
    Param('trip_hold', 0.05, 'With exit_on_trip: stamp time of 0 V commands after the trip '
          'before the node exits (the recording shows the stop)', 's', 0.0, 60.0,
          read_only=True),
    DIAGNOSTICS_READERS,
)

#: how long a node waits for its expected peers before it goes on with a warning [s]
MATCH_TIMEOUT = 10.0

#: the limits' status on /diagnostics: reliable, and kept for a late reader
LIMITS_QOS = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.TRANSIENT_LOCAL)


def gain_params(plant: PlantConfig) -> tuple[Param, ...]:
    """``<mode>.<field>`` for every mode, with the plant's defaults, units and ranges."""
    out = []
    for mode in ControlMode:
        defaults = default_params(mode, plant)
        for f in defaults.fields_with_ranges():
            out.append(Param(f'{mode.label}.{f.name}', float(getattr(defaults, f.name)),
                             f'{mode.label}: {f.description}', f.unit, f.min, f.max))
    return tuple(out)


class ControllerNode(ManagedNode):
    """Computes one command per measurement with the core controller step.

    Managed node: ``configure`` builds the control law from the parameters (and, the
    first time, the ``voltage`` publisher); ``activate`` subscribes ``reference`` and
    ``joint_states`` and starts the stale-data watchdog; while not active the node
    subscribes nothing and so commands nothing (not even the watchdog's 0 V);
    ``deactivate`` drops a pending measurement; ``cleanup`` drops the law (adaptive
    estimates included) and keeps the ``voltage`` writer (a drive's reader stays matched
    to it).
    """

    def __init__(self) -> None:
        super().__init__('controller_node', namespace=DEFAULT_NAMESPACE)
        self.declare_params(BASE_PARAMS)
        cfg = param_files.load_plant('plant', self.p['plant'], self.file_dirs)
        self.limits = limits_from(self.p)   # an invalid travel is a one-line error
        self.declare_params(gain_params(cfg))   # defaults depend on the plant
        # the law knows the nominal model derived from the plant file, never the plant
        self.cfg = dataclasses.replace(derive_nominal(cfg), control_rate=self.p['control_rate'])
        self.timing = Timing(self.p['timing'])
        self.dt = 1.0 / self.p['control_rate']
        self.controller = None
        self.pub = None
        self._ref_sub = self._meas_sub = self._match_timer = self._watchdog_timer = None
        self.steps = 0
        self.published = 0   # commands sent (law and watchdog zeros), over all activations
        self.guard: Guard | None = None
        self.trip: Trip | None = None
        self._trip_t = 0.0
        self._finished = False
        self.pub_diag = None
        ns = self.get_namespace().strip('/') or DEFAULT_NAMESPACE
        self.status_name = f'motor_comp/{ns}: limits'
        self.hardware_id = ns
        self.autostart()

    def configure(self) -> None:
        """Build the control law (all modes' gains ready); the first time, the publisher."""
        mode = self.p['mode']
        gains = {k.split('.', 1)[1]: v for k, v in self.p.items()
                 if k.startswith(mode + '.')}
        controller = make_controller(mode, plant=self.cfg,
                                     feedforward=self.p['feedforward'], **gains)
        comp = load_compensation(self.p, self.file_dirs)   # a bad file fails configure
        if comp is not None:
            comp = comp.with_terms(self.p['compensation_terms'])
            controller.set_compensation(comp)
            self.get_logger().info(comp.summary())
        self.controller = controller
        for m in ControlMode:   # the other modes' gains, ready for a switch
            if m.label != mode:
                self.controller.update(mode=m, **{k.split('.', 1)[1]: v
                                                  for k, v in self.p.items()
                                                  if k.startswith(m.label + '.')})
        # load the compiled step now (numba cache), not inside the first control period
        warm = make_controller(mode, plant=self.cfg, **gains)
        warm.step(0.0, 0.0, 0.0, 0.0, 0.0, self.dt)
        # and the compensation's switch-in (a run-time compensation_model must not stall
        # the loop on a first compilation)
        warm.set_compensation(compensation.from_model(self.cfg.model, source='warm-up'))
        self._refs: dict[int, tuple[float, float, float]] = {}
        self._ref_latest: tuple[float, float, float] | None = None
        self._ref_stamp_ns = 0
        self._last_meas_ns: int | None = None   # realtime: stamp of the last sample used
        self.duplicates = 0
        self.skipped = 0
        # realtime: references that arrived after their sample was answered, and the
        # largest such delay [s]
        self.ref_behind = 0
        self.ref_behind_max = 0.0
        # realtime: age of each answered sample when its command leaves [0.1 ms bins]
        self.latency_hist = np.zeros(DELAY_BINS + 1, dtype=np.int64)
        self._rt_refs: dict[int, tuple[float, float, float]] = {}
        self._meas: tuple[int, float, float] | None = None   # pending (lockstep)
        self._meas_since = 0.0
        now = time.monotonic()
        self._last_ref_rx = self._last_meas_rx = now
        self._stale = False
        self.ignored = 0
        self.steps = 0
        self._out = Float64()
        # the limits: a new guard (configure clears a trip); none without a limit
        u = self.cfg.model.units
        self.guard = (Guard(self.limits, units=(u.position, u.velocity, u.acceleration),
                            accel_window=self.p['accel_window'])
                      if self.limits.active else None)
        self.trip = None
        self.exit_status, self.exit_reason = 0, ''
        self._armed_sent = False
        self._t0_ns: int | None = None
        if self.guard is not None and self.pub_diag is None:
            self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics',
                                                  LIMITS_QOS)
        if self.guard is not None:
            self.get_logger().info(f'limits: {self.limits.describe(*self.guard.units)}')
        if self.pub is None:   # one writer for the node's life (see cleanup)
            self.pub = self.create_publisher(Float64, TOPIC_VOLTAGE, LOOP_QOS)
        # lockstep: never outrun a lagging reader (the recorder) by the writer's history;
        # acknowledgements are per writer, so pacing joint_states alone does not bound
        # what this writer may overwrite (a stress run lost 51 commands of 16 337)
        self._pub_out = Pacer(self.pub) if self.timing is Timing.LOCKSTEP else self.pub
        self.get_logger().info(f'{self.timing.value} controller {self.controller.describe()}')
        if self.timing is Timing.REALTIME:
            set_realtime_priority(self, self.p['realtime_priority'])

    def activate(self) -> None:
        """Subscribe ``reference`` (then ``joint_states``) and start the watchdog."""
        now = time.monotonic()
        self._last_ref_rx = self._last_meas_rx = now
        # raw CDR: read_joint_state takes the numbers straight from the bytes
        self._ref_sub = self.mark_hot(self.create_subscription(
            JointState, TOPIC_REFERENCE, self._on_reference, SUB_QOS, raw=True))
        # measurements only once the trajectory matched and our voltage writer matched
        # its expected readers: the plant starts when it sees our joint_states reader,
        # and neither reference 0 nor command 0 may be missed by anyone
        self._since = now
        self._match_timer = self.create_timer(0.05, self._subscribe_measurements)
        self._watchdog_timer = self._make_watchdog(self.p['stale_timeout'])

    def deactivate(self) -> None:
        """Unsubscribe, stop the watchdog, forget a measurement waiting for its command."""
        for sub in (self._ref_sub, self._meas_sub):
            self.destroy_hot(sub)
        for tmr in (self._match_timer, self._watchdog_timer):
            if tmr is not None:
                self.destroy_timer(tmr)
        self._ref_sub = self._meas_sub = self._match_timer = self._watchdog_timer = None
        self._meas = None
        self._stale = False

    def cleanup(self) -> None:
        """Drop the law (a new configure starts from the parameters); keep the writer.

        The ``voltage`` writer lives as long as the node: a reader matches a new writer
        only once discovery has told it (2.4 s on a loaded machine), and a drive whose
        reader had not yet matched held its old command while a reconfigured controller
        commanded — the axis stood, then jumped at the accumulated command.  An
        unconfigured or inactive node publishes nothing on it all the same.
        """
        self.deactivate()
        self.controller = None

    def _make_watchdog(self, stale_timeout: float) -> Any:
        # a quarter of the timeout: stale data is noticed within 1.25·stale_timeout
        return self.create_timer(min(0.05, stale_timeout / 4), self._watchdog)

    def _subscribe_measurements(self) -> None:
        # writer-side matching of our voltage writer: a reader that sees our writer may
        # not yet be seen *by* it (DDS discovery is not symmetric in time), and a
        # volatile reader gets only what is published after the writer matched it
        readers = self.pub.get_subscription_count()
        missing = []
        if self._ref_sub.get_publisher_count() < 1:
            missing.append('a reference publisher')
        if readers < self.p['expected_subscribers']:
            missing.append(f'{self.p["expected_subscribers"]} voltage readers (have '
                           f'{readers})')
        if self.pub_diag is not None and \
                self.pub_diag.get_subscription_count() < self.p['diagnostics_readers']:
            missing.append(f'{self.p["diagnostics_readers"]} /diagnostics readers')
        if missing:
            if time.monotonic() - self._since < MATCH_TIMEOUT:
                return
            self.get_logger().warning(f'no {" and ".join(missing)} after '
                                      f'{MATCH_TIMEOUT:g} s: subscribing joint_states anyway')
        self.destroy_timer(self._match_timer)
        self._match_timer = None
        self._meas_sub = self.mark_hot(self.create_subscription(
            JointState, TOPIC_JOINT_STATES, self._on_measurement, SUB_QOS, raw=True))

    # -- messages --------------------------------------------------------------------
    def _finite(self, fields: tuple[int, float | None, float | None, float | None],
                what: str, n: int) -> tuple[float, ...] | None:
        """Return the first ``n`` of position, velocity, effort (0 if absent) if finite."""
        _, pos, vel, eff = fields
        if pos is not None and vel is not None:   # (no generator: this runs every step)
            finite = math.isfinite
            if n == 2:
                if finite(pos) and finite(vel):
                    return pos, vel
            else:
                acc = 0.0 if eff is None else eff
                if finite(pos) and finite(vel) and finite(acc):
                    return pos, vel, acc
        self.ignored += 1
        # one call site per kind: rclpy throttles per call site
        if what == 'reference':
            self.get_logger().warning('ignored reference with missing or non-finite values',
                                      throttle_duration_sec=1.0)
        else:
            self.get_logger().warning(f'ignored {what} with missing or non-finite values',
                                      throttle_duration_sec=1.0)
        return None

    def _on_reference(self, msg: JointState | bytes) -> None:
        fields = read_joint_state(msg)
        vals = self._finite(fields, 'reference', 3)
        if vals is None:
            return
        self._last_ref_rx = time.monotonic()
        if self._stale and self.timing is Timing.LOCKSTEP:
            self._stale = False
            self.get_logger().info('reference is back: control resumes')
        self._ref_latest = vals
        t_ns = fields[0]
        if self.timing is Timing.REALTIME:
            last = self._last_meas_ns
            if last is not None and 0 <= last - t_ns <= self.p['stale_timeout'] * 1e9:
                # it arrives after its sample was answered (with the latest reference,
                # extrapolated): a move that starts in the gap is seen only now, and the
                # axis jumps to catch up
                self.ref_behind += 1
                self.ref_behind_max = max(self.ref_behind_max, (last - t_ns) * 1e-9)
            self._ref_stamp_ns = t_ns
            self._rt_refs[t_ns] = vals
            if len(self._rt_refs) > 4096:   # a plant far behind: forget the oldest
                del self._rt_refs[next(iter(self._rt_refs))]
            return
        self._refs[t_ns] = vals
        if self._meas is not None and self._meas[0] == t_ns:
            self._answer()

    def _on_measurement(self, msg: JointState | bytes) -> None:
        if self.timing is Timing.REALTIME:
            msg = self._newest(msg)
        fields = read_joint_state(msg)
        vals = self._finite(fields, 'measurement', 2)
        if vals is None:
            return
        self._last_meas_rx = time.monotonic()
        t_ns = fields[0]
        self._meas = (t_ns, vals[0], vals[1])
        self._meas_since = self._last_meas_rx
        if self.trip is not None:
            self._tripped_step(t_ns)   # 0 V at once, whatever the reference
            return
        if self.timing is Timing.REALTIME:
            self._realtime_step(t_ns)
            return
        if t_ns in self._refs:
            self._answer()
        elif self._stale:
            self._zero('no reference for this step')

    def _answer(self) -> None:
        """Lockstep: both halves of step k are here — compute and publish u_k."""
        t_ns = self._meas[0]
        refs = self._refs
        ref = refs.pop(t_ns)
        # references arrive in stamp order (the trajectory publishes ahead, up to its
        # lookahead): drop the older ones from the front, without scanning the rest
        while refs:
            oldest = next(iter(refs))
            if oldest >= t_ns:
                break
            del refs[oldest]
        self._command(ref)

    def _newest(self, msg: JointState | bytes) -> JointState | bytes:
        """Realtime: the newest measurement queued behind ``msg`` (the backlog is skipped)."""
        msg, _, skipped = take_newest(self._meas_sub, msg)
        self.skipped += skipped
        return msg

    def _realtime_step(self, t_ns: int) -> None:
        """Realtime: one command for a new measurement stamped ``t_ns`` (see module doc)."""
        limit = self.p['stale_timeout']
        limit_ns = int(limit * 1e9)
        last = self._last_meas_ns
        if last is not None and last - limit_ns < t_ns <= last:
            # not newer than the sample already answered: the plant holds that command
            self.duplicates += 1
            self.get_logger().warning('measurement stamp did not advance: holding the last '
                                      'command', throttle_duration_sec=1.0)
            return
        gap_ns = t_ns - last if last is not None else 0
        dt = gap_ns * 1e-9 if (self.p['dt_source'] == 'stamps'
                               and 0 < gap_ns <= limit_ns) else self.dt
        self._last_meas_ns = t_ns
        if self._ref_latest is None:
            return
        if self._stale:
            # fresh again: resume now rather than at the next watchdog tick (the first
            # samples of a run would otherwise go unanswered for up to 50 ms)
            if time.monotonic() - self._last_ref_rx > limit:
                return
            self._stale = False
            self.get_logger().info('reference and measurement are back: control resumes')
        refs = self._rt_refs
        exact = refs.get(t_ns)
        for old in [k for k in refs if k <= t_ns]:
            del refs[old]
        if exact is not None:
            r, rv, ra = exact
        else:
            # nearest in time: the latest, or one published ahead for a plant that slipped
            near = min(refs, key=lambda k: abs(k - t_ns), default=None)
            if near is not None and abs(near - t_ns) < abs(self._ref_stamp_ns - t_ns):
                (r, rv, ra), ref_ns = refs[near], near
            else:
                (r, rv, ra), ref_ns = self._ref_latest, self._ref_stamp_ns
            lead = (t_ns - ref_ns) * 1e-9
            if abs(lead) <= limit:   # same clock; otherwise (foreign stamps) use as it is
                r, rv = r + lead * (rv + 0.5 * lead * ra), rv + lead * ra
        self._command((r, rv, ra), dt)
        age = (time.time_ns() - t_ns) // DELAY_BIN_NS
        self.latency_hist[min(max(age, 0), DELAY_BINS)] += 1

    def _command(self, ref: tuple[float, float, float], dt: float | None = None) -> None:
        t_ns, y, vy = self._meas
        u = self.controller.step(ref[0], ref[1], ref[2], y, vy,
                                 self.dt if dt is None else dt)
        guard = self.guard
        if guard is not None:
            if not self._armed_sent:
                self._armed_sent = True
                self._publish_status(t_ns, None)
            if self._t0_ns is None:
                # lockstep stamps are sim time (from 0); realtime ones are wall-clock
                # based: a trip's time is then counted from the first sample answered
                self._t0_ns = 0 if self.timing is Timing.LOCKSTEP else t_ns
            if guard.check((t_ns - self._t0_ns) * 1e-9, ref[0], ref[1], ref[2], y, vy,
                           u) is not None:
                u = self._on_trip(guard.trip, t_ns)
        self._out.data = u
        self._pub_out.publish(self._out)
        self.published += 1
        self._meas = None if self.timing is Timing.LOCKSTEP else self._meas
        self.steps += 1

    # -- limits ----------------------------------------------------------------------
    def _on_trip(self, trip: Trip, t_ns: int) -> float:
        """Latch a trip, say so (log, /diagnostics); return the command to send: 0 V."""
        self.trip = trip
        self._trip_t = t_ns * 1e-9   # stamp time: trip_hold counts on the samples' clock
        self.exit_status, self.exit_reason = TRIP_EXIT_STATUS, trip.message
        self.get_logger().error(f'TRIP {trip.message}: commanding 0 V from command '
                                f'{self.steps} on (latched until configured again)')
        self._publish_status(t_ns, trip)
        return 0.0

    def _tripped_step(self, t_ns: int) -> None:
        """After a trip: answer every new measurement with 0 V; exit after the hold."""
        if self._finished:
            return   # the hold is over: the plant holds the last command (0 V)
        if self.timing is Timing.REALTIME:
            last = self._last_meas_ns
            if last is not None and t_ns <= last:
                return   # not a new sample: the plant holds the last command (0 V)
            self._last_meas_ns = t_ns
        self._refs.clear()   # never used again: the trajectory may keep publishing
        self._out.data = 0.0
        self._pub_out.publish(self._out)
        self.published += 1
        self.steps += 1
        self._meas = None if self.timing is Timing.LOCKSTEP else self._meas
        if self.p['exit_on_trip'] and t_ns * 1e-9 - self._trip_t >= self.p['trip_hold']:
            self._finished = True

    def _publish_status(self, t_ns: int, trip: Trip | None) -> None:
        """Publish the limits' ``DiagnosticStatus``: OK (armed) or ERROR (the trip)."""
        st = DiagnosticStatus(name=self.status_name, hardware_id=self.hardware_id)
        if trip is None:
            st.level = DiagnosticStatus.OK
            st.message = f'limits armed: {self.limits.describe(*self.guard.units)}'
            values = {'limits': st.message[len('limits armed: '):]}
        else:
            st.level = DiagnosticStatus.ERROR
            st.message = trip.message
            values = {k: (f'{v:.9g}' if isinstance(v, float) else str(v))
                      for k, v in trip.as_dict().items() if k != 'message'}
        st.values = [KeyValue(key=k, value=v) for k, v in values.items()]
        arr = DiagnosticArray(status=[st])
        set_stamp(arr.header.stamp, t_ns)   # the sample's time (sim time in lockstep)
        self.pub_diag.publish(arr)

    @property
    def done(self) -> bool:
        """True once a trip's ``trip_hold`` has passed with ``exit_on_trip``."""
        return self._finished

    def _zero(self, why: str) -> None:
        self._out.data = 0.0
        self._pub_out.publish(self._out)
        self.published += 1
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

    def finish(self, executor: Any) -> None:
        """Log what the loop did (realtime: skipped backlog, duplicates, sample age)."""
        self.get_logger().info(f'stopped: {self.published} commands published')
        if self.timing is Timing.REALTIME:
            pct = format_delays(self.latency_hist)
            self.get_logger().info(f'timing: {self.steps} commands, {self.skipped} backlog '
                                   f'samples skipped, {self.duplicates} duplicates; sample '
                                   f'age at command (0.1 ms bins, last bin = 20 ms or '
                                   f'more): {pct}; {self.ref_behind} references arrived after '
                                   f'their sample was answered, at most '
                                   f'{1e3 * self.ref_behind_max:.1f} ms after')

    # -- parameters ------------------------------------------------------------------
    def apply_params(self, changed: Mapping[str, Any], new: Mapping[str, Any]) -> None:
        """Validate every change first, then apply (all or nothing)."""
        ctl = self.controller
        if ctl is None:   # unconfigured: configure builds the law from the parameters
            ctl = make_controller(new['mode'], plant=self.cfg)
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
        comp_changed = bool({'compensation_model', 'compensation_table'} & changed.keys())
        comp = load_compensation(new, self.file_dirs) if comp_changed else ctl.compensation
        if comp is not None:
            terms = comp.with_terms(new['compensation_terms'])
            comp_changed = comp_changed or terms is not comp
            comp = terms
        if self.controller is None:
            return
        for mode, fields in staged.items():
            ctl.update(mode=mode, **fields)
        if 'mode' in changed:
            ctl.set_mode(new['mode'], keep_estimates=new['keep_estimates'])
        if 'feedforward' in changed:
            ctl.set_feedforward(new['feedforward'])
        if comp_changed:   # after mode and feedforward: it leaves out what they carry
            ctl.set_compensation(comp)
            self.get_logger().info(f'{comp.summary() if comp else "compensation off"} '
                                   f'from command {self.steps}')
        if 'stale_timeout' in changed and self._watchdog_timer is not None:
            # the watchdog's period follows the timeout
            self.destroy_timer(self._watchdog_timer)
            self._watchdog_timer = self._make_watchdog(new['stale_timeout'])
        if {'mode', 'feedforward'} & changed.keys():
            self.get_logger().info(f'now {ctl.mode.label} + {ctl.feedforward.label} '
                                   f'feedforward from command {self.steps}')


def load_compensation(new: Mapping[str, Any], dirs: Sequence[Path]) -> Any:
    """Load the compensation the parameters name (None if both are empty); one-line errors.

    ``compensation_model`` and ``compensation_table`` are exclusive; setting one while
    the other is set is refused, so the user clears one first (no silent precedence).
    The file is read under :mod:`motor_comp.param_files` (inside ``dirs``, regular,
    bounded; a reason never quotes it) and parsed from that text.
    """
    model, table = new.get('compensation_model', ''), new.get('compensation_table', '')
    if model.strip() and table.strip():
        raise ParameterError('compensation_model and compensation_table are exclusive: '
                             'clear one first (set it to an empty string)')
    if model.strip():
        real, axis_model = param_files.load_model('compensation_model', model, dirs)
        return compensation.from_model(axis_model, source=str(real))
    if table.strip():
        real, tab = param_files.load_table('compensation_table', table, dirs)
        return compensation.from_table(tab, source=str(real))
    return None


def main(args: list[str] | None = None) -> int:
    """Console entry point ``controller_node``."""
    return run_node(ControllerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
