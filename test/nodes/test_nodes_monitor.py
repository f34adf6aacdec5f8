"""Live: monitor_node turns OK → WARN naming friction; compensation_model updates.

One lockstep loop of real node processes (plant, trajectory, controller, monitor) on a
private localhost domain, and a probe in the test process:

* the monitor watches the plant's own model file: ``/diagnostics`` says OK;
* a malformed ``compensation_model`` is rejected with the reason (file and field named)
  and the loop keeps commanding; a valid one is accepted and the monitor stays OK;
* the plant's friction changes mid-run (``friction_scale`` 1 → 1.6, a parameter update of
  plant_node): within one monitor window of the change (sim time, from the plant's log)
  the monitor reports WARN and names friction as the candidate.
Every wait is on a condition (message counts, log lines, statuses), never on wall time.
"""
from __future__ import annotations

import json
import re
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.timeout(150)

CONFIG = Path(__file__).resolve().parents[2] / 'motor_comp' / 'config'
WINDOW = 2.0
UPDATE = 0.25


def _log(nodes, name: str) -> str:
    return nodes.procs[name].log.read_text(errors='replace')


def test_monitor_live_friction_change_and_compensation_updates(tmp_path, nodes, probe):
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from motor_comp.physics.config import load_plant

    model = tmp_path / 'pmlm_model.yaml'
    load_plant('pmlm').model.save(model)
    bad = tmp_path / 'bad.yaml'
    bad.write_text('mass: 5.4\neffects:\n  coulomb: {fc: -3}\n')
    overrides = {
        # the plant waits for the controller's, the monitor's and the probe's readers
        '/axis/plant_node': {'duration': 0.0, 'expected_subscribers': 3,
                             'expected_clock_subscribers': 1},
        # voltage readers: plant, monitor, probe; reference readers: the controller
        # (the files the test names are in tmp_path: the nodes may read only there)
        '/axis/controller_node': {'expected_subscribers': 3, 'model_dir': str(tmp_path)},
        '/axis/trajectory_node': {'expected_subscribers': 1},
        '/axis/monitor_node': {'model': str(model), 'window': WINDOW,
                               'update_period': UPDATE, 'model_dir': str(tmp_path)},
    }
    override_file = tmp_path / 'override.yaml'
    override_file.write_text(yaml.safe_dump(
        {k: {'ros__parameters': v} for k, v in overrides.items()}))
    extra = ['--params-file', str(override_file)]
    nodes.start('monitor_node', CONFIG / 'monitor_node.yaml', extra)
    for node in ('plant_node', 'trajectory_node', 'controller_node'):
        nodes.start(node, CONFIG / f'{node}.yaml', extra)

    statuses: list = []
    probe.node.create_subscription(
        DiagnosticArray, '/diagnostics', lambda m: statuses.extend(m.status),
        QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE))

    def kv(st) -> dict[str, str]:
        return {v.key: v.value for v in st.values}

    def verdicts(n: int) -> bool:
        nodes.check_alive()   # a node that died fails at once, with its log
        return len(statuses) >= n

    probe.spin_until(lambda: verdicts(3), 90, lambda: f'3 verdicts, got {len(statuses)}')
    first = statuses[-1]
    assert first.level == b'\x00', first.message          # OK: the model is the plant's
    assert float(kv(first)['force_nrmse']) < 0.15
    assert 'rms_residual_N' in kv(first) and 'axis' in first.name

    # -- compensation_model: malformed file rejected with the reason, loop keeps running
    res = probe.set_parameters('controller_node', compensation_model=str(bad))
    assert not res[0].successful
    assert 'bad.yaml' in res[0].reason and 'coulomb.fc' in res[0].reason, res[0].reason
    res = probe.set_parameters('controller_node', compensation_model=str(tmp_path / 'no.yaml'))
    assert not res[0].successful and 'no.yaml: no such file' in res[0].reason
    assert probe.get_parameter('controller_node', 'compensation_model') == ''
    n0 = len(probe.voltages)
    probe.spin_until(lambda: len(probe.voltages) >= n0 + 300, 30, 'commands after reject')
    res = probe.set_parameters('controller_node', compensation_model=str(model))
    assert res[0].successful, res[0].reason
    probe.spin_until(lambda: 'compensation from' in _log(nodes, 'controller_node'), 20,
                     'compensation log line')
    assert 'coulomb, viscous, stribeck, ripple' in _log(nodes, 'controller_node')
    res = probe.set_parameters('controller_node', compensation_table=str(tmp_path / 't.csv'))
    assert not res[0].successful and 'exclusive' in res[0].reason

    # -- bad monitor / plant parameters: rejected with the reason, nothing changes ------
    res = probe.set_parameters('monitor_node', model=str(bad))
    assert not res[0].successful and 'coulomb.fc' in res[0].reason, res[0].reason
    res = probe.set_parameters('monitor_node', warn_nrmse=0.6)      # above error_nrmse
    assert not res[0].successful and 'warn_nrmse < error_nrmse' in res[0].reason
    res = probe.set_parameters('plant_node', friction_scale=-1.0)
    assert not res[0].successful and 'friction_scale' in res[0].reason

    # -- the plant's friction changes: OK -> WARN within one window, naming friction --
    n1 = len(statuses)
    probe.spin_until(lambda: len(statuses) >= n1 + 2, 60, 'verdicts with compensation')
    assert all(s.level == b'\x00' for s in statuses[n1:]), \
        ([s.message for s in statuses], _log(nodes, 'monitor_node')[-3000:])
    res = probe.set_parameters('plant_node', friction_scale=1.6)
    assert res[0].successful, res[0].reason
    probe.spin_until(lambda: 'friction x1.6 from step' in _log(nodes, 'plant_node'), 20,
                     'plant friction log')
    k = int(re.search(r'friction x1\.6 from step (\d+)', _log(nodes, 'plant_node'))[1])
    t_change = k * 1e-3
    n2 = len(statuses)

    def window_end(st) -> float:
        return float(kv(st)['window_end_s'])

    # verdicts until the window lies entirely after the change
    probe.spin_until(lambda: statuses[n2:] and window_end(statuses[-1]) >= t_change + WINDOW,
                     60, lambda: f'verdicts past the change; got '
                                 f'{[s.message for s in statuses[n2:]]}')
    within = [s for s in statuses[n2:] if window_end(s) <= t_change + WINDOW + 1e-6]
    warned = [s for s in within if s.level != b'\x00']
    tail = _log(nodes, 'monitor_node')[-3000:]
    assert warned, ([s.message for s in within], tail)         # OK -> WARN in the window
    assert all(s.level == b'\x01' for s in warned), ([s.message for s in warned], tail)
    values = kv(warned[-1])      # the window (nearly) all after the change
    assert 'friction' in values['candidate_title'], values
    # the status is not asserted: the model's own friction 'changed' is the right name,
    # but once in 8 suite runs since the screen covers the whole library a friction
    # term it lacks that spans a level shift (load-/position-dependent) scored a little
    # higher ('missing') — still friction, going up (issue 23 note)
    assert float(values['candidate_explains']) > 0.5
    assert 0.15 <= float(values['force_nrmse']) < 0.5
    change = json.loads(values['candidate_change'])
    assert list(change.values())[0] > 0                         # friction went up
    assert 'level OK -> WARN' in _log(nodes, 'monitor_node')
    nodes.check_alive()


