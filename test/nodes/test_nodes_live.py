"""Live checks on one set of node processes (DDS discovery is slow: reuse them).

Runtime reconfiguration through the SetParameters service, controller saturation,
stale-data watchdog, non-finite inputs, and the recorder's fault tolerance: SIGTERM
finalises with every received message, SIGKILL leaves a file readable up to its last
complete chunk.
"""
from __future__ import annotations

import json
import math
import os
import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from motor_comp.logs import read_run

pytestmark = pytest.mark.timeout(300)   # failure bound only: waits are on conditions

CONFIG = Path(__file__).resolve().parents[2] / 'motor_comp' / 'config'


def _counts(path: Path) -> dict[str, int]:
    with open(path, 'rb') as f:
        summary = make_reader(f).get_summary()
    return {ch.topic: summary.statistics.channel_message_counts.get(cid, 0)
            for cid, ch in summary.channels.items()}


def _log(nodes, name: str) -> str:
    return nodes.procs[name].log.read_text(errors='replace')


def _controller_events(nodes) -> list[tuple[float, str]]:
    """(wall time [s], 'stale' | 'back') of the controller's watchdog log lines."""
    pattern = (r'\[(\d+\.\d+)\] \[[\w.]*controller_node\]: '
               r'(stale data \(no reference|reference is back)')
    return [(float(t), 'stale' if what.startswith('stale') else 'back')
            for t, what in re.findall(pattern, _log(nodes, 'controller_node'))]


