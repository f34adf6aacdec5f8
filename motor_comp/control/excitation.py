"""Identification trajectories built from parts, within an axis's limits (``excite``).

An identification run must show the estimator every regime its model's parameters
live in (``../shared/IDENTIFICATION.md`` §6, §9): constant speeds from creep to the
top speed in both directions (friction curve), reversals at amplitudes of a few encoder
counts up to tens of them (pre-sliding), accelerations (mass, dead time), a travel over
several periods of any position-dependent force, and rests.  This module builds such a
trajectory from **parts**, each starting and ending at rest, joined by minimum-jerk
moves and short rests, sampled into a :class:`~motor_comp.control.trajectories.TableData`
(``t, x, v, a``) that ``simulate --trajectory table`` and ``trajectory_node`` play:

* :class:`Pass` — out and back over a stroke at one constant speed, raised-cosine speed
  ramps (acceleration continuous, peak ``π·s/(2·t_r)``);
* :class:`Burst` — a Hann-windowed sine ``c + A·sin²(πτ/T_b)·sin(2πfτ)`` at a small
  amplitude: the reversals of pre-sliding (the window starts and ends it at rest with
  zero acceleration);
* :class:`Sweep` — out and back at a cruise speed ``v0`` modulated by a Hann-windowed
  sine, ``v0 + Δv·sin²(πτ/T)·sin(2πfτ)`` with ``Δv < v0``: accelerations at a given
  frequency *without reversals*, so the friction keeps its sign while the mass and the
  dead time are seen (a reversal smeared by the zero-phase smoothing of the
  identification leaves a residual that a dead time partly absorbs: measured on the
  ball-screw with 1.29 ms, bursts of large reversals above 0.5 Hz put the fitted dead
  time 0.1–1.4 ms off and spread its SE over 4×);
* the joins: :meth:`Profile.move` (minimum-jerk quintic ``10σ³ − 15σ⁴ + 6σ⁵``, the
  time chosen from ``vmax`` and ``amax``: peak speed ``1.875·D/T``, acceleration
  ``5.774·D/T²``) and :meth:`Profile.hold`.

Every profile is analytic (position, velocity and acceleration of the same function),
so the table is exact on its rows; the limits are met by construction (speed,
acceleration, travel) and checked on the samples (:func:`check_limits`).  Which parts,
how many and in which order is the experiment design's business
(:mod:`motor_comp.design.excite`).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np

from motor_comp.control.limits import Limits
from motor_comp.control.trajectories import TableData, table_from_arrays
from motor_comp.errors import ParameterError

#: minimum-jerk quintic: peak speed 1.875·D/T, peak acceleration (10/√3)·D/T²
MJ_SPEED, MJ_ACC = 1.875, 10.0 / math.sqrt(3.0)


@dataclasses.dataclass(frozen=True)
class ExcitationLimits(Limits):
    """The axis limits an excitation is designed within, and what its design needs.

    The axis's own :class:`~motor_comp.control.limits.Limits` (the same ``travel``,
    ``vmax``, ``amax``, ``umax`` and ``max_error`` the nodes enforce while it runs), of
    which ``travel``, ``vmax`` and ``amax`` must be finite here, plus the excitation's
    bandwidth and drive-force bound.  SI units (rad-based on a rotary axis).

    Attributes
    ----------
    travel : (float, float)
        Usable travel ``[min, max]`` [m].
    vmax : float
        Largest speed [m/s].
    amax : float
        Largest acceleration [m/s²].
    umax : float
        Largest command in the model's input unit [V, A or N] (``inf``: none).
    max_error : float
        Largest tracking error the nodes allow while it runs [m] (``inf``: none; the
        design does not use it).
    bandwidth : float
        Highest frequency of the excitation [Hz] (the loop must follow it); speed
        ramps are no shorter than ``1/(2·bandwidth)``.
    fmax : float
        Largest drive force [N] the start model may ask for (``inf``: none).
    """

    bandwidth: float = 5.0
    fmax: float = math.inf

    def __post_init__(self) -> None:
        """Validate (messages name the ``excite`` option), then as the axis limits."""
        try:
            lo, hi = (float(v) for v in self.travel)
        except (TypeError, ValueError):
            raise ParameterError('--travel needs two numbers MIN MAX') from None
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise ParameterError(f'--travel must be two finite numbers MIN < MAX, got '
                                 f'{lo:g} {hi:g}')
        for name in ('vmax', 'amax', 'bandwidth'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ParameterError(f'--{name} must be a finite number > 0, got {value!r}')
        for name in ('fmax', 'umax'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and value > 0 and not math.isnan(value)):
                raise ParameterError(f'--{name} must be a number > 0, got {value!r}')
        super().__post_init__()

    @classmethod
    def of(cls, axis: Limits, **design: float) -> 'ExcitationLimits':
        """Return the excitation limits of an axis's ``Limits`` and the design's bounds."""
        return cls(travel=axis.travel, vmax=axis.vmax, amax=axis.amax, umax=axis.umax,
                   max_error=axis.max_error, **design)

    @property
    def span(self) -> float:
        """Travel length [m]."""
        return self.travel[1] - self.travel[0]

    @property
    def centre(self) -> float:
        """Middle of the travel [m]."""
        return 0.5 * (self.travel[0] + self.travel[1])


# ---- analytic profiles ---------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class _Segment:
    """One analytic piece of a profile, starting at ``t0`` [s] at ``x0`` [m]."""

    kind: str
    t0: float
    dur: float
    x0: float
    p: tuple


class Profile:
    """A motion built piece by piece, continuous in position, velocity and acceleration.

    Parameters
    ----------
    x0 : float
        Start position [m] (at rest).
    """

    def __init__(self, x0: float) -> None:
        self.segments: list[_Segment] = []
        self.t = 0.0
        self.x = float(x0)
        self.v = 0.0

    def _add(self, kind: str, dur: float, p: tuple, x_end: float, v_end: float) -> None:
        if dur <= 0.0:
            return
        self.segments.append(_Segment(kind, self.t, dur, self.x, p))
        self.t += dur
        self.x = x_end
        self.v = v_end

    def ramp(self, dur: float, v1: float) -> None:
        """Raised-cosine speed change from the current speed to ``v1`` [m/s] in ``dur``."""
        v0 = self.v
        self._add('ramp', dur, (v0, v1), self.x + 0.5 * (v0 + v1) * dur, v1)

    def cruise(self, dur: float) -> None:
        """Keep the current speed for ``dur`` [s]."""
        self._add('cruise', dur, (self.v,), self.x + self.v * dur, self.v)

    def hold(self, dur: float) -> None:
        """Rest for ``dur`` [s] (the axis must be at rest)."""
        self._add('hold', dur, (), self.x, 0.0)

    def move(self, x1: float, *, vmax: float, amax: float, t_min: float = 0.05) -> None:
        """Minimum-jerk move to ``x1`` [m] from rest, as fast as ``vmax``/``amax`` allow."""
        d = float(x1) - self.x
        if d == 0.0:
            return
        dur = max(MJ_SPEED * abs(d) / vmax, math.sqrt(MJ_ACC * abs(d) / amax), t_min)
        self._add('move', dur, (d,), float(x1), 0.0)

    def burst(self, amplitude: float, freq: float, cycles: float) -> None:
        """Hann-windowed sine ``A·sin²(πτ/T)·sin(2πfτ)`` around the current position."""
        self._add('burst', cycles / freq, (amplitude, freq), self.x, 0.0)

    def modulate(self, dv: float, freq: float, cycles: float) -> None:
        """Cruise modulated by ``Δv·sin²(πτ/T)·sin(2πfτ)``, T = cycles/f (whole cycles).

        The modulation integrates to zero over whole cycles: the distance is the
        cruise's.
        """
        dur = cycles / freq
        self._add('modulate', dur, (self.v, dv, freq), self.x + self.v * dur, self.v)

    def sample(self, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Return ``t, x, v, a`` on the grid ``k·dt`` up to the end (inclusive)."""
        n = int(math.floor(self.t / dt + 1e-9)) + 1
        t = np.arange(n) * dt
        x = np.full(n, self.x)
        v = np.zeros(n)
        a = np.zeros(n)
        if not self.segments:
            return t, x, v, a
        starts = np.array([s.t0 for s in self.segments])
        idx = np.clip(np.searchsorted(starts, t, side='right') - 1, 0, len(starts) - 1)
        for i, seg in enumerate(self.segments):
            m = (idx == i) & (t <= seg.t0 + seg.dur)
            if not np.any(m):
                continue
            x[m], v[m], a[m] = _evaluate(seg, t[m] - seg.t0)
        after = t > self.t
        x[after], v[after], a[after] = self.x, 0.0, 0.0
        return t, x, v, a


