"""Robots' bags (issue 25): rosbag2 directories in both storages, multi-joint JointState,
the joint's effort as input, joints that change order, references from a controller
state, split bags, and a one-line error naming what the bag has for every bad case.

The bags are written by rosbags (``rosbag_writer``), not by the code under test.
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from motor_comp.cli import main as cli
from motor_comp.errors import InputFileError, ParameterError
from motor_comp.logs import read_run, write_run
from motor_comp.logs.run import Run
from motor_comp.logs.topics import RunTopics
from rosbag_writer import write_bag

N = 600
T_NS = (np.arange(N) * 2_000_000 + 1_700_000_000_000_000_000).astype(np.int64)
_RNG = np.random.default_rng(25)
JOINTS = {name: {'position': np.cumsum(_RNG.normal(size=N)) * 1e-3,
                 'velocity': _RNG.normal(size=N), 'effort': _RNG.normal(size=N)}
          for name in ('shoulder_pan_joint', 'elbow_joint', 'wrist_1_joint')}
STORAGES = ('sqlite3', 'mcap')


@pytest.fixture(scope='module')
def bags(tmp_path_factory) -> dict[tuple[str, bool], Path]:
    """(storage, shuffled) -> a bag with three joints, a command topic and a controller."""
    root = tmp_path_factory.mktemp('bags')
    out = {}
    ref = {j: {'position': JOINTS[j]['position'] + 0.01, 'velocity': JOINTS[j]['velocity']}
           for j in JOINTS}
    for storage in STORAGES:
        for shuffled in (False, True):
            out[storage, shuffled] = write_bag(
                root / f'{storage}_{int(shuffled)}', storage, T_NS, JOINTS,
                shuffle_seed=7 if shuffled else None,
                scalars={'/elbow/command': np.arange(N, dtype=float)},
                controller=('/arm_controller/controller_state',
                            ['wrist_1_joint', 'elbow_joint', 'shoulder_pan_joint'], ref),
                states={'/motor_states': {'elbow_motor': 2 * JOINTS['elbow_joint']['effort'],
                                          'wrist_motor': JOINTS['wrist_1_joint']['effort']}})
    return out


@pytest.mark.parametrize('storage', STORAGES)
@pytest.mark.parametrize('shuffled', [False, True], ids=['fixed order', 'order changes'])
def test_one_joint_of_many_with_effort_as_input(bags, storage, shuffled) -> None:
    """The named joint's samples, matched by name in every message, exactly."""
    sel = RunTopics.of(joint='elbow_joint', input='effort')
    run = read_run(bags[storage, shuffled], topics=sel)
    e = JOINTS['elbow_joint']
    assert np.array_equal(run.t, T_NS / 1e9)
    assert np.array_equal(run.position, e['position'])
    assert np.array_equal(run.velocity, e['velocity'])
    assert np.array_equal(run.voltage, e['effort']) and np.array_equal(run.effort, e['effort'])
    assert run.name == f'{storage}_{int(shuffled)}'


@pytest.mark.parametrize('storage', STORAGES)
def test_input_and_reference_topics(bags, storage) -> None:
    """``--input TOPIC`` (Float64) and ``--reference`` from a controller state's joint."""
    run = read_run(bags[storage, True], topics=RunTopics.of(
        joint='wrist_1_joint', input='/elbow/command',
        reference='/arm_controller/controller_state'))
    w = JOINTS['wrist_1_joint']
    assert np.array_equal(run.voltage, np.arange(N, dtype=float))
    assert np.array_equal(run.reference, w['position'] + 0.01)
    assert np.array_equal(run.reference_velocity, w['velocity'])
    # TOPIC:JOINT picks another joint of the reference
    other = read_run(bags[storage, False], topics=RunTopics.of(
        joint='wrist_1_joint', input='effort',
        reference='/arm_controller/controller_state:elbow_joint'))
    assert np.array_equal(other.reference, JOINTS['elbow_joint']['position'] + 0.01)
    # a JointState input topic: the effort of its joint (here the motor's)
    motor = read_run(bags[storage, True], topics=RunTopics.of(
        joint='elbow_joint', input='/motor_states:elbow_motor'))
    assert np.array_equal(motor.voltage, 2 * JOINTS['elbow_joint']['effort'])


