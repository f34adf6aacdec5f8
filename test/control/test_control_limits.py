"""Axis limits: the guard's trips (cause, value, time) and the reference check.

The node-level behaviour (0 V after the trip, the run's one-line error, the recording)
is in ``test/nodes/test_nodes_limits.py``; here the core on known signals.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from motor_comp.control.limits import CHECK_HORIZON, Guard, Limits, TripCause, \
    check_reference
from motor_comp.control.trajectories import make_trajectory
from motor_comp.errors import ParameterError


@pytest.mark.parametrize('kwargs, needle', [
    ({'travel': (0.05, -0.05)}, 'min < max'),
    ({'travel': (0.0, 0.0)}, 'min < max'),
    ({'travel': (math.nan, 1.0)}, 'min < max'),
    ({'travel': (1.0,)}, 'expected [min, max]'),
    ({'vmax': 0.0}, 'vmax: must be > 0'),
    ({'amax': -1.0}, 'amax: must be > 0'),
    ({'umax': math.nan}, 'umax: must be > 0'),
    ({'max_error': 0.0}, 'max_error: must be > 0'),
])
def test_invalid_limits(kwargs, needle):
    with pytest.raises(ParameterError) as err:
        Limits(**kwargs)
    assert needle in str(err.value)


def test_default_is_no_limit():
    assert not Limits().active and Limits().describe() == 'none'
    lim = Limits(travel=(-0.05, 0.05), umax=10.0)
    assert lim.active
    assert lim.describe() == 'travel [-0.05, 0.05] m, umax 10 V'


def _feed(guard, samples):
    """Check samples (t, r, rv, ra, y, vy, u); index of the first trip (or None)."""
    for i, s in enumerate(samples):
        if guard.check(*s) is not None:
            return i
    return None


@pytest.mark.parametrize('limits, sample, cause, message', [
    (Limits(travel=(-0.05, 0.05)), (0.0, 0.05, 0.0, 0.0, 0.0523, 0.0, 0.0),
     TripCause.TRAVEL, 'travel limit: position 0.0523 m beyond [-0.05, 0.05] m'),
    (Limits(travel=(-0.05, 0.05)), (0.0, -0.06, 0.0, 0.0, -0.049, 0.0, 0.0),
     TripCause.TRAVEL, 'travel limit: reference position -0.06 m beyond [-0.05, 0.05] m'),
    (Limits(vmax=0.2), (0.0, 0.0, 0.1, 0.0, 0.0, -0.25, 0.0),
     TripCause.SPEED, 'speed limit: velocity -0.25 m/s beyond ±0.2 m/s'),
    (Limits(vmax=0.2), (0.0, 0.0, 0.3, 0.0, 0.0, 0.1, 0.0),
     TripCause.SPEED, 'speed limit: reference velocity 0.3 m/s beyond ±0.2 m/s'),
    (Limits(amax=2.0), (0.0, 0.0, 0.0, 2.5, 0.0, 0.0, 0.0),
     TripCause.ACCELERATION, 'acceleration limit: reference acceleration 2.5 m/s² beyond '
                             '±2 m/s²'),
    (Limits(max_error=1e-4), (0.0, 0.01, 0.0, 0.0, 0.0098, 0.0, 0.0),
     TripCause.TRACKING, 'tracking error: |x_ref - x| 0.0002 m beyond 0.0001 m'),
    (Limits(umax=10.0), (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, -12.5),
     TripCause.VOLTAGE, 'voltage limit: command -12.5 V beyond ±10 V'),
])
def test_each_limit_trips_with_its_cause_and_values(limits, sample, cause, message):
    inside = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
    guard = Guard(limits)
    assert guard.check(*inside) is None            # inside every limit: no trip
    t = 3.21
    trip = guard.check(t, *sample[1:])
    assert trip is not None and trip.cause is cause
    assert trip.message == f'{message} at t = 3.210 s'
    assert trip.t == t and trip.as_dict()['cause'] == cause.value
    # latched: later samples, even inside, return the same trip
    assert guard.check(4.0, *inside[1:]) is trip and guard.trip is trip


def test_bounds_are_inclusive():
    guard = Guard(Limits(travel=(-0.05, 0.05), vmax=0.2, umax=10.0, max_error=1e-3))
    assert guard.check(0.0, 0.05, 0.2, 0.0, 0.05, -0.2, 10.0) is None
    assert guard.check(0.001, 0.0499, 0.0, 0.0, 0.0509, 0.0, -10.0) is not None


def test_rotary_units_in_messages():
    guard = Guard(Limits(travel=(-3.0, 3.0)), units=('rad', 'rad/s', 'rad/s²'))
    trip = guard.check(1.0, 0.0, 0.0, 0.0, 3.5, 0.0, 0.0)
    assert trip.message == 'travel limit: position 3.5 rad beyond [-3, 3] rad at t = 1.000 s'


def test_measured_acceleration_over_the_window():
    """v = a·t at 1 kHz: a = 2.5 m/s² trips amax = 2 once the 10 ms window is full."""
    dt = 1e-3
    t = np.arange(200) * dt
    for a, expect in ((2.5, 10), (1.9, None)):
        guard = Guard(Limits(amax=2.0), accel_window=0.01)
        first = _feed(guard, [(ti, 0.0, 0.0, 0.0, 0.0, a * ti, 0.0) for ti in t])
        assert first == expect
        if expect is not None:
            assert guard.trip.cause is TripCause.ACCELERATION
            assert guard.trip.value == pytest.approx(a, rel=1e-9)
            assert guard.trip.t == pytest.approx(t[expect])


def test_measured_acceleration_is_not_fooled_by_the_encoder_quantum():
    """A 1 µm encoder at 1 kHz: the one-period velocity steps by 1 mm/s (1 m/s² as an
    acceleration); over the 10 ms window the estimate stays within 0.1 m/s² of the truth."""
    dt, q = 1e-3, 1e-6
    t = np.arange(2000) * dt
    x = 0.3 * t ** 2 + 1e-4 * np.sin(7.0 * t)          # a ≈ 0.6 m/s²
    y = q * np.round(x / q)
    vy = np.diff(y, prepend=y[0]) / dt                  # the plant's backward difference
    steps = np.abs(np.diff(vy) / dt)
    assert steps.max() > 1.0                            # one period: quantum noise ≥ 1 m/s²
    guard = Guard(Limits(amax=0.75), accel_window=0.01)
    assert _feed(guard, [(ti, 0.0, 0.0, 0.0, 0.0, vi, 0.0) for ti, vi in zip(t, vy)]) is None


def test_reference_check_finds_the_first_sample_beyond():
    traj = make_trajectory('p2p')        # 0 → 0.05 m in 0.5 s, dwell 0.5 s, back
    rate = 1000.0
    t = np.arange(2001) / rate
    ref = traj.at(t)
    k = int(np.flatnonzero(ref.position > 0.03)[0])
    with pytest.raises(ParameterError) as err:
        check_reference(traj, Limits(travel=(-0.01, 0.03)), duration=2.0, rate=rate)
    assert str(err.value) == (f'trajectory refused: travel limit: reference position '
                              f'{ref.position[k]:.6g} m beyond [-0.01, 0.03] m at '
                              f't = {t[k]:.3f} s')
    vpeak = float(np.max(np.abs(ref.velocity)))
    with pytest.raises(ParameterError, match='speed limit: reference velocity'):
        check_reference(traj, Limits(vmax=0.99 * vpeak), duration=2.0, rate=rate)
    check_reference(traj, Limits(vmax=1.01 * vpeak, travel=(0.0, 0.05)), duration=2.0,
                    rate=rate)
    apeak = float(np.max(np.abs(ref.acceleration)))
    with pytest.raises(ParameterError, match='acceleration limit: reference acceleration'):
        check_reference(traj, Limits(amax=0.99 * apeak), duration=2.0, rate=rate)


def test_reference_check_over_the_run_or_the_horizon():
    """Only the run's samples count; without an end, CHECK_HORIZON of them."""
    chirp = make_trajectory('chirp', amplitude=0.001, f_start=1.0, f_end=20.0, duration=10.0)
    ref = chirp.at(np.arange(int(10e3) + 1) * 1e-3)
    vmax = 0.5 * float(np.max(np.abs(ref.velocity)))
    early = chirp.at(np.arange(1001) * 1e-3)            # the first second sweeps slowly
    assert np.max(np.abs(early.velocity)) < vmax
    check_reference(chirp, Limits(vmax=vmax), duration=1.0, rate=1000.0)
    with pytest.raises(ParameterError, match='speed limit'):
        check_reference(chirp, Limits(vmax=vmax), duration=0.0, rate=1000.0)
    assert CHECK_HORIZON >= 60.0
    check_reference(chirp, Limits(), duration=0.0, rate=1000.0)   # no limit: no check
