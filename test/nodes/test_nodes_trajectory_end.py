"""``trajectory_node`` with ``exit_at_end`` (and ``wait_for_command``): a caller's end and start.

A caller that plays one trajectory on a drive with its own clock (``motor-comp
autotune --external-plant``) waits for the trajectory node to exit.  Lockstep: it exits
with status 0 once the reference of tick ``duration·rate`` is out, and the run still
completes, every step with its reference.  Realtime: exactly ``duration·rate + 1``
references on the plant's sample grid after its time origin, the node exits with 0, and
the controller, seeing no reference any more, commands 0 V.  With ``wait_for_command``
the trajectory time starts with a measurement after the controller's first command, not
with the plant's first sample.  Waits are on process exits and messages.
"""
from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from motor_comp.cli.run import RunSpec, write_params_file
from motor_comp.logs import read_run

pytestmark = pytest.mark.timeout(300)   # failure bound only

REMAP = ['-r', '__ns:=/axis']


def _reference_stamps(path: Path, topic: str = '/axis/reference') -> np.ndarray:
    """Header stamps [ns] of every recorded ``topic`` message, in file order."""
    out = []
    with open(path, 'rb') as fh:
        for _, _, msg in make_reader(fh).iter_messages(topics=[topic]):
            sec, nsec = struct.unpack_from('<iI', msg.data, 4)
            out.append(sec * 1_000_000_000 + nsec)
    return np.array(out, dtype=np.int64)


def _start(nodes, tmp_path: Path, spec: RunSpec, extra: dict) -> dict:
    params = spec.node_params()
    for node, values in extra.items():
        params[node].update(values)
    pfile = write_params_file(tmp_path / 'params.yaml', params)
    for node in ('recorder_node', 'controller_node', 'trajectory_node', 'plant_node'):
        nodes.start(node, pfile, REMAP)
    return params


def test_lockstep_exit_at_end_keeps_the_run_whole(tmp_path: Path, nodes) -> None:
    duration = 0.6
    spec = RunSpec(output=tmp_path / 'run.mcap', plant='pmlm', trajectory='sine',
                   duration=duration)
    _start(nodes, tmp_path, spec, {'trajectory_node': {'exit_at_end': True}})
    assert nodes.wait('trajectory_node', 120, watch=False) == 0
    assert nodes.wait('plant_node', 120, watch=False) == 0     # the run completed
    nodes.stop('controller_node')
    assert nodes.stop('recorder_node') == 0
    run = read_run(spec.output)
    n = round(duration * 1000)
    assert len(run) == n and np.all(np.isfinite(run.reference))
    stamps = _reference_stamps(spec.output)
    assert stamps[-1] == round(duration * 1e9)                   # tick duration·rate last
    assert np.unique(stamps).size == n + 1                       # every tick 0 … n once
    assert 'stopping (done)' in nodes.procs['trajectory_node'].log.read_text()


@pytest.mark.alone   # wall-clock ticks: the machine to itself (make test's second part)
@pytest.mark.parametrize('wait', [False, True], ids=['first-sample', 'wait-for-command'])
def test_realtime_exit_at_end_then_zero_volts(tmp_path: Path, nodes, probe, wait) -> None:
    duration = 1.0
    spec = RunSpec(output=tmp_path / 'run.mcap', plant='pmlm', trajectory='sine',
                   timing='realtime', duration=duration)
    # the plant runs on (a drive); the probe reads voltage and joint_states too
    _start(nodes, tmp_path, spec, {'trajectory_node': {'exit_at_end': True,
                                                       'wait_for_command': wait},
                                   'plant_node': {'duration': 0.0, 'expected_subscribers': 4},
                                   'controller_node': {'expected_subscribers': 3}})
    assert nodes.wait('trajectory_node', 120) == 0
    ended = len(probe.voltages)
    # no reference any more: after stale_timeout the controller commands 0 V
    probe.spin_until(lambda: 0.0 in probe.voltages[ended:], 30, 'a 0 V command')
    nodes.check_alive(except_=('trajectory_node',))
    for node in ('plant_node', 'controller_node'):
        nodes.stop(node)
    assert nodes.stop('recorder_node') == 0
    stamps = _reference_stamps(spec.output)
    t0 = stamps[-1] - round(duration * 1e9)
    after = stamps[stamps >= t0]
    grid = after[(after - t0) % 1_000_000 == 0]
    # the grid, every tick in order, to tick duration·rate, the last; it starts at tick 0
    # or a few later: the held start point may be stamped a few ms after t0 on the same
    # clock (the first tick comes after the first sample), and stamps only increase
    assert grid[-1] == stamps[-1] and np.all(np.diff(grid) == 1_000_000)
    assert 0 <= grid[0] - t0 <= 10_000_000
    # the held start point is published for each measurement before the first tick, so
    # how many there are is the scheduler's (1 on an idle machine; 2 and 3 seen in CI):
    # what is asserted is that they all come first, within the grid's own 10 ms bound
    held = after.size - grid.size
    assert held <= 10 and np.all(after[:held] < grid[0])
    run = read_run(spec.output)
    # its time origin is a measurement's stamp: the grid is the plant's
    assert np.min(np.abs(run.t - t0 * 1e-9)) < 1e-6
    # the trajectory says which sample started its time (and, waiting, why)
    log = nodes.procs['trajectory_node'].log.read_text()
    start = re.search(r'trajectory time starts with the sample stamped (\d+\.\d+) s( \(after '
                      r"the controller's first command\))?", log)
    assert start and abs(float(start.group(1)) - t0 * 1e-9) < 1e-5
    assert bool(start.group(2)) == wait
