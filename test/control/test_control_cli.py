"""``motor-comp simulate`` and ``motor-comp sweep``: JSON contract, MCAP output, errors."""
from __future__ import annotations

import concurrent.futures
import csv
import json
import subprocess
import sys

import numpy as np
import pytest

import motor_comp.cli.main as cli
from motor_comp.control import default_trajectory, make_controller, simulate
from motor_comp.control.nominal import derive_nominal
from motor_comp.control.sweep import expand_grid, run_point, run_sweep


@pytest.fixture(autouse=True)
def only_our_subcommands(monkeypatch):
    """Register only simulate/sweep so other helpers' work in progress cannot interfere."""
    monkeypatch.setattr(cli, 'SUBCOMMANDS', ('simulate', 'sweep'))


def _cli(capsys, *argv):
    code = cli.main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_simulate_json_matches_library(capsys, ballscrew):
    code, out, err = _cli(capsys, 'simulate', '--plant', 'ballscrew', '--controller', 'npid',
                          '--feedforward', 'static+gms', '--duration', '3', '--json')
    assert code == 0
    data = json.loads(out)
    (entry,) = data['runs']
    for key in ('rms_error', 'max_error', 'max_glitch', 'mean_glitch', 'glitches'):
        assert key in entry
    assert {'t', 'magnitude'} <= set(entry['glitches'][0])
    assert len(entry['glitches']) == 2          # reversals at 1 s and 2 s (sine, P = 2 s)
    from motor_comp.analysis.metrics import compute_metrics
    # the CLI's controller knows the nominal model derived from the plant file
    ctrl = make_controller('npid', plant=derive_nominal(ballscrew), feedforward='static+gms')
    res = simulate(ballscrew, ctrl, default_trajectory('ballscrew'), duration=3.0)
    m = compute_metrics(res.to_run())
    assert entry['rms_error'] == m.rms_error and entry['max_glitch'] == m.max_glitch


def test_simulate_records_mcap_with_parameters(capsys, tmp_path, pmlm):
    path = tmp_path / 'run.mcap'
    code, out, _ = _cli(capsys, 'simulate', '--plant', 'pmlm', '--controller',
                        'adaptive_sliding', '--duration', '1', '--seed', '3',
                        '--set', 'phi=3e-4', '-o', str(path))
    assert code == 0 and 'recorded' in out
    from motor_comp.logs import read_run
    run = read_run(path)
    meta = run.metadata
    assert meta['plant'] == 'pmlm' and meta['controller'] == 'adaptive_sliding'
    assert meta['seed'] == '3' and meta['feedforward'] == 'none'
    assert json.loads(meta['gains'])['phi'] == 3e-4
    assert json.loads(meta['settings']) == {'phi': 3e-4}
    ctrl = make_controller('adaptive_sliding', plant=derive_nominal(pmlm), phi=3e-4)
    res = simulate(pmlm, ctrl, default_trajectory('pmlm'), duration=1.0, seed=3)
    np.testing.assert_allclose(run.position, res.position, atol=1e-12)
    np.testing.assert_allclose(run.voltage, res.voltage, rtol=1e-12)


@pytest.mark.parametrize('argv,needle', [
    (['--set', 'bogus=1'], "unknown parameter 'bogus'"),
    (['--set', 'plant.coulomb.fc=-3'], 'plant.coulomb.fc'),
    (['--plant', 'missing.yaml'], 'missing.yaml: no such plant file'),
    (['--trajectory', 'sine', '--set', 'traj.period=0'], 'sine.period'),
    (['--set', 'traj.period=2'], "trajectory p2p: unknown parameter 'period'"),
    (['--set', 'nonsense'], 'expected name=value'),
    (['--duration', '1e9'], 'split it into shorter runs'),
    (['--set', 'rates.control_hz=3000'], 'not a whole number of physics steps'),
    (['--controller', 'adaptive_sliding', '--feedforward', 'gms'], 'presliding'),
])
def test_simulate_bad_input_is_one_line(capsys, argv, needle):
    code, out, err = _cli(capsys, 'simulate', '--duration', '0.1', *argv)
    assert code == 2 and out == ''
    assert err.count('\n') == 1 and err.startswith('motor-comp: error:') and needle in err


def test_simulate_subprocess_exit_status_without_traceback():
    prog = ('import sys, motor_comp.cli.main as m; m.SUBCOMMANDS = ("simulate",); '
            'sys.exit(m.main(sys.argv[1:]))')
    out = subprocess.run([sys.executable, '-c', prog, 'simulate', '--duration', '-1'],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2 and 'Traceback' not in out.stderr
    assert '--duration' in out.stderr


def test_sweep_cli_json_and_csv(capsys, tmp_path):
    table = tmp_path / 'sweep.csv'
    code, out, _ = _cli(capsys, 'sweep', '--plant', 'ballscrew', '--controller', 'npid',
                        '--duration', '3', '--grid', 'feedforward=none,static+gms',
                        '--workers', '2', '--csv', str(table), '--json')
    assert code == 0
    data = json.loads(out)
    pts = {p['feedforward']: p for p in data['points']}
    assert set(pts) == {'none', 'static+gms'}
    assert pts['static+gms']['rms_error'] < 0.6 * pts['none']['rms_error']
    assert pts['static+gms']['max_glitch'] < 0.5 * pts['none']['max_glitch']
    with open(table, newline='') as f:
        rows = list(csv.reader(f))
    assert rows[0][:3] == ['feedforward', 'rms_error', 'max_error']
    assert len(rows) == 3 and float(rows[2][1]) == pts['static+gms']['rms_error']


def test_sweep_bad_grid_fails_before_running(capsys):
    code, _, err = _cli(capsys, 'sweep', '--grid', 'kp=1,-2', '--duration', '0.1')
    assert code == 2 and 'kp=-2.0' in err and 'pid.kp' in err
    code, _, err = _cli(capsys, 'sweep', '--duration', '0.1')
    assert code == 2 and 'nothing to sweep' in err


def test_run_sweep_with_injected_executor_matches_serial():
    points = expand_grid({'plant': 'pmlm', 'controller': 'pid', 'duration': 0.5},
                         {'kp': [2e4, 4.8e4], 'plant.coulomb.fc': [5.0, 15.0]})
    assert len(points) == 4 and points[1] == {'plant': 'pmlm', 'controller': 'pid',
                                              'duration': 0.5, 'kp': 2e4,
                                              'plant.coulomb.fc': 15.0}
    with concurrent.futures.ThreadPoolExecutor(max_workers=2) as ex:
        got = run_sweep(points, executor=ex)
    serial = [run_point(p) for p in points]
    assert [g.point for g in got] == points
    for g, s in zip(got, serial):
        assert g.metrics == s.metrics
    # the true friction changed (plant.*), the controller's nominal did not: errors differ
    assert got[0].metrics['rms_error'] != got[1].metrics['rms_error']