def test_window_health_offline_levels_and_candidates():
    """The monitor's core on simulated windows (no ROS): OK, WARN naming friction, STALE."""
    import numpy as np

    from motor_comp.control.controller import make_controller
    from motor_comp.control.simulator import simulate
    from motor_comp.control.trajectories import default_trajectory
    from motor_comp.errors import ParameterError
    from motor_comp.nodes.plant_node import scale_friction
    from motor_comp.physics.config import load_plant
    from motor_comp.physics.effects import make_effect
    from motor_comp.workbench.monitor import Level, window_health

    cfg = load_plant('pmlm')
    traj = default_trajectory('pmlm')

    def window(model):
        res = simulate(cfg.with_model(model), make_controller('pid', plant=cfg), traj,
                       duration=2.0)
        return res.t, res.position, res.voltage

    ok = window_health(*window(cfg.model), cfg.model)
    assert ok.level is Level.OK and ok.nrmse < 0.1 and ok.candidate is None
    worn = window_health(*window(scale_friction(cfg.model, 1.6)), cfg.model)
    assert worn.level is Level.WARN and 0.15 < worn.nrmse < 0.5
    assert worn.candidate.effect == 'coulomb' and worn.candidate.status == 'changed'
    assert 4.0 < worn.candidate.change['fc'] < 12.0        # fc 10 → 16 N, fs 20 → 32 N
    assert worn.rms_residual > 5 * ok.rms_residual
    drag = window_health(*window(cfg.model.with_effect(make_effect('offset', {'f0': 25.0}))),
                         cfg.model)
    assert drag.level is not Level.OK and drag.candidate.effect == 'offset'
    assert drag.candidate.status == 'missing'
    assert drag.candidate.change['f0'] == pytest.approx(25.0, rel=0.1)
    t = np.arange(2000) * 1e-3
    rest = window_health(t, np.full_like(t, 0.01), np.zeros_like(t), cfg.model)
    assert rest.level is Level.STALE
    with pytest.raises(ParameterError, match='warn_nrmse < error_nrmse'):
        window_health(t, t, t, cfg.model, warn=0.5, error=0.2)


