"""Compensation of load- and position-dependent friction (issue 24, issue 23 item 3).

* The feedforward is the model's inverse dynamics with the raised dry level: for random
  models with ``load_friction`` and/or ``position_friction`` (static curve or GMS
  elements, with asymmetry, ripple, offset), the drive force the full compensation asks
  for balances the model's own forward laws (``AxisModel.effect_forces`` with that drive
  force: ``F_in = M·r̈ + Σ F_k(F_in)``) to rounding, and the ``effects`` terms are that
  ``Σ F_k`` (hypothesis).
* Every controller combination leaves out the carried terms at the *unshifted* level, so
  the shift stays (the GMS case against the physics module's shifted/unshifted element
  trajectories).
* Closed loop, ball-screw under N-PID on its slow sine: the model with the effect tracks
  far better than the same model without it (ratios measured, asserted with margin).
* Reporting: both effects are compensated, nothing in the vocabulary falls through, and
  a position table leaves ``position_friction`` out with the reason.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

from motor_comp.control import compensation as cm
from motor_comp.control.controller import make_controller
from motor_comp.control.simulator import simulate
from motor_comp.control.trajectories import make_trajectory
from motor_comp.errors import ModelFileError, ParameterError
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import VOCABULARY, make_effect

T = 1e-3
N = 1500
#: a worn ball-screw's extra effects: a screw efficiency of 80 %, and a tight spot and a
#: low spot over the default sine's stroke (0 … 6 mm)
LOAD = {'mu': 0.2}
SPOTS = {'x': [0.0, 0.0015, 0.003, 0.0045, 0.006], 'dfc': [0.0, 4.0, -3.0, 5.0, 0.0]}


def _finite(lo: float, hi: float) -> st.SearchStrategy[float]:
    return st.floats(lo, hi, allow_nan=False, allow_infinity=False)


@st.composite
def _models(draw, *, gms: bool) -> AxisModel:
    """A random model with load- and/or position-dependent friction."""
    fc = draw(_finite(0.5, 30.0))
    effects = {'coulomb': {'fc': fc},
               'stribeck': {'fs': fc + draw(_finite(0.0, 20.0)),
                            'vs': draw(_finite(1e-3, 0.05)), 'delta': draw(_finite(0.5, 3.0))},
               'viscous': {'fv': draw(_finite(0.0, 300.0))}}
    which = draw(st.sampled_from(['load', 'position', 'both']))
    if which != 'position':
        effects['load_friction'] = {'mu': draw(_finite(0.02, 0.9))}
    if which != 'load':
        n = draw(st.integers(2, 8))
        gaps = draw(st.lists(_finite(1e-3, 0.01), min_size=n - 1, max_size=n - 1))
        knots = np.concatenate([[draw(_finite(-0.02, 0.0))], gaps]).cumsum()
        values = draw(st.lists(_finite(-0.3 * fc, 2.0 * fc), min_size=n, max_size=n))
        effects['position_friction'] = {'x': knots.tolist(), 'dfc': values}
    if draw(st.booleans()):
        effects['asymmetry'] = {'dfc': draw(_finite(-0.5 * fc, 0.5 * fc)),
                                'dfv': draw(_finite(-20.0, 20.0))}
    if draw(st.booleans()):
        effects['ripple'] = {'period': draw(_finite(0.005, 0.05)),
                             'harmonics': [[draw(_finite(-5.0, 5.0)), draw(_finite(-5.0, 5.0))]]}
        effects['offset'] = {'f0': draw(_finite(-10.0, 10.0))}
    if gms:
        n = draw(st.integers(1, 4))
        alpha = np.array(draw(st.lists(_finite(0.1, 1.0), min_size=n, max_size=n)))
        k = draw(st.lists(_finite(1e5, 1e7), min_size=n, max_size=n))
        t_sigma = draw(_finite(0.0, 1.4e-3))     # micro-damping up to the ball-screw's
        effects['presliding'] = {'alpha': (alpha / alpha.sum()).tolist(), 'k': k,
                                 'C': draw(_finite(1e3, 5e4)),
                                 'sigma': [t_sigma * ki for ki in k]}
    try:
        return AxisModel.from_dict({'mass': draw(_finite(0.5, 50.0)),
                                    'input_gain': draw(_finite(1.0, 200.0)),
                                    'back_emf': draw(_finite(0.0, 150.0)),
                                    'damping': draw(_finite(0.0, 50.0)),
                                    'effects': effects})
    except ModelFileError:          # a spline that dips below −fc: not a model
        assume(False)
        raise


@st.composite
def _references(draw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Two sines over the knots' span: reversals, rests at the turning points, drive."""
    t = np.arange(N) * T
    a1, a2 = draw(_finite(1e-3, 0.02)), draw(_finite(0.0, 2e-3))
    f1, f2 = draw(_finite(0.3, 3.0)), draw(_finite(2.0, 15.0))
    r = a1 * np.sin(2 * np.pi * f1 * t) + a2 * np.sin(2 * np.pi * f2 * t + 1.0)
    # the velocity of each step (the GMS elements are driven by Δr = ṙ·T, as in the
    # physics module's trajectory), the acceleration anything consistent
    rv = np.concatenate([[0.0], np.diff(r) / T])
    return r, rv, np.gradient(rv, T)


