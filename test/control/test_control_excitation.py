"""Excitation parts (``motor_comp.control.excitation``): analytic, continuous, within limits.

Each part's position, velocity and acceleration are one function and its derivatives
(checked against finite differences); a pass cruises at its speed both ways; a sweep
accelerates without reversing; a reversal burst oscillates by its amplitude; the limits
are met by construction and a broken one is named.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from motor_comp.control.excitation import Burst, ExcitationLimits, Pass, Profile, Sweep, \
    assemble, check_limits, drive_along, modulation_peaks, van_der_corput
from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel

LIM = ExcitationLimits(travel=(-0.05, 0.05), vmax=0.2, amax=3.0, bandwidth=4.0)
DT = 1e-3


def _sample(part, centre=0.0, dt=1e-4):
    prof = Profile(part.start(centre))
    part.add_to(prof)
    return prof.sample(dt)


@pytest.mark.parametrize('part', [
    Pass.within(0.15, 0.09, 1, LIM), Pass.within(0.002, 0.004, -1, LIM),
    Burst.within(3e-5, 2.0, 3.0, LIM), Sweep.within(2.0, 3.0, LIM, usable=0.09)])
def test_parts_are_one_smooth_function(part):
    t, x, v, a = _sample(part)
    np.testing.assert_allclose(np.gradient(x, t)[2:-2], v[2:-2],
                               atol=2e-6 * max(1.0, np.max(np.abs(v))) + 1e-9)
    np.testing.assert_allclose(np.gradient(v, t)[2:-2], a[2:-2],
                               atol=2e-3 * max(1.0, np.max(np.abs(a))))
    assert v[0] == 0.0 and abs(v[-1]) < 1e-9 and abs(a[-1]) < 1e-6   # rest to rest
    assert x[-1] == pytest.approx(x[0], abs=1e-12)                    # back at its start
    assert np.max(np.abs(v)) <= LIM.vmax * (1 + 1e-9)
    assert np.max(np.abs(a)) <= LIM.amax * (1 + 1e-9)
    assert abs(t[-1] - part.duration) < 2e-4


def test_pass_cruises_both_ways():
    p = Pass.within(0.05, 0.08, 1, LIM)
    t, x, v, a = _sample(p)
    assert p.ramp == pytest.approx(max(math.pi * 0.05 / (2 * 3.0), 0.5 / 4.0))
    assert np.max(v) == pytest.approx(0.05) and np.min(v) == pytest.approx(-0.05)
    assert np.max(x) - np.min(x) == pytest.approx(0.08, rel=1e-9)
    assert np.mean(np.abs(np.abs(v) - 0.05) < 1e-12) > 0.5      # mostly at the speed
    # a speed whose ramps do not fit in the stroke is lowered
    slow = Pass.within(0.2, 0.01, 1, LIM)
    assert slow.speed * slow.ramp <= 0.01 and slow.speed < 0.2


def test_sweep_accelerates_without_reversal():
    s = Sweep.within(4.0, 3.0, LIM, usable=0.09)
    t, x, v, a = _sample(s)
    way = t < s.duration / 2
    cruise = (t > s.ramp) & (t < s.duration / 2 - s.ramp)
    assert np.all(v[cruise & way] > 0.25 * s.speed)               # never reverses
    pv, pa = modulation_peaks(3.0)
    assert s.dv == pytest.approx(min(0.7 * s.speed, (LIM.vmax - s.speed) / pv,
                                     LIM.amax / (pa * 4.0)), rel=1e-5)
    assert np.max(np.abs(a[cruise])) > 0.5 * LIM.amax             # it accelerates
    assert np.max(x) - np.min(x) <= 0.09 * (1 + 1e-6)


def test_reversal_burst_amplitude():
    b = Burst.within(3e-6, 2.0, 3.0, LIM)
    t, x, v, a = _sample(b, centre=0.01)
    # the window reaches 94 % of the amplitude on the sine's crests next to its middle
    assert 0.9 * 3e-6 < np.max(x) - 0.01 <= 3e-6
    assert -3e-6 <= np.min(x) - 0.01 < -0.9 * 3e-6
    assert np.sum(np.diff(np.sign(v[np.abs(v) > 1e-9])) != 0) >= 5    # reversals


def test_burst_limited_by_acceleration():
    b = Burst.within(0.04, 5.0, 3.0, LIM)
    t, x, v, a = _sample(b)
    assert b.amplitude < 0.04
    assert max(np.max(np.abs(v)) / LIM.vmax, np.max(np.abs(a)) / LIM.amax) \
        == pytest.approx(1.0, rel=1e-4)


def test_assemble_and_check_limits():
    parts = [(Pass.within(0.1, 0.09, 1, LIM), 0.0), (Burst.within(1e-5, 2, 3, LIM), 0.03),
             (Sweep.within(2.0, 3.0, LIM, usable=0.06), -0.01)]
    data, windows = assemble(parts, LIM, dt=DT, rest=0.2, start=0.0)
    assert np.all(np.diff(data.t) > 0) and data.derived == ()
    assert [round(t1 - t0, 9) for t0, t1 in windows] == [round(p.duration, 9)
                                                         for p, _ in parts]
    for (t0, t1), (p, centre) in zip(windows, parts):
        m = (data.t >= t0) & (data.t <= t1)
        assert data.x[m][0] == pytest.approx(p.start(centre), abs=1e-9)   # ≤ 1 ms in
    model = AxisModel.from_dict({'mass': 5.0, 'input_gain': 15.0, 'back_emf': 100.0,
                                 'effects': {'coulomb': {'fc': 10.0}}})
    pk = check_limits(data, model, LIM)
    f, u = drive_along(model, data.x, data.v, data.a, DT)
    assert pk.force == pytest.approx(np.max(np.abs(f)))
    assert pk.force >= 10.0 and pk.command == pytest.approx(np.max(np.abs(u)))
    with pytest.raises(ParameterError, match='drive force .* > fmax 12'):
        check_limits(data, model, ExcitationLimits(travel=LIM.travel, vmax=LIM.vmax,
                                                   amax=LIM.amax, fmax=12.0))
    with pytest.raises(ParameterError, match='speed .* > vmax 0.05'):
        check_limits(data, model, ExcitationLimits(travel=LIM.travel, vmax=0.05, amax=LIM.amax))
    with pytest.raises(ParameterError, match='outside'):
        check_limits(data, model, ExcitationLimits(travel=(-0.01, 0.05), vmax=0.2, amax=3.0))


@pytest.mark.parametrize('kw, needle', [
    ({'travel': (0.1, 0.1)}, 'MIN < MAX'), ({'travel': (0.0, math.inf)}, 'finite'),
    ({'vmax': 0.0}, '--vmax'), ({'amax': -1.0}, '--amax'), ({'bandwidth': math.nan}, '--band'),
    ({'fmax': 0.0}, '--fmax'), ({'travel': ('a', 1)}, 'two numbers')])
def test_bad_limits(kw, needle):
    args = {'travel': (0.0, 0.1), 'vmax': 0.1, 'amax': 1.0, **kw}
    with pytest.raises(ParameterError, match=needle):
        ExcitationLimits(**args)


def test_van_der_corput_fills_the_interval():
    u = van_der_corput(15)
    np.testing.assert_allclose(np.sort(u), np.arange(1, 16) / 16)   # 1/2, 1/4, 3/4, …
    assert list(u[:3]) == [0.5, 0.25, 0.75]
