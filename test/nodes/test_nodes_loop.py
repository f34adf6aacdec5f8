"""The four nodes as separate processes close the loop and record a valid MCAP.

The lockstep run must reproduce the in-process simulator exactly: same step functions,
same per-step order, same floats (DESIGN.md §2: one implementation, two drivers).
"""
from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader

from motor_comp.analysis.metrics import compute_metrics
from motor_comp.cli.run import DEFAULT_RT_PRIORITY, RunSpec, run_nodes
from motor_comp.control import make_controller, make_trajectory, simulate
from motor_comp.control.nominal import derive_nominal
from motor_comp.logs import read_run
from motor_comp.physics.config import load_plant

pytestmark = pytest.mark.timeout(300)   # failure bound only

TYPES = {'/axis/reference': 'sensor_msgs/msg/JointState',
         '/axis/joint_states': 'sensor_msgs/msg/JointState',
         '/axis/voltage': 'std_msgs/msg/Float64', '/clock': 'rosgraph_msgs/msg/Clock'}


def _channels(path: Path) -> dict[str, tuple[str, str, str, int]]:
    with open(path, 'rb') as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
        counts = summary.statistics.channel_message_counts
        out = {ch.topic: (summary.schemas[ch.schema_id].name,
                          summary.schemas[ch.schema_id].encoding, ch.message_encoding,
                          counts.get(cid, 0)) for cid, ch in summary.channels.items()}
    out['__profile__'] = (header.profile, '', '', 0)
    return out


def test_lockstep_nodes_equal_in_process_simulator(tmp_path: Path, ros_env) -> None:
    """Ball-screw, N-PID + static+GMS feedforward (delay, GMS state): identical numbers."""
    duration = 1.5
    out = tmp_path / 'nodes.mcap'
    cli = subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', 'run',
                          '--plant', 'ballscrew', '--controller', 'npid',
                          '--feedforward', 'static+gms', '--mode', 'lockstep',
                          '--duration', str(duration), '-o', str(out), '--json',
                          '--domain-id', ros_env['ROS_DOMAIN_ID']],
                         capture_output=True, text=True, timeout=240)
    assert cli.returncode == 0, cli.stderr
    printed = json.loads(cli.stdout)['runs'][0]

    # the file: ros2 profile, ros2msg schemas, CDR, the DESIGN §5 topics with their types
    chans = _channels(out)
    assert chans.pop('__profile__')[0] == 'ros2'
    assert {t: c[0] for t, c in chans.items()} == TYPES
    assert all(c[1] == 'ros2msg' and c[2] == 'cdr' for c in chans.values())
    n = int(round(duration * 1000))
    assert chans['/axis/joint_states'][3] == n
    assert chans['/axis/voltage'][3] == n
    # the trajectory publishes ahead of /clock but not past the run's end (tick n closes
    # it); the plant publishes /clock every clock_every = 10 ticks
    assert chans['/axis/reference'][3] == n + 1
    assert chans['/clock'][3] == n // 10

    recorded = read_run(out)
    cfg = load_plant('ballscrew')
    sim = simulate(cfg, make_controller('npid', plant=derive_nominal(cfg),
                                        feedforward='static+gms'),
                   make_trajectory('sine'), duration=duration).to_run()
    assert len(recorded) == len(sim) == n
    np.testing.assert_allclose(recorded.t, sim.t, rtol=0, atol=1e-12)   # ns stamps
    # same laws, same numbers: equal to the last bit (the contract allows 1e-9)
    assert np.max(np.abs(recorded.error - sim.error)) <= 1e-9
    assert np.max(np.abs(recorded.voltage - sim.voltage)) <= 1e-9
    np.testing.assert_array_equal(recorded.position, sim.position)
    # `motor-comp run` printed the metrics of the recorded file = those of the simulation
    expected = compute_metrics(sim).as_dict()
    for key in ('rms_error', 'max_error', 'max_glitch', 'mean_glitch'):
        assert printed[key] == pytest.approx(expected[key], rel=1e-12, abs=1e-15), key
    # the loop really tracked: the error is far below the 3 mm stroke
    assert 0 < np.max(np.abs(recorded.error)) < 1e-4

    # run parameters as metadata, queried from the nodes' parameter services
    meta = recorded.metadata
    # (the nodes' log on a miss: the recorder says what it waited for and for how long)
    for key in ('params:controller_node/mode', 'params:plant_node/plant',
                'params:trajectory_node/trajectory'):
        assert key in meta, cli.stderr[-3000:]
    assert meta['params:controller_node/mode'] == 'npid'
    assert meta['params:controller_node/feedforward'] == 'static+gms'
    assert meta['params:plant_node/plant'] == 'ballscrew'
    assert meta['params:trajectory_node/trajectory'] == 'sine'
    assert meta['run/count:/axis/voltage'] == str(n)

    # the run describes itself like `motor-comp simulate -o` does, so the workbench's
    # closed-loop replay works on a ROS recording: with the true plant model it is the
    # simulator's run again (lockstep = simulator, bit for bit), with coulomb friction
    # left out of the model it visibly is not
    assert (meta['plant'], meta['controller'], meta['feedforward']) == \
        ('ballscrew', 'npid', 'static+gms')
    assert json.loads(meta['trajectory']) == make_trajectory('sine').params()
    true_model, wrong_model = tmp_path / 'true.yaml', tmp_path / 'wrong.yaml'
    cfg.model.save(true_model)
    cfg.model.without('coulomb').save(wrong_model)
    replays = {}
    for model in (true_model, wrong_model):
        out_cmp = subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', 'compare',
                                  str(out), '--model', str(model), '--json'],
                                 capture_output=True, text=True, timeout=240)
        assert out_cmp.returncode == 0, out_cmp.stderr
        report = json.loads(out_cmp.stdout)
        assert report['replay_note'] == 'ok'
        replays[model.stem] = report['replay']
    assert replays['true']['rms_difference'] <= 1e-12
    assert replays['true']['rms_error_model'] == pytest.approx(
        replays['true']['rms_error_measured'], rel=1e-9)
    assert replays['wrong']['rms_difference'] > 1e-7


