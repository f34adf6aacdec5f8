"""Trajectories: analytic derivatives agree with finite differences; validation."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from motor_comp.control.trajectories import Chirp, ConstantVelocity, PointToPoint, \
    Sinusoid, make_trajectory, trajectory_from_dict
from motor_comp.errors import ParameterError


def _check_derivatives(traj, t_end, tol_v, tol_a, t_start=0.0):
    t = np.linspace(t_start, t_end, 200_001)
    dt = t[1] - t[0]
    ref = traj.at(t)
    v_fd = np.gradient(ref.position, dt)
    a_fd = np.gradient(ref.velocity, dt)
    inner = slice(2, -2)
    assert np.max(np.abs(v_fd - ref.velocity)[inner]) < tol_v
    return np.abs(a_fd - ref.acceleration)[inner], tol_a


@given(amp=st.floats(1e-4, 0.1), period=st.floats(0.5, 20.0))
@settings(max_examples=20, deadline=None)
def test_sine_derivatives_and_reversals(amp, period):
    traj = Sinusoid(amplitude=amp, period=period)
    err, tol = _check_derivatives(traj, 2 * period, 1e-6 * amp / period * 50, 0)
    assert np.max(err) < 1e-4 * amp / period ** 2 * 400
    ref = traj.at(np.array([0.0, period / 2, period]))
    np.testing.assert_allclose(ref.position, [0.0, 2 * amp, 0.0], atol=1e-15)
    np.testing.assert_allclose(ref.velocity, 0.0, atol=1e-12 * amp / period * 10)


@given(dist=st.floats(-0.2, 0.2).filter(lambda d: abs(d) > 1e-4),
       move=st.floats(0.1, 2.0), dwell=st.floats(0.0, 1.0))
@settings(max_examples=20, deadline=None)
def test_p2p_reaches_targets_with_smooth_profile(dist, move, dwell):
    traj = PointToPoint(distance=dist, move_time=move, dwell=dwell)
    err, _ = _check_derivatives(traj, 2 * (move + dwell), 1e-3 * abs(dist) / move, 0)
    assert np.max(err) < 2e-2 * abs(dist) / move ** 2
    ref = traj.at(np.array([move, move + dwell, 2 * move + dwell, 2 * (move + dwell)]))
    np.testing.assert_allclose(ref.position, [dist, dist, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(ref.velocity, 0.0, atol=1e-12)
    peak = traj.at(np.array([move / 2])).velocity[0]
    assert peak == pytest.approx(1.875 * dist / move, rel=1e-12)


def test_constant_velocity_cruises_at_each_speed():
    traj = ConstantVelocity(speeds=(0.01, 0.02), stroke=0.02, acceleration=1.0)
    t = np.linspace(0, traj.period, 100_001)
    ref = traj.at(t)
    for s in (0.01, 0.02):
        # a cruise phase at +s and at −s exists, and the pass returns to the start
        assert np.sum(np.isclose(ref.velocity, s, rtol=0, atol=1e-12)) > 100
        assert np.sum(np.isclose(ref.velocity, -s, rtol=0, atol=1e-12)) > 100
    assert ref.position.max() == pytest.approx(0.02, abs=1e-8)
    assert traj.at(traj.period).position == pytest.approx(0.0, abs=1e-12)
    _check_derivatives(traj, traj.period, 2e-5, 0)  # a·dt at the ramp kinks


def test_chirp_starts_at_rest_and_sweeps():
    traj = Chirp(amplitude=1e-3, f_start=1.0, f_end=5.0, duration=4.0, fade=0.5)
    ref0 = traj.at(0.0)
    assert (ref0.position, ref0.velocity) == (0.0, 0.0)
    err, _ = _check_derivatives(traj, 3.9, 1e-7, 0, t_start=0.501)  # a jumps at fade/sweep end
    assert np.max(err) < 1e-3
    # instantaneous frequency: zero crossings are denser at the end of the sweep
    t = np.linspace(1.0, 4.0, 30001)
    x = traj.at(t).position
    zc = t[1:][np.sign(x[1:]) != np.sign(x[:-1])]
    assert np.diff(zc)[-1] < 0.5 * np.diff(zc)[0]


def test_bad_parameters_name_the_field():
    with pytest.raises(ParameterError, match='sine.period'):
        Sinusoid(period=-1.0)
    with pytest.raises(ParameterError, match='unknown parameter'):
        make_trajectory('sine', frequency=3.0)
    with pytest.raises(ParameterError, match='unknown trajectory'):
        make_trajectory('square')
    with pytest.raises(ParameterError, match='cv: speed'):
        ConstantVelocity(speeds=(1.0,), stroke=0.01, acceleration=1.0)


def test_params_round_trip():
    traj = make_trajectory('cv', speeds=[0.01, 0.03], stroke=0.05)
    again = trajectory_from_dict(traj.params())
    np.testing.assert_array_equal(again.packed(), traj.packed())
