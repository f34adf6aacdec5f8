"""Simulator engines agree exactly; controller API (update, switching, ranges, reset)."""
from __future__ import annotations

import dataclasses
import json
import math
import os
import subprocess
import sys

import numpy as np
import pytest

from motor_comp.control import AdaptiveParams, ControlMode, NPIDParams, PIDParams, \
    default_trajectory, make_controller, make_trajectory, simulate
from motor_comp.control.controller import C_I
from motor_comp.errors import ParameterError
from motor_comp.physics import Plant, Sensors, StepLoad

FIELDS = ('reference', 'reference_velocity', 'position', 'velocity', 'voltage',
          'true_position', 'true_velocity', 'friction', 'ripple', 'estimates')


@pytest.mark.parametrize('plant_name,mode,ff', [('pmlm', 'adaptive_sliding', 'none'),
                                                ('ballscrew', 'npid', 'static+gms'),
                                                ('ballscrew', 'pid', 'gms')])
def test_jit_and_python_engines_identical(request, plant_name, mode, ff):
    plant = request.getfixturevalue(plant_name)
    plant = dataclasses.replace(plant, sensors=Sensors(encoder_resolution=1e-6,
                                                       noise_std=3e-7))
    traj = default_trajectory(plant_name)
    load = StepLoad(force=5.0, t_start=0.1)
    runs = []
    for engine in ('jit', 'python'):
        ctrl = make_controller(mode, plant=plant, feedforward=ff)
        runs.append(simulate(plant, ctrl, traj, duration=0.3, seed=7, load=load,
                             engine=engine))
    for name in FIELDS:
        np.testing.assert_allclose(getattr(runs[0], name), getattr(runs[1], name),
                                   rtol=1e-12, atol=1e-12, err_msg=name)
    assert np.any(runs[0].velocity != 0.0)


def test_first_measurement_velocity_is_zero(pmlm):
    res = simulate(pmlm, make_controller('pid', plant=pmlm), default_trajectory('pmlm'),
                   duration=0.01)
    assert res.velocity[0] == 0.0 and res.t[1] == pytest.approx(1e-3)


_CHILD = r'''
import json, sys
from motor_comp.control import default_trajectory, make_controller, simulate
from motor_comp.physics import load_plant
plant = load_plant('ballscrew')
ctrl = make_controller('npid', plant=plant, feedforward='static+gms')
res = simulate(plant, ctrl, default_trajectory('ballscrew'), duration=0.05)
json.dump({'u': res.voltage.tolist(), 'y': res.position.tolist(),
           'x': res.true_position.tolist()}, sys.stdout)
'''


