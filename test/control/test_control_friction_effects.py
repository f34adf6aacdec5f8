"""Load- and position-dependent friction in the closed loop (issue 23 item 3).

A plant file with ``load_friction`` and ``position_friction`` reaches the simulator
through :func:`~motor_comp.physics.config.plant_from_dict` like every effect: the friction
the plant applies at each control sample is the raised level, both simulator engines
give the same numbers, and the controller's nominal model scales the new levels with
the others (a nominal ``fc`` at 50 % or 0 must not leave ``fc + dfc(x)`` below zero).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from motor_comp.control import default_trajectory, make_controller, simulate
from motor_comp.control.nominal import derive_nominal
from motor_comp.physics import Sensors, StepLoad
from motor_comp.physics.config import plant_from_dict

#: the PMLM of config/pmlm.yaml with a screw-like load term and a tight spot of +60 N
#: in the middle of the default move (0 → 50 mm), and a low spot of −6 N before it
WORN = {
    'plant': 'pmlm',
    'motor': {'mass_kg': 5.4, 'resistance_ohm': 8.6, 'force_constant_N_per_A': 130.0,
              'back_emf_V_s_per_m': 123.0},
    'effects': {'coulomb': {'fc': 10.0}, 'stribeck': {'fs': 20.0, 'vs': 0.1, 'delta': 2.0},
                'viscous': {'fv': 10.0}, 'load_friction': {'mu': 0.15},
                'position_friction': {'x': [0.0, 0.008, 0.015, 0.025, 0.035],
                                      'dfc': [0.0, -6.0, 0.0, 60.0, 0.0]}},
}


@pytest.fixture(scope='module')
def worn():
    """The worn PMLM plant."""
    return plant_from_dict(WORN, source='worn')


def test_closed_loop_friction_is_the_raised_level(worn):
    # the friction the plant applied at each control sample is
    # fc + (fs − fc)·e^{−(v/vs)²} + mu·|F_in| + dfc(x), with F_in from the logged command
    # and the true speed (PMLM back-EMF): the effects act through the plant file
    res = simulate(worn, make_controller('pid', plant=derive_nominal(worn)),
                   default_trajectory('pmlm'), duration=2.0)
    m = worn.model
    x, v, u = res.true_position, res.true_velocity, res.voltage
    f_in = m.input_force(u, v)
    base = 10.0 + 10.0 * np.exp(-(v / 0.1) ** 2)
    raised = m.dry_friction_shift(x, f_in=f_in)
    np.testing.assert_array_equal(
        raised, 0.15 * np.abs(f_in) + m.get('position_friction').level(x))
    sliding = np.abs(v) > 0.01
    assert np.count_nonzero(sliding & (x > 0.02) & (x < 0.03)) > 10   # across the spot
    err = np.abs(res.friction - np.sign(v) * (base + raised))[sliding]
    # the reported friction is the last physics step's average, the state the sample's
    assert np.median(err) < 0.05 and err.max() < 0.2
    assert np.max(raised[sliding]) > 60.0                 # newtons of raised level


def test_jit_and_python_engines_identical_with_the_new_effects(worn):
    plant = dataclasses.replace(worn, sensors=Sensors(encoder_resolution=1e-6,
                                                      noise_std=3e-7))
    runs = []
    for engine in ('jit', 'python'):
        ctrl = make_controller('pid', plant=derive_nominal(plant))
        runs.append(simulate(plant, ctrl, default_trajectory('pmlm'), duration=0.4, seed=3,
                             load=StepLoad(force=5.0, t_start=0.1), engine=engine))
    for name in ('position', 'velocity', 'voltage', 'true_position', 'friction'):
        np.testing.assert_allclose(getattr(runs[0], name), getattr(runs[1], name),
                                   rtol=1e-12, atol=1e-12, err_msg=name)
    assert np.ptp(runs[0].true_position) > 0.01


@pytest.mark.parametrize('start, factor', [('half', 0.5), ('zero', 0.0), ('exact', 1.0),
                                           ('identified', 0.8)])
def test_nominal_scales_mu_and_dfc_with_the_friction(worn, start, factor):
    n = derive_nominal(worn, start).model               # a valid model at every factor
    t = worn.model
    assert n.fc == pytest.approx(factor * t.fc)
    assert n.get('load_friction').mu == pytest.approx(factor * 0.15)
    np.testing.assert_allclose(n.get('position_friction').dfc,
                               factor * np.array(t.get('position_friction').dfc))
    assert n.get('position_friction').x == t.get('position_friction').x
    # the whole nominal level is the factor times the true one, along the travel
    x = np.linspace(-0.01, 0.05, 61)
    np.testing.assert_allclose(n.fc + n.dry_friction_shift(x, f_in=100.0),
                               factor * (t.fc + t.dry_friction_shift(x, f_in=100.0)),
                               rtol=1e-12, atol=1e-12)