@pytest.mark.parametrize('params, needle', [
    ({}, 'model: a model file (YAML) is required'),
    ({'model': 'MODEL', 'warn_nrmse': 0.9}, 'warn_nrmse < error_nrmse'),
])
def test_monitor_bad_start_parameters(tmp_path, nodes, params, needle):
    """A bad start parameter: one line naming it, exit status 2, no traceback.

    (A bad model file at run time, and the ranges, are in the live test above.)
    """
    from motor_comp.physics.config import load_plant
    if params.get('model') == 'MODEL':
        params['model'] = str(tmp_path / 'm.yaml')
        params['model_dir'] = str(tmp_path)
        load_plant('pmlm').model.save(params['model'])
    f = tmp_path / 'p.yaml'
    f.write_text(yaml.safe_dump({'/axis/monitor_node': {'ros__parameters': params}}))
    nodes.start('monitor_node', f)
    assert nodes.wait('monitor_node', 60) == 2
    log = _log(nodes, 'monitor_node')
    assert needle in log and 'Traceback' not in log, log


@pytest.mark.parametrize('seed', range(5))
def test_a_change_of_the_models_own_term_is_preferred_to_a_nested_new_one(seed):
    """The nested test of the screen (issue 23 note): a term the model lacks whose column
    holds the level a change of the model's own term explains is named only when it
    removes more than its price on top of that change."""
    import types

    import numpy as np

    from motor_comp.workbench.monitor import Candidate, _prefer_change

    rng = np.random.default_rng(seed)
    n = 2000
    sgn = np.sign(np.sin(np.linspace(0.0, 12.0 * np.pi, n)))
    load = 20.0 + rng.normal(0.0, 0.3, n)            # a steady drive force [N]
    r = 6.0 * sgn + rng.normal(0.0, 0.5, n)          # a friction level shift + noise
    res = types.SimpleNamespace(r=r, data=types.SimpleNamespace(n_eff=float(n)))
    own = Candidate('coulomb', 'changed', 0.9, {'fc': 6.0})
    new = Candidate('load_friction', 'missing', 0.91, {'mu': 0.3})
    kept = {id(own): (res, sgn[:, None], 1), id(new): (res, (load * sgn)[:, None], 1)}
    # scored a hair higher, the nested term adds nothing beyond the change: the change
    assert _prefer_change((0.91, new), [(0.9, own)], kept)[1] is own
    # a load dependence the level cannot explain: the new term is named
    r2 = 6.0 * sgn + 0.5 * (load - 20.0) * sgn * 10.0 + rng.normal(0.0, 0.5, n)
    res2 = types.SimpleNamespace(r=r2, data=res.data)
    kept2 = {id(own): (res2, sgn[:, None], 1), id(new): (res2, (load * sgn)[:, None], 1)}
    assert _prefer_change((0.95, new), [(0.9, own)], kept2)[1] is new
    # judged on other rows: no joint fit, the scores decide
    kept3 = {id(own): (res, sgn[:, None], 1), id(new): (res2, (load * sgn)[:, None], 1)}
    assert _prefer_change((0.91, new), [(0.9, own)], kept3)[1] is new
