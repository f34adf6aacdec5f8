"""The compiled kernel and the AxisModel force laws describe the same axis.

The workbench inverts :meth:`AxisModel.effect_forces` on logged motion, and the plant
kernel generates that motion: their sign conventions and parameters must agree for a
planted effect to be found again.  Also: mirror symmetry of the kernel (odd friction,
GMS included) for random parameters.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from physics_helpers import DT, model, plant, trace


def _inverse_check(m, u_of_t, n, *, min_speed):
    """Max |M·a − (F_in − Σ F_k)| over sliding samples, and the force scale [N]."""
    tr = trace(plant(m), u_of_t, n)
    x = np.concatenate([[0.0], tr['x']])
    v = np.concatenate([[0.0], tr['v']])
    acc = np.diff(v) / DT
    # midpoint of each step: RK4's average slope is matched to O(dt²) there
    xm, vm = 0.5 * (x[1:] + x[:-1]), 0.5 * (v[1:] + v[:-1])
    u = np.array([u_of_t(t - DT) for t in tr['t']])
    forces = m.effect_forces(xm, vm)
    rhs = m.input_force(u, vm) - sum(forces.values())
    sliding = (np.abs(v[1:]) > min_speed) & (np.abs(v[:-1]) > min_speed)
    assert np.count_nonzero(sliding) > 0.8 * n
    err = np.abs(m.mass * acc - rhs)[sliding]
    return float(err.max()), float(np.abs(m.input_force(u, vm)).max()), forces


def test_kernel_obeys_the_model_force_laws_of_every_force_effect():
    m = model(('coulomb', {'fc': 10.0}), ('stribeck', {'fs': 16.0, 'vs': 0.02, 'delta': 2.0}),
              ('viscous', {'fv': 30.0}),
              ('ripple', {'period': 0.02, 'harmonics': [[6.0, -2.0], [1.0, 1.5]]}),
              ('offset', {'f0': 3.0}), ('spring', {'k': 200.0, 'x0': 0.01}),
              ('asymmetry', {'dfc': 3.0, 'dfv': 8.0}),
              mass=5.4, input_gain=130.0 / 8.6, back_emf=2.0)

    def u_of_t(t):
        return 12.0 * math.sin(2.0 * math.pi * 1.0 * t)

    err, scale, forces = _inverse_check(m, u_of_t, 20000, min_speed=1e-3)
    assert set(forces) == {'coulomb', 'stribeck', 'viscous', 'ripple', 'offset', 'spring',
                           'asymmetry'}
    assert err < 2e-4 * scale            # a wrong sign or factor costs newtons


@pytest.mark.parametrize('sigma, max_err', [
    ([0.0] * 4, 0.5), ([11200.0, 4200.0, 1400.0, 420.0], 1.0)])
def test_kernel_gms_friction_matches_presliding_force_along(sigma, max_err):
    # the same displacement history fed to Presliding.force_along gives the friction
    # the kernel applied (GMS elements updated by the same gms_update)
    m = model(('coulomb', {'fc': 12.0}), ('stribeck', {'fs': 18.0, 'vs': 1e-3, 'delta': 1.0}),
              ('viscous', {'fv': 200.0}),
              ('presliding', {'alpha': [0.45, 0.30, 0.15, 0.10],
                              'k': [8e6, 3e6, 1e6, 3e5], 'C': 12000.0, 'sigma': sigma}),
              mass=25.0, input_gain=50.0, damping=50.0)
    tr = trace(plant(m), lambda t: 1.2 * math.sin(2.0 * math.pi * 2.0 * t), 10000)
    x = np.concatenate([[0.0], tr['x']])
    f_along = m.get('presliding').force_along(x, DT, fc=12.0, fs=18.0, vs=1e-3, delta=1.0)
    # force_along evaluates s(v) at the step's mean velocity, the kernel at its end
    # velocity: equal up to the change of s over one step (with micro-damping, an element
    # that starts to slip one step apart also changes σ_i·ż_i of that step)
    err = np.abs(f_along[1:] - tr['friction'])
    assert np.median(err) < 0.01
    assert np.max(err) < max_err
    assert np.ptp(tr['friction']) >= 24.0                # slid both ways: ±fc reached


@settings(max_examples=25, deadline=None)
@given(fc=st.floats(0.0, 20.0), extra=st.floats(0.0, 10.0), vs=st.floats(1e-3, 0.1),
       delta=st.floats(0.5, 3.0), fv=st.floats(0.0, 50.0), mass=st.floats(0.5, 20.0),
       ripple=st.floats(0.0, 5.0), gms=st.booleans(), amp=st.floats(0.0, 60.0),
       hz=st.floats(0.5, 20.0))
def test_kernel_is_mirror_symmetric_for_odd_effects(fc, extra, vs, delta, fv, mass,
                                                    ripple, gms, amp, hz):
    effects = [('coulomb', {'fc': fc}), ('stribeck', {'fs': fc + extra, 'vs': vs,
                                                      'delta': delta}),
               ('viscous', {'fv': fv}),
               ('ripple', {'period': 0.01, 'harmonics': [[ripple, 0.0]]}),   # odd in x
               ('spring', {'k': 100.0})]
    if gms:
        effects.append(('presliding', {'alpha': [0.7, 0.3], 'k': [1e6, 1e5],
                                       'C': 5000.0, 'sigma': [300.0, 30.0]}))
    m = model(*effects, mass=mass)
    up = trace(plant(m), lambda t: amp * math.sin(2 * math.pi * hz * t), 2000)
    down = trace(plant(m), lambda t: -amp * math.sin(2 * math.pi * hz * t), 2000)
    np.testing.assert_array_equal(down['x'], -up['x'])
    np.testing.assert_array_equal(down['friction'], -up['friction'])
