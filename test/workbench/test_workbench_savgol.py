"""The hand-written Savitzky–Golay filter, correlation and Welch spectrum against scipy's.

They are written in the package only to keep ``scipy.signal``'s import (~0.45 s of CPU)
and ``scipy.ndimage``'s (0.07 s) out of every command; the numbers must be scipy's —
the correlation's to the bit (a last-bit rounding moved samples across the sliding
threshold and flipped backlash decisions).
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.signal as ss
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.ndimage import correlate1d as nd_correlate1d

from motor_comp.workbench import savgol
from motor_comp.workbench.spectral import welch as _welch


@settings(max_examples=60, deadline=None)
@given(half=st.integers(0, 25), polyorder=st.integers(0, 5), deriv=st.integers(0, 3),
       mode=st.sampled_from(['interp', 'mirror']), extra=st.integers(0, 80),
       delta=st.floats(1e-4, 10.0), seed=st.integers(0, 2 ** 16))
def test_filter_matches_scipy(half, polyorder, deriv, mode, extra, delta, seed):
    window = 2 * half + 1
    polyorder = min(polyorder, window - 1)
    y = np.random.default_rng(seed).normal(size=window + extra)
    want = ss.savgol_filter(y, window, polyorder, deriv=deriv, delta=delta, mode=mode)
    got = savgol.savgol_filter(y, window, polyorder, deriv=deriv, delta=delta, mode=mode)
    scale = max(1.0, float(np.max(np.abs(want))))
    assert np.max(np.abs(got - want)) <= 1e-9 * scale


@settings(max_examples=300, deadline=None)
@given(length=st.integers(1, 400), taps=st.integers(1, 41),
       kind=st.sampled_from(['smoother', 'derivative', 'mirrored', 'random']),
       mode=st.sampled_from(['mirror', 'constant']), axis=st.integers(0, 1),
       scale=st.floats(-6, 6), seed=st.integers(0, 2 ** 16))
def test_correlation_is_ndimages_to_the_bit(length, taps, kind, mode, axis, scale, seed):
    """Every kind of kernel ndimage tells apart, every extension the workbench uses.

    Lines shorter than the kernel (reflected more than once), even and odd kernels,
    taps that mirror within the machine epsilon (paired sums), with opposite signs
    (differences) or not at all (taps last-first).
    """
    rng = np.random.default_rng(seed)
    if kind == 'smoother':
        w = np.blackman(2 * (taps // 2) + 3)[1:-1]
        w = w / w.sum()
    elif kind == 'derivative':
        half = max(taps // 2, 1)
        w = savgol.savgol_coeffs(2 * half + 1, min(2, 2 * half), deriv=1)
    elif kind == 'mirrored':
        h = rng.normal(size=taps // 2 + 1)
        w = np.concatenate([h, h[-2::-1]])
        w[0] += 1e-17             # within the epsilon: still paired
    else:
        w = rng.normal(size=taps)
    shape = (length, 3) if axis == 0 else (3, length)
    x = rng.normal(size=shape) * 10.0 ** scale
    want = nd_correlate1d(x, w, axis=axis, mode=mode)
    got = savgol.correlate1d(x, w, axis=axis, mode=mode)
    assert got.shape == want.shape and got.flags.c_contiguous
    assert np.array_equal(got, want)


def test_correlation_refuses_a_mode_it_does_not_have():
    with pytest.raises(ValueError, match="mirror' or 'constant'"):
        savgol.correlate1d(np.ones(5), np.ones(3), mode='wrap')


@pytest.mark.parametrize('axis', [0, 1])
def test_filter_along_either_axis_of_a_2d_array(axis):
    y = np.random.default_rng(0).normal(size=(60, 4) if axis == 0 else (4, 60))
    for mode in ('interp', 'mirror'):
        want = ss.savgol_filter(y, 11, 3, deriv=1, axis=axis, mode=mode)
        got = savgol.savgol_filter(y, 11, 3, deriv=1, axis=axis, mode=mode)
        np.testing.assert_allclose(got, want, atol=1e-12)


def test_coefficients_match_scipy_dot_order():
    for window, polyorder, deriv in ((5, 2, 0), (21, 3, 1), (31, 2, 2), (7, 1, 2)):
        np.testing.assert_allclose(
            savgol.savgol_coeffs(window, polyorder, deriv=deriv, delta=0.001),
            ss.savgol_coeffs(window, polyorder, deriv=deriv, delta=0.001, use='dot'),
            rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize('window, polyorder, mode',
                         [(4, 2, 'interp'), (5, 5, 'interp'), (5, 2, 'nearest')])
def test_bad_arguments_are_refused(window, polyorder, mode):
    with pytest.raises(ValueError):
        savgol.savgol_filter(np.zeros(20), window, polyorder, mode=mode)


@pytest.mark.parametrize('n, nper', [(1000, 256), (300, 255), (64, 64), (513, 257)])
def test_welch_matches_scipy(n, nper):
    rng = np.random.default_rng(n)
    x = rng.normal(size=n) + np.sin(0.3 * np.arange(n))
    x = x - x.mean()
    f_want, p_want = ss.welch(x, fs=500.0, nperseg=nper)
    f_got, p_got = _welch(x, 500.0, nper)
    np.testing.assert_allclose(f_got, f_want)
    np.testing.assert_allclose(p_got, p_want, rtol=1e-9, atol=1e-15)
