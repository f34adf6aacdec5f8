"""Exact checks of the workbench building blocks on analytic signals."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from motor_comp.errors import InputFileError
from motor_comp.logs.run import Run
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import make_effect
from motor_comp.workbench import kinematics, refit_linear, residual
from motor_comp.physics.effects.ripple import spatial_spectrum
from motor_comp.workbench.dataset import Dataset as Data
from motor_comp.workbench.motion import motor_position, reversals
from motor_comp.workbench.processing import smooth_full, smoother_length
from motor_comp.workbench.report import whiteness
from motor_comp.workbench.residual import force_nrmse

DT = 1e-3


def analytic_run(model: AxisModel, *, duration: float = 8.0, amp: float = 0.04,
                 freqs=(0.3, 0.77), name='analytic') -> Run:
    """Motion x(t) = Σ amp·sin(2πft); the input that makes ``model`` follow it exactly."""
    t = np.arange(0.0, duration, DT)
    x = sum(amp * np.sin(2 * np.pi * f * t) for f in freqs)
    v = sum(amp * 2 * np.pi * f * np.cos(2 * np.pi * f * t) for f in freqs)
    a = sum(-amp * (2 * np.pi * f) ** 2 * np.sin(2 * np.pi * f * t) for f in freqs)
    force = model.mass * a + sum(model.effect_forces(x, v).values(), np.zeros_like(t))
    # invert F_in = g·(u − ke·v) − d·v
    u = (force + model.damping * v) / model.input_gain + model.back_emf * v
    return Run(t=t, position=x, voltage=u, name=name)


BASE = AxisModel(mass=5.4, input_gain=15.0, back_emf=123.0, effects=(
    make_effect('coulomb', {'fc': 10.0}), make_effect('viscous', {'fv': 10.0})))


def test_derivatives_exact_on_cubic():
    t = np.arange(0, 2, DT)
    run = Run(t=t, position=0.3 * t ** 3 - 0.1 * t, voltage=np.zeros_like(t))
    kin = kinematics(run, polyorder=3)
    np.testing.assert_allclose(kin.v, 0.9 * t ** 2 - 0.1, atol=1e-9)
    np.testing.assert_allclose(kin.a, 1.8 * t, atol=1e-6)
    assert not kin.resampled and kin.window == 21


def test_zoh_input_is_centred_and_delayed_exactly():
    t = np.arange(0, 1, DT)
    u = np.where(t >= 0.5, 1.0, 0.0)
    kin = kinematics(Run(t=t, position=np.sin(t), voltage=u))
    k = 500
    c = kin.input_at(0.0)
    np.testing.assert_allclose(c[k - 1:k + 2], [0.0, 0.5, 1.0], atol=1e-9)
    d = kin.input_at(2 * DT)
    np.testing.assert_allclose(d[k + 1:k + 4], [0.0, 0.5, 1.0], atol=1e-9)
    # a quarter step: the 3-point second difference at sample k sees the step through
    # the triangle over [t_k-1, t_k+1]: (1 - 1/4)²/2 of it, at k + 1 all but (1/4)²/2
    q = kin.input_at(0.25 * DT)
    np.testing.assert_allclose(q[k:k + 2], [0.28125, 0.96875], atol=1e-9)


def test_delayed_input_by_slices_equals_the_clipped_gather():
    from motor_comp.workbench.derivatives import _shifted
    u = np.random.default_rng(6).standard_normal(40)
    k = np.arange(len(u))
    for s in range(-45, 46):
        assert np.array_equal(_shifted(u, s), u[np.clip(k - s, 0, len(u) - 1)])
    assert _shifted(np.zeros(0), 3).shape == (0,)


@pytest.mark.parametrize('frac', [0.0, 0.1, 0.25, 0.5, 0.77, 1.0, 2.4, 7.93])
def test_zoh_input_matches_the_second_difference_of_the_motion(frac):
    """``input_at(τ)`` is what the 3-point second difference of the motion sees.

    A unit mass driven by the held command delayed by τ: its position at the samples
    is the double integral of the command, evaluated here piece by piece (exact
    parabolas between the delayed hold edges), independently of the implementation.
    """
    rng = np.random.default_rng(7)
    n = 400
    t = np.arange(n) * DT
    u = rng.normal(0.0, 1.0, n)
    tau = frac * DT
    kin = kinematics(Run(t=t, position=np.sin(t), voltage=u))

    def position(s: float) -> float:
        # ∫∫ of u held on [t_j + τ, t_j+1 + τ) (u[0] before, u[-1] after), from 0 at t=-1
        edges = np.concatenate([[-1.0], t[1:] + tau, [np.inf]])
        vals = u
        x = v = 0.0
        for j in range(n):
            a, b = edges[j], min(edges[j + 1], s)
            if b <= a:
                break
            h = b - a
            x += v * h + 0.5 * vals[j] * h * h
            v += vals[j] * h
        return x

    xs = np.array([position(s) for s in t])
    seen = (xs[2:] - 2 * xs[1:-1] + xs[:-2]) / DT ** 2
    np.testing.assert_allclose(kin.input_at(tau)[1:-1], seen, atol=1e-6)


def test_irregular_sampling_is_resampled():
    rng = np.random.default_rng(0)
    t = np.cumsum(rng.uniform(1.5e-3, 4.5e-3, 3000))
    run = Run(t=t, position=0.02 * t, voltage=np.ones_like(t))
    kin = kinematics(run, hold='sample')
    assert kin.resampled
    assert np.allclose(np.diff(kin.t), kin.dt)
    assert kin.dt == pytest.approx(np.median(np.diff(t)))
    np.testing.assert_allclose(kin.v, 0.02, rtol=1e-9)


@given(counts=st.integers(min_value=1, max_value=50),
       q=st.sampled_from([1e-7, 5e-7, 2e-6, 2 * np.pi / 2 ** 16]))
@settings(max_examples=30, deadline=None)
def test_quantum_is_the_encoder_resolution(counts, q):
    """``Kinematics.quantum``: the smallest nonzero step of a quantised position."""
    t = np.arange(400) * 1e-3
    x = q * np.round(counts * q * np.sin(2 * np.pi * t) / q + 0.3 * np.sin(40 * t))
    run = Run(t=t, position=x, voltage=np.zeros_like(t))
    kin = kinematics(run)
    assert kin.quantum() == pytest.approx(q, rel=1e-6)
    still = kinematics(Run(t=t, position=np.full_like(t, 0.1),
                           voltage=np.zeros_like(t)))
    assert still.quantum() == 0.0


def test_bad_run_arrays_are_input_errors():
    t = np.arange(0, 1, DT)
    x = np.sin(t)
    x[10] = np.nan
    with pytest.raises(InputFileError, match='position contains NaN'):
        kinematics(Run(t=t, position=x, voltage=np.zeros_like(t)))
    with pytest.raises(InputFileError, match='voltage'):
        kinematics(Run(t=t, position=np.sin(t)))
    with pytest.raises(InputFileError, match='too short|at least'):
        kinematics(Run(t=t[:30], position=np.sin(t[:30]), voltage=np.zeros(30)))


def test_exact_model_leaves_no_residual_and_missing_effect_is_the_residual():
    ripple = make_effect('ripple', {'period': 0.01, 'harmonics': [[4.0, -2.0]]})
    truth = BASE.with_effect(ripple)
    kin = kinematics(analytic_run(truth), hold='sample')
    res = residual(kin, truth)
    assert res.nrmse() < 2e-3
    res0 = residual(kin, BASE)
    m = res0.mask
    # the model without the ripple leaves the ripple force itself, seen through the one
    # processing (the same smoother as every force)
    rip = smooth_full(ripple.force(kin.position), smoother_length(kin))
    assert np.sqrt(np.mean((res0.r[m] - rip[m]) ** 2)) < 0.01 * np.sqrt(np.mean(rip[m] ** 2))


@settings(max_examples=12, deadline=None)
@given(fc=st.floats(2, 30), fv=st.floats(0, 100), f0=st.floats(-10, 10),
       a1=st.floats(-8, 8), b1=st.floats(-8, 8), mass=st.floats(1, 20))
def test_joint_refit_recovers_every_linear_parameter(fc, fv, f0, a1, b1, mass):
    truth = AxisModel(mass=mass, input_gain=15.0, back_emf=123.0, effects=(
        make_effect('coulomb', {'fc': fc}), make_effect('viscous', {'fv': fv}),
        make_effect('offset', {'f0': f0}),
        make_effect('ripple', {'period': 0.013, 'harmonics': [[a1, b1]]})))
    kin = kinematics(analytic_run(truth, duration=6.0), hold='sample')
    start = AxisModel(mass=1.5 * mass, input_gain=15.0, back_emf=123.0, effects=(
        make_effect('coulomb', {'fc': 1.0}), make_effect('viscous', {'fv': 1.0}),
        make_effect('offset', {'f0': 0.0}),
        make_effect('ripple', {'period': 0.013, 'harmonics': [[0.0, 0.0]]})))
    got = refit_linear(kin, start)
    assert got.mass == pytest.approx(mass, rel=2e-3)
    assert got.fc == pytest.approx(fc, abs=0.02)
    assert got.fv == pytest.approx(fv, abs=0.05)
    assert got.get('offset').f0 == pytest.approx(f0, abs=0.02)
    a, b = got.get('ripple').harmonics[0]
    assert a == pytest.approx(a1, abs=0.03) and b == pytest.approx(b1, abs=0.03)


def test_force_nrmse_exact():
    r = np.array([1.0, -1.0, 1.0, -1.0])
    f = np.array([0.0, 2.0, 0.0, 2.0])
    assert force_nrmse(r, f) == 1.0
    assert force_nrmse(0.5 * r, 4 * f) == pytest.approx(0.5 / 4)


def test_spatial_spectrum_finds_period_and_amplitude():
    t = np.arange(0, 20, DT)
    x = 0.05 * np.sin(2 * np.pi * 0.4 * t)
    r = 3.0 * np.sin(2 * np.pi * x / 0.01 + 0.3)
    spec = spatial_spectrum(x, r)
    p = spec.peak_period(min_period=0.001, max_period=0.05)
    assert abs(p - 0.01) < 0.02 * 0.01   # within the padded FFT's resolution
    assert spec.amplitude_at(1 / 0.01) == pytest.approx(3.0, rel=0.05)


def test_reversals_of_a_sine():
    t = np.linspace(0, 2, 2001)
    x = np.sin(2 * np.pi * t)   # extremes at t = 0.25, 0.75, 1.25, 1.75
    rev = reversals(x, 0.05)
    assert [k for k, _ in rev] == [250, 750, 1250, 1750]
    assert [d for _, d in rev] == [-1, 1, -1, 1]


def test_folds_are_short_interleaved_blocks_with_an_hv_gap():
    """Every fold covers the whole record; training never touches a held-out block."""
    kin = kinematics(analytic_run(BASE, duration=20.0), hold='sample')
    D = Data([kin], BASE, folds=5)
    t = kin.t[D.parts[0].rows]
    assert D.n_blocks >= 25
    half = 0.5 * D.window * kin.dt
    for f in range(5):
        held = D.fold == f
        assert t[held].min() < 0.15 * t.max() and t[held].max() > 0.85 * t.max()
        train = D.train_rows(f)
        assert not np.any(train & held)
        # the hv gap: no training sample within (about) half a smoother of a held-out one
        gap = np.min(np.abs(t[train][:, None] - t[held][None, :]), axis=1)
        assert gap.min() >= 0.8 * half
        # and nothing else is lost: every other row trains
        assert np.count_nonzero(~held & ~train) < 0.2 * np.count_nonzero(~held)


def test_zero_backlash_is_the_measurement():
    kin = kinematics(analytic_run(BASE), hold='sample')
    np.testing.assert_array_equal(motor_position(kin, 0.0, BASE, kin.u), kin.position)


def test_whiteness_passes_white_and_fails_coloured_residuals():
    kin = kinematics(analytic_run(BASE, duration=20.0), hold='sample')
    res = residual(kin, BASE)
    rng = np.random.default_rng(1)
    white = rng.normal(size=len(kin))
    w = whiteness(kin, type(res)(**{**res.__dict__, 'r': white}))
    assert w.auto_outside <= 0.05 and w.cross_outside <= 0.05
    coloured = np.convolve(white, np.ones(400) / 400, mode='same') + 0.01 * kin.u
    w2 = whiteness(kin, type(res)(**{**res.__dict__, 'r': coloured}))
    assert w2.auto_outside > 0.5
