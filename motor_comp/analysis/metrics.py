"""Run metrics: tracking error, quadrant glitches, point-to-point moves, control effort.

All errors are ``e = x_ref − x`` [m] (DESIGN.md §6).  Averages are time integrals
(``sqrt(∫e² dt / T)`` with the sample-midpoint rule), so irregularly sampled logs (e.g.
host-polled drives) are not biased towards densely sampled stretches; for uniform
sampling this equals the sample RMS up to the half weight of the two end samples.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, ClassVar, Iterator

import numpy as np

from motor_comp.analysis.glitches import Glitch, find_glitches, reference_velocity, reversals
from motor_comp.errors import InputFileError, ParameterError, check_positive
from motor_comp.logs.run import Run


@dataclasses.dataclass(frozen=True)
class Segment:
    """Tracking error over one stroke between reference reversals [s], [m]."""

    t_start: float
    t_end: float
    rms_error: float
    max_error: float


@dataclasses.dataclass(frozen=True)
class Move:
    """A point-to-point move: reference moves, then dwells.

    Attributes
    ----------
    t_start, t_end : float
        Start and end of the reference motion [s].
    distance : float
        Commanded displacement [m] (signed).
    overshoot : float
        Largest excursion beyond the target in the direction of motion during the
        dwell [m] (0 if none).
    overshoot_ratio : float
        ``overshoot / |distance|``.
    settling_time : float or None
        Time after ``t_end`` from which ``|x − target|`` stays within the band [s];
        None if it does not settle before the dwell ends.
    band : float
        The settling band [m].
    """

    t_start: float
    t_end: float
    distance: float
    overshoot: float
    overshoot_ratio: float
    settling_time: float | None
    band: float


@dataclasses.dataclass(frozen=True)
class RunMetrics:
    """Metrics of one run (SI units; see :func:`compute_metrics`)."""

    name: str
    samples: int
    duration: float
    rms_error: float
    max_error: float
    mean_error: float
    glitch_window: float
    glitches: tuple[Glitch, ...]
    max_glitch: float | None
    mean_glitch: float | None
    segments: tuple[Segment, ...]
    moves: tuple[Move, ...]
    rms_voltage: float | None
    max_voltage: float | None
    chattering: float | None
    chattering_ratio: float | None
    chatter_cutoff: float

    @property
    def glitch_count(self) -> int:
        """Number of reversals with a glitch."""
        return len(self.glitches)

    def as_dict(self, *, records: bool = True) -> dict[str, Any]:
        """JSON-ready dict (DESIGN.md §6 keys: rms_error, max_error, max_glitch, …).

        ``records=False`` leaves out the per-reversal lists (``glitches``,
        ``segments``, ``moves``), which :meth:`records` yields one by one instead.
        """
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
             if not (f.name in self.RECORDS)}
        if records:
            for name, items in self.records():
                d[name] = list(items)
        d['glitch_count'] = self.glitch_count
        return d

    RECORDS: ClassVar[tuple[str, ...]] = ('glitches', 'segments', 'moves')

    def records(self) -> Iterator[tuple[str, Iterator[dict[str, Any]]]]:
        """Yield ``(name, dicts)`` for glitches, segments and moves, lazily."""
        yield 'glitches', (g.as_dict() for g in self.glitches)
        yield 'segments', (dataclasses.asdict(s) for s in self.segments)
        yield 'moves', (dataclasses.asdict(m) for m in self.moves)


def _weights(t: np.ndarray) -> np.ndarray:
    """Midpoint-rule integration weights [s] of the samples."""
    if t.size < 2:
        return np.ones_like(t)
    w = np.empty_like(t)
    dt = np.diff(t)
    w[0] = dt[0] / 2
    w[-1] = dt[-1] / 2
    w[1:-1] = (dt[:-1] + dt[1:]) / 2
    return w


def _rms(x: np.ndarray, w: np.ndarray) -> float:
    total = float(np.sum(w))
    if x.size == 0:
        return math.nan
    if total <= 0:
        return float(np.sqrt(np.mean(x * x)))
    return float(np.sqrt(np.sum(w * x * x) / total))


def chattering(t: np.ndarray, u: np.ndarray, *, cutoff: float) -> float | None:
    """RMS of the content of ``u`` at frequencies ≥ ``cutoff`` [Hz] (same unit as ``u``).

    Computed from the DFT by Parseval's theorem on a uniform grid (irregular samples
    are linearly interpolated onto the median step first).  None when ``cutoff`` is not
    below the Nyquist frequency.
    """
    if t.size < 4:
        return None
    dt = float(np.median(np.diff(t)))
    if not dt > 0:
        return None
    if cutoff >= 0.5 / dt:
        return None
    d = np.diff(t)
    if np.max(d) > 1.01 * np.min(d):
        grid = t[0] + dt * np.arange(int((t[-1] - t[0]) / dt) + 1)
        u = np.interp(grid, t, u)
    n = u.size
    spec = np.fft.rfft(u - np.mean(u))
    f = np.fft.rfftfreq(n, dt)
    c = np.full(f.size, 2.0)
    c[0] = 1.0
    if n % 2 == 0:
        c[-1] = 1.0
    hi = f >= cutoff
    return float(np.sqrt(np.sum(c[hi] * np.abs(spec[hi]) ** 2)) / n)


def _segments(t: np.ndarray, e: np.ndarray, w: np.ndarray, tr: np.ndarray
              ) -> tuple[Segment, ...]:
    edges = np.concatenate(([t[0]], tr, [t[-1] + 1e-12]))
    idx = np.searchsorted(t, edges, side='left')
    idx[-1] = t.size        # the last stroke ends with the last sample, even where
    #                         1e-12 s is below the spacing of t (t > ~8000 s)
    out = []
    for k in range(edges.size - 1):
        a, b = idx[k], idx[k + 1]
        if b <= a:
            continue
        ae = np.abs(e[a:b])
        out.append(Segment(t_start=float(edges[k]), t_end=float(min(edges[k + 1], t[-1])),
                           rms_error=_rms(e[a:b], w[a:b]), max_error=float(np.max(ae))))
    return tuple(out)


def _moves(t: np.ndarray, x: np.ndarray, ref: np.ndarray, v: np.ndarray, *,
           zero_tol: float, settle_tolerance: float, settle_band: float | None,
           min_dwell: float) -> tuple[Move, ...]:
    vmax = float(np.max(np.abs(v))) if v.size else 0.0
    if vmax == 0.0:
        return ()
    moving = np.abs(v) > zero_tol * vmax
    edges = np.flatnonzero(np.diff(moving.astype(np.int8)))
    starts = edges[~moving[edges]] + 1           # first moving sample
    ends = edges[moving[edges]] + 1              # first resting sample
    if moving[0]:
        starts = np.concatenate(([0], starts))
    out = []
    for s in starts:
        k = np.searchsorted(ends, s, side='right')
        if k == ends.size:
            break
        e = int(ends[k])
        q = np.searchsorted(starts, e, side='right')
        stop = int(starts[q]) if q < starts.size else t.size
        if t[stop - 1] - t[e] < min_dwell:
            continue
        target = float(ref[e])
        origin = float(ref[s - 1] if s > 0 else ref[s])
        dist = target - origin
        if dist == 0.0:
            continue
        dev = x[e:stop] - target
        over = max(0.0, float(np.max(dev * np.sign(dist))))
        band = settle_band if settle_band is not None else settle_tolerance * abs(dist)
        outside = np.flatnonzero(np.abs(dev) > band)
        if outside.size == 0:
            ts: float | None = 0.0
        elif outside[-1] == dev.size - 1:
            ts = None
        else:
            ts = float(t[e + outside[-1] + 1] - t[e])
        out.append(Move(t_start=float(t[s]), t_end=float(t[e]), distance=dist,
                        overshoot=over, overshoot_ratio=over / abs(dist), settling_time=ts,
                        band=float(band)))
    return tuple(out)


def compute_metrics(run: Run, *, glitch_window: float = 0.2, settle_tolerance: float = 0.02,
                    settle_band: float | None = None, min_dwell: float = 0.01,
                    chatter_cutoff: float = 100.0, zero_tol: float = 1e-6) -> RunMetrics:
    """Metrics of a run with a reference.

    Parameters
    ----------
    run : Run
        Needs ``reference`` and ``position``; ``reference_velocity`` is differentiated
        from the reference when absent; ``voltage`` is optional.
    glitch_window : float
        ``W`` of the quadrant-glitch definition [s] (DESIGN.md §6).
    settle_tolerance : float
        Settling band as a fraction of the move distance (classic 2 % criterion).
    settle_band : float, optional
        Absolute settling band [m]; overrides ``settle_tolerance``.
    min_dwell : float
        Shortest rest after a reference motion that makes it a point-to-point move [s].
    chatter_cutoff : float
        Frequency above which voltage content counts as chattering [Hz].
    zero_tol : float
        Reference speed below ``zero_tol·max|v_ref|`` counts as rest.

    Returns
    -------
    RunMetrics
        Whole-run RMS/max/mean error [m]; glitches and their max/mean [m] (None without
        reversals); per-stroke segments; point-to-point moves with overshoot and
        settling time; RMS and max voltage [V], chattering (voltage RMS above
        ``chatter_cutoff``) [V] and its ratio to the voltage RMS.
    """
    window = check_positive('glitch_window', glitch_window)
    check_positive('chatter_cutoff', chatter_cutoff)
    if not 0 < settle_tolerance < 1:
        raise ParameterError(f'settle_tolerance must be in (0, 1), got {settle_tolerance}')
    run.require('reference')
    if len(run) < 2:
        raise InputFileError(f'{run.name}: only {len(run)} sample(s); need at least 2')
    t = run.t
    e = run.error
    if not (np.all(np.isfinite(e)) and np.all(np.isfinite(t))):
        raise InputFileError(f'{run.name}: error or time has NaN/Inf samples')
    w = _weights(t)
    v = reference_velocity(t, run.reference, run.reference_velocity)
    found = reversals(t, v, zero_tol=zero_tol)
    glitches = find_glitches(t, e, v, window=window, found=found)
    tr = found[0]
    mags = np.array([g.magnitude for g in glitches])
    u = run.voltage
    if u is not None and np.all(np.isfinite(u)):
        rms_u = _rms(u, w)
        chat = chattering(t, u, cutoff=chatter_cutoff)
        ratio = (chat / rms_u) if (chat is not None and rms_u > 0) else None
        umax: float | None = float(np.max(np.abs(u)))
    else:
        rms_u = umax = chat = ratio = None
    return RunMetrics(
        name=run.name, samples=len(run), duration=run.duration,
        rms_error=_rms(e, w), max_error=float(np.max(np.abs(e))),
        mean_error=float(np.sum(w * e) / np.sum(w)),
        glitch_window=window, glitches=glitches,
        max_glitch=float(mags.max()) if mags.size else None,
        mean_glitch=float(mags.mean()) if mags.size else None,
        segments=_segments(t, e, w, tr),
        moves=_moves(t, run.position, run.reference, v, zero_tol=zero_tol,
                     settle_tolerance=settle_tolerance, settle_band=settle_band,
                     min_dwell=min_dwell),
        rms_voltage=rms_u, max_voltage=umax, chattering=chat, chattering_ratio=ratio,
        chatter_cutoff=float(chatter_cutoff))