def test_numba_disabled_gives_same_numbers(ballscrew):
    env = dict(os.environ, NUMBA_DISABLE_JIT='1')
    out = subprocess.run([sys.executable, '-c', _CHILD], env=env, capture_output=True,
                         text=True, timeout=120, check=True)
    child = json.loads(out.stdout)
    ctrl = make_controller('npid', plant=ballscrew, feedforward='static+gms')
    res = simulate(ballscrew, ctrl, default_trajectory('ballscrew'), duration=0.05)
    np.testing.assert_allclose(child['u'], res.voltage, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(child['y'], res.position, rtol=0, atol=1e-12)
    np.testing.assert_allclose(child['x'], res.true_position, rtol=1e-9, atol=1e-15)


def test_update_is_validated_and_atomic(ballscrew):
    ctrl = make_controller('pid', plant=ballscrew)
    before = ctrl.packed.copy()
    with pytest.raises(ParameterError, match='pid.kd'):
        ctrl.update(kp=1.0, kd=-5.0)
    with pytest.raises(ParameterError, match="unknown parameter 'lambda1'"):
        ctrl.update(lambda1=3.0)
    np.testing.assert_array_equal(ctrl.packed, before)
    assert ctrl.params.kp == PIDParams().kp
    ctrl.update(kp=1234.0)
    assert ctrl.params.kp == 1234.0 and ctrl.packed[2] == 1234.0
    with pytest.raises(ParameterError, match='controller mode'):
        ctrl.set_mode('lqr')
    with pytest.raises(ParameterError, match='feedforward'):
        make_controller('pid', plant=ballscrew, feedforward='lugre')


def test_fields_with_ranges_describe_every_parameter():
    for cls in (PIDParams, NPIDParams, AdaptiveParams):
        specs = cls.fields_with_ranges()
        assert [s.name for s in specs] == [f.name for f in dataclasses.fields(cls)]
        for s in specs:
            assert s.unit and s.description and s.min <= s.default <= s.max
            assert isinstance(s.default, float)


def _step_many(ctrl, traj, plant, n, start=0):
    """Drive ``plant`` (a Plant) with ``ctrl`` the way the ROS nodes do; return commands."""
    T = 1e-3
    us = []
    for k in range(start, start + n):
        ref = traj.at(k * T)
        m = plant.measure(T)
        u = ctrl.step(ref.position, ref.velocity, ref.acceleration, m.position,
                      m.velocity, T)
        plant.step(u, T)
        us.append(u)
    return us


def _switch_jumps(pmlm, target, *, rebalance):
    """Command jumps [V] at a switch pid → target and back, with or without re-balancing."""
    traj = default_trajectory('pmlm')
    ctrl = make_controller('pid', plant=pmlm)
    plant = Plant(pmlm.model, sensors=pmlm.sensors)
    us = _step_many(ctrl, traj, plant, 300)           # mid-move, ≈ 22 V
    jumps = []
    for k, mode in ((300, target), (305, 'pid')):
        integ = ctrl.state[C_I]
        ctrl.set_mode(mode)
        assert ctrl.mode is ControlMode.parse(mode)
        if not rebalance:
            ctrl.state[C_I] = integ                    # a naive switch keeps the integral
        nxt = _step_many(ctrl, traj, plant, 5, start=k)
        jumps.append(abs(nxt[0] - us[-1]))
        us = nxt
    return jumps


@pytest.mark.parametrize('target', ['adaptive_sliding', 'npid'])
def test_mode_switch_is_bumpless(pmlm, target):
    bumpless = _switch_jumps(pmlm, target, rebalance=True)
    naive = _switch_jumps(pmlm, target, rebalance=False)
    for b, n in zip(bumpless, naive):
        assert b < 2.0                  # V, out of ≈ 22 V during the move
        assert b <= 0.1 * n or n < 2.0  # the re-balanced integral removes ≥ 90 % of the bump


def test_feedforward_switch_is_bumpless(ballscrew):
    def jump(rebalance):
        traj = default_trajectory('ballscrew')
        ctrl = make_controller('pid', plant=ballscrew)
        plant = Plant(ballscrew.model, sensors=ballscrew.sensors)
        us = _step_many(ctrl, traj, plant, 400)
        integ = ctrl.state[C_I]
        ctrl.set_feedforward('static+gms')
        assert ctrl.feedforward.label == 'static+gms'
        if not rebalance:
            ctrl.state[C_I] = integ
        us2 = _step_many(ctrl, traj, plant, 3, start=400)
        # the command's own step-to-step spread (velocity quantisation through Kd)
        spread = np.max(np.abs(np.diff(us[-20:])))
        return abs(us2[0] - us[-1]), spread
    bumpless, spread = jump(True)
    naive, _ = jump(False)
    assert bumpless <= spread            # no larger than the command's own jitter …
    assert naive > 3.0 * spread          # … while a naive switch jumps by the friction


def test_reset_restores_initial_estimates(pmlm):
    ctrl = make_controller('adaptive_sliding', plant=pmlm)
    first = ctrl.estimates
    # the estimates start at the nominal model (itself 50 % of the truth by default)
    assert first['fc'] == pytest.approx(ctrl.nominal['fc'])
    half = make_controller('adaptive_sliding', plant=pmlm, initial_fraction=0.5)
    assert half.estimates['fc'] == pytest.approx(0.5 * ctrl.nominal['fc'])
    assert first['robust_gain'] == 0.0
    simulate(pmlm, ctrl, default_trajectory('pmlm'), duration=1.0)
    assert ctrl.estimates != first
    ctrl.reset()
    assert ctrl.estimates == first
    zero = make_controller('adaptive_sliding', plant=pmlm, initial_fraction=0.0)
    assert all(v == 0.0 for v in zero.estimates.values())


def test_integrator_clamps_while_saturated(ballscrew):
    from motor_comp.control.controller import C_I
    ctrl = make_controller('pid', plant=ballscrew, u_max=1.0)
    dt = 1e-3
    u = [ctrl.step(2e-3, 0.0, 0.0, 0.0, 0.0, dt) for _ in range(50)]   # e = 2 mm
    assert u == [1.0] * 50
    frozen = ctrl.state[C_I]
    assert frozen == 0.0               # never integrated into the limit
    ctrl.step(2e-3, 0.0, 0.0, 0.0, 0.0, dt)
    assert ctrl.state[C_I] == frozen
    # an error of the other sign un-saturates at once and integrates again
    u_back = ctrl.step(-1e-6, 0.0, 0.0, 0.0, 0.0, dt)
    assert abs(u_back) < 1.0 and ctrl.state[C_I] == pytest.approx(-1e-9)
    unclamped = make_controller('pid', plant=ballscrew)
    for _ in range(50):
        unclamped.step(2e-3, 0.0, 0.0, 0.0, 0.0, dt)
    assert unclamped.state[C_I] == pytest.approx(50 * 2e-3 * dt)


def test_saturation_and_anti_windup(pmlm):
    traj = make_trajectory('p2p', distance=0.05, move_time=0.2, dwell=0.8)
    res_sat = simulate(pmlm, make_controller('pid', plant=pmlm, u_max=20.0), traj,
                       duration=1.0)
    assert np.max(np.abs(res_sat.voltage)) <= 20.0 + 1e-12
    # with clamping the overshoot after the saturated move stays small
    over = np.max(res_sat.position) - 0.05
    assert over < 2e-3
    assert math.isfinite(over)
