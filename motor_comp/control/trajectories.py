"""Reference trajectories with analytic position, velocity and acceleration.

Five families (DESIGN.md §4):

* :class:`Sinusoid` — slow sine with reversals (Chiew et al. §V: amplitude 3 mm);
  ``x = x0 + A·(1 − cos 2πt/P)`` starts at rest and reverses every ``P/2``.
* :class:`PointToPoint` — smooth back-and-forth moves with dwell (Tan 2002 Fig. 2/10),
  minimum-jerk quintic ``s(τ) = 10τ³ − 15τ⁴ + 6τ⁵``.
* :class:`ConstantVelocity` — back-and-forth passes at a list of constant speeds with
  constant-acceleration ramps (friction-curve identification).
* :class:`Chirp` — linear chirp with a raised-cosine fade-in, rich excitation for
  fitting.
* :class:`Table` — a CSV ``t, x[, v, a]`` (SI), e.g. an identification trajectory of
  ``motor-comp excite``; between its rows a quintic Hermite polynomial through the
  rows' position, velocity and acceleration.

Every trajectory packs into one float vector whose first element is the kind code;
:func:`traj_eval` (njit) evaluates any packed trajectory at one time.  The in-process
simulator calls it inside its compiled loop and ``.at(t)`` calls it from Python (the
ROS ``trajectory_node``), so both drivers get bit-identical references.
"""
from __future__ import annotations

import dataclasses
import enum
import functools
import os
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.control._jitcache import JIT_INLINE, JIT_OPTIONS
from motor_comp.errors import ParameterError, check_finite, check_nonnegative, \
    check_positive


class TrajectoryKind(enum.IntEnum):
    """Kind code stored in element 0 of a packed trajectory."""

    SINUSOID = 0
    POINT_TO_POINT = 1
    CONSTANT_VELOCITY = 2
    CHIRP = 3
    TABLE = 4


@dataclasses.dataclass(frozen=True)
class Reference:
    """Desired position [m], velocity [m/s] and acceleration [m/s²] (scalars or arrays)."""

    position: Any
    velocity: Any
    acceleration: Any


# ---- compiled evaluation ----------------------------------------------------------
@njit(**JIT_INLINE)
def _sinusoid(T, t):
    amp, period, x0 = T[1], T[2], T[3]
    w = 2.0 * np.pi / period
    return (x0 + amp * (1.0 - np.cos(w * t)), amp * w * np.sin(w * t),
            amp * w * w * np.cos(w * t))


@njit(**JIT_INLINE)
def _point_to_point(T, t):
    dist, t_move, t_dwell, x0 = T[1], T[2], T[3], T[4]
    cycle = 2.0 * (t_move + t_dwell)
    tc = t % cycle if t >= 0.0 else 0.0
    half = t_move + t_dwell
    sign = 1.0
    start = x0
    if tc >= half:
        tc -= half
        sign = -1.0
        start = x0 + dist
    if tc >= t_move:
        return start + sign * dist, 0.0, 0.0
    tau = tc / t_move
    # minimum-jerk quintic and its derivatives (zero velocity/acceleration at both ends)
    s = tau ** 3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
    ds = 30.0 * tau * tau * (1.0 - tau) ** 2
    dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau)
    return (start + sign * dist * s, sign * dist * ds / t_move,
            sign * dist * dds / (t_move * t_move))


@njit(**JIT_INLINE)
def _segments(T, t):
    # packed: [kind, n, period, t0[n], p0[n], v0[n], a[n]]
    n = int(T[1])
    period = T[2]
    tc = t % period if t >= 0.0 else 0.0
    base = 3
    # the segment starts are sorted: binary search for the last start <= tc
    lo, hi = 0, n - 1
    while lo < hi:
        mid = (lo + hi + 1) // 2
        if T[base + mid] <= tc:
            lo = mid
        else:
            hi = mid - 1
    tau = tc - T[base + lo]
    p0 = T[base + n + lo]
    v0 = T[base + 2 * n + lo]
    a = T[base + 3 * n + lo]
    return p0 + v0 * tau + 0.5 * a * tau * tau, v0 + a * tau, a


