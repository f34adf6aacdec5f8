"""``motor-comp autotune``: from a start model to a compensated axis, through the nodes.

The loop on one axis (DESIGN.md §6 ``autotune``), every motion played by the ROS node
processes (:class:`~motor_comp.tuning.session.AxisSession`) under the axis limits they
enforce:

1. ``design`` — an identification trajectory for the start model within the
   excitation limits (:func:`motor_comp.design.excite.design`, the loop the run will
   use simulated on the start model), written as a table CSV;
2. ``excite`` — played through the nodes and recorded (``excite.mcap``);
3. ``fit`` — ``fit --auto`` from the start model on that recording
   (:func:`motor_comp.workbench.fit.fit`), written as ``fitted_model.yaml``;
4. ``task none`` / ``task fitted`` / ``task true`` — the task trajectory without
   compensation, with the fitted model loaded into the running controller through its
   ``compensation_model`` parameter, and (a simulated plant: known) with the true plant
   model, the upper bound; each recorded;
5. ``report`` — ``index.html`` with the figures and ``autotune.json``
   (:mod:`motor_comp.tuning.report`).

A trip (a limit, the tracking-error bound) or any failure stops the axis and autotune:
what was done and recorded so far stays in the directory (the finalised MCAPs, a partial
``index.html`` and ``autotune.json`` naming the stage and the reason) and the error is
one line naming the stage, e.g. ``autotune stopped in stage 'excite': travel limit: …``.
"""
from __future__ import annotations

import dataclasses
import json
import math
import time
from pathlib import Path
from typing import Any, Callable

from motor_comp.control.limits import Limits, check_reference
from motor_comp.control.trajectories import Table, write_table
from motor_comp.errors import InputFileError, LimitTripError, MotorCompError, \
    ParameterError
from motor_comp.tuning import plan
from motor_comp.tuning.report import finite
from motor_comp.tuning.spec import Axis, AxisSpec

#: excitation length [s]: every part of the design once on both plants (46 s on the
#: ball-screw's default limits) and a few repetitions (45–70 s recover the same on the
#: PMLM; bench/README.md, the autotune section)
EXCITE_DURATION = 50.0
#: the excitation's highest frequency [Hz] (``excite --bandwidth``)
BANDWIDTH = 5.0
#: the controller's measured-acceleration window [s] (its ``accel_window`` default)
ACCEL_WINDOW = 0.01


@dataclasses.dataclass(frozen=True)
class Options:
    """What ``motor-comp autotune`` was asked (SI units).

    Attributes
    ----------
    output : Path
        The directory to create (new or empty).
    model : Path
        The start model file.
    plant : str or None
        The simulated axis (``pmlm``, ``ballscrew``, a plant file); None: an external
        drive (``--external-plant``).
    nominal : str or None
        The controller's plant (nominal model, gains, encoder); default ``plant``.
    controller : str or None
        ``pid | adaptive_sliding | npid`` (default: the plant's, :data:`plan.DEFAULT_CONTROLLER`).
    mode : str or None
        ``lockstep | realtime`` (default: lockstep with a simulated plant, realtime
        with a drive).
    task : str
        Task trajectory name or table file ('' = the plant's default).
    task_duration : float or None
        Length of a task run [s].
    excite_duration : float
        Length of the excitation [s].
    bandwidth : float
        Highest frequency of the excitation [Hz].
    travel, vmax, amax, umax, max_error
        Axis limits (None: derived, :func:`plan.axis_limits`).
    monitor : bool
        Start ``monitor_node`` with each run.
    seed : int
        Measurement-noise seed of the simulated plant.
    namespace : str
        Topic namespace.
    domain_id : int or None
        ``ROS_DOMAIN_ID`` (default ``$ROS_DOMAIN_ID`` or a private one).
    realtime_priority : int
        SCHED_FIFO priority of the loop processes (realtime).
    """

    output: Path
    model: Path
    plant: str | None = 'pmlm'
    nominal: str | None = None
    controller: str | None = None
    mode: str | None = None
    task: str = ''
    task_duration: float | None = None
    excite_duration: float = EXCITE_DURATION
    bandwidth: float = BANDWIDTH
    travel: tuple[float, float] | None = None
    vmax: float | None = None
    amax: float | None = None
    umax: float | None = None
    max_error: float | None = None
    monitor: bool = False
    seed: int = 0
    namespace: str = 'axis'
    domain_id: int | None = None
    realtime_priority: int = 0

    @property
    def timing(self) -> str:
        """The timing mode of the run (lockstep for a simulated plant by default)."""
        return self.mode or ('realtime' if self.plant is None else 'lockstep')


