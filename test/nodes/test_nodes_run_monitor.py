"""``motor-comp run --monitor MODEL.yaml`` (issue 24): the verdicts recorded and summarised.

Two lockstep runs of the PMLM (its force ripple is 8.5 N over a 20 mm period), each
with ``monitor_node`` watching a model file:

* the right model (the plant's own): every verdict OK, no candidate, NRMSE < 0.15;
* a wrong one, whose ripple has zero amplitude (the model misses the ripple, at the
  right period): no verdict OK, the last WARN, the candidate ``ripple`` *changed* by
  a₁ ≈ +8.5 N.

The verdicts are in the MCAP as ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``,
``ros2msg`` schema, read here with rosbags as another tool would), stamped with their
window's end; each one is what the monitor's core says on the recorded window.  The run's
JSON and ``motor-comp analyze --json`` carry the same ``monitor`` summary.
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from motor_comp.logs import read_run
from motor_comp.logs.diagnostics import read_diagnostics
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.config import load_plant
from motor_comp.workbench.monitor import window_health

pytestmark = pytest.mark.timeout(300)   # failure bound only

DURATION = 3.0
WINDOW = 2.0      # monitor_node defaults: window 2 s, a verdict every 0.5 s


def _run(tmp_path: Path, model: Path, env) -> tuple[Path, dict]:
    out = tmp_path / f'{model.stem}.mcap'
    cli = subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', 'run',
                          '--plant', 'pmlm', '--controller', 'pid',
                          '--duration', str(DURATION), '--monitor', str(model),
                          '-o', str(out), '--json', '--domain-id', env['ROS_DOMAIN_ID']],
                         capture_output=True, text=True, timeout=240, env=env)
    assert cli.returncode == 0, cli.stderr
    return out, json.loads(cli.stdout)['runs'][0]


def _channel(path: Path) -> tuple[str, str, list]:
    """Message type, serialization and the statuses, as rosbags reads them."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as ar:
        conns = [c for c in ar.connections if c.topic == '/diagnostics']
        assert len(conns) == 1
        c = conns[0]
        statuses = [s for _, _, raw in ar.messages(connections=conns)
                    for s in ar.deserialize(raw, c.msgtype).status]
        return c.msgtype, c.ext.serialization_format, statuses


# once seen failing under heavy load (the wrong model's last verdict ERROR 0.77, not WARN),
# cause not found: it runs with the machine to itself (make test's second part)
@pytest.mark.alone
def test_run_monitor_right_and_wrong_model(tmp_path: Path, ros_env) -> None:
    plant = load_plant('pmlm').model
    right, wrong = tmp_path / 'right.yaml', tmp_path / 'wrong.yaml'
    plant.save(right)
    d = plant.to_dict()
    d['effects']['ripple']['harmonics'] = [[0.0, 0.0]]
    AxisModel.from_dict(d).save(wrong)

    out_r, row_r = _run(tmp_path, right, ros_env)
    out_w, row_w = _run(tmp_path, wrong, ros_env)
    n_verdicts = int(DURATION / 0.5) - 1      # one every 0.5 s of stamp time

    mon = row_r['monitor']
    assert mon['verdicts'] >= n_verdicts, mon
    assert mon['statuses']['OK'] == mon['verdicts'], mon
    assert mon['candidate'] is None and mon['worst_nrmse'] < 0.15, mon

    mon = row_w['monitor']
    assert mon['verdicts'] >= n_verdicts, mon
    assert mon['statuses']['OK'] == 0 and mon['last_level'] == 'WARN', mon
    assert mon['statuses']['WARN'] + mon['statuses']['ERROR'] == mon['verdicts']
    assert (mon['candidate'], mon['candidate_status']) == ('ripple', 'changed'), mon
    assert mon['candidate_verdicts'] == mon['verdicts']
    assert 0.15 <= mon['last_nrmse'] < 0.5 and mon['worst_nrmse'] >= mon['last_nrmse']
    assert 'limits' not in row_w                    # no limits set: no limits status

    # the recorded verdicts: a standard channel, and what the core says on each window
    msgtype, encoding, statuses = _channel(out_w)
    assert (msgtype, encoding) == ('diagnostic_msgs/msg/DiagnosticArray', 'cdr')
    assert len(statuses) == mon['verdicts']
    assert all(s.name == 'motor_comp/axis: model monitor' for s in statuses)
    records = read_diagnostics(out_w)
    run = read_run(out_w)
    model = AxisModel.load(wrong)
    for rec in records:
        end = float(rec.values['window_end_s'])
        assert rec.t == pytest.approx(end, abs=1e-9)          # stamped with its window
        sel = (run.t >= end - WINDOW - 1e-9) & (run.t <= end + 1e-9)
        h = window_health(run.t[sel], run.position[sel], run.voltage[sel], model)
        assert h.level.name == rec.level
        assert h.samples == int(rec.values['samples'])
        assert h.nrmse == pytest.approx(float(rec.values['force_nrmse']), rel=1e-5)
    change = json.loads(records[-1].values['candidate_change'])
    assert change['a1'] == pytest.approx(8.5, rel=0.05)       # the plant's ripple
    assert abs(change['b1']) < 0.5

    # analyze reads the same summary from the file
    ana = subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', 'analyze',
                          str(out_r), str(out_w), '--json'], capture_output=True, text=True,
                         timeout=120)
    assert ana.returncode == 0, ana.stderr
    rows = json.loads(ana.stdout)['runs']
    assert [r['monitor'] for r in rows] == [row_r['monitor'], row_w['monitor']]