@njit(**JIT_INLINE)
def _chirp(T, t):
    amp, f0, f1, dur, t_fade, x0 = T[1], T[2], T[3], T[4], T[5], T[6]
    k = (f1 - f0) / dur
    if t < dur:
        ph = 2.0 * np.pi * (f0 * t + 0.5 * k * t * t)
        dph = 2.0 * np.pi * (f0 + k * t)
        ddph = 2.0 * np.pi * k
    else:  # keep the final frequency after the sweep (phase stays continuous)
        ph = 2.0 * np.pi * (f0 * dur + 0.5 * k * dur * dur + f1 * (t - dur))
        dph = 2.0 * np.pi * f1
        ddph = 0.0
    if t < t_fade:
        wf = np.pi / t_fade
        g = 0.5 * (1.0 - np.cos(wf * t))
        dg = 0.5 * wf * np.sin(wf * t)
        ddg = 0.5 * wf * wf * np.cos(wf * t)
    else:
        g, dg, ddg = 1.0, 0.0, 0.0
    sn, cs = np.sin(ph), np.cos(ph)
    pos = x0 + amp * g * sn
    vel = amp * (dg * sn + g * dph * cs)
    acc = amp * (ddg * sn + 2.0 * dg * dph * cs + g * ddph * cs - g * dph * dph * sn)
    return pos, vel, acc


@njit(**JIT_INLINE)
def _table(T, t):
    # packed: [kind, n, t[n], x[n], v[n], a[n]]; quintic Hermite between rows
    n = int(T[1])
    it, ix, iv, ia = 2, 2 + n, 2 + 2 * n, 2 + 3 * n
    t = t + T[it]                  # the table's time starts at its first row
    if t <= T[it]:
        return T[ix], T[iv], T[ia]
    if t >= T[it + n - 1]:        # after the last row: held there, at rest
        if t == T[it + n - 1]:
            return T[ix + n - 1], T[iv + n - 1], T[ia + n - 1]
        return T[ix + n - 1], 0.0, 0.0
    lo, hi = 0, n - 1
    while hi - lo > 1:            # bisection: rows may have any (increasing) spacing
        mid = (lo + hi) // 2
        if T[it + mid] <= t:
            lo = mid
        else:
            hi = mid
    h = T[it + hi] - T[it + lo]
    tau = t - T[it + lo]
    x0, v0, a0 = T[ix + lo], T[iv + lo], T[ia + lo]
    # the quintic with (x, v, a) of both rows at its ends: x0 + v0·τ + a0·τ²/2 +
    # c3·τ³ + c4·τ⁴ + c5·τ⁵, its coefficients from the end conditions at τ = h
    dx = T[ix + hi] - x0 - h * (v0 + 0.5 * h * a0)
    dv = (T[iv + hi] - v0 - h * a0) * h
    da = (T[ia + hi] - a0) * h * h
    c3 = (10.0 * dx - 4.0 * dv + 0.5 * da) / (h * h * h)
    c4 = (-15.0 * dx + 7.0 * dv - da) / (h * h * h * h)
    c5 = (6.0 * dx - 3.0 * dv + 0.5 * da) / (h * h * h * h * h)
    pos = x0 + tau * (v0 + tau * (0.5 * a0 + tau * (c3 + tau * (c4 + tau * c5))))
    vel = v0 + tau * (a0 + tau * (3.0 * c3 + tau * (4.0 * c4 + tau * 5.0 * c5)))
    acc = a0 + tau * (6.0 * c3 + tau * (12.0 * c4 + tau * 20.0 * c5))
    return pos, vel, acc


@njit(**JIT_INLINE)
def traj_eval(T, t):
    """Evaluate a packed trajectory ``T`` at time ``t`` [s] → (x [m], v [m/s], a [m/s²])."""
    kind = int(T[0])
    if kind == 0:
        return _sinusoid(T, t)
    if kind == 1:
        return _point_to_point(T, t)
    if kind == 2:
        return _segments(T, t)
    if kind == 4:
        return _table(T, t)
    return _chirp(T, t)


