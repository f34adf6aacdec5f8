"""Managed (lifecycle) nodes driven from this (separate) process via ``lifecycle_msgs``.

Plant, controller and recorder start with ``autostart:=false`` (unconfigured) and are
moved through configure → activate → deactivate → cleanup → shutdown by calls to the
standard ``<node>/change_state`` and ``<node>/get_state`` services, as a lifecycle
manager (Nav2's, or ``ros2 lifecycle set``) does it.  Every wait is for a condition (a
service reply, a state, a log line, a message count).
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader

from motor_comp.control import make_controller, make_trajectory, simulate
from motor_comp.control.nominal import derive_nominal
from motor_comp.logs import read_run
from motor_comp.physics.config import load_plant

pytestmark = pytest.mark.timeout(300)   # failure bound only: waits are on conditions

CONFIG = Path(__file__).resolve().parents[2] / 'config'
STEPS = 300


class Lifecycle:
    """Clients of ``/axis/<node>/change_state`` and ``get_state`` on the probe's node."""

    def __init__(self, probe) -> None:
        self.probe = probe
        self._clients: dict[str, object] = {}

    def _client(self, node: str, srv: str):
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState, GetState
        if srv == 'get_state':
            return self.probe.service(GetState, f'/axis/{node}/get_state', GetState.Request())
        # the ping: a transition id that does not exist is refused and changes nothing
        return self.probe.service(ChangeState, f'/axis/{node}/change_state',
                                  ChangeState.Request(transition=Transition(id=250)))

    def state(self, node: str) -> str:
        """Current lifecycle state label of ``node``."""
        from lifecycle_msgs.srv import GetState
        reply = self.probe.call(self._client(node, 'get_state'), GetState.Request(), 30,
                                f'{node} get_state reply', retry=True)
        return reply.current_state.label

    def change(self, node: str, transition: str) -> bool:
        """Request ``transition`` (label: configure, activate …); the reply's success."""
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState
        req = ChangeState.Request(transition=Transition(label=transition))
        # configure may load (or, after a source change, compile) the numba kernels
        return self.probe.call(self._client(node, 'change_state'), req, 120,
                               f'{node} {transition} reply').success


def _counts(path: Path) -> dict[str, int]:
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    return {ch.topic: summary.statistics.channel_message_counts.get(cid, 0)
            for cid, ch in summary.channels.items()}


def _readers(probe, topic: str) -> set[str]:
    return {i.node_name for i in probe.node.get_subscriptions_info_by_topic(topic)}