def _evaluate(seg: _Segment, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Position, velocity, acceleration of one segment at local times ``tau``."""
    T = seg.dur
    if seg.kind == 'ramp':
        v0, v1 = seg.p
        w = math.pi / T
        dv = v1 - v0
        return (seg.x0 + v0 * tau + 0.5 * dv * (tau - np.sin(w * tau) / w),
                v0 + 0.5 * dv * (1.0 - np.cos(w * tau)), 0.5 * dv * w * np.sin(w * tau))
    if seg.kind == 'cruise':
        (v,) = seg.p
        return seg.x0 + v * tau, np.full_like(tau, v), np.zeros_like(tau)
    if seg.kind == 'hold':
        return np.full_like(tau, seg.x0), np.zeros_like(tau), np.zeros_like(tau)
    if seg.kind == 'move':
        (d,) = seg.p
        s = tau / T
        return (seg.x0 + d * s ** 3 * (10.0 - 15.0 * s + 6.0 * s * s),
                d / T * 30.0 * s * s * (1.0 - s) ** 2,
                d / (T * T) * 60.0 * s * (1.0 - s) * (1.0 - 2.0 * s))
    if seg.kind == 'modulate':
        v0, dv, f = seg.p
        b, w = math.pi / T, 2.0 * math.pi * f
        g, dg = np.sin(b * tau) ** 2, b * np.sin(2 * b * tau)
        s, c = np.sin(w * tau), np.cos(w * tau)
        # ∫ sin²(bτ)·sin(wτ) dτ from 0: ½(1 − cos wτ)/w − ¼Σ±(1 − cos((w ± 2b)τ))/(w ± 2b)
        # (w ≠ 2b: at least two cycles)
        integral = 0.5 * (1.0 - c) / w - 0.25 * ((1.0 - np.cos((w + 2 * b) * tau)) / (w + 2 * b)
                                                 + (1.0 - np.cos((w - 2 * b) * tau)) / (w - 2 * b))
        return (seg.x0 + v0 * tau + dv * integral, v0 + dv * g * s,
                dv * (dg * s + g * w * c))
    if seg.kind == 'burst':
        amp, f = seg.p
        wb, wf = math.pi / T, 2.0 * math.pi * f
        g, dg, ddg = (np.sin(wb * tau) ** 2, wb * np.sin(2 * wb * tau),
                      2.0 * wb * wb * np.cos(2 * wb * tau))
        s, c = np.sin(wf * tau), np.cos(wf * tau)
        return (seg.x0 + amp * g * s, amp * (dg * s + g * wf * c),
                amp * (ddg * s + 2.0 * dg * wf * c - g * wf * wf * s))
    raise ValueError(seg.kind)   # pragma: no cover - the kinds above are all there are


def burst_peaks(cycles: float) -> tuple[float, float]:
    """Peak speed and acceleration of a unit burst (A = 1, f = 1 Hz) of ``cycles`` cycles.

    Scale by ``A·f`` and ``A·f²``; the window adds to the sine's ``2π`` and ``(2π)²``.
    """
    seg = _Segment('burst', 0.0, cycles, 0.0, (1.0, 1.0))
    tau = np.linspace(0.0, cycles, int(4000 * cycles) + 1)
    _, v, a = _evaluate(seg, tau)
    return float(np.max(np.abs(v))), float(np.max(np.abs(a)))


# ---- parts ---------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Pass:
    """Out and back over ``stroke`` at the constant speed ``speed``, starting at rest.

    Attributes
    ----------
    speed : float
        Cruise speed [m/s], > 0.
    stroke : float
        Travel of each way [m] (ramps included).
    direction : int
        +1: out in the positive direction first; −1: negative first.
    ramp : float
        Duration of each raised-cosine speed ramp [s].
    """

    speed: float
    stroke: float
    direction: int
    ramp: float

    @classmethod
    def within(cls, speed: float, stroke: float, direction: int,
               limits: ExcitationLimits) -> 'Pass':
        """Return the pass at ``speed`` over ``stroke`` that meets ``amax`` and the bandwidth.

        The ramps take ``t_r = max(π·s/(2·amax), 1/(2·bandwidth))``; when they would not
        fit in the stroke (``s·t_r > stroke``) the speed is lowered until they do.
        """
        bw_ramp = 0.5 / limits.bandwidth
        s = min(speed, limits.vmax)
        for _ in range(60):
            ramp = max(math.pi * s / (2.0 * limits.amax), bw_ramp)
            if s * ramp <= stroke:
                return cls(speed=s, stroke=stroke, direction=1 if direction >= 0 else -1,
                           ramp=ramp)
            s *= 0.9
        raise ParameterError(f'a stroke of {stroke:g} is too short for any pass')

    @property
    def duration(self) -> float:
        """Time of the pass [s]."""
        return 2.0 * (self.stroke / self.speed + self.ramp)

    def start(self, centre: float) -> float:
        """Start (and end) position of the pass centred on ``centre``."""
        return centre - 0.5 * self.direction * self.stroke

    def add_to(self, prof: Profile) -> None:
        """Append the pass to ``prof`` (which must be at rest at :meth:`start`)."""
        cruise = (self.stroke - self.speed * self.ramp) / self.speed
        for d in (self.direction, -self.direction):
            prof.ramp(self.ramp, d * self.speed)
            prof.cruise(cruise)
            prof.ramp(self.ramp, 0.0)


@dataclasses.dataclass(frozen=True)
class Burst:
    """A Hann-windowed sine burst around its centre (reversals, accelerations).

    Attributes
    ----------
    amplitude : float
        Sine amplitude A [m] (the excursion is at most ±A).
    freq : float
        Frequency [Hz].
    cycles : float
        Cycles in the window.
    """

    amplitude: float
    freq: float
    cycles: float

    @classmethod
    def within(cls, amplitude: float, freq: float, cycles: float,
               limits: ExcitationLimits) -> 'Burst':
        """Return the burst, its amplitude lowered until its speed and acceleration fit."""
        pv, pa = burst_peaks(cycles)
        # (the peaks are sampled 4000 times a cycle: 1e-6 keeps the true peak inside)
        amp = min(amplitude, limits.vmax / (pv * freq), limits.amax / (pa * freq * freq)) \
            * (1.0 - 1e-6)
        return cls(amplitude=amp, freq=freq, cycles=cycles)

    @property
    def duration(self) -> float:
        """Time of the burst [s]."""
        return self.cycles / self.freq

    def start(self, centre: float) -> float:
        """Return where the burst begins and ends: at its centre."""
        return centre

    def add_to(self, prof: Profile) -> None:
        """Append the burst to ``prof`` (at rest at its centre)."""
        prof.burst(self.amplitude, self.freq, self.cycles)


def modulation_peaks(cycles: float) -> tuple[float, float]:
    """Peak of ``sin²(πτ/T)·sin(2πτ)`` and of its derivative (f = 1 Hz, unit Δv)."""
    seg = _Segment('modulate', 0.0, cycles, 0.0, (0.0, 1.0, 1.0))
    tau = np.linspace(0.0, cycles, int(4000 * cycles) + 1)
    _, v, a = _evaluate(seg, tau)
    return float(np.max(np.abs(v))), float(np.max(np.abs(a)))


@dataclasses.dataclass(frozen=True)
class Sweep:
    """Out and back at ``speed`` with a speed modulation of ``dv`` at ``freq`` each way.

    Attributes
    ----------
    speed : float
        Cruise speed v0 [m/s].
    dv : float
        Modulation amplitude Δv [m/s], below v0 (no reversal).
    freq : float
        Modulation frequency [Hz].
    cycles : float
        Whole cycles of the modulation each way (≥ 2).
    ramp : float
        Duration of each raised-cosine ramp to and from v0 [s].
    direction : int
        +1: positive way first.
    """

    speed: float
    dv: float
    freq: float
    cycles: float
    ramp: float
    direction: int = 1

    @classmethod
    def within(cls, freq: float, cycles: float, limits: ExcitationLimits, *,
               usable: float) -> 'Sweep':
        """Return the sweep at ``freq`` with the largest modulation the limits allow.

        Each way runs ``v0·(T + t_r)`` (T = cycles/f) within ``usable`` of travel, so
        ``v0 = usable/(T + t_r)`` (at most ``vmax/2``); ``Δv`` is the largest of
        ``0.7·v0`` (no reversal), ``vmax − v0`` and ``amax`` over the modulation's
        peak acceleration.
        """
        T = cycles / freq
        pv, pa = modulation_peaks(cycles)
        v0 = min(0.5 * limits.vmax, usable / T)
        for _ in range(60):
            ramp = max(math.pi * v0 / (2.0 * limits.amax), 0.5 / limits.bandwidth)
            if v0 * (T + ramp) <= usable:
                break
            v0 *= 0.95
        dv = min(0.7 * v0, (limits.vmax - v0) / pv,
                 limits.amax / (pa * freq) * (1.0 - 1e-6))
        return cls(speed=v0, dv=dv, freq=freq, cycles=cycles, ramp=ramp)

    @property
    def stroke(self) -> float:
        """Travel of each way [m] (the modulation returns to the cruise's path)."""
        return self.speed * (self.cycles / self.freq + self.ramp)

    @property
    def duration(self) -> float:
        """Time of the sweep [s]."""
        return 2.0 * (self.cycles / self.freq + 2.0 * self.ramp)

    def start(self, centre: float) -> float:
        """Start (and end) position of the sweep centred on ``centre``."""
        return centre - 0.5 * self.direction * self.stroke

    def add_to(self, prof: Profile) -> None:
        """Append the sweep to ``prof`` (at rest at :meth:`start`)."""
        for d in (self.direction, -self.direction):
            prof.ramp(self.ramp, d * self.speed)
            prof.modulate(d * self.dv, self.freq, self.cycles)
            prof.ramp(self.ramp, 0.0)


Part = Pass | Burst | Sweep


def assemble(parts: Sequence[tuple[Part, float]], limits: ExcitationLimits, *, dt: float,
             rest: float = 0.2, start: float | None = None,
             move_scale: float = 1.0) -> tuple[TableData, list[tuple[float, float]]]:
    """Chain ``(part, centre)`` pairs into one table: move, part, rest, move, ….

    The axis starts at rest at ``start`` (default the first part's start), moves to
    each part's start by a minimum-jerk move within ``move_scale`` of ``vmax`` and
    ``amax``, runs it and rests ``rest`` seconds; it ends at rest at the last part's
    end.  Returns the table and each part's time window ``(t0, t1)`` [s].
    """
    x0 = parts[0][0].start(parts[0][1]) if start is None else float(start)
    prof = Profile(x0)
    prof.hold(rest)
    windows = []
    for part, centre in parts:
        prof.move(part.start(centre), vmax=move_scale * limits.vmax,
                  amax=move_scale * limits.amax)
        t0 = prof.t
        part.add_to(prof)
        windows.append((t0, prof.t))
        prof.hold(rest)
    t, x, v, a = prof.sample(dt)
    return table_from_arrays(t, x, v, a, source='excitation'), windows


@dataclasses.dataclass(frozen=True)
class Peaks:
    """Largest values along a table (SI) and whether each limit holds.

    Attributes
    ----------
    x_min, x_max, v, a : float
        Position range [m], peak speed [m/s], peak acceleration [m/s²].
    force, command : float
        Peak drive force [N] and command [V, A or N] the start model needs (inverse
        dynamics along the reference: ``M·a + damping·v + Σ F_k``, and its command).
    """

    x_min: float
    x_max: float
    v: float
    a: float
    force: float
    command: float

    def violations(self, limits: ExcitationLimits) -> list[str]:
        """Return the limits these peaks break, in words (empty when all hold)."""
        tol = 1e-9
        lo, hi = limits.travel
        out = []
        if self.x_min < lo - tol * limits.span or self.x_max > hi + tol * limits.span:
            out.append(f'travel [{self.x_min:g}, {self.x_max:g}] outside [{lo:g}, {hi:g}]')
        if self.v > limits.vmax * (1 + tol):
            out.append(f'speed {self.v:g} > vmax {limits.vmax:g}')
        if self.a > limits.amax * (1 + tol):
            out.append(f'acceleration {self.a:g} > amax {limits.amax:g}')
        if self.force > limits.fmax:
            out.append(f'drive force {self.force:g} > fmax {limits.fmax:g}')
        if self.command > limits.umax:
            out.append(f'command {self.command:g} > umax {limits.umax:g}')
        return out

    def as_dict(self) -> dict[str, float]:
        """JSON form."""
        return dataclasses.asdict(self)


def drive_along(model: object, x: np.ndarray, v: np.ndarray, a: np.ndarray,
                dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Drive force [N] and command the model needs along a motion (its inverse dynamics).

    ``F = M·a + damping·v + Σ F_k(x, v)`` (GMS pre-sliding simulated along ``x``) and
    ``u = F/input_gain + back_emf·v``, the drive law of
    :meth:`~motor_comp.physics.axis.AxisModel.input_force` solved for ``u``.
    """
    forces = model.effect_forces(x, v, dt=dt)
    f = model.mass * a + model.damping * v + sum(forces.values(), np.zeros_like(x))
    return f, f / model.input_gain + model.back_emf * v


def peaks(data: TableData, model: object) -> Peaks:
    """Peaks of a table and of the drive it needs under ``model``."""
    dt = float(np.median(np.diff(data.t)))
    f, u = drive_along(model, data.x, data.v, data.a, dt)
    return Peaks(x_min=float(np.min(data.x)), x_max=float(np.max(data.x)),
                 v=float(np.max(np.abs(data.v))), a=float(np.max(np.abs(data.a))),
                 force=float(np.max(np.abs(f))), command=float(np.max(np.abs(u))))


def check_limits(data: TableData, model: object, limits: ExcitationLimits) -> Peaks:
    """Return the table's peaks; :class:`ParameterError` naming a broken limit."""
    pk = peaks(data, model)
    bad = pk.violations(limits)
    if bad:
        raise ParameterError('the excitation breaks its limits: ' + '; '.join(bad))
    return pk


def van_der_corput(n: int, base: int = 2) -> np.ndarray:
    """First ``n`` points of the van der Corput sequence in [0, 1) (spread positions)."""
    out = np.empty(n)
    for i in range(n):
        k, f, r = i + 1, 1.0, 0.0
        while k:
            f /= base
            r += f * (k % base)
            k //= base
        out[i] = r
    return out


__all__ = ['Burst', 'ExcitationLimits', 'Part', 'Pass', 'Peaks', 'Profile', 'Sweep', 'assemble',
           'burst_peaks', 'check_limits', 'drive_along', 'modulation_peaks', 'peaks',
           'van_der_corput']
