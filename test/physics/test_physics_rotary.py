"""Rotary axes and the gravity effect (issue 11 item 4): kernel, units, model file, errors."""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from scipy.special import ellipk

from motor_comp.errors import ModelFileError
from motor_comp.physics import AxisModel, Plant, make_effect, plant_from_dict
from motor_comp.physics import kernel as K
from motor_comp.physics.axis import AxisKind, Units
from motor_comp.physics.effects import EFFECTS, BOTH_AXES, Effect
from motor_comp.physics.effects.gravity import Gravity, gravity_torque

from physics_helpers import DT, IDEAL

J = 0.5       # inertia [kg·m²]
MGL = 2.0     # [N·m]  → small-oscillation period 2π·sqrt(J/mgl) = π s
Q0 = 0.3      # [rad]


def _pendulum(theta0: float, *, duration: float, **extra) -> tuple[np.ndarray, ...]:
    """Free swing from rest at ``q0 + theta0`` in the compiled kernel; (t, q, ω) per step."""
    effects = (make_effect('gravity', {'mgl': MGL, 'q0': Q0}),) + tuple(
        make_effect(n, p) for n, p in extra.items())
    m = AxisModel(mass=J, input_gain=1.0, input='force', axis='rotary', effects=effects)
    p = Plant(m, sensors=IDEAL, physics_rate=1.0 / DT, x0=Q0 + theta0)
    n = int(round(duration / DT))
    t = np.empty(n)
    q = np.empty(n)
    w = np.empty(n)
    S, P = p.state, p.params
    for j in range(n):
        K.plant_advance(P, S, 0.0, 0.0, 1)
        t[j], q[j], w[j] = S[K.S_T], S[K.S_X], S[K.S_V]
    return t, q, w


def _period(t: np.ndarray, y: np.ndarray) -> float:
    """Mean period [s] from the zero crossings of ``y`` (linear interpolation)."""
    i = np.flatnonzero(np.sign(y[:-1]) != np.sign(y[1:]))
    tc = t[i] - y[i] * (t[i + 1] - t[i]) / (y[i + 1] - y[i])
    assert len(tc) >= 4
    return 2.0 * float(np.mean(np.diff(tc)))


def test_gravity_pendulum_small_oscillation_period_is_2pi_sqrt_j_over_mgl():
    t, q, _ = _pendulum(0.02, duration=7.0)
    t0 = 2.0 * math.pi * math.sqrt(J / MGL)
    # amplitude correction (1 + θ²/16) is 2.5e-5 here; the tolerance fails a 0.1 % error
    assert _period(t, q - Q0) == pytest.approx(t0, rel=2e-4)


def test_gravity_pendulum_large_swing_matches_the_elliptic_integral_and_keeps_energy():
    theta0 = 2.0                                     # [rad]: far from the linear regime
    t, q, w = _pendulum(theta0, duration=9.0)
    # exact period of the nonlinear pendulum: 4·sqrt(J/mgl)·K(sin²(θ0/2))
    exact = 4.0 * math.sqrt(J / MGL) * ellipk(math.sin(theta0 / 2.0) ** 2)
    assert exact / (2.0 * math.pi * math.sqrt(J / MGL)) > 1.3     # really non-linear
    assert _period(t, q - Q0) == pytest.approx(exact, rel=2e-4)
    energy = 0.5 * J * w ** 2 + MGL * (1.0 - np.cos(q - Q0))
    e0 = MGL * (1.0 - math.cos(theta0))
    assert np.max(np.abs(energy - e0)) < 1e-6 * e0
    # the swing turns at the same height on both sides (q0 ± θ0)
    assert np.max(q) == pytest.approx(Q0 + theta0, abs=1e-5)
    assert np.min(q) == pytest.approx(Q0 - theta0, abs=1e-5)


def test_gravity_with_coulomb_friction_comes_to_rest_inside_the_holding_band():
    fc = 0.5                                          # [N·m]
    t, q, w = _pendulum(1.0, duration=12.0, coulomb={'fc': fc})
    assert w[-1] == 0.0
    # held where gravity is within the static band: |mgl·sin(q − q0)| <= fc
    assert abs(MGL * math.sin(q[-1] - Q0)) <= fc + 1e-9
    # Coulomb damping of a pendulum loses ~4fc/mgl·(…) per cycle: the swing decays
    assert np.max(np.abs(q[-5000:] - Q0)) < 0.3