@njit(**JIT_OPTIONS)
def traj_eval_many(T, t):
    """Evaluate ``T`` at every time in the array ``t``; returns three arrays."""
    n = t.shape[0]
    p = np.empty(n)
    v = np.empty(n)
    a = np.empty(n)
    for i in range(n):
        p[i], v[i], a[i] = traj_eval(T, t[i])
    return p, v, a


# ---- trajectory objects -----------------------------------------------------------
class Trajectory:
    """Base class: a frozen description that packs into a float vector."""

    kind: TrajectoryKind
    name: str

    def packed(self) -> np.ndarray:  # pragma: no cover - abstract
        """Packed float vector for :func:`traj_eval`."""
        raise NotImplementedError

    @functools.cached_property
    def _packed(self) -> np.ndarray:
        # packed once per (immutable) trajectory: the ROS node calls .at() every period
        return self.packed()

    def at(self, t: Any) -> Reference:
        """Evaluate the reference at time(s) ``t`` [s] (scalar → floats, array → arrays)."""
        packed = self._packed
        if np.ndim(t) == 0:
            p, v, a = traj_eval(packed, float(t))
            return Reference(float(p), float(v), float(a))
        p, v, a = traj_eval_many(packed, np.ascontiguousarray(t, dtype=float))
        return Reference(p, v, a)

    def params(self) -> dict[str, Any]:
        """Parameters as plain values (metadata, CLI)."""
        out = {'kind': self.name}
        for f in dataclasses.fields(self):
            val = getattr(self, f.name)
            out[f.name] = list(val) if isinstance(val, tuple) else val
        return out


@dataclasses.dataclass(frozen=True)
class Sinusoid(Trajectory):
    """``x = x0 + A·(1 − cos 2πt/P)``: at rest at t = 0, reversals every ``P/2``.

    Parameters
    ----------
    amplitude : float
        A [m] (Chiew et al.: 3 mm), > 0; the stroke is 2A.
    period : float
        P [s], > 0.  Default 2 s: peak speed 2πA/P ≈ 9.4 mm/s, a reversal every second
        (Chiew's 1 mm/s-scale sine, sped up so that a short run holds many reversals).
    offset : float
        x0 [m].
    """

    amplitude: float = 3e-3
    period: float = 2.0
    offset: float = 0.0
    kind = TrajectoryKind.SINUSOID
    name = 'sine'

    def __post_init__(self) -> None:
        check_positive('sine.amplitude [m]', self.amplitude)
        check_positive('sine.period [s]', self.period)
        check_finite('sine.offset [m]', self.offset)

    def packed(self) -> np.ndarray:
        """Packed float vector for :func:`traj_eval`."""
        return np.array([self.kind, self.amplitude, self.period, self.offset], dtype=float)


@dataclasses.dataclass(frozen=True)
class PointToPoint(Trajectory):
    """Out-and-back minimum-jerk moves of ``distance`` with a dwell after each move.

    Parameters
    ----------
    distance : float
        Stroke [m] (sign gives the first direction), non-zero.
    move_time : float
        Duration of each move [s], > 0; peak speed 1.875·distance/move_time.
    dwell : float
        Rest after each move [s], >= 0.
    offset : float
        Start position [m].
    """

    distance: float = 0.05
    move_time: float = 0.5
    dwell: float = 0.5
    offset: float = 0.0
    kind = TrajectoryKind.POINT_TO_POINT
    name = 'p2p'

    def __post_init__(self) -> None:
        if check_finite('p2p.distance [m]', self.distance) == 0.0:
            raise ParameterError('p2p.distance [m] must be non-zero')
        check_positive('p2p.move_time [s]', self.move_time)
        check_nonnegative('p2p.dwell [s]', self.dwell)
        check_finite('p2p.offset [m]', self.offset)

    def packed(self) -> np.ndarray:
        """Packed float vector for :func:`traj_eval`."""
        return np.array([self.kind, self.distance, self.move_time, self.dwell, self.offset],
                        dtype=float)


