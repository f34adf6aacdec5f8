"""``motor-comp excite``: the table it writes plays, its JSON, its one-line errors.

The written CSV is a ``table`` trajectory: ``simulate --trajectory table`` plays it row
for row (the recorded reference is the file's ``x``); ``--json`` holds the predicted
standard errors for every parameter of the start model with the start values beside
them, the limits and the peaks that keep them; bad input is one line, exit status 2,
and nothing is written.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

import motor_comp.cli.main as cli
from motor_comp.control.trajectories import make_trajectory
from motor_comp.logs import read_run

ARM = ('axis: rotary\ninput: current\ninput_gain: 0.8\nmass: 0.011\neffects:\n'
       '  coulomb: {fc: 0.045}\n  viscous: {fv: 0.011}\n  gravity: {mgl: 1.4, q0: 0.25}\n')
RIPPLE = ('input: voltage\ninput_gain: 15.1\nback_emf: 123.0\nmass: 5.9\neffects:\n'
          '  coulomb: {fc: 9.0}\n  ripple: {period: 0.02, harmonics: [[8.0, 0.0]]}\n')


def _cli(capsys, *argv):
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope='module')
def models(tmp_path_factory):
    d = tmp_path_factory.mktemp('excite')
    (d / 'arm.yaml').write_text(ARM)
    (d / 'ripple.yaml').write_text(RIPPLE)
    (d / 'bad.yaml').write_text('mass: 1\neffects: {coulomb: {fc: -2}}\n')
    return d


def test_excite_writes_a_playable_table(capsys, models, tmp_path):
    exc = tmp_path / 'exc.csv'
    code, out, err = _cli(capsys, 'excite', '--model', models / 'arm.yaml', '--travel', -3, 3,
                          '--vmax', 5, '--amax', 50, '--encoder', 1e-5, '--noise-std', 2e-6,
                          '-o', exc, '--json')
    assert code == 0, err
    data = json.loads(out)
    assert data['path'] == str(exc) and data['limits']['vmax'] == 5.0
    se, params = data['predicted_se'], data['params']
    assert set(se) == {'mass', 'coulomb', 'viscous', 'gravity'}
    assert set(se['gravity']) == {'mgl', 'q0'}
    assert params['gravity'] == {'mgl': 1.4, 'q0': 0.25}
    for g, dd in se.items():       # finite, and small against the values themselves
        for k, v in dd.items():
            assert 0 < v < 0.1 * abs(params[g][k]), (g, k, v)
    pk = data['peaks']
    assert -3 <= pk['x_min'] and pk['x_max'] <= 3 and pk['v'] <= 5 and pk['a'] <= 50
    assert data['controller']['mode'] == 'pid' and data['controller']['kp'] > 0
    speeds = data['speeds_in_order']
    assert speeds != sorted(speeds)
    # the CSV plays: the simulated run's reference is the file's position, row by row
    table = make_trajectory('table', file=str(exc))
    assert table.data.duration == pytest.approx(data['duration'])
    header = exc.read_text().splitlines()[:4]
    assert header[3] == 't,x,v,a' and 'rad' in header[1]
    plant = tmp_path / 'arm_plant.yaml'
    plant.write_text('plant: pmlm\naxis: rotary\nmotor: {mass_kg: 0.011, resistance_ohm: 1.0, '
                     'force_constant_N_per_A: 0.8, back_emf_V_s_per_m: 0.0}\n'
                     'effects: {coulomb: {fc: 0.045}, gravity: {mgl: 1.4, q0: 0.25}}\n')
    g = data['controller']
    run_file = tmp_path / 'run.mcap'
    code, out, err = _cli(capsys, 'simulate', '--plant', plant, '--trajectory', 'table',
                          '--set', f'traj.file={exc}', '--duration', 5.0, '-o', run_file,
                          '--set', f'kp={g["kp"]}', '--set', f'ki={g["ki"]}',
                          '--set', f'kd={g["kd"]}', '--set', f'tf={g["tf"]}', '--json')
    assert code == 0, err
    run = read_run(run_file)
    np.testing.assert_array_equal(run.reference, table.data.x[:len(run)])
    assert json.loads(out)['runs'][0]['max_error'] < 0.05     # the loop followed it


def test_excite_text_output(capsys, models, tmp_path):
    code, out, err = _cli(capsys, 'excite', '--model', models / 'ripple.yaml', '--travel',
                          -0.05, 0.05, '--vmax', 0.2, '--amax', 3, '--plant', 'pmlm',
                          '--fmax', 60, '-o', tmp_path / 'e.csv')
    assert code == 0, err
    assert 'predicted standard errors' in out and 'ripple.period' in out
    assert 'mass.mass' in out and 'passes at' in out and 'loop pid' in out
    assert (tmp_path / 'e.csv').stat().st_size > 0


@pytest.mark.parametrize('argv, needles', [
    (['--model', '{d}/missing.yaml'], ['missing.yaml', 'no such model file']),
    (['--model', '{d}/bad.yaml'], ['bad.yaml', 'coulomb.fc']),
    (['--model', '{d}/ripple.yaml', '--travel', '-0.01', '0.01'],
     ['travel too short', 'ripple period 0.02 m']),
    (['--model', '{d}/arm.yaml', '--travel', '-3', '3', '--period', '4'],
     ['travel too short', '--period 4']),
    (['--model', '{d}/arm.yaml', '--travel', '-1', '1'], ['gravity needs', 'half a revolution']),
    (['--model', '{d}/arm.yaml', '--travel', '3', '-3'], ['--travel', 'MIN < MAX']),
    (['--model', '{d}/arm.yaml', '--travel', '-3', 'x'], ['--travel', 'invalid float']),
    (['--model', '{d}/arm.yaml', '--vmax', '0'], ['--vmax', '> 0']),
    (['--model', '{d}/arm.yaml', '--vmax', 'nan'], ['--vmax', '> 0']),
    (['--model', '{d}/arm.yaml', '--duration', '5'], ['--duration 5 s is too short']),
    (['--model', '{d}/arm.yaml', '--duration', '600'], ['at most 240 s']),
    (['--model', '{d}/arm.yaml', '--fmax', '0.5'], ['leave no room']),
    (['--model', '{d}/arm.yaml', '--controller', 'npid'], ['--controller needs --plant']),
    (['--model', '{d}/arm.yaml', '--plant', 'lathe'], ['lathe', 'no such plant file']),
    (['--model', '{d}/arm.yaml', '-o', '{d}/no/e.csv'], ['-o', 'does not exist']),
])
def test_excite_bad_input(capsys, models, argv, needles):
    args = {'--travel': ['-3', '3'], '--vmax': ['5'], '-o': ['{d}/out.csv']}
    given = set(a for a in argv if a.startswith('-'))
    full = list(argv) + [x for k, v in args.items() if k not in given for x in [k, *v]]
    full = [a.format(d=models) for a in full]
    code, out, err = _cli(capsys, 'excite', *full)
    assert code == 2, (code, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('motor-comp: error:'), err
    assert 'Traceback' not in err
    for n in needles:
        assert n in lines[0], (n, lines[0])
    assert not (models / 'out.csv').exists()


def test_excite_help(capsys):
    code, out, err = _cli(capsys, 'excite', '--help')
    assert code == 0 and '--travel MIN MAX' in out and '--vmax V' in out
