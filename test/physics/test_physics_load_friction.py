"""Load-dependent dry friction ``fc + mu·|F_in|`` in the plant kernel and the model laws.

Issue 23 item 3 (DESIGN.md §6 ``load_friction {mu}``): constant-velocity sweeps under a
force-controlled drive measure the sliding friction from the motion alone (force
balance with the known drive, load and viscous forces) and find ``fc + mu·|F_in|`` at
every load, in both directions, with a voltage drive's back-EMF inside ``F_in`` and with
the delayed command; break-away from rest needs ``(fs + load)/(1 − mu)``; the inverse
dynamics :func:`load_friction_drive_force` holds a constant speed in the plant; the
model's ``effect_forces`` is the law the kernel integrates.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from physics_helpers import DT, model, plant, trace

from motor_comp.errors import ParameterError
from motor_comp.physics import kernel as K
from motor_comp.physics.effects import make_effect
from motor_comp.physics.effects.load_friction import load_friction_drive_force
from motor_comp.physics.plant import Sensors, pack_params

FC, FS, FV, MU = 5.0, 8.0, 40.0, 0.25
GMS = ('presliding', {'alpha': [0.6, 0.4], 'k': [2e6, 4e5], 'C': 6000.0,
                      'sigma': [800.0, 160.0]})


def _steady_friction(m, u, f_ext, *, seconds=1.0, window=0.2):
    """Run a constant command; return (speed [m/s], F_in [N], friction [N]) at steady state.

    The speed is the slope of the position over the last ``window`` seconds, the drive
    force ``F_in`` the model's own ``input_force`` at that speed, and the friction what
    the force balance leaves of it: ``F_in − f_ext − fv·v`` (the axis does not accelerate).
    """
    p = plant(m)
    tr = trace(p, u, int(round(seconds / DT)), f_ext=f_ext)
    k = int(round(window / DT))
    v = (tr['x'][-1] - tr['x'][-1 - k]) / (tr['t'][-1] - tr['t'][-1 - k])
    assert abs(tr['v'][-1] - v) <= 1e-9 * abs(v)      # at steady state: no acceleration
    f_in = float(m.input_force(u, v))
    return v, f_in, f_in - f_ext - m.fv * v


@pytest.mark.parametrize('gms', [False, True], ids=['static', 'gms'])
@pytest.mark.parametrize('u, load', [(60.0, 0.0), (150.0, 40.0), (300.0, 120.0),
                                     (-90.0, -20.0), (-240.0, 30.0)])
def test_sliding_friction_is_fc_plus_mu_times_the_drive_force(u, load, gms):
    effects = [('coulomb', {'fc': FC}), ('viscous', {'fv': FV}), ('load_friction', {'mu': MU})]
    if gms:
        effects.append(GMS)
    m = model(*effects, mass=0.5)           # time constant M/fv = 12.5 ms: steady in 1 s
    v, f_in, friction = _steady_friction(m, u, load)
    assert f_in == u                                   # force drive: F_in is the command
    expected = FC + MU * abs(f_in)
    assert math.copysign(1.0, v) == math.copysign(1.0, u - load)
    # both directions: the friction opposes the motion with the load-raised level
    assert friction * math.copysign(1.0, v) == pytest.approx(expected, rel=1e-7)
    # the analytic steady speed of the force balance
    assert v == pytest.approx((u - load - math.copysign(expected, v)) / FV, rel=1e-7)


def test_load_friction_uses_the_drive_force_after_back_emf_and_damping():
    # voltage drive (PMLM form): F_in = gain·(u − bemf·v) − damping·v, not gain·u
    gain, bemf, damping = 15.0, 2.0, 10.0
    m = model(('coulomb', {'fc': FC}), ('viscous', {'fv': FV}), ('load_friction', {'mu': MU}),
              mass=0.5, input_gain=gain, back_emf=bemf, damping=damping)
    u, load = 12.0, 20.0
    v, f_in, friction = _steady_friction(m, u, load)
    assert f_in == pytest.approx(gain * (u - bemf * v) - damping * v, rel=1e-12)
    assert friction == pytest.approx(FC + MU * abs(f_in), rel=1e-7)
    # the command alone would have raised the level by mu·gain·u: newtons more
    assert abs(MU * gain * u - MU * f_in) > 1.0


def test_load_friction_follows_the_delayed_command():
    # sliding at steady speed, the command steps up at t1; the drive force and the load
    # friction change together τ later, so the axis keeps its speed until then
    tau = 0.0021
    m = model(('coulomb', {'fc': FC}), ('viscous', {'fv': FV}), ('load_friction', {'mu': MU}),
              ('delay', {'tau': tau}), mass=0.5)
    t1 = 1.0
    tr = trace(plant(m), lambda t: 60.0 if t < t1 else 200.0, int(round(1.5 / DT)))
    v_ss = (60.0 - FC - MU * 60.0) / FV
    before = (tr['t'] > t1 - 0.05) & (tr['t'] <= t1 + tau - DT)
    np.testing.assert_allclose(tr['v'][before], v_ss, rtol=1e-9)
    # then it accelerates towards the new balance (F_in = 200 N)
    assert tr['v'][-1] == pytest.approx((200.0 - FC - MU * 200.0) / FV, rel=1e-6)


@pytest.mark.parametrize('d, load', [(1.0, 0.0), (1.0, 20.0), (1.0, 60.0), (-1.0, 0.0),
                                     (-1.0, -35.0)])
def test_breakaway_under_load_needs_fs_plus_load_over_one_minus_mu(d, load):
    # the drive first holds the load (F_in = load: no net force), then ramps slowly in
    # direction d; the axis stays put exactly until |F_in − load| > fs + mu·|F_in|, i.e.
    # F_in = d·(fs + d·load)/(1 − mu): the band widens with the drive force
    m = model(('coulomb', {'fc': FC}), ('stribeck', {'fs': FS, 'vs': 0.01, 'delta': 1.0}),
              ('viscous', {'fv': FV}), ('load_friction', {'mu': MU}), mass=2.0)
    rate = 50.0                                                   # N/s
    expected = d * (FS + d * load) / (1.0 - MU)
    n = int(round(abs(expected - load) * 1.2 / rate / DT))
    tr = trace(plant(m, x0=0.01), lambda t: load + d * rate * t, n, f_ext=load)
    moved = np.flatnonzero(tr['x'] != 0.01)
    assert moved.size > 0 and d * (tr['x'][-1] - 0.01) > 0.0
    f_break = load + d * rate * (tr['t'][moved[0]] - DT)  # command of the first moving step
    assert f_break == pytest.approx(expected, abs=rate * DT * 1.01)
    # without the load term it would break away at load + d·fs: newtons earlier
    assert abs(f_break - (load + d * FS)) > 2.0


@pytest.mark.parametrize('factor, moves', [(0.999, False), (1.001, True)])
def test_a_stuck_screw_under_a_large_drive_force_holds_more(factor, moves):
    m = model(('coulomb', {'fc': FC}), ('stribeck', {'fs': FS, 'vs': 0.01, 'delta': 1.0}),
              ('load_friction', {'mu': 0.6}), mass=2.0)
    u = factor * FS / (1.0 - 0.6)                       # 20 N against a band of 8 + 12 N
    p = plant(m, x0=0.05)
    p.step(u, 0.5)
    assert (p.position != 0.05) is moves
    if not moves:
        assert p.stuck and p.friction_force == u         # static friction balances it


@settings(max_examples=200, deadline=None)
@given(f_other=st.floats(-1e4, 1e4), d=st.sampled_from([-1.0, 0.0, 1.0]),
       level=st.floats(0.0, 500.0), mu=st.floats(0.0, 0.95))
def test_drive_force_inverse_solves_the_force_balance(f_other, d, level, mu):
    f = load_friction_drive_force(f_other, d, level, mu)
    residual = f - f_other - d * (level + mu * abs(f))
    assert abs(residual) <= 1e-12 * (abs(f_other) + level + abs(f) + 1.0)


@pytest.mark.parametrize('v_target, load', [(0.2, 30.0), (-0.15, 10.0), (0.1, -80.0)])
def test_inverse_drive_force_holds_the_speed_in_the_plant(v_target, load):
    # the drive force from the inverse dynamics (what a compensation would send) keeps
    # a sliding axis at its speed: the kernel and the inverse are the same law
    m = model(('coulomb', {'fc': FC}), ('viscous', {'fv': FV}), ('load_friction', {'mu': MU}),
              mass=2.0)
    d = math.copysign(1.0, v_target)
    u = load_friction_drive_force(load + FV * v_target, d, FC, MU)
    p = plant(m, v0=v_target)
    tr = trace(p, u, 5000, f_ext=load)
    np.testing.assert_allclose(tr['v'], v_target, rtol=1e-12)


def test_effect_forces_are_the_law_the_kernel_integrates():
    # inverse model on the plant's own motion: M·a = F_in − Σ F_k with F_in given
    m = model(('coulomb', {'fc': FC}), ('stribeck', {'fs': FS, 'vs': 0.02, 'delta': 2.0}),
              ('viscous', {'fv': FV}), ('load_friction', {'mu': MU}),
              ('asymmetry', {'dfc': 2.0, 'dfv': 5.0}), mass=5.4, input_gain=15.1,
              back_emf=2.0, damping=5.0)

    def u_of_t(t):
        return 14.0 * math.sin(2.0 * math.pi * 1.0 * t)

    tr = trace(plant(m), u_of_t, 20000)
    x = np.concatenate([[0.0], tr['x']])
    v = np.concatenate([[0.0], tr['v']])
    acc = np.diff(v) / DT
    xm, vm = 0.5 * (x[1:] + x[:-1]), 0.5 * (v[1:] + v[:-1])
    f_in = m.input_force(np.array([u_of_t(t - DT) for t in tr['t']]), vm)
    forces = m.effect_forces(xm, vm, f_in=f_in)
    assert set(forces) >= {'coulomb', 'load_friction'}
    np.testing.assert_array_equal(forces['load_friction'], MU * np.abs(f_in) * np.sign(vm))
    sliding = (np.abs(v[1:]) > 1e-3) & (np.abs(v[:-1]) > 1e-3)
    assert np.count_nonzero(sliding) > 0.8 * len(sliding)
    err = np.abs(m.mass * acc - (f_in - sum(forces.values())))[sliding]
    assert err.max() < 2e-4 * np.abs(f_in).max()
    # without the load term the balance is off by mu·|F_in|: newtons
    rest = sum(f for name, f in forces.items() if name != 'load_friction')
    off = np.abs(m.mass * acc - (f_in - rest))
    assert off[sliding].max() > 100.0 * err.max()
    assert m.static_force(xm, vm, f_in=f_in) == pytest.approx(sum(forces.values()))


def test_effect_forces_without_the_drive_force_is_a_one_line_error():
    m = model(('coulomb', {'fc': FC}), ('load_friction', {'mu': MU}))
    x = np.zeros(3)
    for call in (lambda: m.effect_forces(x, x), lambda: m.static_force(x, x),
                 lambda: m.dry_friction_shift(x)):
        with pytest.raises(ParameterError, match='F_in') as info:
            call()
        assert '\n' not in str(info.value)


def test_gms_with_load_friction_matches_force_along_with_the_shift():
    # the kernel's GMS curve s(v) is raised by mu·|F_in| at each step's end; the model's
    # presliding.force_along with the same per-sample shift gives the same friction
    m = model(('coulomb', {'fc': 12.0}), ('stribeck', {'fs': 18.0, 'vs': 1e-3, 'delta': 1.0}),
              ('viscous', {'fv': 200.0}), ('load_friction', {'mu': 0.3}),
              ('presliding', {'alpha': [0.45, 0.30, 0.15, 0.10], 'k': [8e6, 3e6, 1e6, 3e5],
                              'C': 12000.0}),
              mass=25.0, input_gain=50.0, damping=50.0)

    def u_of_t(t):
        return 1.6 * math.sin(2.0 * math.pi * 2.0 * t)

    tr = trace(plant(m), u_of_t, 10000)
    x = np.concatenate([[0.0], tr['x']])
    v = np.concatenate([[0.0], tr['v']])
    f_in = m.input_force(np.concatenate([[0.0], tr['ueff']]), v)
    forces = m.effect_forces(x, v, dt=DT, f_in=f_in)
    assert set(forces) == {'viscous', 'presliding'}   # GMS carries all dry friction
    err = np.abs(forces['presliding'][1:] - tr['friction'])
    assert np.median(err) < 0.01
    assert np.max(err) < 0.5
    # the friction really was load-raised: beyond fs while sliding at the peak drive
    assert np.max(np.abs(tr['friction'])) > 12.0 + 0.3 * 0.5 * 50.0 * 1.6
    without = m.without('load_friction').effect_forces(x, v, dt=DT)['presliding'][1:]
    assert np.max(np.abs(without - tr['friction'])) > 5.0


def test_load_friction_needs_coulomb_one_line():
    with pytest.raises(ParameterError, match="'load_friction' needs 'coulomb'") as info:
        model(('viscous', {'fv': 1.0}), ('load_friction', {'mu': 0.1}))
    assert '\n' not in str(info.value)
    model(('coulomb', {'fc': 0.0}), ('load_friction', {'mu': 0.1}))   # fc = 0 is a level


def test_regressor_column_reproduces_the_force():
    e = make_effect('load_friction', {'mu': 0.35})
    rng = np.random.default_rng(2)
    v, f_in = rng.normal(size=200), rng.normal(0.0, 100.0, 200)
    col = e.regressors(None, v, f_in=f_in)
    assert col.shape == (200, 1)
    np.testing.assert_allclose(col[:, 0] * 0.35, e.force(None, v, f_in=f_in), rtol=1e-15)


def test_the_kernel_gets_mu_in_its_slot():
    # the packed coefficient is the effect's; an axis without it packs 0 (plain path)
    m = model(('coulomb', {'fc': FC}), ('load_friction', {'mu': MU}))
    assert pack_params(m, Sensors(), DT)[K.P_LF_MU] == MU
    assert pack_params(m.without('load_friction'), Sensors(), DT)[K.P_LF_MU] == 0.0