@dataclasses.dataclass(frozen=True)
class ConstantVelocity(Trajectory):
    """Back-and-forth passes over ``stroke`` at each speed, with constant-acceleration ramps.

    Parameters
    ----------
    speeds : tuple of float
        Cruise speeds [m/s], each > 0 (one forward and one backward pass each).
    stroke : float
        Travel of each pass [m], > 0.
    acceleration : float
        Ramp acceleration [m/s²], > 0; a speed whose ramps exceed the stroke is rejected.
    offset : float
        Start position [m].
    """

    speeds: tuple = (0.002, 0.005, 0.01, 0.02, 0.05)
    stroke: float = 0.02
    acceleration: float = 0.5
    offset: float = 0.0
    kind = TrajectoryKind.CONSTANT_VELOCITY
    name = 'cv'

    def __post_init__(self) -> None:
        try:
            speeds = tuple(float(s) for s in np.atleast_1d(self.speeds))
        except (TypeError, ValueError):
            raise ParameterError('cv.speeds must be a list of numbers [m/s]') from None
        if not speeds:
            raise ParameterError('cv.speeds must not be empty')
        for i, s in enumerate(speeds):
            check_positive(f'cv.speeds[{i}] [m/s]', s)
        object.__setattr__(self, 'speeds', speeds)
        stroke = check_positive('cv.stroke [m]', self.stroke)
        acc = check_positive('cv.acceleration [m/s²]', self.acceleration)
        check_finite('cv.offset [m]', self.offset)
        for s in speeds:
            if s * s / acc > stroke:
                raise ParameterError(
                    f'cv: speed {s:g} m/s needs {s * s / acc:g} m of ramps, more than the '
                    f'stroke {stroke:g} m (raise cv.acceleration or cv.stroke)')

    def _segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        t0, p0, v0, a = [], [], [], []
        t, p = 0.0, self.offset
        for s in self.speeds:
            for d in (1.0, -1.0):
                t_ramp = s / self.acceleration
                cruise = (self.stroke - s * t_ramp) / s
                for acc, dur, vstart in ((d * self.acceleration, t_ramp, 0.0),
                                         (0.0, cruise, d * s),
                                         (-d * self.acceleration, t_ramp, d * s)):
                    t0.append(t)
                    p0.append(p)
                    v0.append(vstart)
                    a.append(acc)
                    p += vstart * dur + 0.5 * acc * dur * dur
                    t += dur
        return np.array(t0), np.array(p0), np.array(v0), np.array(a)

    @property
    def period(self) -> float:
        """Duration of all passes [s]; the pattern repeats after it."""
        return float(sum(2.0 * (self.stroke / s + s / self.acceleration)
                         for s in self.speeds))

    def packed(self) -> np.ndarray:
        """Packed float vector for :func:`traj_eval`."""
        t0, p0, v0, a = self._segments()
        n = t0.shape[0]
        return np.concatenate(([float(self.kind), float(n), self.period], t0, p0, v0, a))


@dataclasses.dataclass(frozen=True)
class Chirp(Trajectory):
    """Linear chirp ``x0 + A·g(t)·sin φ(t)`` with ``φ' = 2π(f0 + (f1−f0)·t/T)``.

    ``g`` is a raised-cosine fade-in from 0 to 1 over ``fade`` seconds.

    After ``duration`` the final frequency ``f1`` continues with a continuous phase.

    Parameters
    ----------
    amplitude : float
        A [m], > 0.
    f_start, f_end : float
        Start and end frequency [Hz], > 0.
    duration : float
        Sweep time T [s], > 0.
    fade : float
        Fade-in time [s], > 0 (the axis starts at rest).
    offset : float
        Centre position [m].
    """

    amplitude: float = 1e-3
    f_start: float = 0.2
    f_end: float = 10.0
    duration: float = 20.0
    fade: float = 1.0
    offset: float = 0.0
    kind = TrajectoryKind.CHIRP
    name = 'chirp'

    def __post_init__(self) -> None:
        check_positive('chirp.amplitude [m]', self.amplitude)
        check_positive('chirp.f_start [Hz]', self.f_start)
        check_positive('chirp.f_end [Hz]', self.f_end)
        check_positive('chirp.duration [s]', self.duration)
        check_positive('chirp.fade [s]', self.fade)
        check_finite('chirp.offset [m]', self.offset)

    def packed(self) -> np.ndarray:
        """Packed float vector for :func:`traj_eval`."""
        return np.array([self.kind, self.amplitude, self.f_start, self.f_end, self.duration,
                         self.fade, self.offset], dtype=float)