def test_live_reconfiguration_and_fault_tolerance(tmp_path: Path, nodes, probe) -> None:
    """One lockstep loop (PMLM, PID), two recorders, a probe in the test process."""
    overrides = {
        '/axis/plant_node': {'duration': 0.0, 'expected_subscribers': 4,
                             'expected_clock_subscribers': 3},
        # every reader of voltage (plant, two recorders, probe) and of reference
        # (controller, two recorders) is matched before the first message goes out
        '/axis/controller_node': {'stale_timeout': 0.3, 'expected_subscribers': 4},
        '/axis/trajectory_node': {'expected_subscribers': 3},
        '/axis/recorder_node': {'output': str(tmp_path / 'a.mcap')},
        '/axis/recorder_b': {'output': str(tmp_path / 'b.mcap'), 'chunk_size': 4096},
    }
    override_file = tmp_path / 'override.yaml'
    override_file.write_text(yaml.safe_dump(
        {k: {'ros__parameters': v} for k, v in overrides.items()}))
    extra = ['--params-file', str(override_file)]
    # the shipped parameter files, as a user would pass them, plus the test's overrides;
    # started plant first, recorders last: the nodes wait for each other
    for node in ('plant_node', 'trajectory_node', 'controller_node', 'recorder_node'):
        nodes.start(node, CONFIG / f'{node}.yaml', extra)
    nodes.start_as('recorder_b', 'recorder_node', CONFIG / 'recorder_node.yaml',
                   extra + ['-r', '__node:=recorder_b'])

    # start-up: numba loads (or compiles, after a source change) the kernels first
    probe.spin_until(lambda: len(probe.voltages) >= 300, 180, 'the loop to run')
    nodes.check_alive()

    # -- saturation: a valid runtime change takes effect -------------------------------
    assert max(abs(u) for u in probe.voltages) > 1.0      # the move needs > 1 V unlimited
    res = probe.set_parameters('controller_node', pid__u_max=0.5)
    assert res[0].successful, res[0].reason
    n0 = len(probe.voltages)

    scan = {'next': n0, 'start': n0}

    def settled() -> int | None:
        # commands still queued at the probe predate the change: the limit holds from
        # just after the last command above it (scanned incrementally: the probe must
        # stay fast enough to keep up with the loop)
        volts = probe.voltages
        for i in range(scan['next'], len(volts)):
            if abs(volts[i]) > 0.5 + 1e-12:
                scan['start'] = i + 1
        scan['next'] = len(volts)
        # and the law has reached the limit since: a starved controller's watchdog
        # commands 0 V for a while (a stress run's 300 commands were all zeros)
        if len(volts) - scan['start'] < 300:
            return None
        if max(abs(u) for u in volts[scan['start']:]) < 0.5 - 1e-12:
            return None
        return scan['start']

    probe.spin_until(lambda: settled() is not None, 60, '300 commands within the limit')
    start = settled()
    assert start - n0 < 3000                               # applied promptly
    after = np.array(probe.voltages[start:])
    assert np.max(np.abs(after)) == pytest.approx(0.5)     # and it does saturate

    # -- invalid changes: rejected with a reason, old value kept, loop keeps running ---
    bad = probe.set_parameters('controller_node', pid__kp=-5.0)
    assert not bad[0].successful and 'kp' in bad[0].reason
    bad = probe.set_parameters('controller_node', mode='bogus')
    assert not bad[0].successful and 'bogus' in bad[0].reason
    bad = probe.set_parameters('controller_node', feedforward='gms')   # PMLM: no GMS
    assert not bad[0].successful and 'presliding' in bad[0].reason
    bad = probe.set_parameters('plant_node', plant='ballscrew')
    assert not bad[0].successful and 'read-only' in bad[0].reason
    assert probe.get_parameter('controller_node', 'pid.kp') == 48000.0
    assert probe.get_parameter('controller_node', 'mode') == 'pid'
    n1 = len(probe.voltages)
    probe.spin_until(lambda: len(probe.voltages) >= n1 + 200, 30, 'the loop after rejects')

    # -- mode switch at run time (bumpless, estimates kept) ------------------------------
    res = probe.set_parameters('controller_node', pid__u_max=math.inf,
                               mode='adaptive_sliding')
    assert res[0].successful and res[1].successful
    n2 = len(probe.voltages)
    probe.spin_until(lambda: len(probe.voltages) >= n2 + 300, 30, 'adaptive commands')
    assert 'now adaptive_sliding' in _log(nodes, 'controller_node')

    # -- non-finite inputs never reach the law or the plant ----------------------------
    nan_js = JointState(name=['axis'], position=[math.nan], velocity=[0.0], effort=[0.0])
    nan_ref = JointState(name=['axis'], position=[0.0], velocity=[math.inf], effort=[0.0])
    # readers: controller + recorder + recorder_b (the probe's own is not counted)
    probe.publish('joint_states', nan_js, readers=3)
    probe.publish('reference', nan_ref, readers=3)
    for what in ('measurement', 'reference'):
        line = f'ignored {what} with missing or non-finite'
        probe.spin_until(lambda: line in _log(nodes, 'controller_node'), 30, line)
    n3 = len(probe.voltages)
    probe.spin_until(lambda: len(probe.voltages) >= n3 + 200, 30, 'commands after NaN')
    assert all(math.isfinite(u) for u in probe.voltages)

    # -- bumpless switching through the parameter service (Controller.set_mode/
    # set_feedforward re-balance the integrator to the last output): the step at the
    # switch (the controller logs the index of the first command of the new law) stays
    # within twice the largest step-to-step change of the 50 commands on either side.
    # Offline on this loop a switch *without* re-balancing jumps 10–23 V (adaptive →
    # npid during a move) or 0.13–0.27 V at rest, where the loop moves < 0.01 V per step;
    # with it the step is 0.002–0.22 V, within the natural variation.
    not_judged = []
    for change in ({'mode': 'npid'}, {'feedforward': 'static'}):
        res = probe.set_parameters('controller_node', **change)
        assert res[0].successful, res[0].reason
        label = f'now npid + {change.get("feedforward", "none")} feedforward from command '
        probe.spin_until(lambda: label in _log(nodes, 'controller_node'), 20, 'switch log')
        k = int(re.search(re.escape(label) + r'(\d+)', _log(nodes, 'controller_node'))[1])
        probe.spin_until(lambda: len(probe.voltages) >= k + 60, 30, 'switched commands')
        window = np.array(probe.voltages[k - 51:k + 51])
        if np.any(window == 0.0):
            # watchdog zeros around the switch: the controller was starved of references
            # (> 0.3 s, a stress run at load 8), so the law's step is not in this window
            not_judged.append(f'{change}: {int(np.sum(window == 0.0))} stale 0 V commands '
                              f'among the 101 around the switch')
            continue
        du = np.abs(np.diff(window))   # du[50]: u_k − u_k-1
        natural = max(du[:50].max(), du[51:].max())
        assert du[50] <= 2.0 * natural, (change, du[50], natural)

    # -- SIGKILL of recorder B mid-run: its file is readable up to the last chunk ------
    nodes.stop('recorder_b', sig=signal.SIGKILL)

    # -- stale reference: freeze the trajectory node -> 0 V with a warning -------------
    # Conditions, not wall time: the probe may still be taking commands computed before
    # the stop, so the check is on the *sequence* it receives — law commands, then (once
    # the last reference published ahead is used and the 0.3 s timeout ran out) zeros
    # and nothing else while the trajectory stays stopped.
    traj = nodes.procs['trajectory_node'].popen
    n_stop = len(probe.voltages)
    t_stop = time.time()            # the nodes' log stamps are wall-clock seconds
    os.kill(traj.pid, signal.SIGSTOP)
    try:
        def zeros_run() -> int:
            tail = 0
            for u in reversed(probe.voltages[n_stop:]):
                if u != 0.0:
                    break
                tail += 1
            return tail

        def stale_since_stop() -> list[float]:
            return [t for t, what in _controller_events(nodes)
                    if what == 'stale' and t > t_stop]

        probe.spin_until(lambda: stale_since_stop() and zeros_run() >= 200, 60,
                         '200 stale commands (0 V)')
        t_cont = time.time()
    finally:
        os.kill(traj.pid, signal.SIGCONT)
    # once the references published ahead of the stop are used up, the controller goes
    # stale and stays so while the trajectory is stopped: no "reference is back" in
    # between (judged on the controller's log, not on the probe's list, which may still
    # hold commands from before the stop — among them, on a starved machine, a zero of
    # an earlier 0.3 s stall: a stress run at load 8)
    first_stale = stale_since_stop()[0]
    resumed = [t for t, what in _controller_events(nodes)
               if what == 'back' and first_stale < t < t_cont]
    assert not resumed, (first_stale, resumed, t_cont)
    assert zeros_run() >= 200
    probe.spin_until(lambda: any(u != 0.0 for u in probe.voltages[-20:]), 30,
                     'control to resume')
    assert 'reference is back' in _log(nodes, 'controller_node')

    # -- the plant refuses a non-finite command ----------------------------------------
    probe.publish('voltage', Float64(data=math.nan), readers=2)   # plant + recorder
    probe.spin_until(lambda: 'refused non-finite command' in _log(nodes, 'plant_node'), 20,
                     'the plant to refuse NaN')
    n5 = len(probe.positions)
    probe.spin_until(lambda: len(probe.positions) >= n5 + 100, 30, 'the loop after NaN')
    assert sum(not math.isfinite(x) for x in probe.positions) == 1   # the probe's own

    # -- stop: plant first (quiet graph), then SIGTERM the recorder ---------------------
    assert nodes.stop('plant_node') == 0                    # SIGINT: clean exit
    published = int(re.search(r'stopped: (\d+) measurements published',
                              _log(nodes, 'plant_node')).group(1))
    # the recorder drains until the graph is quiet: every message of the run is in its
    # file — the plant's and controller's own counts (+ 1 each: the probe's injected NaN
    # measurement and NaN command, recorded like any message on the topic)
    assert nodes.stop('controller_node', sig=signal.SIGTERM) == 0
    commands = int(re.search(r'stopped: (\d+) commands published',
                             _log(nodes, 'controller_node')).group(1))
    assert nodes.stop('recorder_node', sig=signal.SIGTERM) == 0
    assert nodes.stop('trajectory_node') == 0
    counts = _counts(tmp_path / 'a.mcap')     # summary present = finalised file
    assert counts['/axis/joint_states'] == published + 1
    assert counts['/axis/voltage'] == commands + 1

    # recorder B: killed without finishing; the reader recovers the complete chunks
    run_b = read_run(tmp_path / 'b.mcap')
    assert 300 < len(run_b) < published
    assert np.all(np.diff(run_b.t) > 0)
    analyze = subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', 'analyze',
                              str(tmp_path / 'b.mcap'), '--json'],
                             capture_output=True, text=True, timeout=60)
    assert analyze.returncode == 0, analyze.stderr
    assert json.loads(analyze.stdout)['runs'][0]['max_error'] > 0
    assert 'Traceback' not in analyze.stderr
    if not_judged:   # everything else was checked; say what was not
        pytest.skip('bumpless switch not judged: ' + '; '.join(not_judged))