def fifo_permitted() -> bool:
    """Tell whether a process may switch itself to SCHED_FIFO here."""
    probe = subprocess.run([sys.executable, '-c', 'import os; os.sched_setscheduler('
                            '0, os.SCHED_FIFO, os.sched_param(1))'], capture_output=True)
    return probe.returncode == 0


def _loop_wall_time(plant_log: str) -> tuple[float, int]:
    """Wall time [s] from the plant's start to its last step, and its slipped periods."""
    stamps = {m.group(2): float(m.group(1)) for m in re.finditer(
        r'\[INFO\] \[(\d+\.\d+)\] \[[\w.]+plant_node\]: (peers matched|run complete)',
        plant_log)}
    slipped = int(re.search(r'slipped (\d+) periods', plant_log).group(1))
    return stamps['run complete'] - stamps['peers matched'], slipped


#: more slipped periods than this fraction of a run: the scheduler did not give the loop
#: real time (SCHED_FIFO throttled, or other realtime processes on both cores)
MAX_SLIP_FRACTION = 0.1
#: runs of a loop that tolerates no slipped period before its bounds are skipped
REALTIME_ATTEMPTS = 3


def _require_real_time(slipped: int, wall: float, duration: float,
                       max_fraction: float = MAX_SLIP_FRACTION) -> None:
    """Skip, saying why, when the plant measured that it did not get real time.

    The plant counts the periods its own process was descheduled for (sim time slipped
    behind the wall clock).  Beyond :data:`MAX_SLIP_FRACTION` of the run the machine,
    not the loop, decided the timing: the tracking bounds then say nothing about the
    code, and passing silently would hide it, so the test is reported as skipped with
    the numbers.  Measured with two CPU-bound processes on both cores and SCHED_FIFO
    priority 40: 0–3 slipped periods per 1000.
    """
    if slipped > max_fraction * duration * 1000:
        pytest.skip(f'the scheduler did not give the loop real time: the plant slipped '
                    f'{slipped} of {duration * 1000:.0f} periods ({wall:.2f} s wall for '
                    f'{duration:g} s); realtime tracking bounds not checked')


