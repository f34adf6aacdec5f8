"""N-PID (Chiew et al.): loop-shaping design, Popov bound, gain shape, feedforward claims."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from motor_comp.control import NPIDParams, default_trajectory, make_controller, simulate
from motor_comp.control.npid import design_pid, frequency_grid, linear_plant_response, \
    loop_margins, npid_gain, pid_response, popov_limit, sampled_loop

TAU = 1.29e-3


@pytest.fixture(scope='module')
def design(ballscrew):
    """The loop-shaping design on the ball-screw with its 1.29 ms delay."""
    return design_pid(ballscrew.model, delay=TAU)


def test_default_gains_are_the_design(design):
    p, d = NPIDParams(), design.params
    for name in ('kp', 'ki', 'kd'):
        assert getattr(p, name) == pytest.approx(getattr(d, name), rel=0.02), name


def test_margins_match_chiew_table_iv_with_python_control(ballscrew):
    """GM 9.9 dB, PM 54.2°, bandwidth 38.5 Hz (Chiew Table IV) — checked by python-control."""
    ct = pytest.importorskip('control')
    p = NPIDParams()
    num, den = ct.pade(TAU, 10)
    plant = ct.tf([2.0], [1.0, 2.0, 0.0]) * ct.tf(num, den)   # A/(s² + B s), A = B = 2
    pid = ct.tf([p.kd + p.kp * p.tf, p.kp + p.ki * p.tf, p.ki], [p.tf, 1.0, 0.0])
    loop = pid * plant
    gm, pm, _, wpc, wgc, _ = ct.stability_margins(loop)
    assert 20 * math.log10(gm) == pytest.approx(9.9, abs=1.0)
    assert pm == pytest.approx(54.2, abs=2.0)
    assert wgc / (2 * math.pi) == pytest.approx(64.9, abs=3.0)
    assert wpc / (2 * math.pi) == pytest.approx(184.0, abs=10.0)
    w = np.logspace(0, 4, 20000)
    sens = np.abs(ct.feedback(1, loop)(1j * w))
    bw = w[np.argmax(sens >= 1 / math.sqrt(2))] / (2 * math.pi)
    assert bw == pytest.approx(38.5, abs=2.0)
    # our numpy margins agree with python-control on the exact-delay loop
    ours = loop_margins(pid_response(p.kp, p.ki, p.kd, p.tf, w) *
                        linear_plant_response(ballscrew.model, w, delay=TAU), w)
    assert ours.gain_margin_db == pytest.approx(20 * math.log10(gm), abs=0.05)
    assert ours.phase_margin_deg == pytest.approx(pm, abs=0.1)


def test_popov_limit_near_paper_and_bounds_k(design, ballscrew):
    # Chiew Fig. 7/eq. 9: k(e_max) <= 1/0.3437 ≈ 2.9 for their plant; ours ≈ 2.7
    assert 2.4 < design.popov_limit < 3.2
    assert design.popov_limit <= 10 ** (design.margins.gain_margin_db / 20) + 1e-9
    # the 1 kHz implementation adds ≈ 1 ms of dead time: a smaller bound, used by default
    w, L = sampled_loop(ballscrew.model, NPIDParams(), delay=TAU, control_period=1e-3)
    k_impl = popov_limit(L, w)
    assert 1.0 < k_impl < design.popov_limit
    ctrl = make_controller('npid', plant=ballscrew)
    assert ctrl.packed[9] == pytest.approx(k_impl)   # Q_KMAX
    assert npid_gain(1.0, 15000.0, 1e-4, k_impl) == pytest.approx(k_impl)


@given(e=st.floats(-1e-3, 1e-3))
@settings(max_examples=200, deadline=None)
def test_npid_gain_is_even_bounded_and_continuous(e):
    k0, e_max, k_max = 15000.0, 1e-4, 2.9
    k = npid_gain(e, k0, e_max, k_max)
    assert 1.0 <= k <= math.cosh(1.5) + 1e-12
    assert k == npid_gain(-e, k0, e_max, k_max)
    # Lipschitz continuity: |dk/de| <= k0·sinh(k0·e_max)
    h = 1e-9
    assert abs(npid_gain(e + h, k0, e_max, k_max) - k) <= k0 * math.sinh(1.5) * h * 1.01


def test_npid_gain_values():
    assert npid_gain(0.0, 15000.0, 1e-4, 0.0) == 1.0
    assert npid_gain(5e-5, 15000.0, 1e-4, 0.0) == pytest.approx(math.cosh(0.75))
    assert npid_gain(2e-4, 15000.0, 1e-4, 0.0) == pytest.approx(math.cosh(1.5))
    assert npid_gain(2e-4, 15000.0, 1e-4, 2.0) == 2.0


def _glitches(res, window=0.2):
    rv = res.reference_velocity
    idx = np.nonzero(np.sign(rv[1:]) != np.sign(rv[:-1]))[0] + 1
    return np.array([np.max(np.abs(res.error[(res.t >= res.t[i]) & (res.t <= res.t[i] + window)]))
                     for i in idx])


@pytest.fixture(scope='module')
def ff_runs(ballscrew):
    """N-PID with each friction feedforward on the default slow sine (12 reversals)."""
    out = {}
    for ff in ('none', 'static', 'gms', 'static+gms'):
        ctrl = make_controller('npid', plant=ballscrew, feedforward=ff)
        res = simulate(ballscrew, ctrl, default_trajectory('ballscrew'), duration=12.0)
        steady = res.t > 1.0
        g = _glitches(res)
        out[ff] = {'rms': float(np.sqrt(np.mean(res.error[steady] ** 2))),
                   'max_glitch': float(g.max()), 'mean_glitch': float(g.mean()),
                   'n': g.size}
    return out


def test_feedforward_claims_of_chiew(ff_runs):
    none, st_, gms, both = (ff_runs[k] for k in ('none', 'static', 'gms', 'static+gms'))
    assert none['n'] == 12
    assert st_['rms'] < 0.5 * none['rms']                     # static cuts the error
    assert gms['mean_glitch'] < st_['mean_glitch']            # GMS cuts glitches more
    assert gms['max_glitch'] < st_['max_glitch']
    assert both['rms'] <= 0.6 * none['rms']                   # paper: ≈ −48 %
    assert both['max_glitch'] <= 0.5 * none['max_glitch']     # paper: ≈ −50 %
    assert both['rms'] <= min(st_['rms'], gms['rms'])         # best on error
    assert both['mean_glitch'] <= min(st_['mean_glitch'], gms['mean_glitch'])


def test_feedforward_needs_gms_in_model(pmlm):
    from motor_comp.errors import ParameterError
    with pytest.raises(ParameterError, match='presliding'):
        make_controller('npid', plant=pmlm, feedforward='gms')


def test_frequency_grid_covers_crossover():
    w = frequency_grid()
    assert w[0] <= 2 * math.pi * 1 and w[-1] >= 2 * math.pi * 10_000
