"""Each effect's identification declarations (its ``TERM``): round trips, columns, needs.

The workbench composes these declarations and never names an effect, so what a term
declares is the whole of what it means for identification: its encoding must round
trip through the model file, its block columns must equal one element at a time, and
its declared needs and domain must say no where the physics does.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import TERMS, VOCABULARY, make_effect
from motor_comp.physics.effects.identification import Context, Summary
from motor_comp.physics.effects.presliding import gms_trajectory, gms_unit_column, \
    gms_unit_columns, gms_unit_columns_sv, gms_unit_curve
from motor_comp.physics.effects.ripple import harmonic_columns


def summary(**kw) -> Summary:
    base = dict(dt=1e-3, duration=20.0, quantum=1e-6, noise=2e-7, span=(-0.05, 0.05),
                speeds={1: 1e-4, 10: 1e-3, 50: 0.02, 90: 0.08, 95: 0.1}, accel90=1.0,
                reversals=20, direction=0, rotary=False)
    base.update(kw)
    return Summary(**base)


def test_every_effect_of_the_vocabulary_declares_a_term():
    assert list(TERMS) == [n for n in VOCABULARY if n in TERMS]
    assert set(TERMS) == set(VOCABULARY)
    for name, t in TERMS.items():
        assert t.name == name and t.effect.name == name


MODEL = AxisModel(mass=5.0, input_gain=15.0, effects=(
    make_effect('coulomb', {'fc': 10.0}), make_effect('viscous', {'fv': 20.0}),
    make_effect('stribeck', {'fs': 14.0, 'vs': 0.01, 'delta': 2.0}),
    make_effect('ripple', {'period': 0.02, 'harmonics': [[3.0, -1.0], [0.5, 0.2]]}),
    make_effect('spring', {'k': 300.0, 'x0': 0.01}),
    make_effect('asymmetry', {'dfc': 1.5, 'dfv': -2.0}),
    make_effect('delay', {'tau': 1.3e-3}), make_effect('backlash', {'width': 2e-5})))


@pytest.mark.parametrize('name', [n for n in MODEL.names])
def test_encode_inverts_decode(name):
    t = TERMS[name]
    ctx = Context(present=frozenset(MODEL.names), eta={}, sticks=False)
    coef, eta = t.decode(MODEL)
    values = {(name, k): v for k, v in coef.items()}
    values[('coulomb', 'fc')] = MODEL.fc
    (effect,) = [e for e in t.encode(values, eta, ctx) if e.name == name]
    assert effect == MODEL.get(name)


@settings(max_examples=25, deadline=None)
@given(fc=st.floats(0.5, 50), a=st.lists(st.floats(0.05, 1.0), min_size=1, max_size=4),
       d0=st.floats(1e-6, 1e-4), c=st.floats(10, 1e5))
def test_presliding_round_trip(fc, a, d0, c):
    alpha = tuple(x / sum(a) for x in a)
    dists = tuple(d0 * 3.0 ** j for j in range(len(a)))
    gms = make_effect('presliding', {'alpha': alpha, 'k': [al * fc / d for al, d in
                                                           zip(alpha, dists)], 'C': c * fc})
    model = AxisModel(mass=1.0, effects=(make_effect('coulomb', {'fc': fc}), gms))
    t = TERMS['presliding']
    coef, eta = t.decode(model)
    ctx = Context(present=frozenset(model.names), eta={'presliding': eta})
    values = {('presliding', k): v for k, v in coef.items()}
    out = {e.name: e for e in t.encode(values, eta, ctx)}
    assert out['coulomb'].fc == pytest.approx(fc, rel=1e-12)
    assert np.allclose(out['presliding'].k, gms.k, rtol=1e-9)
    assert np.allclose(out['presliding'].alpha, gms.alpha, rtol=1e-9)
    assert out['presliding'].C == pytest.approx(gms.C, rel=1e-9)


def test_gms_columns_in_one_pass_equal_one_element_at_a_time():
    rng = np.random.default_rng(3)
    x = np.cumsum(rng.normal(0, 2e-6, 4000)) + 1e-4 * np.sin(np.linspace(0, 30, 4000))
    dists = (2e-6, 7e-6, 3e-5)
    many = gms_unit_columns(x, np.array([1 / d for d in dists]), 800.0, 1.4, 3e-3, 1.3, 1e-3,
                            np.zeros(3))
    for j, d in enumerate(dists):
        one = gms_trajectory(x, np.ones(1), np.array([1.0 / d]), np.zeros(1), 800.0, 1.0,
                             1.4, 3e-3, 1.3, 1e-3)
        assert np.max(np.abs(many[:, j] - one)) == 0.0


def test_gms_one_element_column_equals_the_general_kernel_bit_for_bit():
    rng = np.random.default_rng(4)
    x = np.cumsum(rng.normal(0, 2e-6, 4000)) + 1e-4 * np.sin(np.linspace(0, 30, 4000))
    dists = (2e-6, 7e-6, 3e-5)
    tdamp = (0.0, 1.4e-3, 3e-4)
    for fs in (1.0, 1.4):
        curve = gms_unit_curve(x, fs, 3e-3, 1.3, 1e-3)
        many = gms_unit_columns_sv(x, curve, np.array([1 / d for d in dists]), 800.0, 1e-3,
                                   np.array(tdamp))
        decay = np.full(len(x), -1.0)     # shared by the elements, filled as they slip
        for j, (d, td) in enumerate(zip(dists, tdamp)):
            one = gms_unit_column(x, curve, 1 / d, 800.0, 1e-3, td, decay)
            assert np.array_equal(many[:, j], one)
            # the decays filled give the same column again
            assert np.array_equal(gms_unit_column(x, curve, 1 / d, 800.0, 1e-3, td, decay), one)


def test_ripple_columns_in_one_pass_are_the_harmonics_sine_and_cosine():
    # the fundamental: the same product and libm calls as numpy (bit for bit where
    # numpy's float64 sin/cos are the libm's; within an ulp wherever they are not); the
    # harmonics by the angle-addition recurrence, within 1e-14 of sin/cos(h·w·x)
    rng = np.random.default_rng(7)
    x = np.concatenate([rng.uniform(-0.1, 0.1, 20000), rng.uniform(-50.0, 50.0, 20000)])
    for w in (1.0, 2 * np.pi / 0.0291, 2 * np.pi * 6 / 0.0117):
        sc = harmonic_columns(w, x, 1)
        np.testing.assert_array_max_ulp(sc[:, 0], np.sin(w * x), maxulp=1)
        np.testing.assert_array_max_ulp(sc[:, 1], np.cos(w * x), maxulp=1)
    # arguments up to 60 rad, so that the reference's own rounding of h·z (≤ 60 ulp
    # of 1) stays under the tolerance
    w = 2 * np.pi / 0.0291
    x = rng.uniform(-0.0291 * 60 / (2 * np.pi) / 6, 0.0291 * 60 / (2 * np.pi) / 6, 20000)
    sc = harmonic_columns(w, x, 6)
    assert sc.shape == (len(x), 12)
    assert sc.T.flags.c_contiguous      # column by column: smoothed without a copy
    z = w * x
    for h in range(1, 7):
        assert np.max(np.abs(sc[:, 2 * h - 2] - np.sin(h * z))) < 1e-14
        assert np.max(np.abs(sc[:, 2 * h - 1] - np.cos(h * z))) < 1e-14
    # a harmonic's value does not depend on how many are computed (its cache key)
    assert np.array_equal(harmonic_columns(w, x, 3), sc[:, :6])


def test_declared_needs_say_no_where_the_physics_does():
    assert TERMS['gravity'].applicable(summary()) is not None          # linear axis
    assert TERMS['gravity'].applicable(summary(rotary=True, span=(0, 3))) is None
    # a spring acts within a revolution
    assert TERMS['spring'].applicable(summary(rotary=True, span=(0, 50.0))) is not None
    assert TERMS['spring'].applicable(summary(rotary=True, span=(0, 3.0))) is None
    # pre-sliding and backlash act at reversals; offset and asymmetry need both ways
    for name in ('presliding', 'backlash'):
        assert TERMS[name].applicable(summary(reversals=2)) is not None
    for name in ('offset', 'asymmetry'):
        assert TERMS[name].applicable(summary(direction=1)) is not None
        assert TERMS[name].applicable(summary()) is None


def test_declared_domains():
    s = summary()
    # a spring whose rest position is far outside the travel is a constant by another name
    assert TERMS['spring'].admissible({('spring', 'k'): 100.0, ('spring', 'c'): -100.0 * 5.0},
                                      {}, s) is not None
    assert TERMS['spring'].admissible({('spring', 'k'): 100.0, ('spring', 'c'): -1.0},
                                      {}, s) is None
    # a GMS curve crossed within two samples at the run's acceleration is a stick
    fast = summary(accel90=100.0)          # 2·a·dt² = 200 µm
    assert TERMS['presliding'].admissible({}, {'d': (1e-5, 3e-5)}, fast) is not None
    assert TERMS['presliding'].admissible({}, {'d': (1e-5, 3e-4)}, fast) is None


def test_search_spaces_follow_the_sensor_and_the_record():
    s = summary()
    ctx = Context(present=frozenset(), eta={})
    (tau,) = TERMS['delay'].space(s, ctx)
    assert tau.lo == 0.0 and tau.hi == pytest.approx(0.03)
    assert TERMS['delay'].space(summary(duration=0.1), ctx)[0].hi == pytest.approx(0.01)
    d, c = TERMS['presliding'].space(s, ctx)
    assert d.lo == pytest.approx(3e-6) and d.vector == 4          # three counts
    (w,) = TERMS['backlash'].space(s, ctx)
    assert w.lo >= 10 * s.noise and w.hi <= 0.05 * s.travel + 1e-12
    vs, delta = TERMS['stribeck'].space(s, ctx)
    assert max(vs.grid) <= s.speeds[95] / 3 + 1e-12                # decays within the run
    (period,) = TERMS['ripple'].space(s, ctx)
    assert period.hi == pytest.approx(s.travel / 2)              # two periods seen
    assert math.isfinite(period.lo) and period.lo > 0
    # two periods seen, harmonics too: a ripple must repeat on the periods it was not
    # fitted on (repeats.block_cv), a shape at one place does not
    assert TERMS['ripple'].orders(s, {'period': 0.45 * s.travel})[1] > 1
    assert TERMS['ripple'].repeats_every({'period': 0.02}) == pytest.approx(0.02)
    assert all(TERMS[n].repeats_every({}) is None for n in TERMS if n != 'ripple')


def test_a_rotary_ripple_repeats_within_a_revolution():
    # a force that is a function of the angle repeats every turn: on an axis that turned
    # 450 rad (HSM150's runs), no period of 225 rad is searched or started from
    ctx = Context(present=frozenset(), eta={})
    turns = summary(rotary=True, span=(0.0, 450.0),
                    speeds={1: 0.1, 10: 1.0, 50: 20.0, 90: 40.0, 95: 45.0})
    (period,) = TERMS['ripple'].space(turns, ctx)
    assert period.hi == pytest.approx(2 * math.pi)
    x = np.linspace(0.0, 450.0, 200_001)
    slow = np.sin(2 * math.pi * x / 150.0)               # three "periods" over the travel
    (start,) = TERMS['ripple'].initial(turns, ctx, (x, slow))
    assert start['period'] <= 2 * math.pi + 1e-9
    cogging = slow + 0.5 * np.sin(7 * x)                 # 7 per revolution
    (start,) = TERMS['ripple'].initial(turns, ctx, (x, cogging))
    assert start['period'] == pytest.approx(2 * math.pi / 7, rel=0.01)
    # under a revolution of travel the two-periods rule is the tighter one
    short = summary(rotary=True, span=(0.0, 3.0), speeds=turns.speeds)
    assert TERMS['ripple'].space(short, ctx)[0].hi == pytest.approx(1.5)


def test_gms_columns_times_the_levels_are_the_effects_own_law():
    """A model's GMS, micro-damping included, through its term's columns (``compare``)."""
    rng = np.random.default_rng(5)
    n, dt = 5000, 1e-3
    x = 2e-4 * np.sin(np.linspace(0, 40, n)) + np.cumsum(rng.normal(0, 1e-7, n))
    fc = 12.0
    gms = make_effect('presliding', {'alpha': [0.45, 0.3, 0.15, 0.1],
                                     'k': [8e6, 3e6, 1e6, 3e5], 'C': 12000.0,
                                     'sigma': [11200.0, 4200.0, 1400.0, 420.0]})
    st = make_effect('stribeck', {'fs': 18.0, 'vs': 1e-3, 'delta': 1.0})
    model = AxisModel(mass=25.0, effects=(make_effect('coulomb', {'fc': fc}), st, gms))
    t = TERMS['presliding']
    coef, eta = t.decode(model)
    ctx = Context(present=frozenset(model.names), eta={'stribeck': {'vs': 1e-3, 'delta': 1.0},
                                                       'presliding': eta})

    class P:
        xg = x

        @staticmethod
        def memo(key, make):
            return make()
    P.dt = dt
    cols = t.columns(eta, ctx)
    block = np.stack([c.fn(P) for c in cols], axis=1)
    got = block @ np.array([coef[c.label] for c in cols])
    want = gms.force_along(x, dt, fc=fc, fs=18.0, vs=1e-3, delta=1.0)
    assert np.max(np.abs(got - want)) < 1e-9 * np.max(np.abs(want))


def test_declared_shapes_name_one_term_each_and_say_what_the_law_does():
    """A residual's shape points to one term, and the term's law has that shape.

    Two terms declaring one shape would leave the scan's hint to the order of the
    vocabulary.  The trend is checked against the law: a viscous force grows with
    speed, a Stribeck excess falls from the lowest speeds.
    """
    from motor_comp.physics.effects.identification import Shape
    shapes = [(n, t.shape) for n, t in TERMS.items() if t.shape is not None]
    keys = [(s.against, s.odd, s.trend) for _, s in shapes]
    assert len(keys) == len(set(keys)), keys
    assert {n for n, _ in shapes} >= {'coulomb', 'offset', 'viscous', 'stribeck', 'ripple',
                                      'load_friction', 'position_friction'}
    v = np.array([1e-4, 1e-3, 1e-2, 0.1, 0.3])
    visc = make_effect('viscous', {'fv': 100.0})
    strb = make_effect('stribeck', {'fs': 20.0, 'vs': 1e-3, 'delta': 1.0})
    fv = visc.force(np.zeros_like(v), v)
    fs = strb.force(np.zeros_like(v), v, fc=5.0)
    assert np.all(np.diff(fv) > 0) and TERMS['viscous'].shape.trend == 1
    assert np.all(np.diff(fs) < 0) and TERMS['stribeck'].shape.trend == -1
    with pytest.raises(ValueError, match='against'):
        Shape('time', odd=True)
    with pytest.raises(ValueError, match='trend'):
        Shape('velocity', odd=True, trend=2)


@pytest.mark.parametrize('against, odd, trend, level, want', [
    ('velocity', True, 1, False, 'viscous'), ('velocity', True, -1, False, 'stribeck'),
    ('velocity', True, 0, False, ''), ('force', True, 1, False, 'load_friction'),
    ('position', True, 0, False, 'position_friction'), ('position', False, -1, False, 'ripple'),
    ('velocity', True, 1, True, 'coulomb'), ('time', False, 0, True, 'offset'),
    ('time', True, 1, False, ''), ('reversal', True, 0, False, '')])
def test_the_scan_names_the_term_whose_shape_a_feature_has(against, odd, trend, level, want):
    from motor_comp.workbench.scan import shape_of
    assert shape_of(against, odd, trend, level) == want
