"""Limits enforced by the nodes (issue 24 item 2): a trip stops the axis, the run says why.

``motor-comp run`` with limits, the nodes as processes in lockstep.  A lockstep run is
the in-process simulator's run bit for bit, so the simulator says exactly at which
sample the limit breaks; the test checks that the controller tripped *there*:

* travel: the PMLM's point-to-point move ends at 0.05 m, the travel ends 20 µm beyond;
  the PID's overshoot (37 µm) crosses it mid-run;
* tracking error: the plant's friction is 5× that of the packaged PMLM (a worn axis,
  a plant file): the error grows past a bound (0.1 mm) the nominal axis stays below.

Each time: the command is 0 V from the trip on (in the recording), ``motor-comp run``
exits with status 3 and the one-line reason (limit, value, bound, time), and the MCAP
holds every sample up to the stop, readable by ``motor-comp analyze``.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from motor_comp.control import make_controller, make_trajectory, simulate
from motor_comp.control.nominal import derive_nominal
from motor_comp.logs import read_run
from motor_comp.physics.config import load_plant

pytestmark = pytest.mark.timeout(300)   # failure bound only

DURATION = 1.0
HOLD = 0.05     # controller_node trip_hold default: 0 V commands after the trip


def _cli(*args: str, env) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', *args],
                          capture_output=True, text=True, timeout=240, env=env)


def _simulated(plant: str):
    cfg = load_plant(plant)
    return simulate(cfg, make_controller('pid', plant=derive_nominal(cfg)),
                    make_trajectory('p2p'), duration=DURATION).to_run()


def _check_trip(tmp_path: Path, out: Path, cli, sim, k: int, expected: str) -> None:
    """Exit 3 with ``expected``; 0 V from sample ``k`` on; the samples up to the stop."""
    assert cli.returncode == 3, cli.stderr
    assert cli.stdout == ''                                   # --json: nothing on error
    err = cli.stderr.strip().splitlines()[-1]
    assert err.startswith(f'motor-comp: error: {expected} (the axis was stopped at 0 V; '
                          f'the recording up to the stop is {out})'), err
    assert 'Traceback' not in cli.stderr
    assert sorted(p.name for p in tmp_path.glob('*.mcap')) == [out.name]   # no partial

    rec = read_run(out)
    # every sample up to the trip is the simulator's, bit for bit
    np.testing.assert_array_equal(rec.position[:k + 1], sim.position[:k + 1])
    np.testing.assert_array_equal(rec.voltage[:k], sim.voltage[:k])
    assert sim.voltage[k] != 0.0
    # from the trip on: 0 V, for the hold (then the controller exited and the run stopped)
    after = rec.voltage[k:]
    assert np.all(after == 0.0), after[after != 0.0][:5]
    assert int(round(HOLD * 1000)) <= after.size <= int(round(HOLD * 1000)) + 5
    assert rec.t[-1] < DURATION - 0.1                        # the run ended at the trip

    # the recording is a complete MCAP: analyze reads it and reports the trip
    ana = _cli('analyze', str(out), '--json', env=None)
    assert ana.returncode == 0, ana.stderr
    row = json.loads(ana.stdout)['runs'][0]
    assert row['samples'] == len(rec)
    assert row['limits']['tripped'] is True
    assert row['limits']['message'] == expected
    assert row['limits']['t'] == pytest.approx(sim.t[k], abs=1e-9)


def test_travel_limit_trip(tmp_path: Path, ros_env) -> None:
    sim = _simulated('pmlm')
    hi = 0.05002
    assert sim.reference.max() <= 0.05 < hi < sim.position.max()   # overshoot only
    k = int(np.flatnonzero(sim.position > hi)[0])
    expected = (f'travel limit: position {sim.position[k]:.6g} m beyond [-0.01, {hi:g}] m '
                f'at t = {sim.t[k]:.3f} s')
    out = tmp_path / 'travel.mcap'
    out.write_bytes(b'an older recording')         # -o replaced only by a finished one
    cli = _cli('run', '--plant', 'pmlm', '--controller', 'pid', '--duration', str(DURATION),
               '--travel', '-0.01', str(hi), '-o', str(out), '--json',
               '--domain-id', ros_env['ROS_DOMAIN_ID'], env=ros_env)
    _check_trip(tmp_path, out, cli, sim, k, expected)
    assert read_run(out).metadata['params:controller_node/travel'] == f'[-0.01, {hi}]'


def test_tracking_error_trip_on_a_worn_axis(tmp_path: Path, ros_env) -> None:
    plant = yaml.safe_load((Path(__file__).resolve().parents[2] / 'motor_comp' / 'config'
                            / 'pmlm.yaml').read_text())
    for effect, key in (('coulomb', 'fc'), ('stribeck', 'fs'), ('viscous', 'fv')):
        plant['effects'][effect][key] *= 5.0
    worn = tmp_path / 'plants' / 'worn.yaml'
    worn.parent.mkdir()
    worn.write_text(yaml.safe_dump(plant))
    bound = 1e-4
    nominal, sim = _simulated('pmlm'), _simulated(str(worn))
    assert np.max(np.abs(nominal.reference - nominal.position)) < bound   # would not trip
    err = np.abs(sim.reference - sim.position)
    k = int(np.flatnonzero(err > bound)[0])
    expected = (f'tracking error: |x_ref - x| {err[k]:.6g} m beyond {bound:g} m at '
                f't = {sim.t[k]:.3f} s')
    out = tmp_path / 'worn.mcap'
    # the plant file lies outside the working directory: run lets the nodes read it
    cli = _cli('run', '--plant', str(worn), '--controller', 'pid', '--trajectory', 'p2p',
               '--duration', str(DURATION), '--max-error', str(bound), '-o', str(out),
               '--json', '--domain-id', ros_env['ROS_DOMAIN_ID'], env=ros_env)
    _check_trip(tmp_path, out, cli, sim, k, expected)


def test_limit_parameters_at_start_and_at_run_time(tmp_path: Path, nodes, probe) -> None:
    """Bad limits or a trajectory beyond them: one line, exit 2; live: rejected, kept."""
    def start(name: str, node: str, params: dict) -> None:
        f = tmp_path / f'{name}.yaml'
        f.write_text(yaml.safe_dump({f'/axis/{node}': {'ros__parameters': params}}))
        nodes.start_as(name, node, f)

    start('bad_travel', 'controller_node', {'travel': [0.05, -0.05]})
    start('beyond', 'trajectory_node', {'trajectory': 'p2p', 'duration': 2.0,
                                        'travel': [-0.01, 0.03]})
    for name, needle in (('bad_travel', 'travel: expected min < max, got [0.05, -0.05]'),
                         ('beyond', 'trajectory refused: travel limit: reference position')):
        assert nodes.wait(name, 60, watch=False) == 2
        log = nodes.procs[name].log.read_text()
        errors = [ln for ln in log.splitlines() if ': error: ' in ln]
        assert len(errors) == 1 and needle in errors[0], log
        assert 'Traceback' not in log

    # a running trajectory node: a change beyond the limits is rejected, the old stays
    start('trajectory_node', 'trajectory_node', {'trajectory': 'p2p', 'duration': 2.0,
                                                 'travel': [-0.01, 0.06], 'vmax': 0.2})
    res = probe.set_parameters('trajectory_node', p2p__distance=0.08)[0]
    assert not res.successful
    assert res.reason.startswith('trajectory refused: travel limit: reference position '), \
        res.reason
    assert probe.get_parameter('trajectory_node', 'p2p.distance') == 0.05
    res = probe.set_parameters('trajectory_node', p2p__move_time=0.2)[0]   # 0.47 m/s
    assert not res.successful and 'speed limit: reference velocity' in res.reason
    assert probe.set_parameters('trajectory_node', p2p__distance=0.052)[0].successful
    # limits are read-only: not loosened from the graph
    res = probe.set_parameters('trajectory_node', travel=[-1.0, 1.0])[0]
    assert not res.successful and 'read-only' in res.reason
    nodes.check_alive(except_=('bad_travel', 'beyond'))