@pytest.mark.parametrize('storage', STORAGES)
def test_storages_and_the_streamed_reader_agree(bags, storage) -> None:
    """Both storages give the same arrays; ``analyze``'s streamed reader the same again."""
    from motor_comp.analysis.streaming import open_stream
    sel = RunTopics.of(joint='elbow_joint', input='effort',
                       reference='/arm_controller/controller_state')
    a = read_run(bags[storage, True], topics=sel)
    b = read_run(bags['sqlite3', False], topics=sel)
    src = open_stream(bags[storage, True], topics=sel)
    c = src if isinstance(src, Run) else src.to_run()
    if not isinstance(src, Run):
        src.close()
    for sig in ('t', 'position', 'velocity', 'voltage', 'reference', 'reference_velocity'):
        assert np.array_equal(getattr(a, sig), getattr(b, sig)), sig
        assert np.array_equal(getattr(a, sig), getattr(c, sig)), sig


def test_the_default_topics_then_joint_states(tmp_path) -> None:
    """Our own runs as before; a one-joint ``/joint_states`` bag with no option at all."""
    ours = Run(t=np.arange(50) * 1e-3, position=np.linspace(0, 1, 50),
               voltage=np.ones(50), name='ours')
    write_run(tmp_path / 'ours.mcap', ours)
    assert np.array_equal(read_run(tmp_path / 'ours.mcap').position, ours.position)
    one = write_bag(tmp_path / 'one', 'sqlite3', T_NS[:50],
                    {'slider': {k: v[:50] for k, v in JOINTS['elbow_joint'].items()}})
    run = read_run(one, topics=RunTopics.of(input='effort'))
    assert np.array_equal(run.position, JOINTS['elbow_joint']['position'][:50])


def test_a_split_bag_reads_as_one_run(tmp_path) -> None:
    """Several MCAP files of one recording, in their split order (``_2`` before ``_10``)."""
    n = 12 * 40
    t = np.arange(n) * 1e-3
    full = Run(t=t, position=np.sin(t), voltage=np.cos(t), name='split')
    bag = tmp_path / 'split'
    bag.mkdir()
    for k in range(12):
        write_run(bag / f'split_{k}.mcap', full.slice(t[40 * k], t[40 * k] + 0.04 - 1e-9))
    run = read_run(bag)
    assert np.array_equal(run.position, full.position) and run.name == 'split'


def _error(bag: Path, *argv: str) -> str:
    with pytest.raises((InputFileError, ParameterError)) as exc:
        read_run(bag, topics=RunTopics.of(**dict(zip(argv[::2], argv[1::2]))),
                 require={'voltage': 'the workbench needs the drive input'})
    text = str(exc.value)
    assert '\n' not in text
    return text


@pytest.mark.parametrize('storage', STORAGES)
def test_bad_selections_name_what_the_bag_has(bags, storage, tmp_path) -> None:
    bag = bags[storage, True]
    msg = _error(bag, 'joint', 'elbow')
    assert "joint 'elbow' not in /joint_states (has: " in msg
    assert 'shoulder_pan_joint' in msg and 'elbow_joint' in msg and '--joint NAME' in msg
    msg = _error(bag, 'input', 'effort')        # several joints, none named: which one?
    assert "joint 'axis' not in /joint_states" in msg and '--joint' in msg
    msg = _error(bag, 'topic', '/robot/joint_states', 'joint', 'elbow_joint')
    assert 'no /robot/joint_states messages' in msg
    assert '/joint_states [sensor_msgs/msg/JointState]' in msg and '/elbow/command' in msg
    msg = _error(bag, 'joint', 'elbow_joint', 'input', '/elbow/current')
    assert 'missing voltage: no /elbow/current messages' in msg and '--input' in msg
    msg = _error(bag, 'joint', 'elbow_joint', 'input', '/joint_states')
    assert "measurement's topic" in msg
    # an empty effort field
    no_effort = write_bag(tmp_path / f'noeffort_{storage}', storage, T_NS[:50],
                          {'a': {'position': np.zeros(50), 'velocity': None, 'effort': None},
                           'b': {'position': np.ones(50), 'velocity': None, 'effort': None}})
    msg = _error(no_effort, 'joint', 'b', 'input', 'effort')
    assert "joint 'b' of /joint_states has an empty effort field" in msg
    assert '(topics: /joint_states [sensor_msgs/msg/JointState])' in msg
    # a named joint must be there even in one-joint messages
    one = write_bag(tmp_path / f'one_{storage}', storage, T_NS[:20],
                    {'a': {'position': np.zeros(20), 'velocity': None,
                           'effort': np.zeros(20)}})
    assert "joint 'b' not in /joint_states (has: a)" in _error(one, 'joint', 'b')