def test_gravity_law_effect_and_axis_forces_agree():
    q = np.linspace(-4.0, 4.0, 101)
    g = Gravity(mgl=MGL, q0=Q0)
    np.testing.assert_allclose(g.force(q), MGL * np.sin(q - Q0), rtol=0, atol=1e-13)
    assert gravity_torque(Q0 + math.pi / 2, MGL, Q0) == pytest.approx(MGL)
    # the regressor form: mgl·sin(q − q0) = (mgl cos q0)·sin q + (−mgl sin q0)·cos q
    a, b = MGL * math.cos(Q0), -MGL * math.sin(Q0)
    np.testing.assert_allclose(g.regressors(q) @ [a, b], g.force(q), atol=1e-12)
    back = Gravity.from_coefficients(a, b)
    assert (back.mgl, back.q0) == (pytest.approx(MGL), pytest.approx(Q0))
    m = AxisModel(mass=J, axis=AxisKind.ROTARY, effects=(g, make_effect('offset', {'f0': 1})))
    forces = m.effect_forces(q, np.zeros_like(q))
    np.testing.assert_allclose(forces['gravity'], g.force(q))
    np.testing.assert_allclose(m.static_force(q, q * 0), g.force(q) + 1.0)


def test_units_of_both_axis_kinds():
    lin = AxisModel(mass=2.0).units
    rot = AxisModel(mass=2.0, axis='rotary').units
    assert (lin.position, lin.velocity, lin.acceleration, lin.force, lin.mass, lin.viscous,
            lin.spring) == ('m', 'm/s', 'm/s²', 'N', 'kg', 'N·s/m', 'N/m')
    assert (rot.position, rot.velocity, rot.acceleration, rot.force, rot.mass, rot.viscous,
            rot.spring) == ('rad', 'rad/s', 'rad/s²', 'N·m', 'kg·m²', 'N·m·s/rad', 'N·m/rad')
    assert Units.of('rotary') is rot and rot.rotary and not lin.rotary
    # ripple period in cycles per revolution: a 2π/8 rad period is 8 cycles/rev
    assert rot.cycles_per_revolution(2 * math.pi / 8) == pytest.approx(8.0)
    assert lin.cycles_per_revolution(0.02) is None
    assert rot.period_text(2 * math.pi / 8) == '0.7854 rad (8 /rev)'
    assert rot.input_gain('current') == 'N·m/A' and lin.input_gain('voltage') == 'N/V'
    with pytest.raises(dataclasses.FrozenInstanceError):
        rot.force = 'N'


def test_rotary_model_file_round_trip(tmp_path):
    text = ('axis: rotary\ninput: current\ninput_gain: 0.9\nmass: 0.0123\neffects:\n'
            '  coulomb: {fc: 0.05}\n  viscous: {fv: 0.002}\n'
            '  ripple: {period: 0.2617993877991494, harmonics: [[0.01, 0.002]]}\n'
            '  gravity: {mgl: 1.5, q0: -0.2}\n')
    path = tmp_path / 'joint.yaml'
    path.write_text(text)
    m = AxisModel.load(path)
    assert m.axis is AxisKind.ROTARY and m.rotary and m.units.force == 'N·m'
    assert m.names == ('coulomb', 'viscous', 'ripple', 'gravity')
    assert m.get('gravity') == Gravity(mgl=1.5, q0=-0.2)
    d = m.to_dict()
    assert d['axis'] == 'rotary' and d['effects']['gravity'] == {'mgl': 1.5, 'q0': -0.2}
    out = tmp_path / 'again.yaml'
    m.save(out)
    assert AxisModel.load(out) == m
    assert out.read_text().startswith('axis: rotary\n')
    # a file without the key is linear, and is written back with the explicit default
    lin = AxisModel.from_dict({'mass': 1.0})
    assert lin.axis is AxisKind.LINEAR and lin.to_dict()['axis'] == 'linear'


def _one_line_error(data) -> str:
    with pytest.raises(ModelFileError) as exc:
        AxisModel.from_dict(data, source='m.yaml')
    msg = str(exc.value)
    assert '\n' not in msg and msg.startswith('m.yaml: ')
    return msg


