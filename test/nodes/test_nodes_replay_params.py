"""``motor-comp replay`` as a live source, and the parameter-spec machinery of the nodes."""
from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, strategies as st
from scipy import stats
from rcl_interfaces.msg import ParameterType
from sensor_msgs.msg import JointState

from motor_comp.errors import ParameterError
from motor_comp.logs import Run, write_run
from motor_comp.nodes.common import Param, period_ns


@pytest.mark.alone   # the replay's pacing on the wall clock: the machine to itself
@pytest.mark.timeout(90)
def test_replay_publishes_recorded_run_with_timing(tmp_path: Path, ros_env, probe) -> None:
    """A 0.5 s run replayed at 2× arrives complete, in order, in about 0.25 s."""
    n = 500
    t = np.arange(n) * 1e-3
    run = Run(t=t, position=np.sin(t), velocity=np.cos(t), reference=np.sin(t) + 1e-6,
              reference_velocity=np.cos(t), voltage=0.1 * t, name='synthetic')
    path = tmp_path / 'synthetic.mcap'
    write_run(path, run)
    # when the replay *sent* each sample (the DDS source timestamp, set by the publishing
    # process): the pacing is the replay's, measured without the probe's own scheduling —
    # a probe descheduled on a loaded machine takes its backlog in one go, and arrival
    # times taken in its callback compressed the slope to 0.36 (stress run, load 10)
    arrivals: list[float] = []
    probe.node.hot_subscriptions.append(probe.node.create_subscription(
        JointState, 'joint_states',
        lambda m, info: arrivals.append(info['source_timestamp'] * 1e-9), 10000))
    proc = subprocess.Popen([sys.executable, '-m', 'motor_comp.cli.main', 'replay',
                             str(path), '--rate', '2', '--wait-for-subscribers', '3',
                             '--startup-delay', '0.5', '--json'],
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        probe.spin_until(lambda: min(len(probe.positions), len(probe.voltages),
                                     len(arrivals)) >= n, 60,
                         'the replayed run')
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    np.testing.assert_array_equal(np.array(probe.positions), run.position)
    assert len(probe.voltages) == n
    np.testing.assert_array_equal(np.array(probe.voltages), run.voltage)
    # paced at --rate 2: send time against recorded time has slope 1/2.  Theil–Sen
    # (median of pairwise slopes) ignores the samples a loaded machine delays — the
    # replay catches up after a stall (it paces on the absolute schedule) — while 1×
    # or unpaced replay (slopes 1 and ≈ 0) are far outside the bounds.
    report = json.loads(out)
    assert report['published']['/axis/joint_states'] == n
    # Timing is only checked when the scheduler let the replay keep it: a replay that
    # reached many messages late (descheduled; it then sends them at once to catch up
    # with its absolute schedule) says so itself, and a stress run at load 10 saw
    # slopes of 0.22–0.37 from such bursts.  An unpaced or 1× replay reports itself on
    # time, so the slope bounds still catch it.
    sent = sum(report['published'].values())   # joint_states, reference, voltage
    if report['late'] > MAX_LATE_SHARE * sent:
        pytest.skip(f'the scheduler did not let the replay keep its timing: '
                    f'{report["late"]} of {sent} messages sent > 5 ms late (at most '
                    f'{1e3 * report["max_late_s"]:.0f} ms); pacing not checked')
    slope = stats.theilslopes(np.array(arrivals) - arrivals[0], t).slope
    assert 0.4 < slope < 0.6, (slope, report)


#: late messages a replay may have and still be judged on its pacing (Theil–Sen
#: tolerates ~29 % outliers)
MAX_LATE_SHARE = 0.1


@pytest.mark.timeout(400)
def test_replay_one_joint_of_a_robot_bag(tmp_path: Path, ros_env, probe) -> None:
    """``replay BAG --joint J --input effort``: the joint, live, on the /axis topics.

    A robot's sqlite3 bag (written by rosbags, three joints reordered in every message):
    the nodes of this project (``monitor_node``) then watch a robot's joint as one of
    our axes.
    """
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'logs'))
    from rosbag_writer import write_bag
    n = 300
    ns = (np.arange(n) * 2_000_000 + 1_700_000_000_000_000_000).astype(np.int64)
    rng = np.random.default_rng(5)
    joints = {j: {'position': rng.normal(size=n), 'velocity': rng.normal(size=n),
                  'effort': rng.normal(size=n)} for j in ('shoulder', 'elbow', 'wrist')}
    bag = write_bag(tmp_path / 'arm', 'sqlite3', ns, joints, shuffle_seed=2)
    # paced (--rate 1, 0.6 s): the probe keeps up on a loaded machine
    proc = subprocess.Popen([sys.executable, '-m', 'motor_comp.cli.main', 'replay', str(bag),
                             '--joint', 'elbow', '--input', 'effort', '--rate', '1',
                             '--wait-for-subscribers', '2', '--startup-delay', '0.5',
                             '--json'],
                            env=ros_env, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        # a failure bound only (a fresh clone compiles the decoders first): the wait ends
        # when every sample is in, or when the replay has exited
        def got() -> int:
            return min(len(probe.positions), len(probe.voltages))

        def counts() -> str:
            return (f'the replayed joint ({len(probe.positions)} positions, '
                    f'{len(probe.voltages)} voltages of {n})')
        probe.spin_until(lambda: got() >= n or proc.poll() is not None, 240, counts)
        assert proc.poll() in (None, 0), proc.communicate()[1]
        probe.spin_until(lambda: got() >= n, 30, counts)   # the tail still in flight
        out, err = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    np.testing.assert_array_equal(np.array(probe.positions), joints['elbow']['position'])
    np.testing.assert_array_equal(np.array(probe.voltages), joints['elbow']['effort'])
    assert json.loads(out)['published'] == {'/axis/joint_states': n, '/axis/voltage': n}


def test_replay_bad_file_is_one_line_error(tmp_path: Path) -> None:
    """Missing and corrupt files: exit 2, one line, no traceback."""
    bad = tmp_path / 'bad.mcap'
    bad.write_bytes(b'\x89MCAP0\r\n' + b'garbage' * 20)
    for target in (tmp_path / 'missing.mcap', bad):
        out = subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', 'replay',
                              str(target)], capture_output=True, text=True, timeout=60)
        assert out.returncode == 2
        assert out.stderr.count('\n') == 1 and 'Traceback' not in out.stderr
        assert str(target) in out.stderr