def _realtime_run(tmp_path: Path, ros_env, **spec) -> tuple[object, str]:
    if not fifo_permitted():
        pytest.skip('SCHED_FIFO not permitted here: realtime bounds need realtime priority')
    spec = RunSpec(output=tmp_path / 'rt.mcap', timing='realtime',
                   realtime_priority=DEFAULT_RT_PRIORITY, **spec)
    run_nodes(spec, workdir=tmp_path, domain_id=int(ros_env['ROS_DOMAIN_ID']),
              progress=False)
    logs = ''.join((tmp_path / f'{n}.log').read_text() for n in
                   ('plant_node', 'controller_node', 'trajectory_node'))
    assert logs.count('running SCHED_FIFO priority') == 3
    return spec, logs


def _check_against_lockstep(run, plant: str, controller: str, trajectory: str,
                            duration: float) -> None:
    """Realtime tracking within 8× (rms and max) of the same loop in lockstep (= simulate).

    The reference is computed here, in the same run, so the bound follows the models'
    defaults.  On an idle machine with SCHED_FIFO the realtime/lockstep ratios were
    0.96–1.05 (rms) and 0.9–1.04 (max); with two CPU-bound processes on both cores and
    other test runs (load ≈ 15) a PMLM adaptive run measured rms 6× lockstep — the
    loaded-machine tolerance.  The loops this test guards against (stale reference,
    answering a backlog, open-loop through stalls) measured 16× to divergence (1e50 m).
    """
    cfg = load_plant(plant)
    traj = make_trajectory(trajectory)
    # the controller node's law knows the nominal model derived from the plant file
    sim = simulate(cfg, make_controller(controller, plant=derive_nominal(cfg)), traj,
                   duration=duration, x0=traj.at(0.0).position).to_run()
    rms_sim = np.sqrt(np.mean(sim.error ** 2))
    rms = np.sqrt(np.mean(run.error ** 2))
    assert rms < 8.0 * rms_sim, (rms, rms_sim)
    # the peak is one sample: a single descheduling of the controller on a shared machine
    # (measured: 126 µm = 10× lockstep at 0 slipped periods, rms within bound) is not the
    # failure this guards against; a divergent loop still exceeds this bound by far
    peak, peak_sim = np.max(np.abs(run.error)), np.max(np.abs(sim.error))
    assert peak < 40.0 * peak_sim, (peak, peak_sim)


@pytest.mark.alone   # wall-clock timing: the machine to itself (make test's second part)
def test_realtime_nodes_track_on_wall_clock(tmp_path: Path, ros_env) -> None:
    """Realtime mode: 1 kHz wall timers, 1 s, the default ball-screw PID tracks.

    Realtime with the default priority measured rms and max within 0.9–1.05× of the
    same loop in lockstep (7 runs, idle machine).  The bounds (8× lockstep, computed
    here, :func:`_check_against_lockstep`) leave room for late ticks on a loaded
    machine; a loop that answers a stale reference or a backlog of old samples, or a
    plant that runs open-loop through its own stalls, measured 16× to divergence.
    """
    spec, logs = _realtime_run(tmp_path, ros_env, plant='ballscrew', controller='pid',
                               duration=1.0, namespace='gantry/x')   # multi-axis
    run = read_run(spec.output, namespace='gantry/x')
    assert run.metadata['params:controller_node/timing'] == 'realtime'
    # one sample per period, consecutive stamps (a stall of the plant process pauses sim
    # time instead of skipping samples); every node waits for its last samples to be
    # acknowledged before it exits, so the recording holds every step
    assert 990 <= len(run) <= 1000
    assert np.all(np.diff(np.round(run.t * 1e3)) == 1)
    # 1 s of samples took 1 s of wall time (+ the plant's slip, if its process stalled)
    wall, slipped = _loop_wall_time((tmp_path / 'plant_node.log').read_text())
    assert 0.99 < wall
    _require_real_time(slipped, wall, 1.0)
    assert wall < 1.0 + 0.3 + slipped * 1e-3
    assert run.voltage is not None and np.all(np.isfinite(run.voltage))
    assert np.count_nonzero(run.voltage) > len(run) // 2
    _check_against_lockstep(run, 'ballscrew', 'pid', 'sine', 1.0)
    assert 'timing: ' in logs and 'backlog samples skipped' in logs


