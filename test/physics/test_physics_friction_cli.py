"""Load- and position-dependent friction through plant and model files and ``motor-comp``.

Issue 23 item 3: a plant file with ``load_friction`` and ``position_friction`` runs in
``motor-comp simulate`` (what the closed loop meets there is checked in
``test/control/test_control_friction_effects.py``), model files round-trip them, and
bad parameters — a missing ``coulomb``, knots out of order, lengths that differ, ``mu``
out of range, too many knots, a level ``fc + dfc(x)`` below zero — are one line naming
the file and the problem, exit status 2, through ``simulate --plant`` and
``compare --model``.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

from motor_comp.cli.main import main
from motor_comp.logs import read_run
from motor_comp.physics import AxisModel, load_plant, make_effect

PMLM_HEAD = ('plant: pmlm\nmotor:\n  mass_kg: 5.4\n  resistance_ohm: 8.6\n'
             '  force_constant_N_per_A: 130.0\n  back_emf_V_s_per_m: 123.0\n')
BASE_EFFECTS = ('  coulomb: {fc: 10.0}\n  stribeck: {fs: 20.0, vs: 0.1, delta: 2.0}\n'
                '  viscous: {fv: 10.0}\n')
#: a tight spot of +60 N in the middle of the default PMLM move (0 → 50 mm) and a
#: screw-like load term
NEW_EFFECTS = ('  load_friction: {mu: 0.15}\n'
               '  position_friction: {x: [0.015, 0.025, 0.035], dfc: [0.0, 60.0, 0.0]}\n')


def _plant(tmp_path, name, effects):
    path = tmp_path / f'{name}.yaml'
    path.write_text(PMLM_HEAD + 'effects:\n' + effects)
    return path


BAD = {
    'no_coulomb': ('  viscous: {fv: 10.0}\n  load_friction: {mu: 0.2}\n',
                   ("'load_friction' needs 'coulomb'",)),
    'mu_one': (BASE_EFFECTS + '  load_friction: {mu: 1.0}\n', ('load_friction.mu', '< 1')),
    'mu_negative': (BASE_EFFECTS + '  load_friction: {mu: -0.1}\n',
                    ('load_friction.mu', '>= 0')),
    'knots_order': (BASE_EFFECTS + '  position_friction: {x: [0.0, 0.2, 0.1], '
                                   'dfc: [0.0, 1.0, 0.0]}\n',
                    ('position_friction.x', 'strictly increasing', 'x[2]')),
    'lengths': (BASE_EFFECTS + '  position_friction: {x: [0.0, 0.1, 0.2], dfc: [0.0, 1.0]}\n',
                ('position_friction.dfc has 2 values', '3 knots')),
    'one_knot': (BASE_EFFECTS + '  position_friction: {x: [0.0], dfc: [1.0]}\n',
                 ('position_friction.x', '2..32 knots')),
    'too_many': (BASE_EFFECTS + '  position_friction: {x: [' +
                 ', '.join(f'{0.01 * i:g}' for i in range(40)) + '], dfc: [' +
                 ', '.join('0.0' for _ in range(40)) + ']}\n',
                 ('position_friction.x', '2..32 knots', 'got 40')),
    'below_zero': (BASE_EFFECTS + '  position_friction: {x: [0.0, 0.01, 0.1], '
                                  'dfc: [0.0, -10.0, 0.0]}\n',
                   ('fc + dfc(x) must be >= 0', 'at x = 0.0')),
    'not_a_list': (BASE_EFFECTS + '  position_friction: {x: 0.1, dfc: [1.0, 2.0]}\n',
                   ('position_friction.x [m] must be a list of numbers',)),
    'missing_x': (BASE_EFFECTS + '  position_friction: {dfc: [1.0, 2.0]}\n',
                  ("position_friction: missing parameter 'x'",)),
}


@pytest.mark.parametrize('case', sorted(BAD))
def test_bad_plant_file_is_one_line_and_exit_2(tmp_path, capsys, case):
    effects, needles = BAD[case]
    path = _plant(tmp_path, case, effects)
    rc = main(['simulate', '--plant', str(path), '--duration', '0.1', '--json'])
    out, err = capsys.readouterr()
    assert rc == 2 and out == ''
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f'motor-comp: error: {path}: '), err
    assert 'Traceback' not in err
    for needle in needles:
        assert needle in lines[0], lines[0]


@pytest.mark.parametrize('case', ['no_coulomb', 'knots_order', 'lengths', 'below_zero'])
def test_bad_model_file_is_one_line_and_exit_2(tmp_path, capsys, case):
    effects, needles = BAD[case]
    path = tmp_path / f'{case}.yaml'
    path.write_text('mass: 1.0\neffects:\n' + effects)
    rc = main(['compare', str(tmp_path / 'run.mcap'), '--model', str(path)])
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert rc == 2 and out == ''
    assert len(lines) == 1 and lines[0].startswith(f'motor-comp: error: {path}: '), err
    for needle in needles:
        assert needle in lines[0], lines[0]


def test_plant_file_with_both_effects_runs_in_simulate(tmp_path, capsys):
    path = _plant(tmp_path, 'worn', BASE_EFFECTS + NEW_EFFECTS)
    model = load_plant(str(path)).model
    assert model.names == ('coulomb', 'viscous', 'stribeck', 'load_friction',
                           'position_friction')
    assert (model.get('load_friction').mu, model.get('position_friction').dfc) == \
        (0.15, (0.0, 60.0, 0.0))
    out_file = tmp_path / 'worn.mcap'
    rc = main(['simulate', '--plant', str(path), '--controller', 'pid', '--duration', '1',
               '--json', '-o', str(out_file)])
    out, err = capsys.readouterr()
    assert rc == 0, err
    run = json.loads(out)['runs'][0]
    assert 0.0 < run['rms_error'] <= run['max_error'] < 1e-3
    recorded = read_run(out_file)
    assert len(recorded) == 1000 and np.ptp(recorded.position) > 0.04   # the 50 mm move


def test_model_file_round_trip(tmp_path):
    m = AxisModel(mass=95.0, input_gain=35.15, back_emf=0.5, damping=12.0,
                  effects=(make_effect('coulomb', {'fc': 20.0}),
                           make_effect('load_friction', {'mu': 0.12}),
                           make_effect('position_friction',
                                       {'x': [-0.1, 0.0, 0.05, 0.3],
                                        'dfc': [1.5, -4.0, 8.25, 0.0]})))
    path = tmp_path / 'model.yaml'
    m.save(path)
    back = AxisModel.load(path)
    assert back == m
    assert back.to_dict()['effects']['position_friction'] == {
        'x': [-0.1, 0.0, 0.05, 0.3], 'dfc': [1.5, -4.0, 8.25, 0.0]}
    assert back.to_dict()['effects']['load_friction'] == {'mu': 0.12}
    # canonical order in the file: ... gravity load_friction position_friction
    assert list(back.to_dict()['effects']) == ['coulomb', 'load_friction',
                                               'position_friction']
