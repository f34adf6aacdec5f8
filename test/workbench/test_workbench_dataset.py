"""The dataset's fast paths equal the plain computations they replace, and views are pure.

Smoothing at the rows only (each row's sum in tap order, the same on every machine),
Gram entries cached by column key, the stencil's velocity
and its gain on a position-periodic force must not change a single estimate: each is
checked against the direct formula, the Gram cache against ``ZᵀZ`` over random
sequences of designs — including a backlash gap, whose view changes the motion under
cached columns — and a view never changes what another view returns.
"""
from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from scipy.ndimage import correlate1d

from motor_comp.physics.effects.identification import Signal
from motor_comp.workbench import kinematics
from motor_comp.workbench import processing as proc
from motor_comp.workbench.dataset import Dataset
from motor_comp.physics.effects import TERMS
from motor_comp.workbench.library import Spec, context, design
from motor_comp.workbench.synthetic import scenario


@pytest.fixture(scope='module')
def data():
    sc = scenario(('ripple',), seed=4)
    kin = kinematics(sc.run(duration=6.0, seed=4))
    return Dataset([kin], sc.plant), sc.plant


@settings(max_examples=30, deadline=None)
@given(W=st.sampled_from([7, 21, 41, 81]), step=st.integers(1, 9),
       cols=st.integers(1, 4), seed=st.integers(0, 2**31 - 1))
