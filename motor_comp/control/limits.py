"""Axis limits: travel, speed, acceleration, voltage and tracking error, and their trip.

A precision axis — simulated or a real drive under ``motor-comp autotune`` — runs
inside limits that a wrong model, a bad gain or an excitation designed from a wrong
model must never break.  Two places enforce them (DESIGN.md §5 nodes):

* the *reference* is checked before it is used (:func:`check_reference`):
  ``trajectory_node`` refuses, before the run starts, a trajectory whose position,
  velocity or acceleration leaves the limits, rather than tripping mid-run;
* the *loop* is watched every control period by :class:`Guard` in ``controller_node``,
  which sees the reference, the measurement and the command it issues: the measured
  position outside the travel, a measured or reference speed/acceleration beyond
  ``vmax``/``amax``, a law command beyond ``±umax`` or a tracking error
  ``|x_ref − x|`` beyond ``max_error`` is a :class:`Trip`.  From a trip on the node
  commands 0 V (latched until it is configured again or restarted).

The measured acceleration is the change of the measured velocity over
``accel_window`` (a backward difference over several periods: the encoder's velocity
is itself a backward difference of a quantised position, so a one-period difference
would be noise of ``q/T²`` = 1 m/s² for a 1 µm encoder at 1 kHz; over 10 ms it is
0.01 m/s²).

Every limit defaults to none (infinite), so a run without limits is unchanged.  Units:
the axis's (m, m/s, m/s² or rad, rad/s, rad/s²; the command in V).  Core module: no
rclpy.
"""
from __future__ import annotations

import collections
import dataclasses
import enum
import math
from typing import Any

import numpy as np

from motor_comp.errors import ParameterError


class TripCause(enum.Enum):
    """What broke a limit (the first words of the one-line reason)."""

    TRAVEL = 'travel limit'
    SPEED = 'speed limit'
    ACCELERATION = 'acceleration limit'
    VOLTAGE = 'voltage limit'
    TRACKING = 'tracking error'


@dataclasses.dataclass(frozen=True)
class Limits:
    """The limits of one axis (infinite = no limit).

    Attributes
    ----------
    travel : (float, float)
        Allowed position ``[min, max]`` [m] or [rad], ``min < max``.
    vmax : float
        Largest speed ``|v|`` [m/s] or [rad/s], > 0.
    amax : float
        Largest acceleration ``|a|`` [m/s²] or [rad/s²], > 0.
    umax : float
        Largest command ``|u|`` the law may ask for [V], > 0.
    max_error : float
        Largest tracking error ``|x_ref − x|`` [m] or [rad], > 0.
    """

    travel: tuple[float, float] = (-math.inf, math.inf)
    vmax: float = math.inf
    amax: float = math.inf
    umax: float = math.inf
    max_error: float = math.inf

    def __post_init__(self) -> None:
        """Validate: a travel ``min < max`` (no NaN), every bound > 0."""
        try:
            lo, hi = (float(v) for v in self.travel)
        except (TypeError, ValueError):
            raise ParameterError(f'travel: expected [min, max], got {self.travel!r}') \
                from None
        if math.isnan(lo) or math.isnan(hi) or not lo < hi:
            raise ParameterError(f'travel: expected min < max, got [{lo:g}, {hi:g}]')
        object.__setattr__(self, 'travel', (lo, hi))
        for name in ('vmax', 'amax', 'umax', 'max_error'):
            v = float(getattr(self, name))
            if math.isnan(v) or v <= 0.0:
                raise ParameterError(f'{name}: must be > 0 (inf = no limit), got {v:g}')
            object.__setattr__(self, name, v)

    @property
    def active(self) -> bool:
        """Whether any limit is finite."""
        return any(math.isfinite(v) for v in (*self.travel, self.vmax, self.amax,
                                              self.umax, self.max_error))

    def describe(self, position: str = 'm', velocity: str = 'm/s',
                 acceleration: str = 'm/s²') -> str:
        """Describe the finite limits in words, e.g. ``travel [-0.05, 0.05] m, vmax 0.2 m/s``."""
        parts = []
        lo, hi = self.travel
        if math.isfinite(lo) or math.isfinite(hi):
            parts.append(f'travel [{lo:g}, {hi:g}] {position}')
        for name, unit in (('vmax', velocity), ('amax', acceleration), ('umax', 'V'),
                           ('max_error', position)):
            v = getattr(self, name)
            if math.isfinite(v):
                parts.append(f'{name} {v:g} {unit}')
        return ', '.join(parts) or 'none'


@dataclasses.dataclass(frozen=True)
class Trip:
    """One broken limit.

    Attributes
    ----------
    cause : TripCause
        Which limit.
    quantity : str
        What broke it (``position``, ``reference velocity``, ``command``, ``|e|`` …).
    value : float
        Its value (SI, the axis's units).
    bound : str
        The limit in words (``[-0.05, 0.05] m``, ``±0.2 m/s``).
    unit : str
        Unit of ``value``.
    t : float
        Time of the sample that broke it [s] (the measurement's stamp).
    """

    cause: TripCause
    quantity: str
    value: float
    bound: str
    unit: str
    t: float

    @property
    def message(self) -> str:
        """One line: ``travel limit: position 0.0523 m beyond [-0.05, 0.05] m at t = 3.210 s``."""
        return (f'{self.cause.value}: {self.quantity} {self.value:.6g} {self.unit} beyond '
                f'{self.bound} at t = {self.t:.3f} s')

    def as_dict(self) -> dict[str, Any]:
        """Plain values (diagnostics key-values, JSON)."""
        return {'cause': self.cause.value, 'quantity': self.quantity, 'value': self.value,
                'bound': self.bound, 'unit': self.unit, 't': self.t,
                'message': self.message}