def _check_balance(model: AxisModel, r, rv, ra) -> None:
    """Full and effects compensation against the model's forward laws."""
    gms = model.has('presliding')
    full = cm.from_model(model).force_along(r, rv, T, ra=ra, advance=False)
    f_in = full - model.damping * rv             # the drive force of AxisModel.input_force
    forces = model.effect_forces(r, rv, dt=T if gms else None, f_in=f_in)
    total = sum(forces.values())
    scale = 1.0 + np.max(np.abs(f_in))
    np.testing.assert_allclose(f_in, model.mass * ra + total, rtol=0, atol=1e-11 * scale)
    effects = cm.from_model(model, terms='effects').force_along(r, rv, T, ra=ra,
                                                                advance=False)
    np.testing.assert_allclose(effects, total, rtol=0, atol=1e-11 * scale)


@settings(max_examples=60, deadline=None)
@given(model=_models(gms=False), ref=_references())
def test_static_curve_compensation_is_the_inverse_dynamics(model, ref):
    _check_balance(model, *ref)


@settings(max_examples=60, deadline=None)
@given(model=_models(gms=True), ref=_references())
def test_gms_compensation_is_the_inverse_dynamics(model, ref):
    # the elements carry the raised level: effect_forces steps them along the shifted
    # curve (presliding.gms_trajectory_shifted, the level raised by dfc(r) + mu·|F_in|)
    _check_balance(model, *ref)


def _worn(gms: bool, **extra) -> AxisModel:
    effects = {'coulomb': {'fc': 12.0}, 'stribeck': {'fs': 18.0, 'vs': 0.02, 'delta': 1.0},
               'viscous': {'fv': 200.0}, 'offset': {'f0': 3.0}, 'load_friction': LOAD,
               'position_friction': {'x': [-0.02, 0.0, 0.02], 'dfc': [0.0, 6.0, -2.0]}}
    if gms:
        effects['presliding'] = {'alpha': [0.6, 0.4], 'k': [2e6, 5e5], 'C': 12000.0,
                                 'sigma': [2800.0, 700.0]}
    effects.update(extra)
    return AxisModel.from_dict({'mass': 25.0, 'input_gain': 50.0, 'damping': 50.0,
                                'effects': effects})


def test_delayed_reference_balances_at_the_advanced_state():
    """With a dead time the load level is the drive force T/2 + τ ahead."""
    model = _worn(False, delay={'tau': 0.002})
    t = np.arange(N) * T
    r = 0.015 * np.sin(2 * np.pi * 1.3 * t)
    rv = 0.015 * 2 * np.pi * 1.3 * np.cos(2 * np.pi * 1.3 * t)
    ra = -(2 * np.pi * 1.3) ** 2 * r
    lead = T / 2 + 0.002
    x, v = r + lead * (rv + 0.5 * lead * ra), rv + lead * ra
    full = cm.from_model(model).force_along(r, rv, T, ra=ra)
    f_in = full - model.damping * v
    np.testing.assert_allclose(f_in, model.mass * ra + model.static_force(x, v, f_in=f_in),
                               rtol=0, atol=1e-11 * np.max(np.abs(f_in)))
    # and the command is that force through the drive law
    u = cm.from_model(model).command_along(r, rv, T, ra=ra)
    np.testing.assert_allclose(model.input_force(u, v), f_in, rtol=1e-12, atol=1e-9)
    # the balance is not met without the two effects: the raised level is newtons
    plain = cm.from_model(model.without('load_friction', 'position_friction'))
    missing = f_in - (plain.force_along(r, rv, T, ra=ra) - model.damping * v)
    moving = np.abs(v) > 1e-3
    np.testing.assert_allclose(missing[moving], np.sign(v[moving]) * model.dry_friction_shift(
        x[moving], f_in=f_in[moving]), rtol=1e-9, atol=1e-9)
    assert np.max(np.abs(missing)) > 10.0 and np.median(np.abs(missing)) > 3.0


