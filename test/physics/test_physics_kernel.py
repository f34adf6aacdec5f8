"""The compiled plant kernel against analytic mechanics (DESIGN.md §3).

Stick–slip (Karnopp switch), reversal without dwell, energy balance of friction, the
linear part of both paper plants against their transfer functions (Tan 2002 eq. 1–7,
Chiew eq. 1 with dead time), saturation, delay, backlash, quantisation and noise.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from physics_helpers import DT, IDEAL, model, plant, trace
from scipy import integrate, optimize, signal

from motor_comp.physics import Plant, Sensors, ballscrew_model, load_plant, make_effect
from motor_comp.physics.effects.stribeck import stribeck_magnitude

STICK = (('coulomb', {'fc': 10.0}), ('stribeck', {'fs': 15.0, 'vs': 0.01, 'delta': 1.0}))


# ---- stick–slip --------------------------------------------------------------------
@pytest.mark.parametrize('u', [14.99, -14.99])
def test_push_just_below_breakaway_does_not_move(u):
    p = plant(model(*STICK, mass=2.0), x0=0.0123)
    p.step(u, 1.0)                       # 1 s in one call: 10 000 physics steps
    assert p.position == 0.0123           # exactly unchanged
    assert p.velocity == 0.0
    assert p.stuck
    assert p.friction_force == u          # static friction balances the push


@pytest.mark.parametrize('u', [15.01, -15.01])
def test_push_just_above_breakaway_moves(u):
    p = plant(model(*STICK, mass=2.0))
    p.step(u, 1.0)
    d = math.copysign(1.0, u)
    # friction lies between fc and fs while sliding: bounds on the travelled distance
    assert 0.5 * (abs(u) - 15.0) / 2.0 <= d * p.position <= 0.5 * (abs(u) - 10.0) / 2.0
    assert d * p.velocity > 0.0 and not p.stuck


@pytest.mark.parametrize('u, moves', [(15.9, False), (16.1, True), (-13.9, False),
                                      (-14.1, True)])
def test_asymmetric_breakaway_levels(u, moves):
    # fs± = fs ± dfc/2 = 16 N forward, 14 N backward
    p = plant(model(*STICK, ('asymmetry', {'dfc': 2.0}), mass=2.0))
    p.step(u, 0.2)
    assert (p.position != 0.0) is moves


def test_rest_without_force_stays_rest_even_with_an_overfitted_asymmetry():
    # |dfc| > 2·fc makes fc− negative (not dissipative, but a fit may produce it): the
    # force laws still give zero force at v = 0, so the axis must not start on its own
    p = plant(model(('coulomb', {'fc': 1.0}), ('asymmetry', {'dfc': 4.0})), x0=0.5)
    p.step(0.0, 0.5)
    assert (p.position, p.velocity) == (0.5, 0.0)


def test_ripple_and_load_count_in_the_breakaway_force():
    # at x0 the ripple pulls with -4 N; 12 N command + 4 N ripple + 0 load breaks 15 N
    m = model(*STICK, ('ripple', {'period': 0.02, 'harmonics': [[4.0, 0.0]]}), mass=2.0)
    x0 = 0.015                                     # sin(2π·0.75) = -1: ripple = -4 N
    p = plant(m, x0=x0)
    p.step(12.0, 0.1)
    assert p.position > x0
    p = plant(m, x0=x0)
    p.step(12.0, 0.1, f_ext=2.0)                   # the load takes 2 N: 14 N < 15 N
    assert p.position == x0
    assert p.friction_force == pytest.approx(14.0, abs=1e-12)


def test_decelerating_axis_comes_to_rest_and_stays_without_chattering():
    m = model(*STICK, ('viscous', {'fv': 5.0}), mass=2.0)
    p = plant(m, v0=0.05)
    tr = trace(p, 4.0, 20000)            # 4 N forward push < fc: decelerates, then holds
    stop = int(np.argmax(tr['v'] == 0.0))
    assert stop > 0
    assert np.all(np.diff(tr['v'][:stop + 1]) < 0.0)      # monotone, never below zero
    assert np.all(tr['v'][stop:] == 0.0)
    assert np.all(tr['x'][stop:] == tr['x'][stop])
    assert np.all(tr['friction'][stop + 1:] == 4.0)        # static friction = net force


def test_reversal_under_a_strong_force_has_no_dwell():
    # Coulomb only: decelerate at (30+10)/1, stop at t1 = v0/40, then accelerate back at
    # (30-10)/1.  Piecewise constant acceleration: RK4 with the event handled is exact.
    fc, u, v0 = 10.0, -30.0, 0.0123
    p = plant(model(('coulomb', {'fc': fc})), v0=v0)
    tr = trace(p, u, 100)
    t1 = v0 / (fc - u)
    x1 = 0.5 * v0 * t1
    t = tr['t']
    after = t > t1
    v_ref = np.where(after, (u + fc) * (t - t1), v0 + (u - fc) * t)
    x_ref = np.where(after, x1 + 0.5 * (u + fc) * (t - t1) ** 2,
                     v0 * t + 0.5 * (u - fc) * t ** 2)
    np.testing.assert_allclose(tr['v'], v_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(tr['x'], x_ref, rtol=0, atol=1e-12)


def test_frictionless_oscillator_keeps_its_period_and_amplitude():
    # no friction at all: the zero-velocity switch must not pin the mass at the turns
    w = 2.0 * math.pi * 10.0
    p = plant(model(('spring', {'k': w * w})), x0=0.01)
    tr = trace(p, 0.0, 10000)
    err = np.max(np.abs(tr['x'] - 0.01 * np.cos(w * tr['t'])))
    assert err < 1e-6 * 0.01


def test_coulomb_oscillator_loses_2fc_over_k_per_half_cycle_and_sticks():
    # classic result: each half cycle lasts π/ω and shrinks the excursion by 2·fc/k;
    # motion stops at the first turn inside the stiction band |x| <= fs/k (fs = fc)
    w, fc, x0 = 2.0 * math.pi * 10.0, 20.0, 0.05
    k = w * w
    p = plant(model(('coulomb', {'fc': fc}), ('spring', {'k': k})), x0=x0)
    tr = trace(p, 0.0, 6000)
    turns = [x0]
    while abs(turns[-1]) > fc / k:
        turns.append(-(turns[-1] - math.copysign(2.0 * fc / k, turns[-1])))
    half = math.pi / w
    for i, xt in enumerate(turns[1:], start=1):
        j = int(round(i * half / DT)) - 1
        window = tr['x'][max(j - 3, 0):j + 4]
        extreme = window.max() if xt > 0 else window.min()
        assert extreme == pytest.approx(xt, abs=2e-6)
    rest = tr['x'][-1]
    assert rest == pytest.approx(turns[-1], abs=2e-6)
    t_stop = (len(turns) - 1) * half
    assert np.all(tr['x'][tr['t'] > t_stop + 0.002] == rest)
    assert np.all(tr['v'][tr['t'] > t_stop + 0.002] == 0.0)


# ---- energy --------------------------------------------------------------------------
def test_coulomb_coast_stops_where_and_when_expected():
    mass, v0, fc = 2.0, 0.3, 6.0            # deceleration 3 m/s²: 0.1 s, 15 mm
    p = plant(model(('coulomb', {'fc': fc}), mass=mass), v0=v0)
    tr = trace(p, 0.0, 2000)
    assert tr['x'][-1] == pytest.approx(mass * v0 ** 2 / (2.0 * fc), abs=1e-12)
    stop = int(np.argmax(tr['v'] == 0.0))
    assert tr['t'][stop] == pytest.approx(mass * v0 / fc, abs=DT)
    assert np.all(tr['v'][stop:] == 0.0)


def test_friction_dissipates_kinetic_energy_monotonically_and_exactly():
    fc, fs, vs, delta, fv, mass, v0 = 2.0, 3.0, 0.05, 2.0, 4.0, 0.5, 0.4
    m = model(('coulomb', {'fc': fc}), ('stribeck', {'fs': fs, 'vs': vs, 'delta': delta}),
              ('viscous', {'fv': fv}), mass=mass)
    tr = trace(plant(m, v0=v0), 0.0, 4000)
    v = np.concatenate([[v0], tr['v']])
    t = np.concatenate([[0.0], tr['t']])
    ke = 0.5 * mass * v ** 2
    assert np.all(np.diff(ke) <= 0.0)
    assert ke[-1] == 0.0                  # came to rest (Coulomb stops it in finite time)
    power = (stribeck_magnitude(np.abs(v), fc, fs, vs, delta) * np.sign(v) + fv * v) * v
    work = integrate.cumulative_trapezoid(power, t, initial=0.0)
    np.testing.assert_allclose(ke[0] - ke, work, rtol=0, atol=2e-4 * ke[0])


def test_presliding_oscillation_does_not_gain_energy():
    # ball-screw GMS without any damping (no micro-damping either): the elastic
    # pre-sliding oscillation after a step force may only decay (element slip
    # dissipates), never grow
    cfg = load_plant('ballscrew')
    m = cfg.model.without('viscous', 'delay').replace(damping=0.0)
    m = m.with_effect(m.get('presliding').replace(sigma=()))
    tr = trace(plant(m), 0.2 * 18.0 / 50.0, 10000)      # 0.2·fs of force, 1 s
    first = np.ptp(tr['x'][:1000])
    last = np.ptp(tr['x'][-1000:])
    assert 0.0 < last <= first * (1.0 + 1e-9)


# ---- GMS inside the kernel ----------------------------------------------------------
def test_presliding_stiffness_in_the_plant_is_sum_of_element_stiffnesses():
    cfg = load_plant('ballscrew')
    m = cfg.model.without('delay')
    f = 0.2 * 18.0                        # small enough that every element sticks
    tr = trace(plant(m), f / m.input_gain, 20000)
    k_total = sum(m.get('presliding').k)
    assert tr['x'][-1] == pytest.approx(f / k_total, rel=0.01)
    assert abs(tr['v'][-1]) < 1e-6


@pytest.mark.parametrize('u', [1.0, -0.7, 0.5])
def test_gms_and_static_plants_reach_the_same_sliding_speed(u):
    # at constant velocity GMS friction is the Stribeck curve: both friction models
    # must give the speed solving k_f·u = s(v) + (σ + B·M)·v
    cfg = load_plant('ballscrew')
    gms = cfg.model.without('delay')
    static = gms.without('presliding')
    fc, fs, vs, delta = gms.stribeck_curve_params()
    c_visc = gms.fv + gms.damping

    def balance(v):
        return gms.input_gain * u - math.copysign(1.0, u) * stribeck_magnitude(
            abs(v), fc, fs, vs, delta) - c_visc * v

    v_ref = optimize.brentq(balance, 1e-9 * u, 1.0 * u)
    for m in (gms, static):
        p = plant(m)
        p.step(u, 2.0)                  # 20 mechanical time constants M/(σ + B·M)
        assert p.velocity == pytest.approx(v_ref, rel=1e-6)


@pytest.mark.parametrize('u', [20.0, -20.0])
def test_asymmetry_acts_on_the_dynamics_with_and_without_gms(u):
    # fc± = 10 ± 2 N: the speed under ±20 N is (20 − 12)/100 forward, (20 − 8)/100 back
    base = (('coulomb', {'fc': 10.0}), ('viscous', {'fv': 100.0}),
            ('asymmetry', {'dfc': 4.0}))
    gms = base + (('presliding', {'alpha': [0.5, 0.5], 'k': [1e5, 1e4], 'C': 10000.0,
                                  'sigma': [30.0, 3.0]}),)
    v_ref = 0.08 if u > 0 else -0.12
    for effects in (base, gms):
        p = plant(model(*effects))
        p.step(u, 0.5)
        assert p.velocity == pytest.approx(v_ref, rel=1e-6)
        assert p.friction_force == pytest.approx(u - 100.0 * v_ref, rel=1e-6)


# ---- the linear part of the paper plants ----------------------------------------------
def _positions(p: Plant, u: float, n: int, dt: float = 1e-3) -> tuple[np.ndarray, ...]:
    t, x, v = np.empty(n), np.empty(n), np.empty(n)
    for j in range(n):
        p.step(u, dt)
        t[j], x[j], v[j] = p.time, p.load_position, p.velocity
    return t, x, v


def test_pmlm_linear_part_is_tan_first_order_velocity_response():
    cfg = load_plant('pmlm')
    kf, r, ke, mass = 130.0, 8.6, 123.0, 5.4          # DESIGN.md §3 table
    a, b = kf * ke / (r * mass), kf / (r * mass)      # Tan 2002 eq. 7
    lin = cfg.model.without('coulomb', 'stribeck', 'viscous', 'ripple')
    u = 3.0
    t, x, v = _positions(Plant(lin, sensors=IDEAL), u, 50)
    v_ref = b / a * u * (1.0 - np.exp(-a * t))
    x_ref = b / a * u * (t - (1.0 - np.exp(-a * t)) / a)
    assert np.max(np.abs(v - v_ref)) < 1e-6 * np.max(np.abs(v_ref))
    assert np.max(np.abs(x - x_ref)) < 1e-6 * np.max(np.abs(x_ref))


@pytest.mark.parametrize('c_per_s2', [0.0, 400.0])
def test_ballscrew_linear_part_is_chiew_transfer_function_with_dead_time(c_per_s2):
    a_gain, b_damp, tau, kf = 2.0, 2.0, 0.00129, 50.0       # DESIGN.md §3 table
    lin = ballscrew_model(A_m_per_V_s2=a_gain, B_per_s=b_damp, C_per_s2=c_per_s2,
                          force_constant_N_per_V=kf,
                          effects=(make_effect('delay', {'tau': tau}),))
    if c_per_s2 == 0.0:   # the packaged default must be this same plant
        default = load_plant('ballscrew').model.without(
            'coulomb', 'stribeck', 'viscous', 'presliding')
        assert default == lin
    u = 1.5
    t, y, _ = _positions(Plant(lin, sensors=IDEAL), u, 500)
    fine = np.arange(0.0, 0.6, 1e-5)
    _, y_step = signal.step(signal.lti([a_gain * u], [1.0, b_damp, c_per_s2]), T=fine)
    y_ref = np.interp(t - tau, fine, y_step, left=0.0)     # e^{−τs}: shift by τ
    assert np.max(np.abs(y - y_ref)) < 1e-5 * np.max(np.abs(y_ref))


def test_delay_shifts_the_response_by_tau_within_one_physics_step():
    tau = 0.00129
    fast = ballscrew_model(A_m_per_V_s2=2.0, B_per_s=2.0, C_per_s2=0.0,
                           force_constant_N_per_V=50.0)
    slow = fast.with_effect(make_effect('delay', {'tau': tau}))
    t, x0, v0 = _positions(Plant(fast, sensors=IDEAL), 1.0, 100, dt=DT)
    _, x1, _ = _positions(Plant(slow, sensors=IDEAL), 1.0, 100, dt=DT)
    first = int(np.argmax(x1 > 0.0))
    assert t[first] == pytest.approx(math.ceil(tau / DT) * DT, abs=1e-12)
    shifted = np.interp(t - tau, t, x0, left=0.0)
    assert np.max(np.abs(x1 - shifted)) <= np.max(np.abs(v0)) * DT


def test_saturation_clamps_the_applied_command():
    lin = load_plant('pmlm').model.without('coulomb', 'stribeck', 'viscous', 'ripple')
    sens = Sensors(encoder_resolution=0.0, saturation=2.0)
    for u, u_sat in ((10.0, 2.0), (-10.0, -2.0), (1.5, 1.5)):
        clamped = Plant(lin, sensors=sens)
        free = Plant(lin, sensors=IDEAL)
        for _ in range(20):
            clamped.step(u, 1e-3)
            free.step(u_sat, 1e-3)
        assert clamped.applied_command == u_sat
        assert clamped.position == free.position


# ---- output side: backlash, encoder, noise --------------------------------------------
def test_backlash_load_lags_by_half_width_and_dead_band_is_width():
    w = 2e-4
    m = model(('viscous', {'fv': 10.0}), ('backlash', {'width': w}))
    tr = trace(plant(m), lambda t: 1.0 if t < 0.2 else -1.0, 6000)
    x, xl = tr['x'], tr['xl']
    rev = int(np.argmax(x))
    fwd = slice(0, rev + 1)
    # starting centred in the gap: the load stays until the motor took up w/2
    np.testing.assert_array_equal(xl[fwd], np.where(x[fwd] > w / 2, x[fwd] - w / 2, 0.0))
    assert x[rev] - xl[rev] == pytest.approx(w / 2, abs=1e-15)
    back = slice(rev, None)
    in_band = x[back] >= x[rev] - w
    assert np.all(xl[back][in_band] == xl[rev])            # dead band: exactly w of travel
    np.testing.assert_allclose(xl[back][~in_band], x[back][~in_band] + w / 2, rtol=0,
                               atol=1e-15)
    assert np.count_nonzero(~in_band) > 1000               # and the test saw both phases


def test_measured_positions_are_integer_multiples_of_the_resolution():
    q = 1e-6
    lin = model(('viscous', {'fv': 50.0}), mass=2.0)
    p = plant(lin, sensors=Sensors(encoder_resolution=q))
    ys = []
    for j in range(300):
        p.step(0.5 * math.sin(0.05 * j), 1e-3)
        y = p.measure(1e-3).position
        assert abs(y - p.load_position) <= q / 2 + 1e-15
        ys.append(y)
    counts = np.asarray(ys) / q
    assert np.max(np.abs(counts - np.round(counts))) < 1e-6
    assert len(np.unique(np.round(counts))) > 50           # the axis really moved


def test_measurement_noise_has_the_configured_std_and_is_seeded():
    sd = 2e-6
    sens = Sensors(encoder_resolution=0.0, noise_std=sd)
    m = model(('coulomb', {'fc': 5.0}))

    def readings(seed: int) -> np.ndarray:
        p = plant(m, sensors=sens, seed=seed, x0=0.1)
        return np.array([p.measure(1e-3).position for _ in range(20000)])

    y = readings(7)
    assert np.std(y) == pytest.approx(sd, rel=0.02)              # ±4 standard errors
    assert abs(np.mean(y) - 0.1) < 4.0 * sd / math.sqrt(y.size)
    np.testing.assert_array_equal(y, readings(7))
    assert not np.array_equal(y, readings(8))
