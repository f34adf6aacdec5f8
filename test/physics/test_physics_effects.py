"""Each physical effect on its own: validation, force laws, symmetry, regressors.

DESIGN.md §3/§6: every effect validates its SI parameters (a bad value raises a
``ValueError`` naming the parameter), friction is odd in velocity and zero at rest,
ripple is periodic in position, and linear laws are reproduced by their regressors.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motor_comp.errors import ParameterError
from motor_comp.physics import EFFECTS, VOCABULARY, make_effect
from motor_comp.physics.effects import EffectKind
from motor_comp.physics.effects import Backlash, Coulomb, Delay, Ripple, Stribeck, Viscous
from motor_comp.physics.effects.backlash import play

FAST = settings(max_examples=60, deadline=None)
speeds = st.floats(min_value=1e-6, max_value=10.0)


def test_vocabulary_is_design_section_6():
    assert VOCABULARY == ('coulomb', 'viscous', 'stribeck', 'presliding', 'ripple',
                          'offset', 'spring', 'asymmetry', 'delay', 'backlash', 'gravity',
                          'load_friction', 'position_friction')
    assert all(EFFECTS[name].name == name for name in VOCABULARY)


# ---- validation -----------------------------------------------------------------------
BAD = [
    ('coulomb', {'fc': -1.0}, 'coulomb.fc'),
    ('coulomb', {'fc': float('nan')}, 'coulomb.fc'),
    ('coulomb', {'fc': 'ten'}, 'coulomb.fc'),
    ('viscous', {'fv': -0.1}, 'viscous.fv'),
    ('viscous', {'fv': float('inf')}, 'viscous.fv'),
    ('stribeck', {'fs': -2.0}, 'stribeck.fs'),
    ('stribeck', {'fs': 2.0, 'vs': 0.0}, 'stribeck.vs'),
    ('stribeck', {'fs': 2.0, 'delta': 0.0}, 'stribeck.delta'),
    ('stribeck', {'fs': 2.0, 'delta': 11.0}, 'stribeck.delta'),
    ('presliding', {'alpha': [0.5, 0.4], 'k': [1e6, 1e5]}, 'presliding.alpha'),
    ('presliding', {'alpha': [1.5, -0.5], 'k': [1e6, 1e5]}, 'presliding.alpha[1]'),
    ('presliding', {'alpha': [0.5, 0.5], 'k': [1e6]}, 'presliding.k'),
    ('presliding', {'alpha': [0.5, 0.5], 'k': [1e6, 0.0]}, 'presliding.k[1]'),
    ('presliding', {'alpha': [0.5, 0.5], 'k': [1e6, 1e5], 'C': 0.0}, 'presliding.C'),
    ('presliding', {'alpha': [0.5, 0.5], 'k': [1e6, 1e5], 'sigma': [1.0]}, 'presliding.sigma'),
    ('presliding', {'alpha': [0.5, 0.5], 'k': [1e6, 1e5], 'sigma': [1.0, -1.0]},
     'presliding.sigma[1]'),
    ('presliding', {'alpha': [0.5, 0.5], 'k': [1e6, 1e5], 'c': 100.0}, "'c' [1/s]"),
    ('presliding', {'alpha': [1 / 9] * 9, 'k': [1e6] * 9}, 'presliding.alpha'),
    ('presliding', {'alpha': 'abc', 'k': [1e6]}, 'presliding.alpha'),
    ('ripple', {'period': 0.0}, 'ripple.period'),
    ('ripple', {'period': 0.02, 'harmonics': [[1.0]]}, 'ripple.harmonics'),
    ('ripple', {'period': 0.02, 'harmonics': [[1.0, float('nan')]]}, 'ripple.harmonics[0][1]'),
    ('ripple', {'period': 0.02, 'harmonics': []}, 'ripple.harmonics'),
    ('offset', {'f0': float('inf')}, 'offset.f0'),
    ('spring', {'k': float('nan')}, 'spring.k'),
    ('spring', {'k': 1.0, 'x0': None}, 'spring.x0'),
    ('asymmetry', {'dfc': float('nan')}, 'asymmetry.dfc'),
    ('asymmetry', {'dfv': 'x'}, 'asymmetry.dfv'),
    ('delay', {'tau': -1e-3}, 'delay.tau'),
    ('delay', {'tau': 0.2}, 'delay.tau'),
    ('backlash', {'width': -1e-6}, 'backlash.width'),
    ('backlash', {'width': 0.02}, 'backlash.width'),
    ('coulomb', {'fk': 1.0}, "'fk'"),
    ('load_friction', {'mu': -0.1}, 'load_friction.mu'),
    ('load_friction', {'mu': 1.0}, 'load_friction.mu'),
    ('load_friction', {'mu': float('nan')}, 'load_friction.mu'),
    ('load_friction', {'mu': 'high'}, 'load_friction.mu'),
    ('position_friction', {'x': [0.0, 0.1]}, "'dfc'"),
    ('position_friction', {'dfc': [0.0, 1.0]}, "'x'"),
    ('position_friction', {'x': [0.0], 'dfc': [1.0]}, 'position_friction.x'),
    ('position_friction', {'x': [i * 0.01 for i in range(33)], 'dfc': [0.0] * 33},
     'position_friction.x'),
    ('position_friction', {'x': [0.0, 0.1, 0.1], 'dfc': [0.0, 1.0, 0.0]},
     'position_friction.x'),
    ('position_friction', {'x': [0.0, 0.2, 0.1], 'dfc': [0.0, 1.0, 0.0]},
     'position_friction.x'),
    ('position_friction', {'x': [0.0, 0.1, 0.2], 'dfc': [0.0, 1.0]}, 'position_friction.dfc'),
    ('position_friction', {'x': [0.0, float('inf')], 'dfc': [0.0, 1.0]},
     'position_friction.x[1]'),
    ('position_friction', {'x': [0.0, 0.1], 'dfc': [0.0, None]}, 'position_friction.dfc[1]'),
    ('position_friction', {'x': '0 0.1', 'dfc': [0.0, 1.0]}, 'position_friction.x'),
    ('position_friction', {'x': 0.1, 'dfc': [0.0, 1.0]}, 'position_friction.x'),
    ('position_friction', {'x': [0.0, 1e-12], 'dfc': [0.0, 1.0]}, 'closer than 1e-09'),
    ('position_friction', {'x': [0.0, 2e6], 'dfc': [0.0, 1.0]}, 'position_friction.x[1]'),
    ('position_friction', {'x': [0.0, 1.0], 'dfc': [0.0, -2e9]}, 'position_friction.dfc[1]'),
]


@pytest.mark.parametrize('name, params, field', BAD,
                         ids=[f'{n}-{f}-{i}' for i, (n, _, f) in enumerate(BAD)])
def test_bad_parameter_raises_value_error_naming_it(name, params, field):
    with pytest.raises(ValueError) as info:
        make_effect(name, params)
    assert isinstance(info.value, ParameterError)
    msg = str(info.value)
    assert field in msg and '\n' not in msg


def test_unknown_effect_is_named():
    with pytest.raises(ParameterError, match="unknown effect 'cogging'"):
        make_effect('cogging', {})


#: every effect with parameters that make its law act
EXAMPLES = {
    'coulomb': {'fc': 3.5}, 'viscous': {'fv': 12.0},
    'stribeck': {'fs': 7.0, 'vs': 0.002, 'delta': 1.5},
    'presliding': {'alpha': [0.6, 0.4], 'k': [2e6, 5e5], 'C': 5000.0,
                   'sigma': [200.0, 50.0]},
    'ripple': {'period': 0.016, 'harmonics': [[1.0, -2.0], [0.5, 0.25]]},
    'offset': {'f0': -4.0}, 'spring': {'k': 250.0, 'x0': 0.01},
    'asymmetry': {'dfc': 1.5, 'dfv': -3.0}, 'delay': {'tau': 0.002},
    'backlash': {'width': 5e-6}, 'gravity': {'mgl': 3.0, 'q0': -0.5},
    'load_friction': {'mu': 0.15},
    'position_friction': {'x': [-0.05, 0.0, 0.012, 0.1], 'dfc': [0.0, 2.5, -1.0, 0.5]},
}


@pytest.mark.parametrize('name', VOCABULARY)
def test_params_round_trip_through_the_model_file_form(name):
    e = make_effect(name, EXAMPLES[name])
    assert e.params() == EXAMPLES[name]
    assert make_effect(name, e.params()) == e


@pytest.mark.parametrize('name', VOCABULARY)
def test_an_effect_declares_whether_its_force_reads_the_position(name):
    """The same motion elsewhere on the travel meets the same force unless declared.

    A backlash gap's flights are integrated once for every width when no force of the
    model reads the position (:func:`motor_comp.workbench.motion.motor_position`).
    """
    e = make_effect(name, EXAMPLES[name])
    if e.kind is not EffectKind.FORCE:
        assert not e.position_dependent
        return
    t = np.linspace(0.0, 2.0, 4001)
    x = 0.02 * np.sin(2.0 * np.pi * t) - 0.01
    v = np.gradient(x, t)
    f_in = 40.0 * np.cos(3.0 * t)
    moved = {}
    for shift in (0.0, 0.037):
        if name == 'presliding':
            moved[shift] = e.force_along(x + shift, float(t[1] - t[0]), fc=3.5)
        elif name == 'load_friction':
            moved[shift] = e.force(x + shift, v, f_in=f_in)
        else:
            moved[shift] = e.force(x + shift, v)
    # (to the rounding of a shifted coordinate: a stiff element's force is k times a
    # difference of positions)
    scale = float(np.max(np.abs(moved[0.0])))
    differs = not np.allclose(moved[0.0], moved[0.037], rtol=0.0, atol=1e-9 * scale)
    assert scale > 0.0, name
    assert differs == e.position_dependent, name


# ---- friction laws -------------------------------------------------------------------
@FAST
@given(v=speeds, fc=st.floats(0.0, 100.0), extra=st.floats(0.0, 100.0),
       vs=st.floats(1e-5, 1.0), delta=st.floats(0.2, 10.0), fv=st.floats(0.0, 1e3))
def test_friction_is_odd_in_velocity(v, fc, extra, vs, delta, fv):
    vv = np.array([v, -v])
    for f in (Coulomb(fc=fc).force(None, vv), Viscous(fv=fv).force(None, vv),
              Stribeck(fs=fc + extra, vs=vs, delta=delta).force(None, vv, fc=fc)):
        assert f[1] == -f[0]
        assert f[0] * v >= 0.0               # opposes (is subtracted along) the motion


def test_friction_is_zero_at_rest():
    zero = np.zeros(1)
    assert Coulomb(fc=5.0).force(zero, zero)[0] == 0.0
    assert Viscous(fv=5.0).force(zero, zero)[0] == 0.0
    assert Stribeck(fs=9.0, vs=1e-3).force(zero, zero, fc=5.0)[0] == 0.0
    assert make_effect('asymmetry', {'dfc': 2.0, 'dfv': 3.0}).force(zero, zero)[0] == 0.0


def test_static_curve_values():
    # Chiew eq. 2 at three speeds: v → 0 gives fs, v = vs gives fc + (fs−fc)/e (δ = 1)
    fc, fs, vs = 12.0, 18.0, 1e-3
    v = np.array([1e-9, vs, 1.0])
    total = Coulomb(fc=fc).force(None, v) + Stribeck(fs=fs, vs=vs, delta=1.0).force(
        None, v, fc=fc)
    np.testing.assert_allclose(total, [fs, fc + (fs - fc) / math.e, fc], rtol=1e-6)


def test_stribeck_needs_fs_at_least_fc():
    with pytest.raises(ParameterError, match='stribeck.fs'):
        Stribeck(fs=5.0).force(None, np.ones(2), fc=6.0)


def test_asymmetry_gives_fc_plus_minus_half_dfc():
    v = np.array([0.1, -0.1])
    asym = make_effect('asymmetry', {'dfc': 4.0, 'dfv': 20.0})
    f = Coulomb(fc=10.0).force(None, v) + Viscous(fv=100.0).force(None, v) + asym.force(None, v)
    # fc± = 10 ± 2 N, fv± = 100 ± 10 N·s/m
    np.testing.assert_allclose(f, [12.0 + 110.0 * 0.1, -(8.0 + 90.0 * 0.1)], rtol=1e-12)


# ---- ripple ------------------------------------------------------------------------
@FAST
@given(x=st.floats(-0.5, 0.5), period=st.floats(1e-3, 0.1),
       h=st.lists(st.tuples(st.floats(-20, 20), st.floats(-20, 20)), min_size=1,
                  max_size=4))
def test_ripple_is_periodic_and_its_regressors_reproduce_it(x, period, h):
    r = Ripple(period=period, harmonics=tuple(h))
    xs = np.array([x, x + period, x - 3 * period])
    f = r.force(xs)
    scale = 1.0 + float(np.sum(np.abs(h)))
    assert np.max(np.abs(f - f[0])) < 1e-9 * scale * (1.0 + abs(x) / period)
    coef = np.ravel(np.array(h))               # [a1, b1, a2, b2, ...]
    np.testing.assert_allclose(r.regressors(xs) @ coef, f, rtol=0, atol=1e-9 * scale)


def test_ripple_first_harmonic_is_tan_eq_9():
    r = Ripple(period=0.02, harmonics=((8.5, 0.0),))
    x = np.array([0.0, 0.005, 0.01, 0.015])
    np.testing.assert_allclose(r.force(x), [0.0, 8.5, 0.0, -8.5], atol=1e-12)
    assert r.amplitudes[0] == 8.5


@pytest.mark.parametrize('name, params, coef', [
    ('coulomb', {'fc': 3.0}, [3.0]),
    ('viscous', {'fv': 7.0}, [7.0]),
    ('offset', {'f0': -2.5}, [-2.5]),
    ('spring', {'k': 400.0, 'x0': 0.01}, [400.0, -4.0]),
    ('asymmetry', {'dfc': 1.0, 'dfv': 6.0}, [1.0, 6.0]),
])
def test_linear_effects_regressors_reproduce_the_force(name, params, coef):
    rng = np.random.default_rng(1)
    x, v = rng.uniform(-0.1, 0.1, 200), rng.uniform(-0.2, 0.2, 200)
    e = make_effect(name, params)
    np.testing.assert_allclose(e.regressors(x, v) @ np.array(coef), e.force(x, v),
                               rtol=1e-12, atol=1e-12)


def test_stribeck_regressor_coefficient_is_fs_minus_fc():
    v = np.linspace(-0.01, 0.01, 101)
    s = Stribeck(fs=18.0, vs=1e-3, delta=1.0)
    np.testing.assert_allclose(s.regressors(None, v)[:, 0] * (18.0 - 12.0),
                               s.force(None, v, fc=12.0), rtol=1e-12, atol=1e-12)


# ---- input and output effects ------------------------------------------------------
def test_delay_apply_shifts_a_sampled_signal_with_zero_before_the_start():
    t = np.arange(0.0, 0.1, 1e-4)
    u = 1.0 + np.cos(2 * math.pi * 20 * t)           # u[0] = 2: the start is visible
    out = Delay(tau=0.003).apply(t, u)
    np.testing.assert_allclose(out[30:], u[:-30], atol=1e-12)
    # a drive at power-on: nothing before the start (to the rounding of t − τ)
    np.testing.assert_allclose(out[:30], 0.0, atol=1e-12)
    # a fractional delay ramps in from that zero, one sample before t[0], like the kernel
    half = Delay(tau=0.00005).apply(t, u)
    assert half[0] == pytest.approx(0.5 * u[0])
    np.testing.assert_allclose(half[1:], 0.5 * (u[1:] + u[:-1]), atol=1e-12)
    assert np.array_equal(Delay(tau=0.0).apply(t, u), u)


@FAST
@given(steps=st.lists(st.floats(-1e-3, 1e-3), min_size=1, max_size=200),
       width=st.floats(0.0, 0.01))
def test_play_output_stays_within_half_width_and_moves_only_when_pushed(steps, width):
    x = np.cumsum(steps)
    xl = Backlash(width=width).apply(x, 0.0)
    half = 0.5 * width
    assert np.all(np.abs(x - xl) <= half * (1.0 + 1e-12) + 1e-15)
    prev = 0.0
    for xm, out in zip(x, xl):
        if out != prev:                       # the load moved: an edge is pushing it
            assert abs(abs(xm - out) - half) <= 1e-12
        prev = out


def test_play_dead_band_is_exactly_the_width():
    w = 1e-3
    xl = play(0.004, 0.0, w)                  # pushed forward: load at motor − w/2
    assert xl == 0.004 - w / 2
    for back in np.linspace(0.0, w, 11):      # retreating by up to w: the load stays
        assert play(0.004 - back, xl, w) == xl
    assert play(0.004 - w - 1e-9, xl, w) < xl  # one nanometre beyond: it follows