@pytest.mark.parametrize('gms', [False, True], ids=['static', 'gms'])
@pytest.mark.parametrize('mode, ff', [('pid', 'none'), ('npid', 'static'), ('pid', 'gms'),
                                      ('npid', 'static+gms'), ('adaptive_sliding', 'none')])
def test_carried_terms_leave_the_shift_in(ballscrew, gms, mode, ff):
    """A law that carries dry friction knows no shift: the compensation keeps it."""
    model = _worn(gms)
    nominal = ballscrew.with_model(ballscrew.model)     # has the GMS elements every ff needs
    ctrl = make_controller(mode, plant=nominal, feedforward=ff)
    comp = cm.from_model(model)
    ctrl.set_compensation(comp)
    carried = ctrl.carried
    dry_name = {'none': None, 'static': 'sliding friction curve', 'gms': 'dry friction',
                'static+gms': 'dry friction'}[ff] if mode != 'adaptive_sliding' else 'coulomb'
    if dry_name is not None:    # what the law carries is said to be the base level only
        assert f'{dry_name} at its base level' in carried.names(comp)
    t = np.arange(N) * T
    r = 0.01 * np.sin(2 * np.pi * 1.5 * t) + 0.002 * np.sin(2 * np.pi * 7.0 * t)
    rv = np.concatenate([[0.0], np.diff(r) / T])
    ra = np.gradient(rv, T)
    got = comp.force_along(r, rv, T, ra=ra, advance=False, carried=carried)
    f_in = comp.force_along(r, rv, T, ra=ra, advance=False) - model.damping * rv
    shift = model.dry_friction_shift(r, f_in=f_in)
    fc, fs, vs, delta = model.stribeck_curve_params()
    curve0 = np.sign(rv) * (fc + (fs - fc) * np.exp(-np.abs(rv / vs) ** delta))
    if gms:
        el = model.get('presliding')
        dry = el.force_along(r, T, fc=fc, fs=fs, vs=vs, delta=delta, shift=shift)
        dry0 = el.force_along(r, T, fc=fc, fs=fs, vs=vs, delta=delta)
    else:
        dry, dry0 = curve0 + np.sign(rv) * shift, curve0
    rigid = model.mass * ra + model.damping * rv
    expected = {('pid', 'none'): rigid + 3.0 + dry + 200.0 * rv,
                ('npid', 'static'): rigid + 3.0 + dry - curve0,
                ('pid', 'gms'): rigid + 3.0 + dry - dry0 + 200.0 * rv,
                ('npid', 'static+gms'): rigid + 3.0 + dry - dry0,
                # inertia, damping, fc·sgn and fv·ṙ are the adaptive law's own
                ('adaptive_sliding', 'none'): 3.0 + dry - 12.0 * np.sign(rv)}[mode, ff]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
    # the shift is what stays of the carried dry friction (newtons of it)
    if ff in ('static', 'static+gms'):
        assert np.max(np.abs(got - rigid - 3.0)) > 4.0
    # and the controller's own step adds that compensation (one kernel, same numbers)
    adv = comp.force_along(r, rv, T, ra=ra, carried=carried)
    for k in range(300):
        ctrl.step(r[k], rv[k], ra[k], r[k], rv[k], T)
        assert ctrl.compensation_force == pytest.approx(adv[k], rel=1e-12, abs=1e-9)