def test_gravity_on_a_linear_axis_is_a_one_line_error_naming_both():
    for data in ({'mass': 1.0, 'effects': {'gravity': {'mgl': 1.0, 'q0': 0.0}}},
                 {'axis': 'linear', 'mass': 1.0, 'effects': {'gravity': {'mgl': 1.0}}}):
        msg = _one_line_error(data)
        assert "'gravity'" in msg and 'linear axis' in msg and 'offset' in msg


def test_unknown_axis_kind_is_a_one_line_error():
    msg = _one_line_error({'axis': 'spherical', 'mass': 1.0})
    assert 'axis' in msg and "'spherical'" in msg and 'rotary' in msg
    msg = _one_line_error({'axis': ['rotary'], 'mass': 1.0})
    assert 'axis must be one of' in msg


def test_linear_only_effect_on_a_rotary_axis_is_a_one_line_error(monkeypatch):
    # No effect of the vocabulary is linear-only (every law but gravity reads the same in
    # rad/N·m); the check is general, so it is exercised with a linear-only test effect.
    @dataclasses.dataclass(frozen=True)
    class Rail(Effect):
        name = 'rail'
        axes = frozenset({AxisKind.LINEAR})
        f: float = 1.0

    monkeypatch.setitem(EFFECTS, 'rail', Rail)
    monkeypatch.setattr('motor_comp.physics.axis.VOCABULARY',
                        tuple(EFFECTS), raising=True)
    assert AxisModel.from_dict({'mass': 1.0, 'effects': {'rail': {}}}).has('rail')
    msg = _one_line_error({'axis': 'rotary', 'mass': 1.0, 'effects': {'rail': {'f': 2.0}}})
    assert "'rail'" in msg and 'rotary axis' in msg and 'linear only' in msg
    # every real effect but gravity is valid on both axis kinds
    assert {n for n, c in EFFECTS.items() if c.axes != BOTH_AXES} == {'gravity', 'rail'}


def test_plant_file_may_be_rotary_and_simulates_gravity():
    cfg = plant_from_dict({'plant': 'pmlm', 'axis': 'rotary',
                           'motor': {'mass_kg': J, 'resistance_ohm': 1.0,
                                     'force_constant_N_per_A': 1.0, 'back_emf_V_s_per_m': 0.0},
                           'effects': {'gravity': {'mgl': MGL, 'q0': 0.0}}})
    assert cfg.model.rotary and cfg.model.get('gravity').mgl == MGL
    p = Plant(cfg.model, sensors=IDEAL, physics_rate=1.0 / DT, x0=0.0)
    # holding the load horizontal (q = π/2) takes u = mgl/k_f·R = 2 V
    p.state[K.S_X] = p.state[K.S_XL] = math.pi / 2
    p.step(MGL, 0.1)
    assert p.velocity == pytest.approx(0.0, abs=1e-9)
    with pytest.raises(ModelFileError, match='linear axis'):
        plant_from_dict({'plant': 'ballscrew',
                         'motor': {'A_m_per_V_s2': 2.0, 'B_per_s': 2.0, 'C_per_s2': 0.0,
                                   'force_constant_N_per_V': 50.0},
                         'effects': {'gravity': {'mgl': 1.0}}})


def test_gravity_with_cogging_both_act_and_the_ripple_report_is_the_ripple_alone():
    period = 2 * math.pi / 12                          # 12 cogging cycles per revolution
    effects = (make_effect('gravity', {'mgl': MGL, 'q0': Q0}),
               make_effect('ripple', {'period': period, 'harmonics': [[0.1, 0.05]]}))
    m = AxisModel(mass=J, input='force', axis='rotary', effects=effects)
    q = 1.0
    expected = MGL * math.sin(q - Q0) + float(m.get('ripple').force(np.array([q]))[0])
    p = Plant(m, sensors=IDEAL, physics_rate=1.0 / DT, x0=q)
    p.step(expected, 0.05)                             # the exact holding torque
    assert p.velocity == pytest.approx(0.0, abs=1e-9)
    assert p.position == pytest.approx(q, abs=1e-9)
    assert p.ripple_force == pytest.approx(expected - MGL * math.sin(q - Q0), abs=1e-12)
    # 1 % less torque and the load falls back towards q0
    p.step(0.99 * expected, 0.05)
    assert p.velocity < -1e-3