def test_lifecycle_transitions_from_another_process(tmp_path: Path, nodes, probe) -> None:
    """Unconfigured until told; inactive commands nothing; the run equals ``simulate``."""
    out = tmp_path / 'life.mcap'
    overrides = {
        '/axis/plant_node': {'autostart': False, 'duration': STEPS * 1e-3,
                             'plant': 'ballscrew', 'expected_subscribers': 3},
        # voltage readers: plant, recorder, probe
        '/axis/controller_node': {'autostart': False, 'plant': 'ballscrew',
                                  'expected_subscribers': 3},
        '/axis/trajectory_node': {'trajectory': 'sine'},
        '/axis/recorder_node': {'autostart': False, 'output': str(out)},
    }
    extra = tmp_path / 'override.yaml'
    extra.write_text(yaml.safe_dump({k: {'ros__parameters': v} for k, v in overrides.items()}))
    for node in ('plant_node', 'trajectory_node', 'controller_node', 'recorder_node'):
        nodes.start(node, CONFIG / f'{node}.yaml', ['--params-file', str(extra)])
    life = Lifecycle(probe)
    managed = ('plant_node', 'controller_node', 'recorder_node')

    # -- unconfigured; a transition that does not exist there is refused, not a crash --
    for node in managed:
        assert life.state(node) == 'unconfigured'
    assert not life.change('controller_node', 'activate')
    assert not life.change('recorder_node', 'deactivate')
    assert life.state('controller_node') == 'unconfigured'
    nodes.check_alive()
    assert 'refused lifecycle transition activate: not available in state unconfigured' \
        in nodes.procs['controller_node'].log.read_text()
    assert not out.exists()                      # the recorder opens its file on configure
    # autostart/discard are read-only: a runtime change is rejected with the reason
    res = probe.set_parameters('recorder_node', autostart=True, discard=True)
    assert not res[0].successful and 'read-only' in res[0].reason
    assert probe.get_parameter('recorder_node', 'autostart') is False

    # -- configure: the recorder's file is open (MCAP header written), nothing recorded --
    for node in managed:
        assert life.change(node, 'configure'), node
        assert life.state(node) == 'inactive'
    assert out.read_bytes()[:8] == b'\x89MCAP0\r\n'

    # -- the controller stays inactive: it reads nothing, so it commands nothing, and the
    # lockstep plant (active) does not start a run it would not answer --------------------
    assert life.change('recorder_node', 'activate')
    assert life.change('plant_node', 'activate')
    probe.spin_until(lambda: 'recorder_node' in _readers(probe, '/axis/joint_states'), 30,
                     'the recorder to subscribe joint_states')
    assert 'controller_node' not in _readers(probe, '/axis/joint_states')
    assert 'controller_node' not in _readers(probe, '/axis/reference')
    assert probe.voltages == [] and probe.positions == []
    assert 'peers matched' not in nodes.procs['plant_node'].log.read_text()

    # -- activate the controller: the loop runs its 300 steps ----------------------------
    assert life.change('controller_node', 'activate')
    assert life.state('controller_node') == 'active'
    probe.spin_until(lambda: len(probe.voltages) >= STEPS, 120, f'{STEPS} commands')
    assert nodes.wait('plant_node', 60, watch=False) == 0      # duration reached: exits

    # -- deactivate the recorder: the file is finalised (summary, every message) -------
    assert life.change('recorder_node', 'deactivate')
    assert life.state('recorder_node') == 'inactive'
    counts = _counts(out)
    assert counts['/axis/joint_states'] == counts['/axis/voltage'] == STEPS
    # activating again opens the next segment, never the finished file
    assert life.change('recorder_node', 'activate')
    seg = tmp_path / 'life.1.mcap'
    probe.spin_until(seg.exists, 10, 'the second segment')
    assert life.change('recorder_node', 'deactivate')
    assert _counts(seg).get('/axis/joint_states', 0) == 0
    assert _counts(out)['/axis/voltage'] == STEPS             # first file untouched

    # -- cleanup and shutdown of the controller and recorder ---------------------------
    for node in ('controller_node', 'recorder_node'):
        if life.state(node) == 'active':
            assert life.change(node, 'deactivate')
        assert life.change(node, 'cleanup')
        assert life.state(node) == 'unconfigured'
        assert life.change(node, 'shutdown')
        assert life.state(node) == 'finalized'
    log = nodes.procs['controller_node'].log.read_text()
    for step in ('configure', 'activate', 'deactivate', 'cleanup', 'shutdown'):
        assert f'lifecycle: {step} done' in log, step

    # the managed run is the in-process simulator's run, bit for bit
    recorded = read_run(out)
    cfg = load_plant('ballscrew')
    # (the controller node's law knows the nominal model derived from the plant file)
    sim = simulate(cfg, make_controller('pid', plant=derive_nominal(cfg)),
                   make_trajectory('sine'), duration=STEPS * 1e-3).to_run()
    assert len(recorded) == STEPS
    np.testing.assert_array_equal(recorded.position, sim.position)
    np.testing.assert_array_equal(recorded.voltage, sim.voltage)
    assert re.search(r'closed .*life\.mcap: ', nodes.procs['recorder_node'].log.read_text())


def test_autostart_failure_is_one_line(tmp_path: Path, ros_env) -> None:
    """autostart: a configure that fails (no such output directory) exits 2, one line."""
    import subprocess
    import sys
    res = subprocess.run([sys.executable, '-m', 'motor_comp.nodes.recorder_node',
                          '--ros-args', '-p', f'output:={tmp_path}/nope/r.mcap'],
                         capture_output=True, text=True, timeout=60, env=ros_env)
    assert res.returncode == 2, res.stderr
    assert 'Traceback' not in res.stderr
    err = [ln for ln in res.stderr.splitlines() if 'error:' in ln]
    assert len(err) == 1 and 'does not exist' in err[0], res.stderr
    # a wrongly typed autostart is rejected at declaration, one line
    res = subprocess.run([sys.executable, '-m', 'motor_comp.nodes.controller_node',
                          '--ros-args', '-p', 'autostart:=maybe'],
                         capture_output=True, text=True, timeout=60, env=ros_env)
    assert res.returncode == 2 and 'Traceback' not in res.stderr, res.stderr
    assert 'autostart' in res.stderr
    # the output rule: an existing file, or a link at the path, is never written
    kept = tmp_path / 'kept.mcap'
    kept.write_bytes(b'an earlier recording')
    link = tmp_path / 'link.mcap'
    link.symlink_to(kept)
    for out in (kept, link):
        res = subprocess.run([sys.executable, '-m', 'motor_comp.nodes.recorder_node',
                              '--ros-args', '-p', f'output:={out}'],
                             capture_output=True, text=True, timeout=60, env=ros_env)
        err = [ln for ln in res.stderr.splitlines() if 'error:' in ln]
        assert res.returncode == 2 and len(err) == 1, res.stderr
        assert f'{out}: exists; refused' in err[0], err
        assert kept.read_bytes() == b'an earlier recording'
    assert link.is_symlink()
