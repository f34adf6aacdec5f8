"""The workbench model file (DESIGN.md §6) and the packaged plant defaults (§3 table)."""
from __future__ import annotations

import math

import pytest
import yaml

from motor_comp.errors import InputFileError, ModelFileError
from motor_comp.physics import AxisModel, InputKind, PlantKind, load_plant, make_effect

EVERY_EFFECT = {
    'coulomb': {'fc': 20.0},
    'viscous': {'fv': 200.0},
    'stribeck': {'fs': 25.0, 'vs': 0.002, 'delta': 1.5},
    'presliding': {'alpha': [0.45, 0.3, 0.15, 0.1], 'k': [8e6, 3e6, 1e6, 3e5], 'C': 9600.0,
                   'sigma': [1e4, 4e3, 1e3, 5e2]},
    'ripple': {'period': 0.02, 'harmonics': [[8.5, 0.0], [1.0, -0.5]]},
    'offset': {'f0': -3.0},
    'spring': {'k': 150.0, 'x0': 0.001},
    'asymmetry': {'dfc': 2.0, 'dfv': 10.0},
    'delay': {'tau': 0.00129},
    'backlash': {'width': 4e-6},
    'load_friction': {'mu': 0.08},
    'position_friction': {'x': [-0.2, 0.05, 0.07, 0.3], 'dfc': [0.0, 6.5, -2.0, 1.0]},
}


def _full_model() -> AxisModel:
    return AxisModel(mass=95.0, input_gain=35.15, back_emf=0.5, damping=12.0,
                     input=InputKind.CURRENT,
                     effects=tuple(make_effect(n, p) for n, p in EVERY_EFFECT.items()))


def test_to_dict_is_the_design_layout_and_round_trips():
    m = _full_model()
    d = m.to_dict()
    assert d['input'] == 'current' and d['mass'] == 95.0 and d['input_gain'] == 35.15
    assert d['effects'] == EVERY_EFFECT
    assert AxisModel.from_dict(d) == m


def test_save_and_load_round_trip_every_effect(tmp_path):
    path = tmp_path / 'model.yaml'
    m = _full_model()
    m.save(path)
    assert AxisModel.load(path) == m
    assert yaml.safe_load(path.read_text())['effects']['ripple']['harmonics'][1] == [1.0, -0.5]


def test_design_section_6_example_file_loads(tmp_path):
    path = tmp_path / 'example.yaml'
    path.write_text(
        'input: voltage\ninput_gain: 35.15\nback_emf: 0.0\nmass: 95.0\neffects:\n'
        '  coulomb: {fc: 20.0}\n  viscous: {fv: 200.0}\n'
        '  ripple: {period: 0.02, harmonics: [[8.5, 0.0]]}\n')
    m = AxisModel.load(path)
    assert m.names == ('coulomb', 'viscous', 'ripple')
    assert (m.fc, m.fv, m.get('ripple').a[0]) == (20.0, 200.0, 8.5)
    assert m.damping == 0.0


@pytest.mark.parametrize('text, needle', [
    ('mass: 5.0\neffects:\n  cogging: {a: 1}\n', "unknown effect 'cogging'"),
    ('input_gain: 2.0\n', "missing field 'mass'"),
    ('mass: -1.0\n', 'mass [kg] must be > 0'),
    ('mass: heavy\n', 'mass [kg] must be a number'),
    ('mass: [1, 2]\n', 'mass [kg] must be a number'),
    ('mass: 5.0\neffects: [coulomb]\n', 'effects must be a mapping'),
    ('mass: 5.0\neffects:\n  coulomb: 3.0\n', 'effects.coulomb must be a mapping'),
    ('mass: 5.0\neffects:\n  coulomb: {fc: x}\n', 'coulomb.fc [N] must be a number'),
    ('mass: 5.0\neffects:\n  coulomb: {fc: 1.0, fs: 2.0}\n', "unknown parameter 'fs'"),
    ('mass: 5.0\ninput: torque\n', 'input must be one of'),
    ('mass: 5.0\ngain: 3\n', "unknown field 'gain'"),
    ('mass: 5.0\neffects:\n  coulomb: {fc: 10}\n  stribeck: {fs: 5}\n', 'stribeck.fs'),
    ('- just\n- a list\n', 'expected a mapping'),
    ('mass: [1, 2\n', 'not valid YAML'),
    ('', 'empty model file'),
])
def test_malformed_model_files_give_one_line_errors_naming_the_file(tmp_path, text, needle):
    path = tmp_path / 'bad.yaml'
    path.write_text(text)
    with pytest.raises(ModelFileError) as info:
        AxisModel.load(path)
    msg = str(info.value)
    assert needle in msg
    assert str(path) in msg and '\n' not in msg