@dataclasses.dataclass(frozen=True)
class Step:
    """One thing autotune did.

    Attributes
    ----------
    name : str
        ``design | excite | fit | task none | task fitted | task true | report``.
    seconds : float
        Its wall time [s].
    files : tuple of str
        The files it wrote (names inside the output directory).
    note : str
        One line on what it did.
    """

    name: str
    seconds: float
    files: tuple = ()
    note: str = ''

    def as_dict(self) -> dict[str, Any]:
        """JSON form (an entry of ``autotune --json`` ``steps``)."""
        return {'name': self.name, 'duration': self.seconds, 'files': list(self.files),
                'note': self.note}


@dataclasses.dataclass
class Outcome:
    """What autotune found and did (filled stage by stage; the report's input).

    ``error`` is set when it stopped early (the one-line reason, with its stage).
    """

    options: Options
    directory: Path
    controller: str = ''
    axis_limits: Limits | None = None
    excitation: Any = None
    task_label: str = ''
    steps: list = dataclasses.field(default_factory=list)
    fit: Any = None
    scores: dict = dataclasses.field(default_factory=dict)
    diagnostics: dict = dataclasses.field(default_factory=dict)
    #: label (``excite``, ``none``, ``fitted``, ``true``) → its MCAP file name
    recordings: dict = dataclasses.field(default_factory=dict)
    #: task label → the recorded task run cut to the task (figures)
    task_runs: dict = dataclasses.field(default_factory=dict)
    start_model: Any = None
    true_model: Any = None
    domain: str = ''
    error: str = ''
    stage: str = ''

    @property
    def recovered_rms(self) -> float | None:
        """Share of the RMS reduction of the true model the fitted one recovers."""
        s = self.scores
        if not {'none', 'fitted', 'true'} <= s.keys():
            return None
        return plan.recovered(s['none'].rms_error, s['fitted'].rms_error, s['true'].rms_error)

    @property
    def recovered_glitch(self) -> float | None:
        """Share of the max-glitch reduction of the true model the fitted one recovers."""
        s = self.scores
        if not {'none', 'fitted', 'true'} <= s.keys():
            return None
        return plan.recovered(s['none'].max_glitch, s['fitted'].max_glitch,
                              s['true'].max_glitch)

    def as_dict(self) -> dict[str, Any]:
        """Return the ``autotune --json`` object (DESIGN.md §6 keys, what autotune did)."""
        o = self.options
        lim = self.axis_limits
        exc = self.excitation
        out: dict[str, Any] = {
            'complete': not self.error, 'directory': str(self.directory),
            'plant': o.plant, 'external_plant': o.plant is None,
            'nominal': o.nominal or o.plant, 'controller': self.controller, 'mode': o.timing,
            'task_name': self.task_label,
            'limits': None if lim is None else {
                'travel': list(lim.travel), 'vmax': lim.vmax, 'amax': lim.amax,
                'umax': lim.umax, 'max_error': lim.max_error},
            'excitation_limits': None if exc is None else {
                'travel': list(exc.travel), 'vmax': exc.vmax, 'amax': exc.amax,
                'umax': exc.umax, 'bandwidth': exc.bandwidth},
            'task': {k: v.as_dict() for k, v in self.scores.items()},
            'recovered_rms': self.recovered_rms, 'recovered_glitch': self.recovered_glitch,
            'model': None if self.fit is None else self.fit.model.to_dict(),
            'steps': [s.as_dict() for s in self.steps],
            'fit': None if self.fit is None else self.fit.as_dict(),
            'diagnostics': self.diagnostics, 'recordings': self.recordings,
            'ros_domain_id': self.domain,
        }
        if self.error:
            out.update(error=self.error, stage=self.stage)
        return out


