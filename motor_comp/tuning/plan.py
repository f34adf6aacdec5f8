"""What ``motor-comp autotune`` runs: the task, the limits, the segments' tables, the scores.

The pure half of autotune (no rclpy; :mod:`motor_comp.tuning.session` drives the nodes):

* the **task** — the trajectory the axis is judged on before and after, sampled into a
  table (:func:`task_table`; by default each plant's own: p2p moves on the PMLM, the slow
  sine on the ball-screw, :data:`DEFAULT_TASK`);
* the **axis limits** the nodes enforce throughout (:func:`axis_limits`: the ones given,
  the rest derived from the task and the encoder, so that the task and its tracking
  error keep well inside them while a runaway is stopped), and the tighter **excitation
  limits** the identification trajectory is designed within (:func:`excitation_limits`:
  the measured speed and acceleration carry the encoder's quantisation noise and the
  tracking error, so the design stays a margin inside what trips);
* the **segment table** each run plays (:func:`segment_table`): the payload (the
  excitation or the task), on a drive with its own clock led in from where the axis
  stands by a minimum-jerk move and rests (:data:`LEAD`, :data:`TAIL`);
* the **scores**: tracking error and quadrant glitches of a task run
  (:class:`TaskScore`, DESIGN.md §6 definitions) and the share of the possible
  reduction the fitted model recovers (:func:`recovered`).
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from motor_comp.control.excitation import ExcitationLimits, Profile
from motor_comp.control.limits import Limits
from motor_comp.control.trajectories import TRAJECTORIES, TableData, Trajectory, \
    make_trajectory, read_table_file, table_from_arrays
from motor_comp.errors import ParameterError
from motor_comp.physics.config import PlantKind

#: the task of each plant (DESIGN.md §4 seed claims): Tan's p2p moves, Chiew's slow sine
DEFAULT_TASK = {PlantKind.PMLM: 'p2p', PlantKind.BALLSCREW: 'sine'}
#: and the controller it runs under (PID on the PMLM, N-PID on the ball-screw)
DEFAULT_CONTROLLER = {PlantKind.PMLM: 'pid', PlantKind.BALLSCREW: 'npid'}
#: length of a task run [s]: five periods of either default task (2 s each)
TASK_DURATION = 10.0
#: default axis travel: the task's range widened by this share of its span at each end
TRAVEL_MARGIN = 0.25
#: default speed and acceleration limits: this multiple of the task's peaks, plus noise
SPEED_MARGIN, ACCEL_MARGIN = 1.5, 3.0
#: the excitation asks at most this share of the speed and of the acceleration limit
#: (after the measurement noise is taken off), so that the loop's transients do not trip
#: them: the speed overshoots by the tracking error's rate (the PMLM's PID in realtime on
#: a loaded machine: 0.3 m/s on a 0.225 m/s move), the measured acceleration by far
#: more (a sticky axis breaks away: 3.5 m/s² over the 10 ms window on 1.85 m/s²)
SPEED_SHARE, ACCEL_SHARE = 0.7, 0.5
#: share of the travel span the excitation keeps clear at each end (at least
#: :data:`DESIGN_CLEAR_COUNTS` encoder counts)
DESIGN_CLEAR, DESIGN_CLEAR_COUNTS = 0.05, 50.0
#: encoder counts of velocity noise the nodes' speed check allows for: the measured
#: velocity is a position difference over one period, so one count is ``q·rate``
SPEED_NOISE_COUNTS = 2.0
#: and of the windowed acceleration (a velocity difference over ``accel_window``): its
#: quantisation (±1 count at each end) and the loop's transients at a reversal or a
#: breakaway (a ball-screw on its 6 mm sine measured 0.5 m/s², 5 counts, in realtime
#: with a fitted compensation, on a 0.03 m/s² reference)
ACCEL_NOISE_COUNTS = 10.0
#: rests before and after the payload of a segment on a drive with its own clock [s]:
#: the controller holds the axis at the start for the first, it settles in the second
LEAD, TAIL = 0.5, 0.5


@dataclasses.dataclass(frozen=True)
class Task:
    """The task trajectory sampled on the control grid.

    Attributes
    ----------
    label : str
        What it is (``p2p``, ``sine``, a table file name).
    table : TableData
        Its rows ``t = k/rate``, ``x, v, a`` (SI).
    """

    label: str
    table: TableData

    @property
    def duration(self) -> float:
        """Length [s]."""
        return self.table.duration


def sample(trajectory: Trajectory, duration: float, rate: float) -> TableData:
    """Return ``trajectory`` on the grid ``k/rate``, ``0 ≤ k/rate ≤ duration``, as a table."""
    n = int(math.floor(duration * rate + 1e-9)) + 1
    t = np.arange(n) * (1.0 / rate)   # the nodes' and the simulator's grid, bit for bit
    ref = trajectory.at(t)
    return table_from_arrays(t, np.asarray(ref.position, dtype=float),
                             np.asarray(ref.velocity, dtype=float),
                             np.asarray(ref.acceleration, dtype=float), source='task')


def task_table(task: str, *, kind: PlantKind | None, duration: float | None,
               rate: float) -> Task:
    """Return the task: a trajectory name (library defaults) or a table CSV, sampled.

    Parameters
    ----------
    task : str
        ``sine | p2p | cv | chirp``, a table file (``t, x[, v, a]``), or '' for the
        plant's default (:data:`DEFAULT_TASK`; p2p when ``kind`` is None).
    kind : PlantKind or None
        The plant's kind (None: not known).
    duration : float or None
        Length [s] (default :data:`TASK_DURATION`; a table's own length).
    rate : float
        Control rate [Hz].
    """
    if duration is not None and not (math.isfinite(duration) and duration > 0):
        raise ParameterError(f'--task-duration must be a finite number > 0, got {duration!r}')
    name = task or DEFAULT_TASK.get(kind, 'p2p')
    if name in TRAJECTORIES and name != 'table':
        traj = make_trajectory(name)
        return Task(label=name, table=sample(traj, duration or TASK_DURATION, rate))
    data = read_table_file(name, param='--task')
    if duration is not None and duration < data.duration:
        rows = data.t <= data.t[0] + duration + 1e-12
        data = table_from_arrays(data.t[rows], data.x[rows], data.v[rows], data.a[rows],
                                 source='--task')
    from motor_comp.control.trajectories import Table
    return Task(label=Path(name).name, table=sample(Table(file=name, data=data),
                                                    data.duration, rate))


def axis_limits(task: TableData, *, quantum: float, rate: float, accel_window: float,
                travel: tuple[float, float] | None = None, vmax: float | None = None,
                amax: float | None = None, umax: float | None = None,
                max_error: float | None = None) -> Limits:
    """Return the limits the nodes enforce: the ones given, the rest derived from the task.

    Derived (each only when not given):

    * ``travel``: the task's position range widened by :data:`TRAVEL_MARGIN` of its
      span at each end (at least 100 encoder counts);
    * ``vmax``: :data:`SPEED_MARGIN` × the task's peak speed + the velocity noise of
      :data:`SPEED_NOISE_COUNTS` counts (``q·rate`` each: the measured velocity is a
      position difference over one period);
    * ``amax``: :data:`ACCEL_MARGIN` × the task's peak acceleration + the noise of
      :data:`ACCEL_NOISE_COUNTS` velocity counts over ``accel_window``;
    * ``umax`` and ``max_error``: none (a wrong start model may need more voltage than
      the task; give them to bound a real drive).

    Parameters
    ----------
    task : TableData
        The task's rows (SI).
    quantum : float
        Encoder resolution [m] (or [rad]).
    rate : float
        Control rate [Hz].
    accel_window : float
        Window of the controller's measured acceleration [s].
    """
    lo, hi = float(np.min(task.x)), float(np.max(task.x))
    if travel is None:
        margin = max(TRAVEL_MARGIN * (hi - lo), 100.0 * quantum)
        travel = (lo - margin, hi + margin)
    v_noise = SPEED_NOISE_COUNTS * quantum * rate
    a_noise = ACCEL_NOISE_COUNTS * quantum * rate / accel_window
    if vmax is None:
        vmax = SPEED_MARGIN * float(np.max(np.abs(task.v))) + v_noise
    if amax is None:
        amax = ACCEL_MARGIN * float(np.max(np.abs(task.a))) + a_noise
    return Limits(travel=travel, vmax=vmax, amax=amax,
                  umax=math.inf if umax is None else umax,
                  max_error=math.inf if max_error is None else max_error)


def excitation_limits(axis: Limits, *, quantum: float, rate: float, accel_window: float,
                      bandwidth: float) -> ExcitationLimits:
    """Return the limits the excitation is designed within, a margin inside ``axis``.

    The travel loses :data:`DESIGN_CLEAR` of its span (at least
    :data:`DESIGN_CLEAR_COUNTS` counts) at each end; speed and acceleration keep
    :data:`SPEED_SHARE` and :data:`ACCEL_SHARE` of the limit less its measurement noise
    (the nodes check the *measured* values); ``umax`` :data:`SPEED_SHARE` of it; the
    excitation's ``max_error`` is the axis's.
    One-line :class:`ParameterError` when nothing is left.
    """
    lo, hi = axis.travel
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise ParameterError('autotune needs a finite --travel MIN MAX')
    clear = max(DESIGN_CLEAR * (hi - lo), DESIGN_CLEAR_COUNTS * quantum)
    v = SPEED_SHARE * (axis.vmax - SPEED_NOISE_COUNTS * quantum * rate)
    a = ACCEL_SHARE * (axis.amax - ACCEL_NOISE_COUNTS * quantum * rate / accel_window)
    if not hi - lo > 2.0 * clear:
        raise ParameterError(f'--travel {lo:g} {hi:g} is too short for an excitation: '
                             f'{clear:g} is kept clear at each end')
    if not v > 0.0:
        raise ParameterError(f'--vmax {axis.vmax:g} leaves no speed for an excitation once '
                             f'the encoder\'s velocity noise ({SPEED_NOISE_COUNTS:g} counts '
                             f'per period) is taken off')
    if not a > 0.0:
        raise ParameterError(f'--amax {axis.amax:g} leaves no acceleration for an '
                             f'excitation once the measured acceleration\'s noise is '
                             f'taken off')
    umax = SPEED_SHARE * axis.umax
    return ExcitationLimits(travel=(lo + clear, hi - clear), vmax=v, amax=a, umax=umax,
                            max_error=axis.max_error, bandwidth=bandwidth)


@dataclasses.dataclass(frozen=True)
class Segment:
    """The table one run plays and where its payload lies in it.

    Attributes
    ----------
    table : TableData
        Lead-in, payload, lead-out (``t = k/rate`` from 0).
    window : (float, float)
        Trajectory times ``[t0, t1]`` of the payload [s].
    """

    table: TableData
    window: tuple[float, float]


def _profile_rows(prof: Profile, rate: float) -> np.ndarray:
    """Rows ``(x, v, a)`` of a profile padded with rest to whole periods, both ends kept."""
    n = int(math.ceil(prof.t * rate - 1e-9))
    prof.hold(n / rate - prof.t)
    t, x, v, a = prof.sample(1.0 / rate)
    return np.stack((x[:n + 1], v[:n + 1], a[:n + 1]))


def segment_table(payload: TableData, *, rate: float, limits: Limits,
                  x_from: float | None = None, x_to: float | None = None,
                  lead: float = 0.0, tail: float = 0.0) -> Segment:
    """Return ``payload`` led in from ``x_from`` and out to ``x_to``, with rests.

    Before the payload: a rest of ``lead`` seconds at ``x_from`` (default the payload's
    start), a minimum-jerk move to the payload's start within ``limits.vmax`` and
    ``limits.amax`` (:meth:`~motor_comp.control.excitation.Profile.move`) and, after a
    move, another rest of ``lead``; after it: a move to ``x_to`` (if given) and a rest of
    ``tail``.  The payload must start and end at rest; its rows keep their values (only
    their times shift by a whole number of periods).
    """
    dt = 1.0 / rate
    if abs(payload.v[0]) > 1e-12 or abs(payload.v[-1]) > 1e-12:
        raise ParameterError('a segment\'s payload must start and end at rest')
    start, end = float(payload.x[0]), float(payload.x[-1])
    pre = Profile(start if x_from is None else float(x_from))
    pre.hold(lead)
    if x_from is not None and x_from != start:
        pre.move(start, vmax=limits.vmax, amax=limits.amax)
        pre.hold(lead)
    post = Profile(end)
    if x_to is not None and x_to != end:
        post.move(float(x_to), vmax=limits.vmax, amax=limits.amax)
    post.hold(tail)
    # the lead-in's last row is the payload's first, the lead-out's first its last
    before = _profile_rows(pre, rate)[:, :-1]
    after = _profile_rows(post, rate)[:, 1:]
    x, v, a = (np.concatenate((before[i], col, after[i]))
               for i, col in enumerate((payload.x, payload.v, payload.a)))
    t = np.arange(x.size) * dt   # k·(1/rate), as the nodes evaluate it
    t0 = before.shape[1] * dt
    return Segment(table=table_from_arrays(t, x, v, a, source='segment'),
                   window=(t0, t0 + payload.duration))


@dataclasses.dataclass(frozen=True)
class TaskScore:
    """Tracking of one task run (SI: m), DESIGN.md §6 definitions.

    Attributes
    ----------
    rms_error, max_error : float
        RMS and largest ``|x_ref − x|`` [m].
    max_glitch, mean_glitch : float or None
        Largest and mean quadrant glitch [m] (None without a reversal).
    """

    rms_error: float
    max_error: float
    max_glitch: float | None
    mean_glitch: float | None

    @classmethod
    def of(cls, run: Any) -> 'TaskScore':
        """Score a run (:class:`~motor_comp.logs.run.Run` with reference and position)."""
        from motor_comp.analysis.metrics import compute_metrics
        m = compute_metrics(run)
        return cls(rms_error=float(m.rms_error), max_error=float(m.max_error),
                   max_glitch=None if m.max_glitch is None else float(m.max_glitch),
                   mean_glitch=None if m.mean_glitch is None else float(m.mean_glitch))

    def as_dict(self) -> dict[str, float | None]:
        """JSON form (``task.<label>`` of ``autotune --json``)."""
        return dataclasses.asdict(self)


def recovered(none: float | None, fitted: float | None, true: float | None) -> float | None:
    """Share of the reduction the true model gives that the fitted one recovers.

    ``(none − fitted) / (none − true)``; None when a value is missing or the true model
    reduces nothing.
    """
    if none is None or fitted is None or true is None or not none - true > 0.0:
        return None
    return (none - fitted) / (none - true)


__all__ = ['DEFAULT_CONTROLLER', 'DEFAULT_TASK', 'LEAD', 'Segment', 'TAIL', 'TASK_DURATION',
           'Task', 'TaskScore', 'axis_limits', 'excitation_limits', 'recovered', 'sample',
           'segment_table', 'task_table']
