"""The fast forms of the force laws equal the general laws; the kernel uses exactly them.

Issue 7 (speed): the Stribeck decay for δ = 1, 2 without ``pow``, the ripple harmonics
by the angle-addition recurrence, and the plant kernel's per-advance constants.  Each
special case must be the law itself (to the last bits), and the compiled kernel must
give the numbers of its pure-Python run (``NUMBA_DISABLE_JIT=1``) on every effect.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from numba import njit
from physics_helpers import model, plant

from motor_comp.physics import make_effect
from motor_comp.physics import kernel as K
from motor_comp.physics.effects.ripple import MAX_HARMONICS, ripple_force
from motor_comp.physics.effects.stribeck import stribeck_magnitude, stribeck_shape

EPS = np.finfo(float).eps


@njit(cache=False)
def _general_shape(z, delta):
    """``exp(−|z|^δ)`` with the power, compiled like the kernel (same exp and pow)."""
    out = np.empty_like(z)
    for i in range(z.shape[0]):
        out[i] = np.exp(-np.abs(z[i]) ** delta)
    return out


@njit(cache=False)
def _fast_shape(z, delta):
    out = np.empty_like(z)
    for i in range(z.shape[0]):
        out[i] = stribeck_shape(z[i], delta)
    return out


def test_stribeck_delta_one_is_exactly_the_power_law():
    z = np.random.default_rng(3).uniform(-80.0, 80.0, 100_000)
    np.testing.assert_array_equal(_fast_shape(z, 1.0), _general_shape(z, 1.0))


def test_stribeck_delta_two_equals_the_power_law_to_one_rounding_of_the_exponent():
    rng = np.random.default_rng(4)
    z = np.concatenate([rng.uniform(-30.0, 30.0, 100_000), rng.normal(0.0, 1e-3, 10_000)])
    fast, general = _fast_shape(z, 2.0), _general_shape(z, 2.0)
    # z·z and pow(|z|, 2) are each within half an ulp of z²: the decays differ by at
    # most exp(±ulp(z²)), i.e. a relative 2·eps·max(z², 1)
    bound = 2.0 * EPS * np.maximum(z * z, 1.0) * general + 1e-300
    assert np.all(np.abs(fast - general) <= bound)
    assert np.count_nonzero(fast != general) < 0.01 * z.size    # nearly all identical


@pytest.mark.parametrize('delta', [0.5, 1.0, 1.7, 2.0])
def test_stribeck_level_is_fc_to_fs(delta):
    assert stribeck_magnitude(0.0, 10.0, 20.0, 0.1, delta) == 20.0
    assert stribeck_magnitude(0.1, 10.0, 20.0, 0.1, delta) == pytest.approx(
        10.0 + 10.0 * np.exp(-1.0), rel=1e-15)
    assert stribeck_magnitude(100.0, 10.0, 20.0, 0.1, delta) == pytest.approx(10.0, rel=1e-15)


@njit(cache=False)
def _one_harmonic(x, period, a1, b1):
    """``a1·sin θ + b1·cos θ`` elementwise, with the kernel's libm sin/cos (not numpy's)."""
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        th = 2.0 * np.pi / period * x[i]
        out[i] = a1 * np.sin(th) + b1 * np.cos(th)
    return out


@njit(cache=False)
def _sine_only(x, period, a1):
    out = np.empty_like(x)
    for i in range(x.shape[0]):
        out[i] = a1 * np.sin(2.0 * np.pi / period * x[i])
    return out


def _ripple_reference(x, period, a, b):
    """Σ a_h sin(hθ) + b_h cos(hθ) at θ = (2π/period)·x, the harmonics in long double."""
    th = (2.0 * np.pi / period * np.asarray(x, dtype=float)).astype(np.longdouble)
    f = np.zeros_like(th)
    for h in range(len(a)):
        f += np.longdouble(a[h]) * np.sin((h + 1) * th) \
            + np.longdouble(b[h]) * np.cos((h + 1) * th)
    return f


@settings(max_examples=60, deadline=None)
@given(n=st.integers(1, MAX_HARMONICS), period=st.floats(0.002, 0.2),
       seed=st.integers(0, 2 ** 31))
def test_ripple_recurrence_matches_the_harmonic_sum(n, period, seed):
    rng = np.random.default_rng(seed)
    a, b = rng.uniform(-10.0, 10.0, n), rng.uniform(-10.0, 10.0, n)
    x = rng.uniform(-0.5, 0.5, 2000)
    got = ripple_force(x, period, a, b)
    ref = _ripple_reference(x, period, a, b)
    scale = np.sum(np.abs(a) + np.abs(b))
    # the recurrence loses about one rounding per harmonic (h·eps of the amplitude)
    assert float(np.max(np.abs(got - ref))) <= 4.0 * n * EPS * scale
    if n == 1:     # one harmonic: exactly a·sin θ + b·cos θ, no recurrence
        np.testing.assert_array_equal(got, _one_harmonic(x, period, a[0], b[0]))


def test_single_sine_harmonic_skips_the_cosine_exactly():
    # the PMLM default (Tan eq. 9 with B1 = 0): a·sin θ, the same bits as a·sin θ + 0·cos θ
    x = np.random.default_rng(6).uniform(-0.3, 0.3, 5000)
    got = ripple_force(x, 0.02, np.array([8.5]), np.array([0.0]))
    np.testing.assert_array_equal(got, _sine_only(x, 0.02, 8.5))
    np.testing.assert_array_equal(got, _one_harmonic(x, 0.02, 8.5, 0.0))
    both = ripple_force(x, 0.02, np.array([8.5]), np.array([1e-300]))   # general branch
    np.testing.assert_allclose(both, got, rtol=0, atol=1e-299)


def test_ripple_sine_part_is_odd_and_cosine_part_even_bit_for_bit():
    x = np.random.default_rng(5).uniform(0.0, 0.3, 5000)
    a = np.array([8.5, -1.2, 0.7, 0.3, 0.05])
    zero = np.zeros_like(a)
    np.testing.assert_array_equal(ripple_force(-x, 0.02, a, zero), -ripple_force(x, 0.02, a, zero))
    np.testing.assert_array_equal(ripple_force(-x, 0.02, zero, a), ripple_force(x, 0.02, zero, a))


def test_kernel_reports_the_effect_law_exactly():
    # one implementation: the kernel's ripple force at its position is Ripple.force there
    params = {'period': 0.013, 'harmonics': [[4.0, 1.0], [0.5, -0.3], [0.2, 0.1]]}
    rip = make_effect('ripple', params)
    p = plant(model(('coulomb', {'fc': 1.0}), ('viscous', {'fv': 20.0}), ('ripple', params)))
    for _ in range(200):
        K.plant_advance(p.params, p.state, 12.0, 0.0, 7)
        assert p.ripple_force == rip.force(np.array([p.position]))[0]
    assert p.position > 0.013                 # more than one ripple period travelled


_ALL_EFFECTS = {
    'coulomb': {'fc': 3.0}, 'stribeck': {'fs': 4.5, 'vs': 0.02, 'delta': 1.4},
    'viscous': {'fv': 30.0},
    'ripple': {'period': 0.01, 'harmonics': [[1.5, 0.4], [0.3, -0.2], [0.1, 0.05]]},
    'offset': {'f0': 0.7}, 'spring': {'k': 400.0, 'x0': 0.001},
    'asymmetry': {'dfc': 0.6, 'dfv': 4.0}, 'delay': {'tau': 0.00033},
    'backlash': {'width': 2e-5}}
_GMS = {'alpha': [0.6, 0.3, 0.1], 'k': [2e6, 5e5, 1e5], 'C': 2400.0,
        'sigma': [400.0, 100.0, 20.0]}

#: runs in the test process (compiled) and in a child with NUMBA_DISABLE_JIT=1 (pure
#: Python): the same source, so any difference is the compilation
_RUN = r'''
import numpy as np
from motor_comp.physics import AxisModel, Plant, Sensors, load_plant, make_effect
from motor_comp.physics import kernel as K


def run(m, steps):
    p = Plant(m, sensors=Sensors(encoder_resolution=0.0), physics_rate=10000.0)
    out = []
    for k in range(steps):
        u = 6.0 * np.sin(2 * np.pi * 3.0 * k * 1e-3)    # reversals: stick, slip, events
        K.plant_advance(p.params, p.state, u, 0.0, 10)
        out.append([p.position, p.velocity, p.load_position, p.friction_force,
                    p.ripple_force, p.applied_command, p.time])
    return out


def build(spec):
    if isinstance(spec, str):
        return load_plant(spec).model
    return AxisModel(mass=2.0, input_gain=1.0, back_emf=0.0, damping=0.0,
                     effects=tuple(make_effect(n, p) for n, p in spec))


result = {name: run(build(spec), STEPS) for name, spec in CASES.items()}
'''


def _cases():
    every = list(_ALL_EFFECTS.items())
    gms = [e for e in every if e[0] != 'stribeck'] + [('presliding', _GMS)]
    delta2 = [('coulomb', {'fc': 3.0}), ('stribeck', {'fs': 5.0, 'vs': 0.01, 'delta': 2.0}),
              ('viscous', {'fv': 10.0})]
    # issue 23: the level shift mu·|F_in| + dfc(x) runs in its own compiled copy of the
    # step (kernel._advance_shifted), so it is compared on its own, static and GMS
    shifted = [('load_friction', {'mu': 0.05}),
               ('position_friction', {'x': [-0.004, -0.001, 0.003], 'dfc': [0.0, 0.4, -0.5]})]
    return {'pmlm': 'pmlm', 'ballscrew': 'ballscrew', 'every_static': every,
            'every_gms': gms, 'delta2': delta2, 'shifted_static': every + shifted,
            'shifted_gms': gms + shifted}


def test_compiled_kernel_equals_its_pure_python_run_on_every_effect(jit_and_pure):
    src = _RUN.replace('STEPS', '300').replace('CASES', repr(_cases()))
    jit, pure = jit_and_pure(src)
    assert set(pure) == set(jit) == set(_cases())
    for name in jit:
        a, b = np.array(jit[name]), np.array(pure[name])
        # libm and numpy's scalar exp/sin may differ in the last bit; nothing more
        np.testing.assert_allclose(a, b, rtol=1e-9, atol=1e-12, err_msg=name)
        assert np.ptp(a[:, 0]) > 1e-4, name             # the axis really moved
        assert np.any(a[:, 1] > 0) and np.any(a[:, 1] < 0), name   # and reversed
