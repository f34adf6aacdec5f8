"""CLI of issue 12: ``simulate --compensation``, ``export-table``, ``study compensate``.

Behaviour with numbers (the compensation lowers the tracking error; the exported table
is the model's position-dependent force; the loop study recovers ≥ 80 % of the possible
RMS reduction) and every new option's bad input: one line ``motor-comp: error: …``
naming the problem, exit status 2, no traceback.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest

import motor_comp.cli.main as cli
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.config import load_plant
from motor_comp.physics.effects import make_effect


def _cli(capsys, *argv):
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as exc:   # argparse's own errors (already one line, status 2)
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def _one_line_error(code, err, *needles):
    assert code == 2, err
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('motor-comp: error:'), err
    assert 'Traceback' not in err
    for n in needles:
        assert n in lines[0], (n, lines[0])


@pytest.fixture(scope='module')
def models(tmp_path_factory):
    d = tmp_path_factory.mktemp('models')
    true = load_plant('ballscrew').model
    true.save(d / 'ballscrew_true.yaml')
    cog = AxisModel.from_dict({'mass': 5.4, 'input_gain': 15.1, 'effects': {
        'coulomb': {'fc': 10.0},
        'ripple': {'period': 0.02, 'harmonics': [[8.5, 0.0], [2.0, 1.0]]},
        'offset': {'f0': 4.0}}})
    cog.save(d / 'cogging.yaml')
    spring = cog.with_effect(make_effect('spring', {'k': 100.0, 'x0': 0.0}))
    spring.save(d / 'spring.yaml')
    friction_only = AxisModel.from_dict({'mass': 5.4, 'effects': {'coulomb': {'fc': 3.0}}})
    friction_only.save(d / 'friction_only.yaml')
    spots = make_effect('position_friction', {'x': [0.0, 0.01, 0.02], 'dfc': [0.0, 2.0, 0.0]})
    cog.with_effect(spots).save(d / 'worn_cogging.yaml')
    friction_only.with_effect(spots).save(d / 'spots_only.yaml')
    true.with_effect(make_effect('load_friction', {'mu': 0.2})).with_effect(spots).save(
        d / 'ballscrew_worn.yaml')
    (d / 'bad.yaml').write_text('mass: 1\neffects: {stribeck: {vs: 0}}\n')
    return d


def test_simulate_with_compensation(capsys, models):
    args = ('simulate', '--plant', 'ballscrew', '--controller', 'npid', '--duration', '4',
            '--json')
    code, out, err = _cli(capsys, *args)
    assert code == 0, err
    base = json.loads(out)['runs'][0]
    code, out, err = _cli(capsys, *args, '--compensation', models / 'ballscrew_true.yaml')
    assert code == 0, err
    comp = json.loads(out)['runs'][0]
    assert comp['compensated'] == ['coulomb', 'viscous', 'stribeck', 'presliding', 'delay']
    assert comp['not_compensated'] == {} and comp['compensation_terms'] == 'full'
    # the compensation from the plant's own model: tracking error and glitch fall
    assert comp['rms_error'] < 0.5 * base['rms_error']
    assert comp['max_glitch'] < 0.5 * base['max_glitch']
    code, out, err = _cli(capsys, *args, '--compensation', models / 'ballscrew_true.yaml',
                          '--compensation-terms', 'effects')
    assert code == 0, err
    effects = json.loads(out)['runs'][0]
    assert effects['compensation_terms'] == 'effects'
    # the inertia and the drive's damping are most of what the effects leave
    assert comp['rms_error'] < 0.6 * effects['rms_error'] < 0.6 * base['rms_error']
    code, out, err = _cli(capsys, 'simulate', '--plant', 'ballscrew', '--controller', 'npid',
                          '--duration', '1', '--compensation',
                          models / 'ballscrew_true.yaml')
    assert code == 0 and '(full): inertia, back-EMF, damping, coulomb' in out


def test_simulate_with_table(capsys, models, tmp_path):
    table = tmp_path / 'cog.csv'
    code, out, err = _cli(capsys, 'export-table', models / 'cogging.yaml', '--points', '512',
                          '-o', table, '--json')
    assert code == 0, err
    info = json.loads(out)
    assert info['points'] == 512 and info['period'] == pytest.approx(0.02)
    assert info['effects'] == ['ripple', 'offset']
    assert info['units'] == {'position': 'm', 'force': 'N', 'command': 'V'}
    data = np.loadtxt(table, delimiter=',', comments='#', skiprows=7)
    x, f, u = data.T
    model = AxisModel.load(models / 'cogging.yaml')
    truth = model.get('ripple').force(x) + 4.0
    np.testing.assert_allclose(f, truth, atol=1e-9)
    np.testing.assert_allclose(u, truth / 15.1, rtol=1e-12)
    header = table.read_text().splitlines()[:7]
    assert any('source_model' in h and 'cogging.yaml' in h for h in header)
    assert any('units: position [m], force [N], command [V]' in h for h in header)
    code, out, err = _cli(capsys, 'simulate', '--plant', 'pmlm', '--duration', '1',
                          '--compensation-table', table, '--json')
    assert code == 0, err
    assert json.loads(out)['runs'][0]['compensation_kind'] == 'table'


def test_simulate_compensates_the_new_friction_effects(capsys, models):
    code, out, err = _cli(capsys, 'simulate', '--plant', 'ballscrew', '--controller', 'npid',
                          '--duration', '0.5', '--compensation', models / 'ballscrew_worn.yaml',
                          '--json')
    assert code == 0, err
    run = json.loads(out)['runs'][0]
    assert run['compensated'] == ['coulomb', 'viscous', 'stribeck', 'presliding', 'delay',
                                  'load_friction', 'position_friction']
    assert run['not_compensated'] == {}


def test_export_table_leaves_position_friction_out(capsys, models, tmp_path):
    code, out, err = _cli(capsys, 'export-table', models / 'worn_cogging.yaml', '--points',
                          '256', '-o', tmp_path / 'w.csv')
    assert code == 0, err
    assert 'position_friction not in the table: its force dfc(x)·sgn(v) acts against the ' \
           'motion' in out
    assert 'not position-dependent (not in the table): coulomb\n' in out
    code, out, err = _cli(capsys, 'export-table', models / 'worn_cogging.yaml', '--points',
                          '256', '-o', tmp_path / 'w2.csv', '--json')
    info = json.loads(out)
    assert info['effects'] == ['ripple', 'offset']
    assert list(info['left_out']) == ['position_friction']
    # the table is the cogging and the offset, the same as without the tight spot
    x, f, _ = np.loadtxt(tmp_path / 'w2.csv', delimiter=',', comments='#', skiprows=7).T
    cog = AxisModel.load(models / 'cogging.yaml')
    np.testing.assert_allclose(f, cog.get('ripple').force(x) + 4.0, atol=1e-9)


@pytest.mark.parametrize('argv, needles', [
    (['--compensation', '{d}/missing.yaml'], ['missing.yaml', 'no such model file']),
    (['--compensation', '{d}/bad.yaml'], ['bad.yaml', 'stribeck.vs']),
    (['--compensation-table', '{d}/missing.csv'], ['missing.csv', 'no such']),
    (['--compensation-table', '{d}/bad.yaml'], ['bad.yaml', 'expected columns']),
    (['--compensation', '{d}/cogging.yaml', '--compensation-table', '{d}/x.csv'],
     ['not allowed with']),
    (['--compensation-terms', 'effects'], ['--compensation-terms needs --compensation']),
    (['--compensation-table', '{d}/x.csv', '--compensation-terms', 'full'],
     ['--compensation-terms needs --compensation']),
    (['--compensation', '{d}/cogging.yaml', '--compensation-terms', 'all'],
     ['--compensation-terms', 'invalid choice']),
])
def test_simulate_compensation_bad_input(capsys, models, argv, needles):
    argv = [a.format(d=models) for a in argv]
    code, out, err = _cli(capsys, 'simulate', '--duration', '0.1', *argv)
    _one_line_error(code, err, *needles)


@pytest.mark.parametrize('argv, needles', [
    (['{d}/cogging.yaml', '--points', '1', '-o', '{o}'], ['--points', 'between 2']),
    (['{d}/cogging.yaml', '--points', 'many', '-o', '{o}'], ['--points', 'not an integer']),
    (['{d}/spring.yaml', '-o', '{o}'], ['not periodic', '--range']),
    (['{d}/spring.yaml', '--range', '0.1', '-0.1', '-o', '{o}'], ['--range', 'MIN < MAX']),
    (['{d}/spring.yaml', '--range', '0', 'inf', '-o', '{o}'], ['--range', 'finite']),
    (['{d}/friction_only.yaml', '-o', '{o}'], ['no position-dependent effect']),
    (['{d}/spots_only.yaml', '-o', '{o}'], ['no position-dependent effect',
                                            'position_friction is not tabulated',
                                            'against the motion']),
    (['{d}/missing.yaml', '-o', '{o}'], ['no such model file']),
    (['{d}/bad.yaml', '-o', '{o}'], ['stribeck.vs']),
    (['{d}/cogging.yaml', '-o', '{d}/no_dir/t.csv'], ['-o', 'does not exist']),
    (['{d}/cogging.yaml'], ['-o']),
])
def test_export_table_bad_input(capsys, models, tmp_path, argv, needles):
    argv = [a.format(d=models, o=tmp_path / 't.csv') for a in argv]
    code, out, err = _cli(capsys, 'export-table', *argv)
    _one_line_error(code, err, *needles)
    assert not (tmp_path / 't.csv').exists()


def test_export_table_spring_with_range(capsys, models, tmp_path):
    code, out, err = _cli(capsys, 'export-table', models / 'spring.yaml', '--range', '-0.05',
                          '0.05', '--points', '101', '-o', tmp_path / 's.csv')
    assert code == 0, err
    assert '101 points over -0.05 … 0.05 m' in out
    assert 'not position-dependent (not in the table): coulomb' in out
    data = np.loadtxt(tmp_path / 's.csv', delimiter=',', comments='#', skiprows=7)
    assert data[-1, 1] - data[0, 1] == pytest.approx(100.0 * 0.1 + (
        AxisModel.load(models / 'spring.yaml').get('ripple').force(np.array([0.05, -0.05]))
        @ [1, -1]))


@pytest.mark.parametrize('argv, needles', [
    (['study'], ['required: STUDY']),
    (['study', 'compensate', '--duration', '0'], ['--duration']),
    (['study', 'compensate', '--plant', 'lathe'], ['--plant', 'invalid choice']),
    (['study', 'compensate', '--duration', 'nan'], ['--duration']),
    (['study', 'compensate', '--seed', 'x'], ['--seed', 'invalid int']),
    (['study', 'compensate', '--out', '{f}/sub'], ['--out', 'cannot create directory']),
])
def test_study_bad_input(capsys, tmp_path, argv, needles):
    (tmp_path / 'file').write_text('not a directory')
    argv = [a.format(f=tmp_path / 'file') for a in argv]
    code, out, err = _cli(capsys, *argv)
    _one_line_error(code, err, *needles)


def test_study_compensate_recovers_most_of_the_possible_reduction(capsys, tmp_path):
    """Record → fit --auto from the bare model → compensate: ≥ 80 % of what truth gives."""
    code, out, err = _cli(capsys, 'study', 'compensate', '--plant', 'pmlm', '--duration', '10',
                          '--out', tmp_path, '--json')
    assert code == 0, err
    (res,) = json.loads(out)['plants']
    none, fitted, true = res['runs']
    assert none['label'] == 'uncompensated' and true['label'] == 'true-plant compensation'
    assert true['rms_error'] < 0.9 * none['rms_error']        # there is something to gain
    assert true['max_glitch'] < 0.6 * none['max_glitch']
    assert res['recovery_rms'] >= 0.8 and math.isfinite(res['recovery_rms'])
    found = {s['effect'] for s in res['fit_steps']}
    assert 'ripple' in found                                    # the cogging was identified
    fitted_model = AxisModel.load(tmp_path / 'pmlm_fitted.yaml')
    assert fitted_model.get('ripple').period == pytest.approx(0.02, rel=0.02)
    assert (tmp_path / 'pmlm_record.mcap').stat().st_size > 0