@pytest.mark.alone   # wall-clock timing: the machine to itself (make test's second part)
def test_realtime_pmlm_adaptive_sliding_stays_bounded(tmp_path: Path, ros_env) -> None:
    """PMLM + adaptive sliding in realtime, 3 s (three 50 mm moves): lockstep accuracy.

    This loop used to diverge (to 1e50 m within 0.15 s): the controller paired each
    measurement with whatever reference had arrived last, 0.1–2 ms apart, and that
    timing noise in e drove the adaptive mass estimate to its bound.  Realtime measured
    rms and max within 1.0–1.05× of lockstep (6 runs, idle machine), 6× on a machine at
    load 15 with the plant slipping 20 periods.  Bounds: 8× lockstep (the old loop
    without priority but time-aligned still reached 0.5–1.4 mm after a stall, > 100×).
    """
    # any stall of the plant process is an open-loop interval the adaptive law reacts
    # to (measured: 7 slipped periods at load 15 gave a 0.43 mm excursion, 34× lockstep;
    # the same stall physics as the "0.5–1.4 mm after a stall" above): no tolerance.  A
    # run the scheduler stalled is run again, up to REALTIME_ATTEMPTS runs (in CI's
    # second part 2–4 of 3000 periods slipped in about every other run, which skipped
    # the bounds as often)
    for attempt in range(REALTIME_ATTEMPTS):
        where = tmp_path / f'attempt{attempt}'
        where.mkdir()
        spec, logs = _realtime_run(where, ros_env, plant='pmlm',
                                   controller='adaptive_sliding', duration=3.0)
        wall, slipped = _loop_wall_time((where / 'plant_node.log').read_text())
        if slipped == 0:
            break
    _require_real_time(slipped, wall, 3.0, max_fraction=0.0)
    run = read_run(spec.output)
    assert 2990 <= len(run) <= 3000
    assert np.all(np.isfinite(run.voltage))
    _check_against_lockstep(run, 'pmlm', 'adaptive_sliding', 'p2p', 3.0)
    # the moves really happened (50 mm strokes) and were tracked
    assert np.ptp(run.position) == pytest.approx(0.05, abs=1e-4)


def test_demo_records_runs_and_reports_ratios(tmp_path: Path, ros_env) -> None:
    """``motor-comp demo`` (two of its six runs, 1.2 s: one reversal): MCAPs, ratios."""
    out = tmp_path / 'demo'
    cli = subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', 'demo', '--out',
                          str(out), '--only', 'pmlm_pid', 'pmlm_adaptive',
                          '--pmlm-duration', '1.2', '--json'],
                         capture_output=True, text=True, timeout=240, env=ros_env)
    assert cli.returncode == 0, cli.stderr
    summary = json.loads(cli.stdout)
    assert summary == json.loads((out / 'summary.json').read_text())
    rows = {r['name']: r for r in summary['runs']}
    assert set(rows) == {'pmlm_pid', 'pmlm_adaptive'}
    for name, row in rows.items():
        # the table is the metrics of the recorded file
        recorded = compute_metrics(read_run(out / f'{name}.mcap')).as_dict()
        for key in ('rms_error', 'max_error', 'max_glitch', 'mean_glitch'):
            assert row[key] == recorded[key], key
        assert row['max_glitch'] is not None and row['max_glitch'] > 0
    (ratio,) = summary['ratios']
    assert ratio['ratio'] == rows['pmlm_adaptive']['max_error'] / rows['pmlm_pid']['max_error']
    assert '| pmlm_adaptive |' in (out / 'summary.md').read_text()
