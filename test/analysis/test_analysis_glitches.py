"""Reversal and glitch detection on constructed signals."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motor_comp.analysis.glitches import find_glitches, reversals


def test_interpolated_zero_crossing_and_direction() -> None:
    t = 0.0007 + 0.003 * np.arange(400)          # samples never hit the zero crossings
    v = np.cos(2 * np.pi * t)
    tr, d = reversals(t, v)
    np.testing.assert_allclose(tr, [0.25, 0.75], atol=2e-6)
    assert list(d) == [-1, 1]


def test_dwell_reversal_starts_when_new_motion_starts() -> None:
    t = np.arange(9) * 0.1
    v = np.array([1.0, 1.0, 0.0, 0.0, 0.0, -1.0, -1.0, 0.0, 1.0])
    tr, d = reversals(t, v)
    np.testing.assert_allclose(tr, [0.4, 0.7])
    assert list(d) == [-1, 1]


def test_rest_without_reversal_and_roundoff_are_ignored() -> None:
    t = np.arange(10) * 0.1
    v = np.array([1.0, 1.0, 0.0, 0.0, 1.0, 1.0, -1e-12, 1.0, 1.0, 1.0])
    assert reversals(t, v)[0].size == 0
    assert reversals(t, np.zeros(10))[0].size == 0


def test_glitch_count_time_and_magnitude() -> None:
    t = np.arange(3000) * 1e-3                   # 3 s, reversals at 0.5, 1.5, 2.5 s
    v = np.cos(np.pi * t)
    e = np.zeros_like(t)
    e[[520, 1690, 2505]] = [3e-6, -7e-6, 2e-6]   # inside the 0.2 s windows
    e[1750] = 50e-6                              # outside every window: not a glitch
    g = find_glitches(t, e, v, window=0.2)
    assert len(g) == 3
    np.testing.assert_allclose([x.t for x in g], [0.5, 1.5, 2.5], atol=1e-9)
    np.testing.assert_allclose([x.magnitude for x in g], [3e-6, 7e-6, 2e-6])
    np.testing.assert_allclose([x.t_peak for x in g], [0.52, 1.69, 2.505])
    assert [x.direction for x in g] == [-1, 1, -1]
    # a wider window catches the far peak of the second reversal
    assert find_glitches(t, e, v, window=0.3)[1].magnitude == pytest.approx(50e-6)


@settings(max_examples=40, deadline=None)
@given(f=st.floats(0.2, 3.0), phase=st.floats(0.0, 0.001))
def test_reversals_of_a_sine_match_its_extrema(f: float, phase: float) -> None:
    dt = 1e-3
    t = phase + dt * np.arange(5000)
    tr, _ = reversals(t, np.cos(2 * np.pi * f * t))
    expected = (2 * np.arange(100) + 1) / (4 * f)
    expected = expected[(expected > t[0]) & (expected < t[-1])]
    assert tr.size == expected.size
    np.testing.assert_allclose(tr, expected, atol=1e-6)