def _prepare_directory(path: Path) -> Path:
    """Create the output directory; refuse one that holds anything (nothing is overwritten)."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise InputFileError(f'-o {path}: is a file, expected a directory')
    if path.is_dir() and any(path.iterdir()):
        raise InputFileError(f'-o {path}: exists and is not empty (autotune never '
                             f'overwrites a recording): choose a new directory')
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputFileError(f'-o {path}: cannot create directory '
                             f'({exc.strerror or exc})') from None
    return path.resolve()


def _model_dirs(out: Path, *files: str | None) -> tuple[str, ...]:
    """Return the nodes' ``model_dir``: defaults, the output directory, the files' dirs."""
    from motor_comp.param_files import default_dirs
    dirs = [str(d) for d in default_dirs()] + [str(out)]
    for f in files:
        if f and f not in ('pmlm', 'ballscrew'):
            d = str(Path(f).expanduser().resolve().parent)
            if d not in dirs:
                dirs.append(d)
    return tuple(dirs)


def reference_end(path: Path, namespace: str) -> float:
    """Return the stamp [s] of the last reference recorded in ``path``.

    The trajectory publishes the reference of trajectory time ``duration`` last,
    stamped ``t0 + duration`` (its time origin ``t0`` is the plant's clock in lockstep,
    the first measurement it saw in realtime), so this locates the table in the
    recording's time base.
    """
    import struct

    from mcap.reader import make_reader
    topic = f'/{namespace.strip("/")}/reference'
    last = None
    with open(path, 'rb') as fh:
        for _, _, msg in make_reader(fh).iter_messages(topics=[topic]):
            # CDR: 4-byte encapsulation header, then header.stamp {int32 sec, uint32 nsec}
            sec, nsec = struct.unpack_from('<iI', msg.data, 4)
            stamp = sec + nsec * 1e-9
            last = stamp if last is None else max(last, stamp)
    if last is None:
        raise InputFileError(f'{path}: no {topic} recorded')
    return last


def payload(path: Path, *, duration: float, window: tuple[float, float],
            namespace: str) -> Any:
    """Return the recorded run cut to the segment's payload ``window`` (trajectory time)."""
    from motor_comp.logs import read_run
    # exact_time: a real drive's wall-clock stamps to the ns, as `motor-comp fit` reads them
    run = read_run(path, require={'voltage': 'the fit needs the command autotune sent'},
                   exact_time=True)
    t0 = reference_end(path, namespace) - duration \
        - run.metadata.get('time_origin_ns', 0) / 1e9
    dt = float(run.t[1] - run.t[0]) if len(run) > 1 else 0.0
    part = run.slice(t0 + window[0] - 0.25 * dt, t0 + window[1] + 0.25 * dt)
    if len(part) < 2:
        raise InputFileError(f'{path}: the recording does not hold the trajectory\'s '
                             f'{window[1] - window[0]:g} s')
    return dataclasses.replace(part, name=Path(path).stem)


#: builds the axis of a session: ``(spec, log directory, ROS_DOMAIN_ID or None)``
AxisFactory = Callable[[AxisSpec, Path, 'int | None'], Axis]


