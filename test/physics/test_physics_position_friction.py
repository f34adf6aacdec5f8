"""Position-dependent dry friction ``fc + dfc(x)``: the spline, the kernel, the model.

Issue 23 item 3 (DESIGN.md §6 ``position_friction {x, dfc}``): the spline passes
through its knots, is linear in the knot values (``basis(x) @ dfc``, what the
identification fits), is constant beyond the end knots and smooth (C¹) everywhere; a
slow traverse over a tight spot needs exactly ``dfc(x)`` more force over the knots' span
and nowhere else; a coast across it stops where its kinetic energy equals the friction
work; break-away at rest needs ``fs + dfc(x0)``; the model refuses a level
``fc + dfc(x)`` below zero, also where the spline dips between knots.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from physics_helpers import DT, model, plant, trace
from scipy.interpolate import CubicSpline
from scipy.optimize import brentq

from motor_comp.errors import ParameterError
from motor_comp.physics import AxisModel
from motor_comp.physics import kernel as K
from motor_comp.physics.effects import make_effect
from motor_comp.physics.effects.position_friction import MAX_KNOTS, PositionFriction, \
    slope_matrix

FAST = settings(max_examples=80, deadline=None)

#: a tight spot: 8 N more friction over 100–160 mm, peaking at 130 mm
SPOT = {'x': [0.10, 0.13, 0.16], 'dfc': [0.0, 8.0, 0.0]}


@st.composite
def splines(draw, min_knots=2):
    """Knots (strictly increasing, spacing 1–50 mm) and knot values in ±20 N."""
    n = draw(st.integers(min_knots, MAX_KNOTS))
    gaps = draw(st.lists(st.floats(1e-3, 0.05), min_size=n - 1, max_size=n - 1))
    x0 = draw(st.floats(-0.5, 0.5))
    knots = np.concatenate([[x0], x0 + np.cumsum(gaps)])
    values = draw(st.lists(st.floats(-20.0, 20.0), min_size=n, max_size=n))
    return knots, np.array(values)


def _pf(knots, values) -> PositionFriction:
    return make_effect('position_friction', {'x': list(knots), 'dfc': list(values)})


# ---- the spline ------------------------------------------------------------------------
@FAST
@given(splines())
def test_spline_passes_through_every_knot_exactly(spline):
    knots, values = spline
    np.testing.assert_array_equal(_pf(knots, values).level(knots), values)


@FAST
@given(splines(), st.floats(-5.0, 5.0), st.floats(-5.0, 5.0), st.integers(0, 2 ** 31))
def test_spline_is_linear_in_the_knot_values(spline, a, b, seed):
    knots, y1 = spline
    y2 = np.random.default_rng(seed).uniform(-20.0, 20.0, y1.size)
    x = np.linspace(knots[0] - 0.02, knots[-1] + 0.02, 400)
    combo = _pf(knots, a * y1 + b * y2).level(x)
    parts = a * _pf(knots, y1).level(x) + b * _pf(knots, y2).level(x)
    scale = (abs(a) * np.abs(y1).max() + abs(b) * np.abs(y2).max() + 1.0)
    assert np.max(np.abs(combo - parts)) <= 1e-11 * scale
    # and the basis is that linear map: dfc(x) = basis(x) @ dfc, columns summing to 1
    B = _pf(knots, y1).basis(x)
    assert B.shape == (x.size, knots.size)
    assert np.max(np.abs(B @ y1 - _pf(knots, y1).level(x))) <= 1e-11 * (np.abs(y1).max() + 1)
    np.testing.assert_allclose(B.sum(axis=1), 1.0, rtol=0, atol=1e-12)


@FAST
@given(splines(), st.floats(1e-6, 10.0))
def test_spline_is_constant_beyond_the_end_knots(spline, far):
    knots, values = spline
    pf = _pf(knots, values)
    np.testing.assert_array_equal(pf.level(np.array([knots[0] - far, knots[0]])),
                                  values[0])
    np.testing.assert_array_equal(pf.level(np.array([knots[-1], knots[-1] + far])),
                                  values[-1])


@FAST
@given(splines())
def test_spline_is_the_clamped_cubic_spline_and_c1_smooth(spline):
    knots, values = spline
    pf = _pf(knots, values)
    # the independent reference: scipy's clamped spline (zero end slopes)
    ref = CubicSpline(knots, values, bc_type='clamped')
    x = np.linspace(knots[0], knots[-1], 2000)
    scale = np.abs(values).max() + 1.0
    assert np.max(np.abs(pf.level(x) - ref(x))) <= 1e-9 * scale
    # C¹: one-sided difference quotients agree at every knot, the end knots included
    # (slope 0 on the constant side); the second derivative may jump, so the quotients
    # differ by O(h·|S''|)
    h = 1e-7 * (knots[-1] - knots[0])
    left = (pf.level(knots) - pf.level(knots - h)) / h
    right = (pf.level(knots + h) - pf.level(knots)) / h
    curv = np.abs(ref(knots, 2)).max() + 1.0
    np.testing.assert_allclose(left, right, rtol=0, atol=10.0 * h * curv + 1e-6 * scale)
    np.testing.assert_array_equal(pf.slopes[[0, -1]], 0.0)


def test_spline_lowest_point_is_found_between_knots():
    # a dip with uneven spacing: the clamped spline overshoots below its lowest knot
    pf = _pf([0.0, 0.01, 0.1], [0.0, -5.0, 0.0])
    x_low, low = pf.lowest
    dense = np.linspace(0.0, 0.1, 200001)
    assert low == pytest.approx(pf.level(dense).min(), abs=1e-9)
    assert x_low == pytest.approx(dense[np.argmin(pf.level(dense))], abs=1e-6)
    assert low < -5.0 - 0.1 and 0.01 < x_low < 0.1


# ---- the kernel --------------------------------------------------------------------------
@pytest.mark.parametrize('direction', [1.0, -1.0])
def test_traverse_over_a_tight_spot_needs_dfc_more_force_there_and_nowhere_else(direction):
    # constant drive force, Coulomb + viscous: the dry friction along the travel is what
    # the force balance leaves, F − fv·v − M·a, from the positions alone (central
    # differences); it must be fc + dfc(x) over 100–160 mm and fc everywhere else
    fc, fv, mass, u = 5.0, 100.0, 1.0, 30.0
    spot = {'x': [direction * s for s in SPOT['x']][::int(direction)],
            'dfc': SPOT['dfc']}
    m = model(('coulomb', {'fc': fc}), ('viscous', {'fv': fv}), ('position_friction', spot),
              mass=mass)
    tr = trace(plant(m), direction * u, int(round(1.2 / DT)))
    x = np.concatenate([[0.0], tr['x']])
    v = (x[2:] - x[:-2]) / (2.0 * DT)
    a = (x[2:] - 2.0 * x[1:-1] + x[:-2]) / DT ** 2
    xc = x[1:-1]
    dry = direction * (direction * u - fv * v - mass * a)
    moving = np.abs(v) > 0.1                          # past the start-up transient
    assert (direction * xc[moving]).max() > 0.25    # the whole spot was crossed
    ref = fc + CubicSpline(SPOT['x'], SPOT['dfc'], bc_type='clamped')(
        np.clip(direction * xc, SPOT['x'][0], SPOT['x'][-1]))
    err = np.abs(dry - ref)[moving]
    assert err.max() < 1e-3                         # newtons of tight spot, mN of error
    inside = moving & (direction * xc > 0.10) & (direction * xc < 0.16)
    outside = moving & ~((direction * xc >= 0.10) & (direction * xc <= 0.16))
    assert dry[inside].max() == pytest.approx(fc + 8.0, abs=1e-3)
    assert abs(direction * xc[inside][np.argmax(dry[inside])] - 0.13) < 1e-3
    np.testing.assert_allclose(dry[outside], fc, rtol=0, atol=1e-3)


def test_coast_across_a_tight_spot_stops_where_friction_work_equals_kinetic_energy():
    # energy: ½·M·v0² = ∫ (fc + dfc(x)) dx from the start to the stop
    fc, mass, v0 = 2.0, 1.0, 1.2
    pf = make_effect('position_friction', SPOT)
    m = model(('coulomb', {'fc': fc}), ('position_friction', SPOT), mass=mass)
    tr = trace(plant(m, v0=v0), 0.0, 20000)
    cs = CubicSpline(SPOT['x'], SPOT['dfc'], bc_type='clamped')

    def work(xs):
        lo, hi = SPOT['x'][0], SPOT['x'][-1]
        return fc * xs + cs.integrate(lo, min(max(xs, lo), hi)) + \
            SPOT['dfc'][-1] * max(xs - hi, 0.0)

    x_stop = brentq(lambda xs: work(xs) - 0.5 * mass * v0 ** 2, 0.0, 1.0)
    assert 0.16 < x_stop                               # it crossed the spot
    assert tr['x'][-1] == pytest.approx(x_stop, abs=1e-9)
    assert tr['v'][-1] == 0.0
    # the spot cost 0.24 J: without it the axis would coast to 0.36 m
    assert x_stop < 0.5 * mass * v0 ** 2 / fc - 0.02
    assert pf.level(np.array([x_stop]))[0] == 0.0


@pytest.mark.parametrize('x0, extra', [(0.13, 8.0), (0.115, None), (0.05, 0.0), (0.5, 0.0)])
def test_breakaway_at_rest_needs_fs_plus_dfc_at_the_position(x0, extra):
    fc, fs = 5.0, 7.0
    m = model(('coulomb', {'fc': fc}), ('stribeck', {'fs': fs, 'vs': 0.01, 'delta': 1.0}),
              ('position_friction', SPOT), mass=2.0)
    if extra is None:
        extra = float(make_effect('position_friction', SPOT).level(np.array([x0]))[0])
        assert 0.5 < extra < 7.5                       # between the knots
    band = fs + extra
    for push, moves in ((band * (1 - 1e-6), False), (band * (1 + 1e-6), True)):
        p = plant(m, x0=x0)
        p.step(-push, 0.2)
        assert (p.position != x0) is moves, (x0, push)


def test_zero_effects_are_bit_for_bit_the_model_without_them():
    # mu = 0 and dfc = 0: the kernel takes the shifted path (knots present) and adds
    # exactly nothing — positions, velocities, friction, stick phases all identical
    base = [('coulomb', {'fc': 3.0}), ('stribeck', {'fs': 4.5, 'vs': 0.02, 'delta': 1.4}),
            ('viscous', {'fv': 30.0}),
            ('ripple', {'period': 0.01, 'harmonics': [[1.5, 0.4]]}),
            ('asymmetry', {'dfc': 0.6, 'dfv': 4.0}), ('delay', {'tau': 0.00033})]
    zero = [('load_friction', {'mu': 0.0}),
            ('position_friction', {'x': [-0.01, 0.0, 0.01], 'dfc': [0.0, 0.0, 0.0]})]
    gms = ('presliding', {'alpha': [0.6, 0.4], 'k': [2e6, 4e5], 'C': 6000.0,
                          'sigma': [800.0, 160.0]})

    def u_of_t(t):
        return 6.0 * math.sin(2.0 * math.pi * 3.0 * t)

    for extra in ([], [gms]):
        with_zero = model(*base, *extra, *zero, mass=2.0)
        assert with_zero.has('position_friction')
        assert plant(with_zero).params[K.P_PF_N] == 3       # the shifted path runs
        a = trace(plant(with_zero), u_of_t, 6000)
        b = trace(plant(model(*base, *extra, mass=2.0)), u_of_t, 6000)
        for key in a:
            np.testing.assert_array_equal(a[key], b[key], err_msg=key)
        assert np.ptp(a['x']) > 1e-3 and np.any(a['v'] > 0) and np.any(a['v'] < 0)
        if not extra:
            assert np.any(a['v'] == 0.0)                    # Karnopp stick phases too


def test_effect_forces_and_gms_force_along_carry_the_position_law():
    m = model(('coulomb', {'fc': 12.0}), ('stribeck', {'fs': 18.0, 'vs': 1e-3, 'delta': 1.0}),
              ('viscous', {'fv': 200.0}),
              ('position_friction', {'x': [-0.002, 0.0, 0.002], 'dfc': [0.0, 9.0, 0.0]}),
              ('presliding', {'alpha': [0.45, 0.30, 0.15, 0.10], 'k': [8e6, 3e6, 1e6, 3e5],
                              'C': 12000.0}),
              mass=25.0, input_gain=50.0, damping=50.0)

    def u_of_t(t):
        return 1.2 * math.sin(2.0 * math.pi * 2.0 * t)

    tr = trace(plant(m), u_of_t, 10000)
    x = np.concatenate([[0.0], tr['x']])
    v = np.concatenate([[0.0], tr['v']])
    forces = m.effect_forces(x, v, dt=DT)
    assert set(forces) == {'viscous', 'presliding'}
    err = np.abs(forces['presliding'][1:] - tr['friction'])
    assert np.median(err) < 0.01 and np.max(err) < 0.5
    without = m.without('position_friction').effect_forces(x, v, dt=DT)['presliding'][1:]
    assert np.max(np.abs(without - tr['friction'])) > 5.0
    # without dt (static curve): dfc(x)·sgn(v) is its own term
    static = m.effect_forces(x, v)
    pf = m.get('position_friction')
    np.testing.assert_array_equal(static['position_friction'], pf.level(x) * np.sign(v))


# ---- the model -------------------------------------------------------------------------
def test_level_below_zero_between_knots_is_refused_naming_the_place():
    dip = {'x': [0.0, 0.01, 0.1], 'dfc': [0.0, -5.0, 0.0]}
    low = make_effect('position_friction', dip).lowest
    with pytest.raises(ParameterError) as info:
        model(('coulomb', {'fc': 5.0}), ('position_friction', dip))
    msg = str(info.value)
    assert '\n' not in msg and 'fc + dfc(x) must be >= 0' in msg
    assert f'x = {low[0]:.6g} m' in msg
    # every knot alone would pass (5 − 5 = 0): only the spline's own minimum fails
    model(('coulomb', {'fc': -low[1]}), ('position_friction', dip))
    model(('coulomb', {'fc': 5.0}), ('position_friction', {'x': [0.0, 0.01, 0.02],
                                                           'dfc': [0.0, -5.0, 0.0]}))
    with pytest.raises(ParameterError, match='fc \\+ dfc'):
        model(('position_friction', {'x': [0.0, 0.1], 'dfc': [0.0, -0.1]}))   # no coulomb


def test_rotary_axis_reads_rad_and_newton_metres():
    pf = make_effect('position_friction', {'x': [0.0, math.pi], 'dfc': [-2.0, 0.0]})
    with pytest.raises(ParameterError, match='N·m at x = 0 rad'):
        AxisModel(mass=0.01, axis='rotary', effects=(make_effect('coulomb', {'fc': 1.0}), pf))


def test_compiled_basis_equals_the_array_form_bit_for_bit():
    # the Hermite weights as numpy array operations (the form before the compiled pass)
    rng = np.random.default_rng(5)
    for n in (2, 3, 8, 16):
        knots = np.sort(rng.uniform(-0.05, 0.05, n))
        x = 0.06 * np.sin(np.linspace(0.0, 40.0, 5000)) + 1e-5 * rng.standard_normal(5000)
        x[::97] = knots[n // 2]                       # exactly at a knot
        S = slope_matrix(knots)
        xc = np.clip(x, knots[0], knots[-1])
        lo = np.clip(np.searchsorted(knots, xc, side='right') - 1, 0, n - 2)
        hi = lo + 1
        h = knots[hi] - knots[lo]
        t = (xc - knots[lo]) / h
        s = 1.0 - t
        rows = np.arange(len(x))
        ref = np.zeros((len(x), n))
        ref[rows, lo] = (1.0 + 2.0 * t) * s * s
        ref[rows, hi] = t * t * (3.0 - 2.0 * t)
        ref += (h * t * s * s)[:, None] * S[lo] - (h * t * t * s)[:, None] * S[hi]
        B = _pf(knots, np.zeros(n)).basis(x)
        assert np.array_equal(B, ref) and np.array_equal(np.signbit(B), np.signbit(ref))
        # the identification's block: knots from the second, times the direction share,
        # column-major (each column's samples contiguous, as the smoother reads them)
        d = np.where(np.arange(len(x)) % 3 == 0, -1.0, rng.uniform(0.0, 1.0, len(x)))
        C = _pf(knots, np.zeros(n)).basis(x, d, first=1)
        want = ref[:, 1:] * d[:, None]
        assert C.shape == (len(x), n - 1) and C.T.flags.c_contiguous
        assert np.array_equal(C, want) and np.array_equal(np.signbit(C), np.signbit(want))


def test_the_local_basis_mapped_is_the_basis():
    """``L·mix`` of :meth:`PositionFriction.local_basis` is :meth:`basis` (to rounding)."""
    rng = np.random.default_rng(9)
    for n in (2, 3, 8, MAX_KNOTS):
        knots = np.sort(rng.uniform(-0.05, 0.05, n))
        x = 0.06 * np.sin(np.linspace(0.0, 40.0, 3000))
        x[::97] = knots[n // 2]                       # exactly at a knot
        d = np.where(np.arange(len(x)) % 3 == 0, -1.0, rng.uniform(0.0, 1.0, len(x)))
        pf = _pf(knots, np.zeros(n))
        for first, sign in ((0, None), (1, d)):
            lb = pf.local_basis(x, sign, first=first)
            assert lb.index.shape == lb.value.shape == (len(x), 4)
            assert lb.mix.shape == (2 * n, n - first)
            L = np.zeros((len(x), 2 * n))
            for k in range(4):
                np.add.at(L, (np.arange(len(x)), lb.index[:, k]), lb.value[:, k])
            want = pf.basis(x, sign, first=first)
            np.testing.assert_allclose(L @ lb.mix, want, rtol=0,
                                       atol=1e-12 * max(1.0, float(np.abs(want).max())))


def test_regressors_are_basis_times_direction():
    pf = make_effect('position_friction', SPOT)
    x = np.linspace(0.0, 0.3, 301)
    v = np.where(np.arange(301) % 2 == 0, 0.1, -0.2)
    np.testing.assert_allclose(pf.regressors(x, v) @ np.array(SPOT['dfc']),
                               pf.force(x, v), rtol=0, atol=1e-12)


_ANY_FLOAT = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                       st.floats(-1e-300, 1e-300), st.sampled_from([-1e308, 1e308]))


@settings(max_examples=400, deadline=None)
@given(x=st.one_of(st.lists(_ANY_FLOAT, max_size=40),
                   st.lists(_ANY_FLOAT, max_size=40, unique=True).map(sorted)),
       dfc=st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=40),
       fc=st.floats(0.0, 1e308))
def test_any_knots_give_a_model_or_a_one_line_parameter_error(x, dfc, fc):
    # untrusted model files: sorted, extreme or degenerate knots never escape as another
    # exception (what the CLI would call an internal error), and an accepted model has a
    # finite level everywhere
    try:
        pf = make_effect('position_friction', {'x': x, 'dfc': dfc[:len(x)]})
        m = AxisModel(mass=1.0, effects=(make_effect('coulomb', {'fc': fc}), pf))
    except ParameterError as exc:
        assert '\n' not in str(exc)
        return
    probe = np.concatenate([pf.knots, 0.5 * (pf.knots[1:] + pf.knots[:-1])])
    level = m.fc + m.dry_friction_shift(probe)
    assert np.all(np.isfinite(level)) and np.all(level >= -1e-9 * (np.abs(level).max() + 1))


@FAST
@given(n=st.integers(2, MAX_KNOTS), seed=st.integers(0, 2 ** 32 - 1),
       fc=st.floats(0.0, 1e3), gms=st.booleans(),
       extreme=st.sampled_from([0.0, 1.0]))
def test_any_levels_the_estimator_can_reach_encode_to_a_model(n, seed, fc, gms, extreme):
    """Levels anywhere within the bounds its columns declare encode to a valid model.

    The estimator holds each fitted level within its column's bounds; whatever it
    returns there (a near-collinear design puts it at a bound), the encoded effect — its
    dip below zero friction lifted — is one the model file holds, never an input error.
    """
    from motor_comp.physics.effects import TERMS
    from motor_comp.physics.effects.identification import Context
    from motor_comp.physics.effects.position_friction import uniform_knots
    term = TERMS['position_friction']
    eta = {'x': uniform_knots(0.01, 0.2, n)}
    present = frozenset({'coulomb', 'position_friction'} | ({'presliding'} if gms else set()))
    ctx = Context(present=present, eta={'position_friction': eta})
    cols = term.columns(eta, ctx)
    rng = np.random.default_rng(seed)
    lo, hi = np.array([c.lo for c in cols]), np.array([c.hi for c in cols])
    assert np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))
    # at the bounds (alternating: the deepest dips) or anywhere inside them
    u = rng.integers(0, 2, len(cols)) if extreme else rng.uniform(0.0, 1.0, len(cols))
    values = {('coulomb', 'fc'): fc}
    values.update({('position_friction', c.label): float(a + w * (b - a))
                   for c, a, b, w in zip(cols, lo, hi, u)})
    (pf,) = term.encode(values, eta, ctx)
    AxisModel(effects=(make_effect('coulomb', {'fc': fc}), pf))
