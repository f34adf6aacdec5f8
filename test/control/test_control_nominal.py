"""The controller's nominal model: derived from the plant file, never the plant (issue 15)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

import motor_comp.cli.main as cli
from motor_comp.control.controller import Q_FC, Q_GAIN, Q_OMEGA, Q_TH0
from motor_comp.control.nominal import NominalSpec, NominalStart, derive_nominal
from motor_comp.control.scenario import Scenario
from motor_comp.errors import ParameterError


def test_half_start_is_tan_simulation(pmlm):
    nom = derive_nominal(pmlm, 'half')
    t, n = pmlm.model, nom.model
    assert n.mass == pytest.approx(1.2 * t.mass)
    assert n.fc == pytest.approx(0.5 * t.fc) and n.fv == pytest.approx(0.5 * t.fv)
    assert n.get('stribeck').fs == pytest.approx(0.5 * t.get('stribeck').fs)
    assert n.get('stribeck').vs == t.get('stribeck').vs
    np.testing.assert_allclose(n.get('ripple').a, 0.5 * t.get('ripple').a)
    assert n.get('ripple').period == t.get('ripple').period       # the magnet pitch
    assert (n.input_gain, n.back_emf) == (t.input_gain, t.back_emf)
    assert nom.sensors == pmlm.sensors and nom.control_rate == pmlm.control_rate
    assert 'friction_factor=0.5' in nom.source


def test_zero_start_is_tan_experiment(pmlm):
    n = derive_nominal(pmlm, NominalStart.ZERO).model
    assert n.fc == 0.0 and n.fv == 0.0 and n.get('stribeck').fs == 0.0
    assert not np.any(n.get('ripple').a) and n.get('ripple').period == 0.02


def test_identified_ballscrew_and_the_defaults(ballscrew, pmlm):
    n, t = derive_nominal(ballscrew).model, ballscrew.model       # default: identified
    assert n.fc == pytest.approx(0.8 * t.fc) and n.mass == t.mass
    np.testing.assert_allclose(n.get('presliding').k, 0.7 * np.array(t.get('presliding').k))
    assert n.get('presliding').alpha == t.get('presliding').alpha
    assert n.get('delay').tau == t.get('delay').tau
    assert derive_nominal(pmlm).model == derive_nominal(pmlm, 'half').model
    assert derive_nominal(pmlm, 'exact').model == pmlm.model     # the oracle only


def test_scenario_controller_knows_the_nominal_not_the_plant(pmlm):
    true, nominal, ctrl, _, _ = Scenario(plant='pmlm', controller='adaptive_sliding').build()
    assert true.model == pmlm.model
    assert nominal.model != true.model
    assert ctrl.nominal['fc'] == pytest.approx(5.0) and ctrl.nominal['mass'] == \
        pytest.approx(6.48)
    assert ctrl.estimates['fc'] == pytest.approx(5.0)             # starts at the nominal
    g = ctrl.packed[Q_GAIN]
    assert ctrl.packed[Q_TH0 + 2] * g == pytest.approx(5.0)      # leakage target: nominal
    # the static feedforward of a PID, too
    _, _, pid, _, _ = Scenario(plant='pmlm', controller='pid', feedforward='static').build()
    assert pid.packed[Q_FC] == pytest.approx(5.0)


def test_scenario_nominal_settings(pmlm):
    def build(*settings):
        return Scenario(plant='pmlm', controller='adaptive_sliding',
                        settings=tuple(settings)).build()
    true, nominal, ctrl, _, _ = build(('nominal.start', 'zero'),
                                      ('nominal.ripple.period', 0.025),
                                      ('nominal.ripple.a1', 4.0), ('nominal.ripple.b1', 2.0),
                                      ('plant.ripple.a1', 12.0))
    assert nominal.model.fc == 0.0 and nominal.model.mass == pytest.approx(6.48)
    assert nominal.model.get('ripple').harmonics == ((4.0, 2.0),)
    assert ctrl.packed[Q_OMEGA] == pytest.approx(2 * math.pi / 0.025)
    assert true.model.get('ripple').harmonics == ((12.0, 0.0),)    # plant.* = truth only
    assert true.model.get('ripple').period == 0.02
    _, nominal, _, _, _ = build(('nominal.friction_factor', 0.3), ('nominal.mass_factor', 0.8),
                                ('plant.coulomb.fc', 15.0))
    assert nominal.model.fc == pytest.approx(3.0)                  # from the file, not 15 N
    assert nominal.model.mass == pytest.approx(0.8 * pmlm.model.mass)
    _, nominal, _, _, _ = build(('nominal.ripple.a2', 1.5))      # a second harmonic
    assert nominal.model.get('ripple').harmonics == ((4.25, 0.0), (1.5, 0.0))


def test_run_metadata_names_the_derivation():
    res, _ = Scenario(plant='pmlm', duration=0.01,
                      settings=(('nominal.start', 'zero'),)).run()
    assert 'friction_factor=0' in res.metadata['nominal']


@pytest.mark.parametrize('setting, needle', [
    ('nominal.start=bogus', 'nominal.start must be one of exact, half, zero, identified'),
    ('nominal.mass_factor=-1', 'nominal.mass_factor'),
    ('nominal.friction_factor=x', 'nominal factors must be numbers'),
    ('nominal.ripple.a1=nan', 'nominal.ripple.a1'),
    ('nominal.speed_factor=2', 'nominal.speed_factor'),
])
def test_bad_nominal_settings_are_one_line(capsys, monkeypatch, setting, needle):
    monkeypatch.setattr(cli, 'SUBCOMMANDS', ('simulate',))
    code = cli.main(['simulate', '--duration', '0.01', '--set', setting])
    out, err = capsys.readouterr()
    assert code == 2 and out == ''
    assert err.count('\n') == 1 and err.startswith('motor-comp: error:') and needle in err


def test_spec_validation():
    with pytest.raises(ParameterError, match='nominal.stiffness_factor'):
        NominalSpec(stiffness_factor=0.0)
    with pytest.raises(ParameterError, match='unknown setting nominal.bogus'):
        NominalSpec().replace(bogus=1.0)


@given(mass=st.floats(0.5, 2.0), friction=st.floats(0.0, 2.0), ripple=st.floats(0.0, 2.0),
       stiffness=st.floats(0.1, 3.0))
@settings(max_examples=60, deadline=None)
def test_derivation_scales_exactly_what_it_names(ballscrew, pmlm, mass, friction, ripple,
                                                 stiffness):
    spec = NominalSpec(mass, friction, ripple, stiffness)
    for plant in (pmlm, ballscrew):
        t, n = plant.model, derive_nominal(plant, spec).model      # always a valid model
        assert n.mass == pytest.approx(mass * t.mass)
        assert n.fc == pytest.approx(friction * t.fc) and n.fv == pytest.approx(friction * t.fv)
        fc, fs, vs, delta = n.stribeck_curve_params()
        assert fs == pytest.approx(friction * t.stribeck_curve_params()[1]) and fs >= fc
        assert (vs, delta) == t.stribeck_curve_params()[2:]
        assert (n.input_gain, n.back_emf, n.damping) == (t.input_gain, t.back_emf, t.damping)
        if t.has('ripple'):
            np.testing.assert_allclose(n.get('ripple').a, ripple * t.get('ripple').a)
            assert n.get('ripple').period == t.get('ripple').period
        if t.has('presliding'):
            np.testing.assert_allclose(n.get('presliding').k,
                                       stiffness * np.array(t.get('presliding').k))
        assert n.names == t.names