def test_smoothing_at_the_rows_equals_full_rate_filtering(W, step, cols, seed):
    rng = np.random.default_rng(seed)
    n = 3000
    y = rng.normal(size=(n, cols)) * rng.uniform(0.1, 100.0)
    rows = np.arange(W // 2 + 2, n - W // 2 - 2, step)
    ref = correlate1d(y, proc.kernel(W), axis=0, mode='mirror')[rows]
    scale = np.max(np.abs(y))
    assert np.max(np.abs(proc.smooth_at(y, rows, W) - ref)) < 1e-13 * scale
    assert np.max(np.abs(proc.smooth_at(y[:, 0], rows, W) - ref[:, 0])) < 1e-13 * scale


@settings(max_examples=30, deadline=None)
@given(W=st.sampled_from([7, 41, 81]), cols=st.integers(1, 3), seed=st.integers(0, 2**31 - 1))
def test_each_row_is_summed_over_the_taps_in_order(W, cols, seed):
    """The same sum on every machine: tap by tap, as written, whichever path a row takes.

    Rows in stretches of consecutive samples, equally spaced stretches longer than a
    tile (summed side by side by phase) and shorter than eight rows, rows further
    apart than the smoother, stretches that end at the record's last admissible row,
    and isolated rows (summed one at a time) equal the plain loop bit for bit; a
    reassociated (fast-math) sum differs from it in the last bits.
    """
    rng = np.random.default_rng(seed)
    n = 9000
    y = rng.normal(size=(n, cols)) * 10.0 ** rng.uniform(-3, 3)
    h = W // 2
    s = int(rng.integers(2, 10))
    rows = np.unique(np.concatenate([
        np.arange(h + 5, h + 5 + int(rng.integers(1, 40))),                 # consecutive
        np.arange(1000, 2000, int(rng.integers(2, 7))),                      # strided
        np.arange(2000, 2000 + s * int(rng.integers(257, 700)), s),          # > one tile
        np.arange(6500, 6500 + 7 * s, s),                                    # < 8 rows
        np.arange(7000, 7000 + 12 * (W + 3), W + 3),                         # spaced > W
        rng.integers(7600, n - h - 1, size=int(rng.integers(0, 30))),       # scattered
        np.arange(n - h - 1 - s * int(rng.integers(8, 40)), n - h - 1, s)]))  # to the end
    b = proc.kernel(W)
    want = np.empty((len(rows), cols))
    for c in range(cols):
        for i, r in enumerate(rows):
            acc = 0.0
            for j in range(W):
                acc += float(b[j]) * float(y[r - h + j, c])
            want[i, c] = acc
    assert np.array_equal(proc.smooth_at(y, rows, W), want)
    assert np.array_equal(proc.smooth_at(y[:, 0], rows, W), want[:, 0])


@settings(max_examples=40, deadline=None)
@given(tau_samples=st.floats(0.0, 30.0), hold=st.sampled_from(['zoh', 'sample']))
def test_the_delayed_input_smoothed_per_shift_equals_smoothing_it_whole(data, tau_samples,
                                                                        hold):
    # a delay search sums two or three smoothed whole-sample shifts: the same numbers as
    # smoothing the delayed input itself (np.interp for a sampled input)
    import dataclasses
    from motor_comp.workbench.derivatives import InputHold
    D0, plant = data
    kin = dataclasses.replace(D0.kins[0], hold=InputHold(hold))
    D = Dataset([kin], plant)
    tau = tau_samples * kin.dt
    view = D.at(tau=tau)
    p, mo = D.parts[0], view.motions[0]
    g = plant.input_gain
    k = g * plant.back_emf + plant.damping        # the back-EMF and damping force
    direct = kin.input_at(tau) if hold == 'zoh' else np.interp(kin.t - tau, kin.t, kin.u)
    for got, factor in ((view.y(), g), (view.y(rests=True), g * (1.0 - mo.shares[3]))):
        want = proc.smooth_at(factor * direct, p.rows, p.W) - k * view.signal(Signal.VELOCITY)
        assert np.max(np.abs(got - want)) <= 1e-12 * max(1.0, float(np.max(np.abs(want))))


@settings(max_examples=30, deadline=None)
@given(W=st.sampled_from([7, 41, 81]), size=st.integers(1, 12), m=st.integers(1, 4),
       seed=st.integers(0, 2**31 - 1))
def test_a_local_basis_smooths_as_its_dense_columns(W, size, m, seed):
    """Each sample's few functions, smoothed: the dense columns' sums (zeros add nothing)."""
    rng = np.random.default_rng(seed)
    n = 3000
    index = rng.integers(0, size, size=(n, m))
    value = rng.normal(size=(n, m)) * 10.0 ** rng.uniform(-3, 3)
    dense = np.zeros((n, size))
    for k in range(m):
        np.add.at(dense, (np.arange(n), index[:, k]), value[:, k])
    h = W // 2
    rows = np.unique(rng.integers(h, n - h - 1, size=400))
    got = proc.smooth_local_at(index, value, size, rows, W)
    want = proc.smooth_at(dense, rows, W)
    assert got.shape == (len(rows), size)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12 * float(np.abs(value).max()))
    with pytest.raises(ValueError, match='record ends'):
        proc.smooth_local_at(index, value, size, np.array([h - 1]), W)


def test_a_friction_along_the_travel_is_the_same_block_smoothed_local_or_dense(data):
    """The view smooths a position friction on its local basis: its dense block's values."""
    import dataclasses as dc
    D0, plant = data
    x = D0.kins[0].position
    knots = tuple(np.linspace(float(x.min()), float(x.max()), 9))
    spec = Spec(('coulomb', 'position_friction'), {'coulomb': {}, 'position_friction':
                                                   {'x': knots}}, True, plant.mass)
    for rests in (False, True):
        D = Dataset(D0.kins, plant)
        view = D.at()
        cols = [c for c in TERMS['position_friction'].columns({'x': knots}, context(spec, D))]
        got = view.columns(cols, rests=rests)
        dense = Dataset(D0.kins, plant).at().columns([dc.replace(c, local=None) for c in cols],
                                                     rests=rests)
        for g, w in zip(got, dense):
            np.testing.assert_allclose(g, w, rtol=0, atol=1e-12 * float(np.abs(w).max()))