#: fewest rows of a table (a position-only table is differentiated by a quintic spline)
TABLE_MIN_ROWS = 6
#: column names of a table CSV header (SI: s, m, m/s, m/s²), and their long forms
TABLE_COLUMNS = ('t', 'x', 'v', 'a')
_COLUMN_ALIASES = {'t': 't', 'time': 't', 'x': 'x', 'position': 'x', 'v': 'v',
                   'velocity': 'v', 'a': 'a', 'acceleration': 'a'}


@dataclasses.dataclass(frozen=True)
class TableData:
    """The rows of a trajectory table, complete (SI units).

    Attributes
    ----------
    t : ndarray
        Times [s], strictly increasing.
    x, v, a : ndarray
        Position [m], velocity [m/s], acceleration [m/s²] at each time.
    derived : tuple of str
        The columns the file did not have (``v``, ``a``), derived from the others.
    """

    t: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    derived: tuple = ()

    @property
    def duration(self) -> float:
        """Time from the first row to the last [s]."""
        return float(self.t[-1] - self.t[0])


def table_from_arrays(t: Any, x: Any, v: Any = None, a: Any = None, *,
                      source: str = 'table') -> TableData:
    """Check a table's columns and derive the missing velocity and acceleration.

    A missing ``v`` is the derivative of the quintic interpolating spline through
    ``(t, x)`` and a missing ``a`` that of the cubic one through ``(t, v)``
    (``scipy.interpolate.make_interp_spline``): smooth derivatives that keep every
    given position exact (a table of a noisy measured position should be filtered
    first, or carry its own ``v`` and ``a``).  Errors name ``source`` and the row,
    never a cell's content.
    """
    from scipy.interpolate import make_interp_spline
    cols = {'t': t, 'x': x, 'v': v, 'a': a}
    arrays: dict[str, np.ndarray | None] = {}
    for name, col in cols.items():
        if col is None:
            arrays[name] = None
            continue
        arr = np.asarray(col, dtype=float)
        if arr.ndim != 1:
            raise ParameterError(f'{source}: column {name} must be one-dimensional')
        arrays[name] = arr
    tt, xx = arrays['t'], arrays['x']
    if tt is None or xx is None:
        raise ParameterError(f'{source}: a table needs the columns t and x')
    n = tt.shape[0]
    for name, arr in arrays.items():
        if arr is not None and arr.shape[0] != n:
            raise ParameterError(f'{source}: column {name} has {arr.shape[0]} rows, t has {n}')
    if n < TABLE_MIN_ROWS:
        raise ParameterError(f'{source}: too short: {n} rows, a table needs at least '
                             f'{TABLE_MIN_ROWS}')
    for name, arr in arrays.items():
        if arr is not None and not np.all(np.isfinite(arr)):
            row = int(np.flatnonzero(~np.isfinite(arr))[0])
            raise ParameterError(f'{source}: column {name} is not finite (NaN or inf) in '
                                 f'data row {row + 1}')
    bad = np.flatnonzero(np.diff(tt) <= 0.0)
    if bad.size:
        raise ParameterError(f'{source}: time is not strictly increasing at data row '
                             f'{int(bad[0]) + 2}')
    derived = []
    vv, aa = arrays['v'], arrays['a']
    if vv is None:
        vv = make_interp_spline(tt, xx, k=5).derivative()(tt)
        derived.append('v')
    if aa is None:
        aa = make_interp_spline(tt, vv, k=3).derivative()(tt)
        derived.append('a')
    return TableData(t=tt.copy(), x=xx.copy(), v=np.asarray(vv, dtype=float).copy(),
                     a=np.asarray(aa, dtype=float).copy(), derived=tuple(derived))


