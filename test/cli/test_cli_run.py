"""``motor-comp run``'s node parameters and what it passes on from the nodes' logs."""
from __future__ import annotations

import subprocess
import sys

import pytest

from motor_comp.cli.run import NodeProcess, RunSpec


def test_the_recorder_waits_for_the_nodes_as_long_as_the_run_may_take(tmp_path):
    """The recorder knows which nodes come; a 10 s cap gave up on a slow-starting plant.

    The plant then ran its short lockstep run and exited before the recorder had its
    parameters (``params:plant_node`` missing under load).  Its wait is bounded by the
    run's own timeout (60 s + 20 s per second of run), not by its own clock.
    """
    pytest.importorskip('rclpy')
    from motor_comp.nodes.recorder_node import PARAMS
    spec = RunSpec(output=tmp_path / 'r.mcap', duration=1.5)
    wait = spec.node_params()['recorder_node']['match_timeout']
    # the most the recorder's parameter takes (a larger value would be refused)
    assert wait == next(p for p in PARAMS if p.name == 'match_timeout').high
    assert wait >= 60.0 + 20.0 * spec.duration


def test_a_nodes_warnings_are_read_from_its_log(tmp_path):
    log = tmp_path / 'recorder_node.log'
    log.write_text('[INFO] [1.0] [axis.recorder_node]: recording to r.mcap\n'
                   '[WARN] [2.0] [axis.recorder_node]: no parameters from plant_node after '
                   '600 s: recording without them\n'
                   '[ERROR] [3.0] [axis.recorder_node]: disk full\n')
    proc = NodeProcess('recorder_node', subprocess.Popen([sys.executable, '-c', 'pass']), log)
    proc.popen.wait()
    assert proc.warnings() == [
        '[WARN] [2.0] [axis.recorder_node]: no parameters from plant_node after 600 s: '
        'recording without them', '[ERROR] [3.0] [axis.recorder_node]: disk full']
    assert NodeProcess('x', proc.popen, tmp_path / 'missing.log').warnings() == []
