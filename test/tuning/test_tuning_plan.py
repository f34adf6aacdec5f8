"""Autotune's plan: the task, the derived limits, the excitation's margins, segment tables.

Numbers checked against hand calculations: the default axis limits are the task's range
± 25 % of its span, 1.5× its peak speed and 3× its peak acceleration plus the encoder's
noise (2 and 10 counts); the excitation keeps 5 % of the travel clear at each end, 70 %
of the speed and 50 % of the acceleration after the noise; a segment keeps its payload's
rows bit for bit and joins the lead-in and lead-out moves continuously within the limits.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from motor_comp.control.limits import Limits, check_reference
from motor_comp.control.trajectories import Table, table_from_arrays, write_table
from motor_comp.errors import ParameterError
from motor_comp.physics.config import PlantKind
from motor_comp.tuning import plan

RATE, Q, WIN = 1000.0, 1e-6, 0.01


def test_default_tasks_are_the_plants_own():
    """PMLM: p2p 0 → 50 mm (peak 1.875·D/T = 0.1875 m/s); ball-screw: sine 0 → 6 mm."""
    p = plan.task_table('', kind=PlantKind.PMLM, duration=None, rate=RATE)
    assert p.label == 'p2p' and p.duration == pytest.approx(10.0)
    assert p.table.t.shape == (10001,)
    assert np.array_equal(p.table.t, np.arange(10001) * (1.0 / RATE))   # the nodes' grid
    assert (p.table.x.min(), p.table.x.max()) == pytest.approx((0.0, 0.05), abs=1e-12)
    assert np.max(np.abs(p.table.v)) == pytest.approx(1.875 * 0.05 / 0.5, rel=1e-6)
    b = plan.task_table('', kind=PlantKind.BALLSCREW, duration=4.0, rate=RATE)
    assert b.label == 'sine' and b.duration == pytest.approx(4.0)
    assert b.table.x.max() == pytest.approx(0.006, rel=1e-6)   # amplitude 3 mm, 1 − cos
    w = 2 * math.pi / 2.0
    assert np.max(np.abs(b.table.v)) == pytest.approx(0.003 * w, rel=1e-5)


def test_task_from_a_table_file_is_cut_to_the_duration(tmp_path):
    t = np.arange(0, 3001) * 1e-3
    x = 0.01 * (1 - np.cos(2 * np.pi * t / 3.0))
    write_table(tmp_path / 'task.csv', table_from_arrays(t, x))
    task = plan.task_table(str(tmp_path / 'task.csv'), kind=None, duration=1.5, rate=RATE)
    assert task.label == 'task.csv' and task.duration == pytest.approx(1.5)
    np.testing.assert_allclose(task.table.x, x[:1501], atol=1e-12)
    with pytest.raises(ParameterError, match='--task: .*no such file'):
        plan.task_table(str(tmp_path / 'none.csv'), kind=None, duration=None, rate=RATE)
    with pytest.raises(ParameterError, match='--task-duration'):
        plan.task_table('p2p', kind=None, duration=-1.0, rate=RATE)


def test_axis_limits_derived_from_the_task():
    task = plan.task_table('p2p', kind=None, duration=None, rate=RATE).table
    lim = plan.axis_limits(task, quantum=Q, rate=RATE, accel_window=WIN)
    assert lim.travel == pytest.approx((-0.0125, 0.0625))          # 50 mm ± 25 %
    assert lim.vmax == pytest.approx(1.5 * 0.1875 + 2 * Q * RATE)   # + 2 counts per period
    a_peak = float(np.max(np.abs(task.a)))
    assert a_peak == pytest.approx(5.7735 * 0.05 / 0.25, rel=1e-3)   # minimum jerk
    assert lim.amax == pytest.approx(3 * a_peak + 10 * Q * RATE / WIN)
    assert math.isinf(lim.umax) and math.isinf(lim.max_error)
    # the task keeps the limits it was derived from
    check_reference(Table(data=task), lim, duration=10.0, rate=RATE)
    given = plan.axis_limits(task, quantum=Q, rate=RATE, accel_window=WIN,
                             travel=(-0.01, 0.07), vmax=0.5, umax=12.0, max_error=1e-3)
    assert given.travel == (-0.01, 0.07) and given.vmax == 0.5 and given.umax == 12.0
    assert given.max_error == 1e-3 and given.amax == pytest.approx(lim.amax)


def test_excitation_keeps_inside_the_axis_limits():
    axis = Limits(travel=(-0.01, 0.09), vmax=0.3, amax=3.0, umax=20.0, max_error=2e-3)
    exc = plan.excitation_limits(axis, quantum=Q, rate=RATE, accel_window=WIN, bandwidth=4.0)
    assert isinstance(exc, Limits)                 # the same limits the nodes enforce
    assert exc.travel == pytest.approx((-0.005, 0.085))   # 5 % of 100 mm clear each end
    assert exc.vmax == pytest.approx(0.7 * (0.3 - 0.002))
    assert exc.amax == pytest.approx(0.5 * (3.0 - 1.0))
    assert exc.umax == pytest.approx(14.0) and exc.max_error == 2e-3
    assert exc.bandwidth == 4.0
    # a short travel keeps 50 counts clear, not 5 %
    short = plan.excitation_limits(Limits(travel=(0.0, 0.0008), vmax=0.3, amax=3.0),
                                   quantum=Q, rate=RATE, accel_window=WIN, bandwidth=4.0)
    assert short.travel == pytest.approx((5e-5, 0.00075))


@pytest.mark.parametrize('axis, needle', [
    (Limits(travel=(0.0, 0.00008), vmax=0.3, amax=3.0), 'too short'),
    (Limits(travel=(0.0, 0.1), vmax=0.002, amax=3.0), '--vmax 0.002 leaves no speed'),
    (Limits(travel=(0.0, 0.1), vmax=0.3, amax=0.9), '--amax 0.9 leaves no acceleration'),
    (Limits(vmax=0.3, amax=3.0), 'finite --travel')])
def test_excitation_limits_refuse_what_leaves_no_room(axis, needle):
    with pytest.raises(ParameterError, match=needle):
        plan.excitation_limits(axis, quantum=Q, rate=RATE, accel_window=WIN, bandwidth=4.0)


def test_segment_leads_in_and_out_continuously():
    task = plan.task_table('p2p', kind=None, duration=4.0, rate=RATE).table
    lim = Limits(travel=(-0.05, 0.1), vmax=0.1, amax=1.0)
    seg = plan.segment_table(task, rate=RATE, limits=lim, x_from=0.08, x_to=-0.02,
                             lead=0.5, tail=0.3)
    tab = seg.table
    assert np.array_equal(tab.t, np.arange(tab.t.size) * (1.0 / RATE))
    assert tab.x[0] == 0.08 and tab.x[-1] == pytest.approx(-0.02)
    assert tab.v[0] == 0.0 and tab.v[-1] == 0.0
    i0 = round(seg.window[0] * RATE)
    assert seg.window[1] - seg.window[0] == pytest.approx(4.0)
    assert np.array_equal(tab.x[i0:i0 + task.x.size], task.x)   # the payload, bit for bit
    assert np.array_equal(tab.v[i0:i0 + task.x.size], task.v)
    # rest, move 80 mm → 0 within vmax/amax (minimum jerk: 1.875·D/T), rest
    assert np.all(tab.x[:500] == 0.08)
    move = slice(500, i0 - 500)
    assert np.max(np.abs(tab.v[move])) <= 0.1 + 1e-12
    assert np.max(np.abs(tab.a[move])) <= 1.0 + 1e-9
    assert np.max(np.abs(tab.v[move])) == pytest.approx(0.1, rel=0.01)   # speed-bound move
    assert np.all(tab.x[i0 - 500:i0] == pytest.approx(0.0, abs=1e-15))
    # continuous: no step larger than the fastest speed (the task's own) allows in a period
    fastest = max(0.1, float(np.max(np.abs(task.v))))
    assert np.max(np.abs(np.diff(tab.x))) <= fastest / RATE + 1e-12
    # the nodes accept the joins (the speed-bound move peaks at vmax to the last bit)
    joins = Table(data=table_from_arrays(tab.t[:i0], tab.x[:i0], tab.v[:i0], tab.a[:i0]))
    check_reference(joins, Limits(travel=lim.travel, vmax=0.1 * (1 + 1e-9), amax=1.0),
                    duration=seg.window[0] - 1e-3, rate=RATE)


def test_segment_without_lead_is_the_payload():
    task = plan.task_table('sine', kind=None, duration=2.0, rate=RATE).table
    seg = plan.segment_table(task, rate=RATE, limits=Limits())
    assert seg.window == (0.0, pytest.approx(2.0))
    assert np.array_equal(seg.table.x, task.x) and np.array_equal(seg.table.t, task.t)
    moving = table_from_arrays(task.t[:500], task.x[:500], task.v[:500], task.a[:500])
    with pytest.raises(ParameterError, match='at rest'):
        plan.segment_table(moving, rate=RATE, limits=Limits())


def test_recovered_share():
    assert plan.recovered(40e-6, 4e-6, 0.0) == pytest.approx(0.9)
    assert plan.recovered(40e-6, 12e-6, 5e-6) == pytest.approx(0.8)
    assert plan.recovered(40e-6, 50e-6, 5e-6) == pytest.approx(-10 / 35)   # worse than none
    assert plan.recovered(40e-6, 4e-6, 40e-6) is None    # the true model reduces nothing
    assert plan.recovered(None, 4e-6, 1e-6) is None      # no reversal, no glitch