class Autotune:
    """Run the stages of module docstring; :meth:`run` returns the :class:`Outcome`.

    Parameters
    ----------
    options : Options
        What was asked.
    axis : callable
        Builds the axis the runs are played on (``motor-comp autotune`` gives
        :class:`motor_comp.cli.axis_session.AxisSession`: the node processes).
    say : callable
        Progress lines (one per stage, with its wall time).
    """

    def __init__(self, options: Options, *, axis: AxisFactory,
                 say: Callable[[str], None] = lambda s: None) -> None:
        self.o = options
        self.axis = axis
        self.say = say
        self.stage = ''

    # -- checks before anything moves ---------------------------------------------------
    def _setup(self) -> None:
        from motor_comp.physics.axis import AxisModel
        from motor_comp.physics.config import load_plant
        o = self.o
        if o.timing not in ('lockstep', 'realtime'):
            raise ParameterError(f'--mode must be lockstep or realtime, got {o.timing!r}')
        if o.plant is None and o.timing == 'lockstep':
            raise ParameterError('--external-plant runs in realtime (a drive keeps its own '
                                 'clock; lockstep is the simulated plant\'s): use --mode '
                                 'realtime')
        nominal = o.nominal or o.plant
        if nominal is None:
            raise ParameterError('--external-plant needs --nominal PLANT (pmlm, ballscrew or '
                                 'a plant file): the controller\'s nominal model, gains and '
                                 'encoder')
        self.start = AxisModel.load(o.model)
        self.nominal_cfg = load_plant(nominal)
        self.plant_cfg = load_plant(o.plant) if o.plant is not None else None
        self.rate = self.nominal_cfg.control_rate
        kind = (self.plant_cfg or self.nominal_cfg).kind
        self.controller = o.controller or plan.DEFAULT_CONTROLLER[kind]
        if not (math.isfinite(o.excite_duration) and o.excite_duration > 0):
            raise ParameterError(f'--excite-duration must be > 0, got {o.excite_duration!r}')
        self.task = plan.task_table(o.task, kind=kind, duration=o.task_duration,
                                    rate=self.rate)
        q = self.nominal_cfg.sensors.encoder_resolution or 1e-6
        self.quantum = q
        if o.travel is not None and not o.travel[0] < o.travel[1]:
            raise ParameterError(f'--travel: expected MIN < MAX, got {o.travel[0]:g} '
                                 f'{o.travel[1]:g}')
        self.limits = plan.axis_limits(self.task.table, quantum=q, rate=self.rate,
                                       accel_window=ACCEL_WINDOW, travel=o.travel,
                                       vmax=o.vmax, amax=o.amax, umax=o.umax,
                                       max_error=o.max_error)
        # the task itself must keep the limits: refused before anything moves
        try:
            check_reference(Table(data=self.task.table), self.limits,
                            duration=self.task.duration, rate=self.rate)
        except ParameterError as exc:
            raise ParameterError(f'the task {self.task.label}: {exc}') from None
        self.design_limits = plan.excitation_limits(self.limits, quantum=q, rate=self.rate,
                                                    accel_window=ACCEL_WINDOW,
                                                    bandwidth=o.bandwidth)

    # -- the stages ---------------------------------------------------------------------
    def _step(self, out: Outcome, name: str, t0: float, files: tuple = (),
              note: str = '') -> None:
        step = Step(name=name, seconds=time.monotonic() - t0, files=tuple(files), note=note)
        out.steps.append(step)
        self.say(f'autotune: {name:<12} {step.seconds:6.1f} s  {note}')

    def _design(self, out: Outcome) -> Any:
        from motor_comp.design.excite import design, loop_for
        t0 = time.monotonic()
        loop = loop_for(self.start, plant=self.o.nominal or self.o.plant,
                        mode=self.controller, control_rate=self.rate)
        d = design(self.start, self.design_limits, duration=self.o.excite_duration,
                   loop=loop, seed=self.o.seed)
        (out.directory / 'excite.json').write_text(json.dumps(finite(d.as_dict()),
                                                              indent=1), encoding='utf-8')
        self._step(out, 'design', t0, ('excite.json',),
                   f'{d.table.duration:.1f} s excitation, {len(d.order)} parts, peak '
                   f'speed {d.peaks.v:.4g}, acceleration {d.peaks.a:.4g} (limits: '
                   f'{self.limits.describe(*self.units)})')
        return d

    @property
    def units(self) -> tuple[str, str, str]:
        """Position, velocity, acceleration units of the start model."""
        u = self.start.units
        return u.position, u.velocity, u.acceleration

    def _segment(self, axis: Axis, payload_table: Any, *, lead_to: float | None
                 ) -> plan.Segment:
        """Return the run's table: led in and out on a drive with its own clock."""
        if self.o.timing == 'lockstep':
            return plan.segment_table(payload_table, rate=self.rate, limits=self.design_limits)
        x_from = axis.position() if self.o.plant is None else None
        if x_from is not None:
            lo, hi = self.limits.travel
            if not lo <= x_from <= hi:   # refused before anything moves
                raise ParameterError(
                    f'the axis stands at {x_from:g} {self.units[0]}, outside the travel '
                    f'[{lo:g}, {hi:g}] {self.units[0]}: move it inside (or give --travel)')
        seg = plan.segment_table(payload_table, rate=self.rate, limits=self.design_limits,
                                 x_from=x_from, x_to=lead_to, lead=plan.LEAD,
                                 tail=plan.TAIL)
        check_reference(Table(data=seg.table), self.limits, duration=seg.table.duration,
                        rate=self.rate)
        return seg

    def _play(self, axis: Axis, out: Outcome, name: str, label: str, seg: plan.Segment, *,
              compensation: str = '', monitor_model: str = '') -> tuple[Any, tuple, float]:
        """Write the run's table, play it; the run cut to its payload, its files, start."""
        from motor_comp.analysis.diagnostics import summarise
        from motor_comp.logs.diagnostics import read_diagnostics
        t0 = time.monotonic()
        table_file = out.directory / f'{name}.csv'
        write_table(table_file, seg.table, comments=(f'motor-comp autotune: {label}',))
        mcap = out.directory / f'{name}.mcap'
        out.recordings[label] = mcap.name
        try:
            axis.run(name, table_file, duration=seg.table.duration,
                     x0=float(seg.table.x[0]), output=mcap, compensation=compensation,
                     monitor_model=monitor_model)
        finally:   # also a tripped run's: the limits' ERROR, the monitor's verdicts
            if mcap.exists():
                try:
                    out.diagnostics[label] = summarise(read_diagnostics(mcap))
                except MotorCompError:   # an unreadable file: the error already says
                    pass
        run = payload(mcap, duration=seg.table.duration, window=seg.window,
                      namespace=self.o.namespace)
        return run, (table_file.name, mcap.name), t0

    def run(self) -> Outcome:
        """Run every stage; the outcome (raises after recording what was done)."""
        o = self.o
        self._setup()
        directory = _prepare_directory(o.output)
        out = Outcome(options=o, directory=directory, controller=self.controller,
                      axis_limits=self.limits,
                      excitation=self.design_limits, task_label=self.task.label,
                      start_model=self.start,
                      true_model=None if self.plant_cfg is None else self.plant_cfg.model)
        self.say(f'autotune: {o.plant or "external drive"}, {self.controller}, {o.timing}, '
                 f'task {self.task.label} → {directory}')
        try:
            self.stage = 'design'
            self.start.save(directory / 'start_model.yaml')
            d = self._design(out)
            spec = AxisSpec(plant=o.plant, nominal=o.nominal or o.plant,
                            controller=self.controller, timing=o.timing,
                            control_rate=self.rate, limits=self.limits,
                            model_dirs=_model_dirs(directory, o.plant, o.nominal),
                            monitor=o.monitor, namespace=o.namespace, seed=o.seed,
                            realtime_priority=o.realtime_priority)
            self.stage = 'excite'
            with self.axis(spec, directory / 'logs', o.domain_id) as axis:
                out.domain = axis.domain
                self._stages(axis, out, d)
            self.stage = 'report'
            self._report(out)
        except MotorCompError as exc:
            out.error, out.stage = str(exc), self.stage
            self._report(out, failed=True)
            err = (LimitTripError if isinstance(exc, LimitTripError) else MotorCompError)(
                f'autotune stopped in stage {self.stage!r}: {exc} (what was done and '
                f'recorded so far is in {directory})')
            err.exit_code = exc.exit_code
            raise err from None
        except BaseException as exc:   # an internal error or ^C: keep the record, re-raise
            out.error, out.stage = f'{type(exc).__name__}: {exc}', self.stage
            self._report(out, failed=True)
            raise
        return out

    def _stages(self, axis: Axis, out: Outcome, d: Any) -> None:
        # the workbench's public entry points only (its internals are being rebuilt)
        from motor_comp.workbench import fit, kinematics
        o = self.o
        directory = out.directory
        start_task = float(self.task.table.x[0])
        # -- excite: the designed table through the nodes --------------------------------
        self.stage = 'excite'
        seg = self._segment(axis, d.table, lead_to=start_task)
        run, files, t0 = self._play(
            axis, out, 'excite', 'excite', seg,
            monitor_model=str(directory / 'start_model.yaml') if o.monitor else '')
        self._step(out, 'excite', t0, files,
                   f'{d.table.duration:.1f} s recorded → {files[1]}')
        # -- fit --auto from the start model ---------------------------------------------
        self.stage = 'fit'
        t0 = time.monotonic()
        # a voltage command is held over the period; a logged current or force sampled
        hold = 'zoh' if self.start.input.value == 'voltage' else 'sample'
        result = fit(kinematics(run, hold=hold), self.start, auto=True)
        out.fit = result
        fitted = directory / 'fitted_model.yaml'
        result.model.save(fitted)
        (directory / 'fit.json').write_text(json.dumps(finite(result.as_dict()), indent=1),
                                            encoding='utf-8')
        found = [s.effect for s in result.steps if s.effect]
        self._step(out, 'fit', t0, ('fitted_model.yaml', 'fit.json'),
                   f'fit --auto: {", ".join(found) or "no effect"}; force NRMSE '
                   f'{result.steps[0].force_nrmse:.3f} → {result.steps[-1].force_nrmse:.3f}')
        # -- the task: none, fitted, true ------------------------------------------------
        runs = [('none', ''), ('fitted', str(fitted))]
        if self.plant_cfg is not None:
            true = directory / 'true_model.yaml'
            self.plant_cfg.model.save(true)
            runs.append(('true', str(true)))
        for label, comp in runs:
            self.stage = f'task {label}'
            seg = self._segment(axis, self.task.table, lead_to=start_task)
            run, files, t0 = self._play(
                axis, out, f'task_{label}', label, seg, compensation=comp,
                monitor_model=str(fitted) if o.monitor else '')
            score = plan.TaskScore.of(run)
            out.scores[label] = score
            self._step(out, f'task {label}', t0, files,
                       f'RMS error {1e6 * score.rms_error:.3f} µm, max '
                       f'{1e6 * score.max_error:.3f} µm, max glitch '
                       + ('-' if score.max_glitch is None
                          else f'{1e6 * score.max_glitch:.3f} µm'))
            out.task_runs[label] = run

    def _report(self, out: Outcome, *, failed: bool = False) -> None:
        from motor_comp.tuning.report import write_report
        t0 = time.monotonic()
        try:
            files = write_report(out)
        except Exception as exc:   # noqa: BLE001 - a failed report never hides the result
            if failed:
                return
            raise MotorCompError(f'cannot write the report ({exc})') from None
        if not failed:
            self._step(out, 'report', t0, files, f'→ {out.directory / "index.html"}')
            # the last step's own line: rewrite the JSON with it
            write_report(out, figures=False)


def autotune(options: Options, *, axis: AxisFactory,
             say: Callable[[str], None] = lambda s: None) -> Outcome:
    """Run the stages of the module docstring on ``axis``; return the :class:`Outcome`."""
    return Autotune(options, axis=axis, say=say).run()


__all__ = ['ACCEL_WINDOW', 'AxisFactory', 'Autotune', 'BANDWIDTH', 'EXCITE_DURATION',
           'Options', 'Outcome', 'Step', 'autotune', 'payload', 'reference_end']