def test_bad_bags_are_one_line(tmp_path) -> None:
    (tmp_path / 'nometa').mkdir()
    (tmp_path / 'nometa' / 'x.db3').write_bytes(b'SQLite format 3\0')
    with pytest.raises(InputFileError, match='without metadata.yaml'):
        read_run(tmp_path / 'nometa')
    with pytest.raises(InputFileError, match='without its metadata.yaml'):
        read_run(tmp_path / 'nometa' / 'x.db3')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(InputFileError, match='no .mcap file and no rosbag2 metadata'):
        read_run(tmp_path / 'empty')
    meta = tmp_path / 'other' / 'metadata.yaml'
    meta.parent.mkdir()
    meta.write_text('rosbag2_bagfile_information:\n  storage_identifier: rocksdb\n'
                    '  relative_file_paths: [a.rdb]\n')
    with pytest.raises(InputFileError, match="storage 'rocksdb' is not read"):
        read_run(meta.parent)
    meta.write_text('rosbag2_bagfile_information:\n  storage_identifier: mcap\n'
                    '  relative_file_paths: [gone_0.mcap]\n')
    with pytest.raises(InputFileError, match=r'lists 1 files, 1 missing \(gone_0.mcap\)'):
        read_run(meta.parent)
    with pytest.raises(ParameterError, match='not a topic name'):
        RunTopics.of(topic='/a b')
    with pytest.raises(ParameterError, match='no joint after the colon'):
        RunTopics.of(reference='/ctrl:')


@pytest.fixture
def only(monkeypatch):
    """Register only the subcommands a test runs (the dispatcher imports them all)."""
    def set_(*names: str) -> None:
        monkeypatch.setattr(cli, 'SUBCOMMANDS', names)
    return set_


def test_import_and_analyze_a_joint_of_a_bag(bags, tmp_path, capsys, only) -> None:
    """``import BAG --joint J --input effort`` and ``analyze BAG --joint J --reference``."""
    only('import_cmd', 'analyze')
    bag = bags['sqlite3', True]
    out = tmp_path / 'elbow.mcap'
    assert cli.main(['import', str(bag), '--joint', 'elbow_joint', '--input', 'effort',
                     '--reference', '/arm_controller/controller_state', '-o', str(out),
                     '--json']) == 0
    info = json.loads(capsys.readouterr().out)
    assert info['samples'] == N and 'reference' in info['signals']
    run = read_run(out)
    assert np.array_equal(run.voltage, JOINTS['elbow_joint']['effort'])
    sel = ['--joint', 'elbow_joint', '--input', 'effort',
           '--reference', '/arm_controller/controller_state']
    assert cli.main(['analyze', str(bag), *sel, '--json']) == 0
    from_bag = json.loads(capsys.readouterr().out)['runs'][0]
    assert cli.main(['analyze', str(out), '--json']) == 0
    imported = json.loads(capsys.readouterr().out)['runs'][0]
    assert from_bag['rms_error'] == pytest.approx(0.01, rel=1e-9)
    assert from_bag['rms_error'] == imported['rms_error']
    assert from_bag['max_glitch'] == imported['max_glitch']
    # a table option given to a bag is refused with the reason
    assert cli.main(['import', str(bag), '--time', '0', '-o', str(tmp_path / 'x.mcap')]) == 2
    assert 'column options of tables' in capsys.readouterr().err


def test_options_are_never_abbreviated(bags, capsys, only) -> None:
    """``--input`` is never taken for ``--input-hold``; an abbreviation is an error."""
    only('fit', 'diagnose', 'compare', 'analyze', 'import_cmd', 'replay')
    parser = cli.build_parser()
    args = parser.parse_args(['fit', 'run.mcap', '--model', 'm.yaml', '--input', 'effort'])
    assert args.input == 'effort' and args.input_hold is None
    for argv in (['fit', 'run.mcap', '--model', 'm.yaml', '--inp', 'effort'],
                 ['fit', 'run.mcap', '--mod', 'm.yaml'],
                 ['analyze', 'run.mcap', '--glitch', '0.1'],
                 ['diagnose', 'run.mcap', '--model', 'm.yaml', '--input-h', 'zoh']):
        with pytest.raises(SystemExit) as exc:
            parser.parse_args(argv)
        assert exc.value.code == 2
        err = capsys.readouterr().err
        assert err.startswith('motor-comp: error:') and err.count('\n') == 1, err
    # every parser of the package, including the subcommands'
    stack = [parser]
    while stack:
        p = stack.pop()
        assert p.allow_abbrev is False, p.prog
        for action in p._actions:
            if hasattr(action, 'choices') and isinstance(action.choices, dict):
                stack.extend(action.choices.values())
