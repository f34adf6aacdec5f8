"""Generalized Maxwell-slip pre-sliding friction (Lampaert, Al-Bender, Swevers 2003).

The properties Chiew et al. (eq. 3–5) rely on: hysteresis with non-local memory in
pre-sliding (loop area, stiffness Σk_i at a reversal, wiping-out of minor loops), and
the Stribeck curve s(v) (+ σ·v) at constant velocity.  At a slow constant speed the
elements are elastic–perfectly-plastic, so the loops have closed forms.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from motor_comp.physics import load_plant, make_effect
from motor_comp.physics.effects import Presliding
from motor_comp.physics.effects.presliding import gms_update
from motor_comp.physics.effects.stribeck import stribeck_curve

# Chiew's N = 4 structure with the DESIGN.md §3 stand-in values (no micro-damping: the
# quasi-static loops below have closed forms for the spring forces alone)
GMS = Presliding(alpha=(0.45, 0.30, 0.15, 0.10), k=(8e6, 3e6, 1e6, 3e5), C=12000.0)
FC, FS, VS, DELTA = 12.0, 18.0, 1e-3, 1.0
DT = 1e-3
STEP = 1e-8                     # 10 nm per sample: 10 µm/s, far below vs = 1 mm/s
A = 10e-6                       # ±10 µm: every element slips (largest f_i/k_i is 6 µm)


def _legs(*targets: float) -> np.ndarray:
    """Piecewise-linear displacement through ``targets`` [m], starting at 0, STEP apart."""
    x = [np.zeros(1)]
    for a, b in zip((0.0,) + targets[:-1], targets):
        n = int(round(abs(b - a) / STEP))
        x.append(np.linspace(a, b, n + 1)[1:])
    return np.concatenate(x)


def _force(x: np.ndarray) -> np.ndarray:
    return GMS.force_along(x, DT, fc=FC, fs=FS, vs=VS, delta=DELTA)


def _s_slow() -> float:
    """|s(v)| at the test speed STEP/DT [N]."""
    return float(stribeck_curve(STEP / DT, FC, FS, VS, DELTA))


def test_slow_reversal_traces_a_hysteresis_loop_with_the_elastoplastic_area():
    x = _legs(A, -A, A)
    f = _force(x)
    i_top = int(round(A / STEP))
    i_bottom = i_top + int(round(2 * A / STEP))
    s = _s_slow()
    assert f[i_top] == pytest.approx(s, rel=1e-9)       # fully sliding: F = s(v)
    assert f[i_bottom] == pytest.approx(-s, rel=1e-9)
    down = f[i_top:i_bottom + 1]
    assert np.all(np.diff(down) <= 1e-12)                # monotone descending branch
    assert np.count_nonzero(np.diff(np.sign(down)) != 0) == 1   # changes sign once
    # ∮F·dx over the steady cycle, and its closed form Σ 4·f_i·(A − f_i/k_i)
    loop = slice(i_top, None)
    area = np.sum(0.5 * (f[loop][1:] + f[loop][:-1]) * np.diff(x[loop]))
    fi = np.array(GMS.alpha) * s
    expected = np.sum(4.0 * fi * (A - fi / np.array(GMS.k)))
    assert area > 0.0
    assert area == pytest.approx(expected, rel=2e-3)


def test_presliding_stiffness_right_after_a_reversal_is_the_sum_of_k():
    x = _legs(A, -A)
    f = _force(x)
    i_top = int(round(A / STEP))
    # all elements stick for 2·min(f_i/k_i) ≈ 2 µm after the turn; look at 0.5 µm
    n = 50
    slope = np.polyfit(x[i_top:i_top + n], f[i_top:i_top + n], 1)[0]
    assert slope == pytest.approx(GMS.stiffness, rel=1e-9)
    assert GMS.stiffness == sum(GMS.k)


def test_minor_loop_is_wiped_out_non_local_memory():
    xa, xb, xc = 2e-6, -1e-6, 5e-6
    major = _legs(-A, A)
    minor = _legs(-A, xa, xb, A)
    fm, fn = _force(major), _force(minor)

    def at(x, f, target, leg_start):
        j = leg_start + int(np.argmin(np.abs(x[leg_start:] - target)))
        assert abs(x[j] - target) < 1e-12
        return f[j]

    start_up = int(round(A / STEP))                      # both paths rise from −A here
    start_last = start_up + int(round((xa + A) / STEP)) + int(round((xa - xb) / STEP))
    # the minor loop really is a different path: at x = 0 on its way down the force
    # differs from the major branch at the same displacement
    down_minor = start_up + int(round((xa + A) / STEP))
    assert abs(at(minor, fn, 0.0, down_minor) - at(major, fm, 0.0, start_up)) > 1.0
    # the loop closes at its turning point xa ...
    assert at(minor, fn, xa, start_last) == pytest.approx(at(minor, fn, xa, start_up),
                                                          abs=1e-9)
    # ... and beyond it the force is back on the major branch (wiping-out property)
    assert at(minor, fn, xc, start_last) == pytest.approx(at(major, fm, xc, start_up),
                                                          abs=1e-9)


@pytest.mark.parametrize('v', [1e-4, 5e-3, 0.1])
def test_constant_velocity_force_converges_to_the_stribeck_curve(v):
    dt = 1e-4
    t = np.arange(0.0, 0.2, dt)
    up = _force_dt(v * t, dt)
    down = _force_dt(-v * t, dt)
    s = stribeck_curve(v, FC, FS, VS, DELTA)
    assert up[-1] == pytest.approx(s, rel=1e-9)
    assert down[-1] == -up[-1]                           # odd at steady state


def _force_dt(x: np.ndarray, dt: float) -> np.ndarray:
    return GMS.force_along(x, dt, fc=FC, fs=FS, vs=VS, delta=DELTA)


def test_model_gms_plus_viscous_is_s_of_v_plus_sigma_v():
    model = load_plant('ballscrew').model
    dt, v = 1e-4, 0.02
    x = v * np.arange(0.0, 0.2, dt)
    forces = model.effect_forces(x, np.full_like(x, v), dt=dt)
    assert set(forces) == {'presliding', 'viscous'}      # GMS replaces coulomb+stribeck
    total = forces['presliding'][-1] + forces['viscous'][-1]
    s = stribeck_curve(v, FC, FS, VS, DELTA)
    assert total == pytest.approx(s + 200.0 * v, rel=1e-9)
    # without a trajectory step the static curve stands in, with the same value
    static = model.static_force(x[-1:], np.array([v]))
    assert static[0] == pytest.approx(total, rel=1e-9)


@settings(max_examples=60, deadline=None)
@given(data=st.data(),
       n=st.integers(1, 8),
       fc=st.floats(0.0, 50.0), extra=st.floats(0.0, 50.0),
       vs=st.floats(1e-5, 0.1), delta=st.floats(0.3, 5.0),
       C=st.floats(1.0, 1e6), dt=st.sampled_from([1e-4, 1e-3]))
def test_element_forces_stay_within_their_slip_limits(data, n, fc, extra, vs, delta, C, dt):
    weights = np.array(data.draw(st.lists(st.floats(0.05, 1.0), min_size=n, max_size=n)))
    alpha = weights / weights.sum()
    k = np.array(data.draw(st.lists(st.floats(1e4, 1e8), min_size=n, max_size=n)))
    steps = data.draw(st.lists(st.floats(-1e-5, 1e-5), min_size=5, max_size=150))
    fs = fc + extra
    forces, slip = np.zeros(n), np.zeros(n)
    for dx in steps:
        v = dx / dt
        s = stribeck_curve(v, fc, fs, vs, delta)
        total = gms_update(forces, slip, alpha, k, np.zeros(n), C, dx, v, s, dt)
        tol = 1e-9 * (1.0 + fs)
        assert total == pytest.approx(forces.sum(), abs=tol)   # no σ: Σ F_i
        # every element is bounded by its share of the breakaway force ...
        assert np.all(np.abs(forces) <= alpha * fs + tol)
        # ... and, along the motion, a sticking element by its share of s(v) (against
        # the motion it may still carry more while it unloads elastically)
        along = (slip == 0.0) & (np.sign(forces) == np.sign(v))
        if v != 0.0:
            assert np.all(np.abs(forces[along]) <= alpha[along] * abs(s) + tol)
        assert np.all(np.isin(slip, (-1.0, 0.0, 1.0)))
        assert np.all(slip * np.sign(v) >= 0.0)          # slipping only along the motion


def test_presliding_effect_from_model_file_form():
    e = make_effect('presliding', {'alpha': [0.45, 0.30, 0.15, 0.10],
                                   'k': [8e6, 3e6, 1e6, 3e5], 'C': 12000.0})
    assert e == GMS and e.sigma == (0.0,) * 4            # no sigma given: none
    assert e.stiffness == pytest.approx(1.23e7)
    assert e.params() == {'alpha': [0.45, 0.30, 0.15, 0.10], 'k': [8e6, 3e6, 1e6, 3e5],
                          'C': 12000.0, 'sigma': [0.0] * 4}


def test_sticking_elements_are_elastic_right_after_a_fast_reversal():
    # Lampaert/Chiew: a sticking element follows dF_i = k_i·dx until F_i reaches
    # α_i·s(v) in the direction of motion.  Reverse from slow sliding (|s| ≈ fs) straight
    # into fast motion (|s| ≈ fc): the elements, still loaded the old way, must unload
    # elastically — a 1 nm step changes the force by Σk·1 nm, not by fs − fc.
    alpha, k = np.array(GMS.alpha), np.array(GMS.k)
    s_slow = _s_slow()
    forces, slip = alpha * s_slow, np.ones(4)           # all slipping forward
    v, dx = -0.1, -1e-9
    s_fast = stribeck_curve(v, FC, FS, VS, DELTA)
    assert abs(s_fast) < 12.0 + 1e-6                      # deep in the Coulomb regime
    total = gms_update(forces, slip, alpha, k, np.zeros(4), GMS.C, dx, v, s_fast, dx / v)
    assert np.all(slip == 0.0)
    assert total == pytest.approx(s_slow + GMS.stiffness * dx, abs=1e-9)


def test_without_a_friction_level_the_elements_carry_no_force():
    # s(v) ≡ 0 (no coulomb, no stribeck): α_i·s(v) = 0, so the elements slip at once and
    # must not act as springs of stiffness Σk holding the axis
    x = _legs(A, -A)
    f = GMS.force_along(x, DT, fc=0.0, fs=0.0)
    assert np.max(np.abs(f)) == 0.0