def test_smoothing_refuses_rows_at_the_record_ends():
    with pytest.raises(ValueError, match='record ends'):
        proc.smooth_at(np.zeros(200), np.array([5, 100]), 21)


def test_stencil_gain_is_the_triangle_average_the_second_difference_sees(data):
    """At a constant speed, the 3-point second difference sees ``sin(w·x)`` averaged
    with a ±1-sample triangle: ``∫ tri(s)·sin(w·(x + v·s)) ds = g·sin(w·x)``."""
    D, _ = data
    view = D.at()
    dt = D.kins[0].dt
    v = view.gather(lambda p, mo: mo.v)
    w = 2 * np.pi / 0.004           # a 4 mm ripple: up to ~1 rad per sample here
    s = np.linspace(-dt, dt, 4001)
    tri = (1 - np.abs(s) / dt) / dt
    # the sine's phase drops out: the triangle is even, so only cos(w·v·s) survives
    avg = np.trapezoid(tri * np.cos(w * np.outer(v, s)), s, axis=1)
    g = view.stencil_gain(w)
    assert np.max(np.abs(w * v * dt)) > 0.5            # the test has teeth
    assert np.max(np.abs(g - avg)) < 1e-6
    assert np.min(g) < 0.99


SPECS = [
    Spec(('coulomb', 'viscous'), {}),
    Spec(('coulomb', 'viscous', 'ripple'), {'ripple': {'period': 0.0137, 'harmonics': 2}}),
    Spec(('coulomb', 'viscous', 'stribeck'), {'stribeck': {'vs': 4e-3, 'delta': 1.0}}),
    Spec(('coulomb', 'viscous', 'offset', 'spring'), {}),
    Spec(('coulomb', 'viscous', 'delay'), {'delay': {'tau': 1.3e-3}}),
    Spec(('coulomb', 'viscous', 'presliding'),
         {'presliding': {'d': (1.2e-6, 4e-6, 1.2e-5), 'c': 900.0, 'ratio': 0.0}}),
    Spec(('coulomb', 'asymmetry', 'backlash'), {'backlash': {'width': 3e-5}}),
    Spec(('coulomb', 'viscous'), {}, mass_free=False, mass=5.0),
]


@settings(max_examples=25, deadline=None)
@given(order=st.lists(st.integers(0, len(SPECS) - 1), min_size=2, max_size=8),
       fold=st.integers(-1, 4))
def test_cached_gram_equals_the_direct_product(data, order, fold):
    D, model = data
    rows = None if fold < 0 else D.train_rows(fold)
    for i in order:
        d = design(D, SPECS[i], model)
        Z = np.column_stack(d.cols + [d.y])
        if rows is not None:
            Z = Z[rows]
        ref = Z.T @ Z
        assert np.allclose(d.gram(rows), ref, rtol=1e-12, atol=1e-12 * np.max(np.abs(ref)))


@settings(max_examples=25, deadline=None)
@given(order=st.lists(st.integers(0, len(SPECS) - 1), min_size=2, max_size=8))
def test_cached_part_grams_and_fold_sums_equal_their_definitions(data, order):
    """Per-part Grams from cached products, and each fold's sums, as written with masks."""
    D, model = data
    for i in order:
        d = design(D, SPECS[i], model)
        Z = np.column_stack(d.cols + [d.y])
        ref = D.part_grams(Z)
        P = d.part_grams()
        scale = np.max(np.abs(ref))
        assert np.allclose(P, ref, rtol=1e-12, atol=1e-12 * scale)
        train, test = D.fold_grams(P)
        assert train.shape == test.shape == (D.folds,) + ref.shape[1:]
        for f, (tr, te) in enumerate(zip(D.train_parts, D.test_parts)):
            assert np.allclose(train[f], ref[tr].sum(axis=0), rtol=1e-12, atol=1e-12 * scale)
            assert np.allclose(test[f], ref[te].sum(axis=0), rtol=1e-12, atol=1e-12 * scale)
        # the training rows' Gram is the same product over the fold's rows
        rows = D.train_rows(0)
        assert np.allclose(train[0], Z[rows].T @ Z[rows], rtol=1e-12, atol=1e-12 * scale)