def test_missing_model_file_and_directory(tmp_path):
    with pytest.raises(ModelFileError, match='no such model file'):
        AxisModel.load(tmp_path / 'nope.yaml')
    with pytest.raises(ModelFileError, match='is a directory'):
        AxisModel.load(tmp_path)


def test_pmlm_defaults_are_the_design_table():
    cfg = load_plant('pmlm')
    m = cfg.model
    assert cfg.kind is PlantKind.PMLM
    assert m.mass == 5.4
    assert m.input_gain == pytest.approx(130.0 / 8.6)       # k_f/R  [N/V]
    assert m.back_emf == 123.0                              # k_e    [V·s/m]
    assert m.damping == 0.0
    assert m.stribeck_curve_params() == (10.0, 20.0, 0.1, 2.0)
    assert m.fv == 10.0
    rip = m.get('ripple')
    assert (rip.period, rip.harmonics) == (0.02, ((8.5, 0.0),))
    assert set(m.names) == {'coulomb', 'stribeck', 'viscous', 'ripple'}
    # Tan 2002 eq. 7: a = k_f·k_e/(R·M), b = k_f/(R·M)
    assert m.input_gain * m.back_emf / m.mass == pytest.approx(130 * 123 / (8.6 * 5.4))
    assert m.input_gain / m.mass == pytest.approx(130 / (8.6 * 5.4))
    _common_rates_and_sensors(cfg)


def test_ballscrew_defaults_are_the_design_table():
    cfg = load_plant('ballscrew')
    m = cfg.model
    assert cfg.kind is PlantKind.BALLSCREW
    assert m.mass == 50.0 / 2.0                             # M = k_f/A
    assert m.input_gain == 50.0                             # k_f [N/V]
    assert m.damping == 2.0 * m.mass                        # B·M
    assert m.input_gain / m.mass == 2.0                     # A back
    assert not m.has('spring')                              # C = 0
    assert m.get('delay').tau == 0.00129
    assert m.stribeck_curve_params() == (12.0, 18.0, 0.001, 1.0)
    assert m.fv == 200.0
    gms = m.get('presliding')
    assert gms.alpha == (0.45, 0.30, 0.15, 0.10)
    assert gms.k == (8e6, 3e6, 1e6, 3e5)
    _common_rates_and_sensors(cfg)


def _common_rates_and_sensors(cfg):
    assert cfg.physics_rate == 10_000.0 and cfg.control_rate == 1_000.0
    assert cfg.sensors.encoder_resolution == 1e-6
    assert cfg.sensors.noise_std == 0.0 and math.isinf(cfg.sensors.saturation)


def test_plant_file_errors_are_one_line(tmp_path):
    with pytest.raises(InputFileError, match='no such plant file'):
        load_plant(tmp_path / 'missing.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('plant: pmlm\nmotor: {mass_kg: 5.4, resistance_ohm: 0.0, '
                   'force_constant_N_per_A: 130, back_emf_V_s_per_m: 123}\n')
    with pytest.raises(ModelFileError, match='resistance_ohm must be > 0') as info:
        load_plant(bad)
    assert str(bad) in str(info.value)
    bad.write_text('plant: stepper\n')
    with pytest.raises(ModelFileError, match='plant must be one of'):
        load_plant(bad)
    bad.write_text('plant: pmlm\nmotor: {mass_kg: 5.4, voltage: 3}\n')
    with pytest.raises(ModelFileError, match='bad motor parameters'):
        load_plant(bad)


@pytest.mark.parametrize('text, needle', [
    ('plant: pmlm\nsensor: {noise_std_m: 1e-6}\n', "unknown field 'sensor'"),
    ('plant: pmlm\nsensors: {encoder_resolutoin_m: 1e-6}\n',
     "sensors: unknown field 'encoder_resolutoin_m'"),
    ('plant: pmlm\nrates: {physics: 5000}\n', "rates: unknown field 'physics'"),
    ('plant: pmlm\nsensors: {saturation_V: high}\n', 'saturation [V] must be a number'),
    ('plant: pmlm\nsensors: {saturation_V: .nan}\n', 'saturation [V] must be > 0'),
])
def test_plant_file_typos_and_bad_sensor_values_are_named(tmp_path, text, needle):
    # a misspelt key must not silently fall back to its default
    path = tmp_path / 'plant.yaml'
    path.write_text(text.replace('plant: pmlm\n', 'plant: pmlm\nmotor: {mass_kg: 5.4, '
                                 'resistance_ohm: 8.6, force_constant_N_per_A: 130, '
                                 'back_emf_V_s_per_m: 123}\n'))
    with pytest.raises(ModelFileError) as info:
        load_plant(path)
    assert needle in str(info.value) and str(path) in str(info.value)


def test_non_effect_in_a_model_is_a_parameter_error():
    with pytest.raises(ValueError, match='effects must be Effect instances'):
        AxisModel(mass=1.0, effects=('coulomb',))