def parse_table(text: str, *, source: str = 'table') -> TableData:
    """Parse the text of a table CSV: a header naming ``t, x[, v, a]``, numeric rows.

    Lines starting with ``#`` are comments.  The header names the columns (any order;
    ``time``, ``position``, ``velocity``, ``acceleration`` also accepted; a unit
    suffix such as ``t_s`` or ``x [m]`` is ignored); without a header the columns are
    ``t, x[, v, a]`` in that order.  Errors are one line naming ``source`` and the row
    or column, never quoting the file's content (it may come from an untrusted
    parameter).
    """
    rows: list[list[str]] = []
    for line in text.splitlines():
        line = line.strip()
        if not line or line.startswith('#'):
            continue
        rows.append([c.strip() for c in line.split(',')])
    if not rows:
        raise ParameterError(f'{source}: empty trajectory table')
    names = _header(rows[0], source)
    if names is None:
        width = len(rows[0])
        if not 2 <= width <= 4:
            raise ParameterError(f'{source}: expected the columns t, x[, v, a]; the first '
                                 f'row has {width} columns and no header naming them')
        names = TABLE_COLUMNS[:width]
        data_rows = rows
    else:
        data_rows = rows[1:]
    missing = [c for c in ('t', 'x') if c not in names]
    if missing:
        raise ParameterError(f'{source}: missing column {" and ".join(missing)} (a table '
                             f'has the columns t, x[, v, a])')
    values = np.empty((len(data_rows), len(names)))
    for i, row in enumerate(data_rows):
        if len(row) != len(names):
            raise ParameterError(f'{source}: data row {i + 1} has {len(row)} columns, the '
                                 f'header {len(names)}')
        for j, cell in enumerate(row):
            try:
                values[i, j] = float(cell)
            except ValueError:
                raise ParameterError(f'{source}: data row {i + 1}, column {names[j]}: not '
                                     f'a number') from None
    cols = {name: values[:, j] for j, name in enumerate(names)}
    return table_from_arrays(cols['t'], cols['x'], cols.get('v'), cols.get('a'),
                             source=source)


def _header(row: list[str], source: str) -> tuple[str, ...] | None:
    """Column names of a header row, or None when the row is numbers."""
    try:
        [float(c) for c in row]
        return None
    except ValueError:
        pass
    names = []
    for j, cell in enumerate(row):
        key = cell.lower().replace('[', ' ').replace('(', ' ').replace('_', ' ').split()
        name = _COLUMN_ALIASES.get(key[0]) if key else None
        if name is None:
            raise ParameterError(f'{source}: header column {j + 1} is not one of t, x, v, a')
        if name in names:
            raise ParameterError(f'{source}: header names column {name} twice')
        names.append(name)
    return tuple(names)


def read_table_file(path: str | Path, *, param: str = 'traj.file') -> TableData:
    """Read and parse a table CSV a user named (a regular file under the size bound).

    One-line :class:`ParameterError` naming ``param`` and the file, never its content
    (the reading rules of :mod:`motor_comp.param_files`, with the file's own
    directory allowed).
    """
    from motor_comp.param_files import read_text
    text = str(path)
    if not text.strip():
        raise ParameterError(f'{param}: a table trajectory needs a file (--set '
                             f'{param}=F.csv)')
    # the user named this file on the command line: its own directory is allowed
    real_dir = Path(os.path.realpath(Path(text).expanduser())).parent
    real, body = read_text(param, text, (real_dir,))
    return parse_table(body, source=f'{param}: {real}')


