"""The identification's fast paths equal the plain computations they replace.

The speed work of issue 11 (smoothing at the rows only, Gram entries cached by column
key, the GMS element columns in one pass, ripple harmonics by angle addition) must not
change a single estimate: each fast path is checked against the direct formula on
random data, and the Gram cache against ``ZᵀZ`` over random sequences of designs —
including a backlash gap that changes the motion under the cached columns.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.ndimage import correlate1d

from motor_comp.physics.effects.presliding import gms_trajectory
from motor_comp.workbench import ident, kinematics
from motor_comp.workbench.synthetic import scenario


@pytest.fixture(scope='module')
def data():
    sc = scenario(('ripple',), seed=4)
    kin = kinematics(sc.run(duration=6.0, seed=4))
    return ident.Data([kin], sc.plant), sc.plant


class _Part:
    def __init__(self, W: int, rows: np.ndarray) -> None:
        self.W, self.rows = W, rows


@settings(max_examples=30, deadline=None)
@given(W=st.sampled_from([7, 21, 41, 81]), step=st.integers(1, 9),
       cols=st.integers(1, 4), seed=st.integers(0, 2**31 - 1))
def test_smoothing_at_the_rows_equals_full_rate_filtering(W, step, cols, seed):
    rng = np.random.default_rng(seed)
    n = 3000
    y = rng.normal(size=(n, cols)) * rng.uniform(0.1, 100.0)
    rows = np.arange(W // 2 + 2, n - W // 2 - 2, step)
    p = _Part(W, rows)
    ref = correlate1d(y, ident._kernel(W), axis=0, mode='mirror')[rows]
    scale = np.max(np.abs(y))
    assert np.max(np.abs(ident._smooth_at(p, y) - ref)) < 1e-13 * scale
    assert np.max(np.abs(ident._smooth_at(p, y[:, 0]) - ref[:, 0])) < 1e-13 * scale


def test_smoothing_refuses_rows_at_the_record_ends():
    p = _Part(21, np.array([5, 100]))
    with pytest.raises(ValueError, match='record ends'):
        ident._smooth_at(p, np.zeros(200))


def test_gms_columns_in_one_pass_equal_one_element_at_a_time(data):
    D, _ = data
    p = D.parts[0]
    dists = (2e-6, 7e-6, 3e-5)
    many = ident.gms_columns(p, dists, 800.0, 0.4, 3e-3, 1.3)
    for j, d in enumerate(dists):
        one = gms_trajectory(np.ascontiguousarray(p.xg), np.ones(1), np.array([1.0 / d]),
                             np.zeros(1), 800.0, 1.0, 1.4, 3e-3, 1.3, p.kin.dt)
        assert np.max(np.abs(many[:, j] - one)) == 0.0


def test_ripple_harmonics_by_angle_addition(data):
    D, _ = data
    w = 2 * np.pi * np.arange(1, 7) / 0.0137
    S, C = D.smooth_harmonics(w)
    G = np.sinc(np.outer(D.gather(lambda p: p.v * p.kin.dt), w) / (2 * np.pi)) ** 2
    S0 = D.smooth_gather(lambda p: np.sin(np.outer(p.x, w))) * G
    C0 = D.smooth_gather(lambda p: np.cos(np.outer(p.x, w))) * G
    assert np.max(np.abs(S - S0)) < 1e-12 and np.max(np.abs(C - C0)) < 1e-12
    assert np.max(np.abs(D.stencil_gain(w) - G)) < 1e-12


def test_stencil_gain_is_the_triangle_average_the_second_difference_sees(data):
    """At a constant speed, the 3-point second difference sees ``sin(w·x)`` averaged
    with a ±1-sample triangle: ``∫ tri(s)·sin(w·(x + v·s)) ds = g·sin(w·x)``."""
    D, _ = data
    dt = D.kins[0].dt
    v = D.gather(lambda p: p.v)
    w = 2 * np.pi / 0.004           # a 4 mm ripple: up to ~1 rad per sample here
    s = np.linspace(-dt, dt, 4001)
    tri = (1 - np.abs(s) / dt) / dt
    # the sine's phase drops out: the triangle is even, so only cos(w·v·s) survives
    avg = np.trapezoid(tri * np.cos(w * np.outer(v, s)), s, axis=1)
    g = D.stencil_gain(np.array([w]))[:, 0]
    assert np.max(np.abs(w * v * dt)) > 0.5            # the test has teeth
    assert np.max(np.abs(g - avg)) < 1e-6
    assert np.min(g) < 0.99


def test_fold_period_searches_share_evaluations_but_not_answers(data):
    """Each fold's ripple period (searched on shared trial periods) is its own optimum.

    Every fold's period from :func:`ident.fit_ripple_folds` is within the search's
    tolerance (1e-6 of the period) of a plain Brent search on that fold alone, and
    folds that disagree keep different periods.
    """
    D, model = data
    spec = ident.spec_of(model)
    ident.sync(D, spec.without('ripple'), model)
    rows = [D.train_rows(f) for f in range(D.folds)]
    joint = ident.fit_ripple_folds(D, spec, rows)
    for r, (period, nh) in zip(rows, joint):
        alone, nh1 = ident.fit_ripple(D, spec, r)
        assert nh == nh1
        assert abs(period - alone) <= 2e-6 * alone, (period, alone)
    assert len({p for p, _ in joint}) > 1


SPECS = [
    ident.Spec(('coulomb', 'viscous'), {}),
    ident.Spec(('coulomb', 'viscous', 'ripple'), {'ripple': (0.0137, 2)}),
    ident.Spec(('coulomb', 'viscous', 'stribeck'), {'stribeck': (4e-3, 1.0)}),
    ident.Spec(('coulomb', 'viscous', 'offset', 'spring'), {}),
    ident.Spec(('coulomb', 'viscous', 'delay'), {'delay': 1.3e-3}),
    ident.Spec(('coulomb', 'viscous', 'presliding'),
               {'presliding': ident.gms_eta(4e-6, 900.0, 0.0)}),
    ident.Spec(('coulomb', 'asymmetry', 'backlash'), {'backlash': 3e-5}),
    ident.Spec(('coulomb', 'viscous'), {}, mass_free=False, mass=5.0),
]


@settings(max_examples=25, deadline=None)
@given(order=st.lists(st.integers(0, len(SPECS) - 1), min_size=2, max_size=8),
       fold=st.integers(-1, 4))
def test_cached_gram_equals_the_direct_product(data, order, fold):
    D, model = data
    rows = None if fold < 0 else D.train_rows(fold)
    for i in order:
        spec = SPECS[i]
        ident.sync(D, spec, model)
        cols, _, keys = ident.keyed_columns(D, spec)
        y = ident.target(D, spec)
        G = D.gram(cols + [y], keys + [ident.target_key(D, spec)], rows)
        Z = np.column_stack(cols + [y])
        if rows is not None:
            Z = Z[rows]
        ref = Z.T @ Z
        assert np.allclose(G, ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))
    ident.sync(D, ident.Spec((), {}), model)


class _StencilPart:
    def __init__(self, x: np.ndarray, dt: float, rows: np.ndarray) -> None:
        class _Kin:
            pass
        self.xs, self.rows, self.kin = x, rows, _Kin()
        self.kin.dt = dt


@pytest.mark.parametrize('w_dt', [0.05, 0.3, 0.8])
def test_stencil_velocity_is_the_hat_average_the_second_difference_sees(w_dt):
    """The velocity column is ``ẋ`` under the hat kernel of the acceleration stencil.

    For ``x = sin(w·t)``: ``∫ hat(s)·ẋ(t + s) ds = w·cos(w·t)·sinc²(w·dt/2π)`` (the
    3-point second difference sees ``a`` with the same gain).  The central difference
    is a box over ±dt (gain ``sinc(w·dt/π)``): with a back-EMF damping k it left a
    dead time of k·dt²/(12·M) in the fits.
    """
    dt = 1e-3
    w = w_dt / dt
    t = np.arange(2000) * dt
    x = np.sin(w * t)
    rows = np.arange(5, 1995)
    p = _StencilPart(x, dt, rows)
    hat = w * np.cos(w * t[rows]) * np.sinc(w * dt / (2 * np.pi)) ** 2
    acc = -w * w * np.sin(w * t[rows]) * np.sinc(w * dt / (2 * np.pi)) ** 2
    assert np.allclose(ident._stencil(p, 'al'), acc, rtol=0, atol=1e-9 * w * w)
    err = np.max(np.abs(ident._stencil(p, 'vl') - hat)) / w
    central = np.max(np.abs((x[rows + 1] - x[rows - 1]) / (2 * dt) - hat)) / w
    # 4-point midpoint rule: error O((w·dt)⁴) against the central difference's O((w·dt)²)
    assert err < 0.02 * (w_dt ** 4) + 1e-12
    assert central > 0.05 * w_dt ** 2