_EXAMPLES = itertools.count()


@settings(max_examples=25, deadline=None)
@given(q=st.integers(2, 6), new=st.data(), seed=st.integers(0, 2**31 - 1))
def test_a_trials_new_column_anywhere_gives_the_gram_of_its_columns(data, q, new, seed):
    """Cached products with new columns anywhere in the design: the Grams as defined.

    A search trial replaces one term's columns, often in the middle of the design: the
    pairs of the later columns with the new one come with the new column's products,
    the rest from the cache.
    """
    D, _ = data
    rng = np.random.default_rng(seed)
    run = next(_EXAMPLES)        # a key names one column's values: one set per example
    cols = [rng.standard_normal(D.n) for _ in range(q)]
    keys = [('test-gram', run, i) for i in range(q)]
    D.gram(cols, keys)
    D.part_grams_of(cols, keys)
    # replace a random set of columns by new ones under new keys
    fresh = new.draw(st.lists(st.integers(0, q - 1), min_size=1, max_size=q, unique=True))
    for i in fresh:
        cols[i] = rng.standard_normal(D.n)
        keys[i] = ('test-gram', run, i, 'new')
    Z = np.column_stack(cols)
    scale = float(np.max(np.abs(Z.T @ Z)))
    np.testing.assert_allclose(D.gram(cols, keys), Z.T @ Z, rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(D.part_grams_of(cols, keys), D.part_grams(Z), rtol=1e-12,
                               atol=1e-12 * scale)


def test_views_do_not_change_each_other(data):
    """A view with a gap and a delay leaves the measured view's arrays as they were."""
    D, model = data
    before = D.at().signal(Signal.ACCELERATION).copy()
    y0 = D.at().y().copy()
    gap = D.at(width=3e-5, tau=1e-3, model=model)
    assert not np.allclose(gap.signal(Signal.ACCELERATION), before)
    assert not np.allclose(gap.y(), y0)
    np.testing.assert_array_equal(D.at().signal(Signal.ACCELERATION), before)
    np.testing.assert_array_equal(D.at().y(), y0)
    assert D.at() is D.at()


class _Kin:
    def __init__(self, dt: float) -> None:
        self.dt = dt


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
    hat = w * np.cos(w * t[rows]) * np.sinc(w * dt / (2 * np.pi)) ** 2
    acc = -w * w * np.sin(w * t[rows]) * np.sinc(w * dt / (2 * np.pi)) ** 2
    assert np.allclose(proc.stencil(x, rows, dt, 'acceleration'), acc, rtol=0,
                       atol=1e-9 * w * w)
    err = np.max(np.abs(proc.stencil(x, rows, dt, 'velocity') - hat)) / w
    central = np.max(np.abs((x[rows + 1] - x[rows - 1]) / (2 * dt) - hat)) / w
    # 4-point midpoint rule: error O((w·dt)⁴) against the central difference's O((w·dt)²)
    assert err < 0.02 * (w_dt ** 4) + 1e-12
    assert central > 0.05 * w_dt ** 2


def test_a_block_with_columns_cached_smooths_only_the_new_ones(data):
    """One harmonic more: its columns equal those of a dataset that computes all afresh."""
    D, model = data
    fresh = Dataset(D.kins, model)
    eta = {'period': 0.0137, 'harmonics': 2}
    design(D, Spec(('coulomb', 'ripple'), {'ripple': eta}), model)
    more = Spec(('coulomb', 'ripple'), {'ripple': dict(eta, harmonics=3)})
    got = design(D, more, model)
    want = design(fresh, more, model)
    assert got.labels == want.labels
    for a, b in zip(got.cols, want.cols):
        assert np.array_equal(a, b)