def test_param_descriptor_carries_unit_and_range() -> None:
    """Descriptions state units; numeric ranges become Floating/IntegerRange."""
    d = Param('kp', 1.0, 'gain', 'V/m', 0.0, 10.0).descriptor()
    assert d.type == ParameterType.PARAMETER_DOUBLE
    assert d.description == 'gain [V/m]'
    assert (d.floating_point_range[0].from_value, d.floating_point_range[0].to_value) == \
        (0.0, 10.0)
    i = Param('seed', 0, 'seed', '', 0, 5).descriptor()
    assert i.type == ParameterType.PARAMETER_INTEGER and i.integer_range[0].to_value == 5
    c = Param('mode', 'pid', 'law', choices=('pid', 'npid')).descriptor()
    assert 'one of: pid, npid' in c.description
    a = Param('speeds', (1.0, 2.0), 'speeds', 'm/s').descriptor()
    assert a.type == ParameterType.PARAMETER_DOUBLE_ARRAY


@given(st.floats(allow_nan=True, allow_infinity=True))
def test_param_check_accepts_exactly_the_range(value: float) -> None:
    """In [low, high] and finite → accepted; anything else → ParameterError naming it."""
    spec = Param('stale_timeout', 0.5, 'timeout', 's', 1e-3, 60.0)
    if math.isfinite(value) and 1e-3 <= value <= 60.0:
        spec.check(value)
    else:
        with pytest.raises(ParameterError, match='stale_timeout'):
            spec.check(value)


def test_param_check_types_and_infinite_limit() -> None:
    """Ints widen to float; wrong types and unknown choices are rejected; u_max may be inf."""
    Param('x', 1.0, 'x', 'm', 0.0, 2.0).check(1)
    with pytest.raises(ParameterError, match='expected float'):
        Param('x', 1.0, 'x', 'm').check('one')
    with pytest.raises(ParameterError, match="'bogus' is not one of"):
        Param('mode', 'pid', 'law', choices=('pid',)).check('bogus')
    Param('u_max', math.inf, 'limit', 'V', 1e-6, math.inf).check(math.inf)
    with pytest.raises(ParameterError, match=r'speeds\[1\]'):
        Param('speeds', (1.0,), 'v', 'm/s', 0.0, 10.0).check([1.0, -2.0])


def test_period_ns_requires_whole_nanoseconds() -> None:
    """1 kHz → 1 000 000 ns; a rate whose period is not whole ns is refused."""
    assert period_ns(1000.0) == 1_000_000
    assert period_ns(400.0) == 2_500_000
    with pytest.raises(ParameterError, match='control_rate'):
        period_ns(3.0)
