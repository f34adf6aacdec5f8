"""Nodes: a ``table`` trajectory and the full inverse-model compensation, live.

* Lockstep ``motor-comp run``-style loop (four node processes) playing a table CSV with
  the plant's model as full compensation: the recorded reference is the CSV, and the
  whole run equals the in-process simulator's (the reference acceleration travels as the
  reference message's effort; the compensation is the controller's one compiled step).
* A live loop with a probe: ``compensation_terms`` is validated and switches bumplessly
  (the command at the switch steps by far less than the feedforward it changes); a bad
  table ``file`` is rejected with a one-line reason that names the row, never the file's
  content; a file outside ``model_dir`` is refused unopened; a valid table is accepted.
Every wait is on a condition (counts, log lines), never on wall time.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml

from motor_comp.cli.run import RunSpec, run_nodes
from motor_comp.control import compensation as cm
from motor_comp.control import make_controller, simulate
from motor_comp.control.nominal import derive_nominal
from motor_comp.control.trajectories import make_trajectory
from motor_comp.logs import read_run
from motor_comp.physics.config import load_plant

pytestmark = pytest.mark.timeout(300)   # failure bound only

CONFIG = Path(__file__).resolve().parents[2] / 'motor_comp' / 'config'
MARKER = 'SECRET-MARKER-91c2'


def _table(path: Path, duration: float = 1.2, amplitude: float = 0.01) -> np.ndarray:
    """A move from rest and back (positions only: v, a derived by the reader)."""
    t = np.arange(0.0, duration, 1e-3)
    x = amplitude * (1.0 - np.cos(2 * np.pi * t / duration))
    path.write_text('t,x\n' + ''.join(f'{float(a)!r},{float(b)!r}\n' for a, b in zip(t, x)))
    return x


def _cruise(path: Path, speed: float = 0.02, ramp: float = 0.5,
            duration: float = 60.0) -> None:
    """Ramp up smoothly (raised-cosine velocity over ``ramp``), then a constant speed."""
    t = np.arange(0.0, duration, 1e-3)
    tr = np.minimum(t, ramp)
    x = speed * (0.5 * tr - ramp / (2 * np.pi) * np.sin(np.pi * tr / ramp)) \
        + speed * np.maximum(t - ramp, 0.0)
    path.write_text('t,x\n' + ''.join(f'{float(a)!r},{float(b)!r}\n' for a, b in zip(t, x)))


def test_lockstep_table_with_full_compensation_equals_simulator(tmp_path: Path,
                                                                ros_env) -> None:
    csv = tmp_path / 'move.csv'
    x = _table(csv)
    model = tmp_path / 'pmlm.yaml'
    cfg = load_plant('pmlm')
    cfg.model.save(model)
    duration = 1.2
    spec = RunSpec(output=tmp_path / 'nodes.mcap', plant='pmlm', controller='pid',
                   trajectory='table', trajectory_file=str(csv), duration=duration,
                   extra_params={'controller_node': {'compensation_model': str(model),
                                                     'compensation_terms': 'full',
                                                     'model_dir': str(tmp_path)}})
    out = run_nodes(spec, workdir=tmp_path, domain_id=int(ros_env['ROS_DOMAIN_ID']),
                    progress=False)
    recorded = read_run(out)
    n = int(round(duration * 1000))
    assert len(recorded) == n
    np.testing.assert_array_equal(recorded.reference, x[:n])        # the CSV, row by row
    ctrl = make_controller('pid', plant=derive_nominal(cfg))
    ctrl.set_compensation(cm.load_model(model))
    sim = simulate(cfg, ctrl, make_trajectory('table', file=str(csv)),
                   duration=duration).to_run()
    np.testing.assert_array_equal(recorded.reference_velocity, sim.reference_velocity)
    # the feedforward's inertia needs the acceleration: equal commands prove it arrived
    assert np.max(np.abs(recorded.voltage - sim.voltage)) <= 1e-9
    np.testing.assert_array_equal(recorded.position, sim.position)
    # and the inverse model did the work: the error is a few encoder counts
    assert np.sqrt(np.mean(recorded.error ** 2)) < 5e-6


def _log(nodes, name: str) -> str:
    return nodes.procs[name].log.read_text(errors='replace')


def test_live_terms_switch_and_table_file_rules(tmp_path, nodes, probe) -> None:
    allowed = tmp_path / 'allowed'
    outside = tmp_path / 'outside'
    allowed.mkdir()
    outside.mkdir()
    _cruise(allowed / 'move.csv')
    cfg = load_plant('pmlm')
    cfg.model.save(allowed / 'pmlm.yaml')
    overrides = {
        # joint_states readers: controller and probe; /clock readers: the trajectory
        '/axis/plant_node': {'duration': 0.0, 'expected_subscribers': 2,
                             'expected_clock_subscribers': 1, 'x0': 0.0},
        # voltage readers: plant and probe (the probe sees every command from the first)
        '/axis/controller_node': {'expected_subscribers': 2,
                                  'compensation_model': str(allowed / 'pmlm.yaml'),
                                  'compensation_terms': 'full', 'model_dir': str(allowed)},
        '/axis/trajectory_node': {'expected_subscribers': 1, 'trajectory': 'table',
                                  'file': str(allowed / 'move.csv'),
                                  'model_dir': str(allowed)},
    }
    override_file = tmp_path / 'override.yaml'
    override_file.write_text(yaml.safe_dump(
        {k: {'ros__parameters': v} for k, v in overrides.items()}))
    extra = ['--params-file', str(override_file)]
    for node in ('plant_node', 'trajectory_node', 'controller_node'):
        nodes.start(node, CONFIG / f'{node}.yaml', extra)

    def commands(n: int) -> bool:
        nodes.check_alive()
        return len(probe.voltages) >= n

    probe.spin_until(lambda: commands(600), 90, lambda: f'600 commands, '
                     f'got {len(probe.voltages)}')

    # -- compensation_terms: validated, switched bumplessly while the axis moves ------
    res = probe.set_parameters('controller_node', compensation_terms='inverse')
    assert not res[0].successful and 'compensation_terms' in res[0].reason, res[0].reason
    res = probe.set_parameters('controller_node', compensation_terms='effects')
    assert res[0].successful, res[0].reason
    pattern = re.compile(r'\(effects\): [^\n]* from command (\d+)')
    probe.spin_until(lambda: pattern.search(_log(nodes, 'controller_node')), 30,
                     'effects log line')
    k = int(pattern.search(_log(nodes, 'controller_node')).group(1))
    probe.spin_until(lambda: commands(k + 50), 30, 'commands after the switch')
    u = np.asarray(probe.voltages)
    # the feedforward the switch removed: the back-EMF at the cruise speed (the table
    # cruises at 20 mm/s from 0.5 s to 60 s); the command must not step by it
    assert 600 <= k < 59_000
    removed = 123.0 * 0.02
    jump = abs(u[k] - u[k - 1])             # command k is the first without it
    # the level around the switch (5 commands each side: a single derivative spike of a
    # velocity-count flip, Kd·1 mm/s ≈ 0.23 V, averages out; a switch that is not
    # bumpless shifts the level by the whole removed feedforward)
    shift = abs(np.mean(u[k:k + 5]) - np.mean(u[k - 5:k]))
    assert jump < 0.2 * abs(removed), (jump, removed)
    assert shift < 0.1 * abs(removed), (shift, removed)

    # -- the table file: a bad one rejected (row named, content never), rules enforced --
    bad = allowed / 'bad.csv'
    bad.write_text(f'# {MARKER}\nt,x\n0,0\n0.002,0\n0.001,{MARKER}\n0.003,0\n0.004,0\n'
                   '0.005,0\n')
    res = probe.set_parameters('trajectory_node', file=str(bad))
    assert not res[0].successful
    assert 'data row 3, column x: not a number' in res[0].reason, res[0].reason
    assert MARKER not in res[0].reason
    bad.write_text(f'# {MARKER}\nt,x\n0,0\n0.002,0\n0.001,0\n0.003,0\n0.004,0\n0.005,0\n')
    res = probe.set_parameters('trajectory_node', file=str(bad))
    assert not res[0].successful and 'not strictly increasing at data row 3' in \
        res[0].reason and MARKER not in res[0].reason, res[0].reason
    _table(outside / 'move.csv')
    res = probe.set_parameters('trajectory_node', file=str(outside / 'move.csv'))
    assert not res[0].successful and 'outside the allowed directories' in res[0].reason
    assert probe.get_parameter('trajectory_node', 'file') == str(allowed / 'move.csv')
    res = probe.set_parameters('trajectory_node', model_dir=str(outside))
    assert not res[0].successful and 'read-only' in res[0].reason
    log = _log(nodes, 'trajectory_node')
    assert MARKER not in log
    _table(allowed / 'other.csv', duration=2.0)
    res = probe.set_parameters('trajectory_node', file=str(allowed / 'other.csv'))
    assert res[0].successful, res[0].reason
    n = len(probe.voltages)
    probe.spin_until(lambda: commands(n + 200), 30, 'commands after the new table')