@dataclasses.dataclass(frozen=True)
class Table(Trajectory):
    """A trajectory table ``t, x[, v, a]`` (DESIGN.md §4), played from its first row.

    Between rows the reference is the quintic Hermite polynomial through both rows'
    position, velocity and acceleration (so ``x``, ``v``, ``a`` stay each other's
    derivatives and every row is met exactly); before the first row the first is held,
    after the last the last position is held at rest.

    Parameters
    ----------
    file : str
        The CSV file (:func:`parse_table`); read when ``data`` is not given.
    data : TableData, optional
        The rows themselves (a table read under other rules — ``trajectory_node`` reads
        its file with :mod:`motor_comp.param_files` — or designed in memory).
    """

    file: str = ''
    data: TableData | None = dataclasses.field(default=None, repr=False, compare=False)
    kind = TrajectoryKind.TABLE
    name = 'table'

    def __post_init__(self) -> None:
        if not isinstance(self.file, str):
            raise ParameterError(f'table.file must be a file name, got {self.file!r}')
        if self.data is None:
            object.__setattr__(self, 'data', read_table_file(self.file))
        elif not isinstance(self.data, TableData):
            raise ParameterError('table data must be a TableData (parse_table)')

    @property
    def duration(self) -> float:
        """Time from the first row to the last [s]."""
        return self.data.duration

    def params(self) -> dict[str, Any]:
        """Kind and file (the rows stay in the file)."""
        return {'kind': self.name, 'file': self.file}

    def packed(self) -> np.ndarray:
        """Packed float vector for :func:`traj_eval`."""
        d = self.data
        return np.concatenate(([float(self.kind), float(d.t.shape[0])], d.t, d.x, d.v, d.a))


def write_table(path: str | Path, data: TableData, *, comments: tuple = ()) -> None:
    """Write a table CSV ``t,x,v,a`` (17 significant digits) with ``#`` comment lines.

    :func:`parse_table` reads it back exactly (a float written with ``repr`` parses to
    the same float).
    """
    import io
    buf = io.StringIO()
    for c in comments:
        buf.write(f'# {c}\n')
    buf.write('t,x,v,a\n')
    for row in zip(data.t, data.x, data.v, data.a):
        buf.write(','.join(repr(float(c)) for c in row) + '\n')
    with Path(path).open('w', encoding='utf-8') as fh:
        fh.write(buf.getvalue())


TRAJECTORIES: dict[str, type[Trajectory]] = {
    'sine': Sinusoid, 'p2p': PointToPoint, 'cv': ConstantVelocity, 'chirp': Chirp,
    'table': Table,
}


def make_trajectory(kind: str, **params: Any) -> Trajectory:
    """Build a trajectory by name (``sine``, ``p2p``, ``cv``, ``chirp``, ``table``)."""
    try:
        cls = TRAJECTORIES[kind]
    except KeyError:
        raise ParameterError(f'unknown trajectory {kind!r} (known: '
                             f'{", ".join(TRAJECTORIES)})') from None
    names = {f.name for f in dataclasses.fields(cls)}
    for key in params:
        if key not in names:
            raise ParameterError(f'trajectory {kind}: unknown parameter {key!r} '
                                 f'(known: {", ".join(sorted(names))})')
    try:
        return cls(**params)
    except TypeError as exc:
        raise ParameterError(f'trajectory {kind}: {exc}') from None


def default_trajectory(plant_kind: str) -> Trajectory:
    """Return the study's trajectory: p2p moves on the PMLM (Tan), slow sine on the ball-screw."""
    return PointToPoint() if plant_kind == 'pmlm' else Sinusoid()


def trajectory_from_dict(data: Mapping[str, Any]) -> Trajectory:
    """Build from ``{'kind': name, **params}`` (the inverse of :meth:`Trajectory.params`)."""
    data = dict(data)
    kind = data.pop('kind', None)
    if not isinstance(kind, str):
        raise ParameterError('trajectory needs a "kind" string')
    return make_trajectory(kind, **data)
