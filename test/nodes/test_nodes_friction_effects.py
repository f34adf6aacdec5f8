"""The nodes get load- and position-dependent friction through the plant and model files.

Issue 23 item 3: a ball-screw plant file with ``load_friction`` and ``position_friction``
run by ``motor-comp run --mode lockstep`` (four node processes) records the numbers of
the in-process simulator exactly, and those differ from the plain ball-screw's; the
plant node's live ``friction_scale`` scales the new levels with the others.  Issue 24:
``controller_node`` accepts a ``compensation_model`` with both effects, reports them
compensated, and its commands are the in-process simulator's with that compensation.
"""
from __future__ import annotations

import json
import subprocess
import sys
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

from motor_comp.cli.run import RunSpec, run_nodes
from motor_comp.control import compensation as cm
from motor_comp.control import make_controller, make_trajectory, simulate
from motor_comp.control.nominal import derive_nominal
from motor_comp.errors import ParameterError
from motor_comp.logs import read_run
from motor_comp.physics.config import load_plant

pytestmark = pytest.mark.timeout(300)   # failure bound only

#: a screw-like load term and a tight spot of +8 N at 1.5 mm, inside the default
#: ball-screw sine (±3 mm)
NEW_EFFECTS = ('  load_friction: {mu: 0.2}\n'
               '  position_friction: {x: [0.0005, 0.0015, 0.0025], dfc: [0.0, 8.0, 0.0]}\n')


def _worn_ballscrew(tmp_path: Path) -> Path:
    """Write config/ballscrew.yaml with the new effects added; return its path."""
    base = resources.files('motor_comp').joinpath('config', 'ballscrew.yaml').read_text(
        encoding='utf-8')
    head, sensors = base.split('\nsensors:')
    path = tmp_path / 'worn_ballscrew.yaml'
    path.write_text(head + '\n' + NEW_EFFECTS + 'sensors:' + sensors)
    return path


def test_lockstep_nodes_run_the_new_effects_like_the_simulator(tmp_path: Path, ros_env):
    plant_file = _worn_ballscrew(tmp_path)
    cfg = load_plant(plant_file)
    assert {'load_friction', 'position_friction', 'presliding', 'delay'} <= set(
        cfg.model.names)
    duration = 1.0
    out = tmp_path / 'nodes.mcap'
    cli = subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', 'run',
                          '--plant', str(plant_file), '--controller', 'npid',
                          '--feedforward', 'static+gms', '--mode', 'lockstep',
                          '--duration', str(duration), '-o', str(out), '--json',
                          '--domain-id', ros_env['ROS_DOMAIN_ID']],
                         capture_output=True, text=True, timeout=240)
    assert cli.returncode == 0, cli.stderr
    assert json.loads(cli.stdout)['runs'][0]['plant'] == str(plant_file)
    recorded = read_run(out)

    def in_process(plant):
        ctrl = make_controller('npid', plant=derive_nominal(plant), feedforward='static+gms')
        return simulate(plant, ctrl, make_trajectory('sine'), duration=duration).to_run()

    sim = in_process(cfg)
    assert len(recorded) == len(sim) == int(round(duration * 1000))
    np.testing.assert_array_equal(recorded.position, sim.position)
    assert np.max(np.abs(recorded.voltage - sim.voltage)) <= 1e-9
    # the effects acted: the plain ball-screw tracks differently (tens of µm)
    plain = in_process(load_plant('ballscrew'))
    assert np.max(np.abs(plain.position - sim.position)) >= 2e-5


def test_friction_scale_scales_the_whole_dry_level(tmp_path: Path):
    from motor_comp.nodes.plant_node import scale_friction
    model = load_plant(_worn_ballscrew(tmp_path)).model
    x = np.linspace(-0.004, 0.004, 81)
    for scale in (0.0, 0.5, 2.0):
        scaled = scale_friction(model, scale)
        assert scaled.get('load_friction').mu == pytest.approx(scale * 0.2)
        np.testing.assert_allclose(
            scaled.fc + scaled.dry_friction_shift(x, f_in=40.0),
            scale * (model.fc + model.dry_friction_shift(x, f_in=40.0)), rtol=1e-12)
    with pytest.raises(ParameterError, match='load_friction.mu'):
        scale_friction(model, 5.0)                        # mu = 1: refused, one line


def test_lockstep_controller_compensates_the_new_effects(tmp_path: Path, ros_env):
    plant_file = _worn_ballscrew(tmp_path)
    cfg = load_plant(plant_file)
    model = tmp_path / 'worn_model.yaml'
    cfg.model.save(model)
    duration = 1.0
    spec = RunSpec(output=tmp_path / 'nodes.mcap', plant=str(plant_file), controller='npid',
                   duration=duration,
                   extra_params={'controller_node': {'compensation_model': str(model),
                                                     'compensation_terms': 'full'}})
    out = run_nodes(spec, workdir=tmp_path, domain_id=int(ros_env['ROS_DOMAIN_ID']),
                    progress=False)
    recorded = read_run(out)
    # the node loaded the file and says what it compensates, with nothing left out
    log = (tmp_path / 'controller_node.log').read_text(errors='replace')
    assert 'presliding, delay, load_friction, position_friction' in log
    assert 'not compensated' not in log and "'not_compensated': {}" in log

    def in_process(comp):
        ctrl = make_controller('npid', plant=derive_nominal(cfg))
        ctrl.set_compensation(comp)
        return simulate(cfg, ctrl, make_trajectory('sine'), duration=duration).to_run()

    sim = in_process(cm.load_model(model))
    assert len(recorded) == len(sim) == int(round(duration * 1000))
    assert np.max(np.abs(recorded.voltage - sim.voltage)) <= 1e-9
    np.testing.assert_array_equal(recorded.position, sim.position)
    # the compensation with the effects acted: without them the loop tracks worse
    plain = in_process(cm.from_model(cfg.model.without('load_friction',
                                                       'position_friction')))
    rms = float(np.sqrt(np.mean((recorded.position - recorded.reference) ** 2)))
    rms_plain = float(np.sqrt(np.mean((plain.position - plain.reference) ** 2)))
    assert rms < 0.1 * rms_plain, (rms, rms_plain)     # measured 0.58 / 24.3 µm = 0.024