def test_both_effects_reported_compensated():
    comp = cm.from_model(_worn(True), source='worn.yaml')
    d = comp.describe()
    assert {'load_friction', 'position_friction'} <= set(d['compensated'])
    assert d['not_compensated'] == {}
    assert 'not compensated' not in comp.summary()
    assert comp.summary().endswith('presliding, offset, load_friction, position_friction')
    # every effect of the vocabulary is either compensated or refused with a reason
    assert set(VOCABULARY) == set(cm.COMPENSABLE) | set(cm.NOT_COMPENSABLE)
    assert not set(cm.COMPENSABLE) & set(cm.NOT_COMPENSABLE)


def test_position_table_leaves_position_friction_out():
    model = _worn(False, ripple={'period': 0.02, 'harmonics': [[8.0, 2.0]]})
    table = cm.position_table(model, points=400)
    assert table.effects == ('ripple', 'offset')
    assert set(table.left_out) == {'position_friction'}
    assert 'against the motion' in table.left_out['position_friction']
    # the table is the ripple and the offset alone, not dfc(x)
    np.testing.assert_allclose(table.force, model.get('ripple').force(table.position) + 3.0,
                               rtol=0, atol=1e-12)
    with pytest.raises(ParameterError, match='position_friction is not tabulated'):
        cm.position_table(model.without('ripple', 'offset'))


def _loop_errors(cfg, model, *, terms: str, ff: str = 'none') -> tuple[float, float]:
    """RMS and peak-to-peak tracking error [m] after the first second, slow sine, N-PID."""
    ctrl = make_controller('npid', plant=cfg, feedforward=ff)
    ctrl.set_compensation(cm.from_model(model, terms=terms))
    res = simulate(cfg, ctrl, make_trajectory('sine'), duration=6.0, seed=1)
    e = res.error[res.t >= 1.0]
    return float(np.sqrt(np.mean(e ** 2))), float(np.ptp(e))


# measured, with / without the effect in the compensation model (full | effects terms):
# load mu = 0.1: RMS 0.474/7.783 µm = 0.061 | 0.153, p2p 3.01/49.92 µm = 0.060 | 0.102;
# mu = 0.3: RMS 0.665/20.57 µm = 0.032 | 0.063, p2p 4.80/136.5 µm = 0.035 | 0.041;
# position: RMS 0.473/22.66 µm = 0.021 | 0.049, p2p 2.91/88.04 µm = 0.033 | 0.056
@pytest.mark.parametrize('terms', ['full', 'effects'])
@pytest.mark.parametrize('name, params, bound', [
    ('load_friction', {'mu': 0.1}, 0.25), ('load_friction', {'mu': 0.3}, 0.1),
    ('position_friction', SPOTS, 0.1)], ids=['load0.1', 'load0.3', 'position'])
def test_closed_loop_model_with_the_effect_tracks_better(ballscrew, terms, name, params,
                                                         bound):
    cfg = ballscrew.with_model(ballscrew.model.with_effect(make_effect(name, params)))
    rms_with, p2p_with = _loop_errors(cfg, cfg.model, terms=terms)
    rms_without, p2p_without = _loop_errors(cfg, cfg.model.without(name), terms=terms)
    assert rms_without > 5e-6                    # the effect is there to compensate
    assert rms_with < bound * rms_without, (rms_with, rms_without)
    assert p2p_with < bound * p2p_without, (p2p_with, p2p_without)


def test_closed_loop_with_the_gms_feedforward_keeps_the_shift(ballscrew):
    """N-PID with its own static+gms friction feedforward: the shift still helps."""
    cfg = ballscrew.with_model(ballscrew.model.with_effect(make_effect('load_friction', LOAD))
                               .with_effect(make_effect('position_friction', SPOTS)))
    rms_with, p2p_with = _loop_errors(cfg, cfg.model, terms='full', ff='static+gms')
    rms_without, p2p_without = _loop_errors(
        cfg, cfg.model.without('load_friction', 'position_friction'), terms='full',
        ff='static+gms')
    # measured: RMS 0.703/30.08 µm = 0.023, p2p 4.17/127.4 µm = 0.033
    assert rms_with < 0.1 * rms_without, (rms_with, rms_without)
    assert p2p_with < 0.1 * p2p_without, (p2p_with, p2p_without)