class Guard:
    """Checks every control period against :class:`Limits`; the first break is a trip.

    Parameters
    ----------
    limits : Limits
        The limits.
    units : (str, str, str)
        Position, velocity and acceleration unit strings (messages only).
    accel_window : float
        Window of the measured acceleration [s] (velocity change over it), > 0.
    """

    def __init__(self, limits: Limits, *, units: tuple[str, str, str] = ('m', 'm/s', 'm/s²'),
                 accel_window: float = 0.01) -> None:
        if not accel_window > 0.0 or not math.isfinite(accel_window):
            raise ParameterError(f'accel_window: must be > 0, got {accel_window!r}')
        self.limits = limits
        self.units = units
        self.accel_window = float(accel_window)
        lo, hi = limits.travel
        self._lo, self._hi = lo, hi
        self._travel = f'[{lo:g}, {hi:g}] {units[0]}'
        self._check_accel = math.isfinite(limits.amax)
        # (t, v) of the measured velocity over the last accel_window
        self._history: collections.deque[tuple[float, float]] = collections.deque()
        self.trip: Trip | None = None

    def check(self, t: float, r: float, rv: float, ra: float, y: float, vy: float,
              u: float) -> Trip | None:
        """Check one control period; return the trip (also kept in :attr:`trip`) or None.

        Parameters
        ----------
        t : float
            Stamp of the measurement [s].
        r, rv, ra : float
            Reference position, velocity, acceleration (SI, axis units).
        y, vy : float
            Measured position and velocity.
        u : float
            The command the law asks for [V].
        """
        if self.trip is not None:
            return self.trip
        L = self.limits
        pos, vel, acc = self.units
        trip = None
        if not self._lo <= y <= self._hi:
            trip = Trip(TripCause.TRAVEL, 'position', y, self._travel, pos, t)
        elif not self._lo <= r <= self._hi:
            trip = Trip(TripCause.TRAVEL, 'reference position', r, self._travel, pos, t)
        elif abs(vy) > L.vmax:
            trip = Trip(TripCause.SPEED, 'velocity', vy, f'±{L.vmax:g} {vel}', vel, t)
        elif abs(rv) > L.vmax:
            trip = Trip(TripCause.SPEED, 'reference velocity', rv, f'±{L.vmax:g} {vel}',
                        vel, t)
        elif abs(ra) > L.amax:
            trip = Trip(TripCause.ACCELERATION, 'reference acceleration', ra,
                        f'±{L.amax:g} {acc}', acc, t)
        elif abs(r - y) > L.max_error:
            trip = Trip(TripCause.TRACKING, '|x_ref - x|', abs(r - y),
                        f'{L.max_error:g} {pos}', pos, t)
        elif abs(u) > L.umax:
            trip = Trip(TripCause.VOLTAGE, 'command', u, f'±{L.umax:g} V', 'V', t)
        if trip is None and self._check_accel:
            a = self._acceleration(t, vy)
            if a is not None and abs(a) > L.amax:
                trip = Trip(TripCause.ACCELERATION, 'acceleration', a, f'±{L.amax:g} {acc}',
                            acc, t)
        self.trip = trip
        return trip

    def _acceleration(self, t: float, vy: float) -> float | None:
        """Measured acceleration over the window ending at ``t`` (None until it is full)."""
        h = self._history
        h.append((t, vy))
        while len(h) > 1 and t - h[1][0] >= self.accel_window:
            h.popleft()
        t0, v0 = h[0]
        if t - t0 < self.accel_window or t <= t0:
            return None
        return (vy - v0) / (t - t0)


#: longest run a reference is checked over when it has no end [s] (every trajectory
#: of the library is periodic or settles within it)
CHECK_HORIZON = 600.0


def check_reference(trajectory: Any, limits: Limits, *, duration: float, rate: float,
                    units: tuple[str, str, str] = ('m', 'm/s', 'm/s²')) -> None:
    """Refuse a reference that leaves the limits, before it is used.

    The trajectory is evaluated on the control grid ``k/rate`` over ``[0, duration]``
    (the samples the loop will be given; :data:`CHECK_HORIZON` when ``duration`` is 0:
    no end).

    Raises
    ------
    ParameterError
        One line naming the limit, the value, the bound and the time, e.g.
        ``trajectory refused: travel limit: reference position 0.0523 m beyond
        [-0.05, 0.05] m at t = 1.000 s``.
    """
    if not limits.active:
        return
    span = duration if duration > 0 else CHECK_HORIZON
    t = np.arange(int(math.floor(span * rate + 1e-9)) + 1) / rate
    ref = trajectory.at(t)
    p, v, a = (np.asarray(x, dtype=float)
               for x in (ref.position, ref.velocity, ref.acceleration))
    lo, hi = limits.travel
    pos, vel, acc = units
    checks = (
        (TripCause.TRAVEL, 'reference position', p, (p < lo) | (p > hi),
         f'[{lo:g}, {hi:g}] {pos}', pos),
        (TripCause.SPEED, 'reference velocity', v, np.abs(v) > limits.vmax,
         f'±{limits.vmax:g} {vel}', vel),
        (TripCause.ACCELERATION, 'reference acceleration', a, np.abs(a) > limits.amax,
         f'±{limits.amax:g} {acc}', acc),
    )
    for cause, quantity, values, bad, bound, unit in checks:
        hit = np.flatnonzero(bad | ~np.isfinite(values))
        if hit.size:
            k = int(hit[0])
            trip = Trip(cause, quantity, float(values[k]), bound, unit, float(t[k]))
            raise ParameterError(f'trajectory refused: {trip.message}')


__all__ = ['CHECK_HORIZON', 'Guard', 'Limits', 'Trip', 'TripCause', 'check_reference']
