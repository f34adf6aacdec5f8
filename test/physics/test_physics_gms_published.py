"""GMS as published (Lampaert, Al-Bender & Swevers 2003), issue 15 items 5–6.

* the slip phase ``dF_i/dt = sgn(v)·C·(α_i − F_i/s(v))``: its relaxation rate ``C/|s(v)|``
  follows the Stribeck curve (checked against an ODE solver and the closed-form friction
  lag after a velocity step);
* element micro-damping ``σ_i`` gives the pre-sliding resonance the ζ stated in
  ``config/ballscrew.yaml``;
* old model files (slip rate ``c`` [1/s]) are read with a one-line note;
* the dead-time start-up convention (zero before the start) is the same in the effect
  and in the kernel.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from motor_comp.errors import ModelFileError, ParameterError
from motor_comp.physics import AxisModel, Plant, load_plant, make_effect, plant_from_dict
from motor_comp.physics import kernel as K
from motor_comp.physics.effects import Delay, Presliding
from motor_comp.physics.effects.presliding import gms_update
from motor_comp.physics.effects.stribeck import stribeck_curve
from motor_comp.physics.plant import initial_state, pack_params

from physics_helpers import DT, IDEAL, model, plant, trace

FC, FS, VS, DELTA = 12.0, 18.0, 1e-3, 1.0
C = 12000.0                     # [N/s]
ALPHA = np.array([0.45, 0.30, 0.15, 0.10])
KS = np.array([8e6, 3e6, 1e6, 3e5])


def _s(v: float) -> float:
    return float(stribeck_curve(v, FC, FS, VS, DELTA))


@pytest.mark.parametrize('v', [2e-4, 1e-3, 0.05, -1e-3, -0.05])
def test_slip_phase_is_the_published_ode_with_rate_c_over_abs_s(v):
    # one element slipping at constant v, started off its target α·s(v): the exact step
    # of gms_update against the published ODE integrated by an independent solver
    s = _s(v)
    alpha, k = np.array([1.0]), np.array([1e6])
    f0 = 0.3 * s
    dt = 2e-4
    forces, slip = np.array([f0]), np.array([np.sign(v)])
    got = [f0]
    for _ in range(20):
        gms_update(forces, slip, alpha, k, np.zeros(1), C, v * dt, v, s, dt)
        got.append(forces[0])
    sol = solve_ivp(lambda t, f: np.sign(v) * C * (1.0 - f / s), (0.0, 20 * dt), [f0],
                    t_eval=np.arange(21) * dt, rtol=1e-11, atol=1e-12 * abs(s))
    np.testing.assert_allclose(got, sol.y[0], rtol=1e-8, atol=1e-9 * abs(s))
    # the rate is C/|s(v)| (not a constant): log-decrement per step
    rate = -np.log((s - got[1]) / (s - got[0])) / dt
    assert rate == pytest.approx(C / abs(s), rel=1e-12)


def test_slip_rate_follows_the_stribeck_curve_in_a_velocity_step():
    # Lampaert's frictional lag: sliding at v1, then v2 (both forward), every element
    # slips and the friction relaxes from s(v1) to s(v2) as a first-order lag with the
    # time constant |s(v2)|/C of the *new* velocity: closed form
    #     F(t) = s2 + (s1 − s2)·exp(−C·t/|s2|)
    gms = Presliding(alpha=tuple(ALPHA), k=tuple(KS), C=C)
    dt = 1e-5
    for v1, v2 in ((0.05, 1e-3), (1e-3, 0.05)):     # into and out of the Stribeck dip
        n1, n2 = 20000, 1000
        x = np.concatenate([[0.0], v1 * dt * np.arange(1, n1 + 1),
                            v1 * dt * n1 + v2 * dt * np.arange(1, n2 + 1)])
        f = gms.force_along(x, dt, fc=FC, fs=FS, vs=VS, delta=DELTA)
        s1, s2 = _s(v1), _s(v2)
        assert f[n1] == pytest.approx(s1, rel=1e-12)          # converged before the step
        t = dt * np.arange(1, n2 + 1)
        closed = s2 + (s1 - s2) * np.exp(-C * t / abs(s2))
        np.testing.assert_allclose(f[n1 + 1:], closed, rtol=1e-10)
        # the fitted time constant is |s(v2)|/C: 1.18 ms at 1 mm/s, 1.00 ms at 50 mm/s
        tau = -1.0 / np.polyfit(t[:300], np.log(np.abs(f[n1 + 1:n1 + 301] - s2)), 1)[0]
        assert tau == pytest.approx(abs(s2) / C, rel=1e-6)
    assert abs(_s(1e-3)) / C == pytest.approx((FC + (FS - FC) / math.e) / C)


def test_micro_damping_of_slipping_elements_in_the_velocity_step():
    # with σ_i = k_i·T the slipping elements add σ_i·Ḟ_i/k_i = T·dF/dt:
    #     F(t) = s2 + (s1 − s2)·e^{−t/τ}·(1 − T/τ),  τ = |s2|/C
    t_sigma = 2e-4
    gms = Presliding(alpha=tuple(ALPHA), k=tuple(KS), C=C, sigma=tuple(KS * t_sigma))
    dt, v1, v2, n1, n2 = 1e-6, 0.05, 1e-3, 200000, 3000
    x = np.concatenate([[0.0], v1 * dt * np.arange(1, n1 + 1),
                        v1 * dt * n1 + v2 * dt * np.arange(1, n2 + 1)])
    f = gms.force_along(x, dt, fc=FC, fs=FS, vs=VS, delta=DELTA)
    s1, s2 = _s(v1), _s(v2)
    tau = abs(s2) / C
    t = dt * np.arange(1, n2 + 1)
    closed = s2 + (s1 - s2) * np.exp(-t / tau) * (1.0 - t_sigma / tau)
    # ΔF/(k·dt) over a step is the rate half a step earlier: O(dt/τ) = 1e-3 of the jump
    np.testing.assert_allclose(f[n1 + 1:], closed, rtol=0, atol=2e-3 * abs(s1 - s2))
    # right after the step the damping takes T/τ = 0.17 of the lag away at once
    assert f[n1 + 1] - s2 == pytest.approx((s1 - s2) * (1.0 - t_sigma / tau), rel=3e-3)
    assert 1.0 - t_sigma / tau == pytest.approx(0.831, abs=1e-3)


def _step_response(m: AxisModel, force: float, n: int) -> np.ndarray:
    p = plant(m)
    tr = trace(p, force / m.input_gain, n)
    return tr['x']


@pytest.mark.parametrize('with_sigma', [True, False])
def test_micro_damping_gives_the_stated_zeta_of_the_presliding_resonance(with_sigma):
    # config/ballscrew.yaml states ζ = 0.50 (ω_n = 701 rad/s); without σ_i it is 0.0071.
    # A 3.6 N force step keeps every element sticking: a linear 2nd-order system whose
    # overshoot and ringing frequency give ζ and ω_n, measured on the kernel.
    m = load_plant('ballscrew').model.without('delay')
    gms = m.get('presliding')
    if not with_sigma:
        gms = gms.replace(sigma=())
        m = m.with_effect(gms)
    zeta = gms.damping_ratio(m.mass, m.damping + m.fv)
    wn = math.sqrt(gms.stiffness / m.mass)
    assert wn == pytest.approx(701.4, abs=0.1)
    assert zeta == pytest.approx(0.498 if with_sigma else 0.00713, abs=1e-3)
    force = 0.2 * FS
    x = _step_response(m, force, 1500 if with_sigma else 400)
    x_ss = force / gms.stiffness
    overshoot = (np.max(x) - x_ss) / x_ss
    ln_os = math.log(overshoot)
    zeta_meas = -ln_os / math.sqrt(math.pi ** 2 + ln_os ** 2)
    assert zeta_meas == pytest.approx(zeta, rel=0.02)
    t_peak = (np.argmax(x) + 1) * DT                     # first peak at π/ω_d
    wd = wn * math.sqrt(1.0 - zeta ** 2)
    assert t_peak == pytest.approx(math.pi / wd, abs=1.5 * DT)
    if with_sigma:
        assert x[-1] == pytest.approx(x_ss, rel=1e-4)   # rung down within 0.15 s


def test_ballscrew_config_uses_the_published_parameters():
    gms = load_plant('ballscrew').model.get('presliding')
    assert gms.C == 12000.0 and gms.sigma == (11200.0, 4200.0, 1400.0, 420.0)
    np.testing.assert_allclose(np.array(gms.sigma) / np.array(gms.k), 1.4e-3)
    # the same σ from the helper that solves for a wanted ζ
    m = load_plant('ballscrew').model
    again = gms.with_damping_ratio(0.5, m.mass, m.damping + m.fv)
    np.testing.assert_allclose(again.sigma, gms.sigma, rtol=0.01)


# ---- old files ------------------------------------------------------------------------
OLD = {'mass': 25.0, 'effects': {
    'coulomb': {'fc': 12.0},
    'presliding': {'alpha': [0.45, 0.30, 0.15, 0.10], 'k': [8e6, 3e6, 1e6, 3e5],
                   'c': 1000.0}}}


def test_old_model_file_with_slip_rate_c_is_converted_with_a_one_line_note(capsys):
    m = AxisModel.from_dict(OLD, source='old.yaml')
    assert m.get('presliding').C == 12000.0                # C = c·fc
    assert m.get('presliding').sigma == (0.0,) * 4
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('motor-comp: warning: old.yaml: ')
    assert 'C = c·fc = 12000 N/s' in err and "'C: 12000'" in err
    # at sliding speeds (|s| = fc) the converted law relaxes at the old rate c
    assert m.get('presliding').C / m.fc == 1000.0
    # written back in the new form, it loads silently
    again = AxisModel.from_dict(m.to_dict())
    assert again == m and capsys.readouterr().err == ''
    assert m.to_dict()['effects']['presliding']['C'] == 12000.0


def test_old_plant_file_is_converted_too(capsys):
    cfg = plant_from_dict({'plant': 'ballscrew',
                           'motor': {'A_m_per_V_s2': 2.0, 'B_per_s': 2.0, 'C_per_s2': 0.0,
                                     'force_constant_N_per_V': 50.0},
                           'effects': OLD['effects']}, source='bs.yaml')
    assert cfg.model.get('presliding').C == 12000.0
    assert 'bs.yaml: presliding.c = 1000 1/s' in capsys.readouterr().err


@pytest.mark.parametrize('effects, needle', [
    ({'presliding': {'alpha': [1.0], 'k': [1e6], 'c': 100.0}}, 'C = c·fc'),
    ({'coulomb': {'fc': 0.0}, 'presliding': {'alpha': [1.0], 'k': [1e6], 'c': 100.0}},
     'coulomb.fc must be > 0'),
    ({'coulomb': {'fc': 1.0},
      'presliding': {'alpha': [1.0], 'k': [1e6], 'c': 100.0, 'C': 5.0}}, 'not both'),
])
def test_unconvertible_old_slip_rate_is_a_one_line_error(effects, needle):
    with pytest.raises(ModelFileError) as exc:
        AxisModel.from_dict({'mass': 1.0, 'effects': effects}, source='m.yaml')
    msg = str(exc.value)
    assert '\n' not in msg and msg.startswith('m.yaml: ') and needle in msg
    assert "'c' [1/s]" in msg or 'not both' in msg


def test_a_standalone_effect_refuses_the_old_key():
    with pytest.raises(ParameterError, match=r"use C = c·fc"):
        make_effect('presliding', {'alpha': [1.0], 'k': [1e6], 'c': 100.0})


# ---- dead-time start-up ---------------------------------------------------------------
def test_delay_start_up_is_zero_in_the_effect_and_in_the_kernel():
    # one convention: before the start the command was 0 (a drive at power-on); the
    # kernel's applied command equals Delay.apply on the same samples, start included
    tau = 3.37 * DT                                     # fractional number of steps
    m = model(('delay', {'tau': tau}), mass=1.0)
    p = Plant(m, sensors=IDEAL, physics_rate=1.0 / DT)
    n = 200
    t = np.arange(n) * DT                                # start of each physics step
    u = 2.0 + np.sin(2 * math.pi * 50.0 * t)             # u[0] = 2, far from 0
    ueff = np.empty(n)
    for j in range(n):
        K.plant_advance(p.params, p.state, float(u[j]), 0.0, 1)
        ueff[j] = p.applied_command
    np.testing.assert_allclose(ueff, Delay(tau=tau).apply(t, u), rtol=0, atol=1e-12)
    assert np.all(ueff[:3] == 0.0) and 0.0 < ueff[3] < u[0]
    # and the axis does not move before the command arrives
    q = Plant(m, sensors=IDEAL, physics_rate=1.0 / DT)
    K.plant_advance(q.params, q.state, 5.0, 0.0, 3)
    assert q.position == 0.0 and q.velocity == 0.0


# ---- the explicit step must resolve the damped pre-sliding mode -------------------------
def test_a_physics_rate_too_low_for_the_presliding_mode_is_a_one_line_error():
    m = load_plant('ballscrew').model.replace(mass=0.2)  # ω_n 7.8 krad/s, σ/M 86 000 1/s
    with pytest.raises(ParameterError) as exc:
        Plant(m, physics_rate=10_000.0)
    msg = str(exc.value)
    assert '\n' not in msg and 'physics_rate' in msg and 'unstable' in msg
    need = int(msg.rsplit('>= ', 1)[1].split()[0])
    assert 10_000 < need < 60_000
    # the rate it names does hold the axis: a force step rings down to Σk·x = f
    p = Plant(m, sensors=IDEAL, physics_rate=float(need))
    p.step(0.2 * FS / m.input_gain, 2000 / need)
    assert p.position == pytest.approx(0.2 * FS / m.get('presliding').stiffness, rel=1e-3)
    # while the last rate the check refused really does blow up (what it prevents)
    P = pack_params(m, IDEAL, 1.25 / need)
    S = initial_state(P)
    K.plant_advance(P, S, 0.2 * FS / m.input_gain, 0.0, 2000)
    assert not abs(S[K.S_X]) < 1.0                       # diverged (or NaN)
