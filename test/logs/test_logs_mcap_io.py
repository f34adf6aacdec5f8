"""MCAP writing/reading: round trip, other tools' files, alignment, damage recovery."""
from __future__ import annotations

import os
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap_ros2.writer import Writer as Ros2Writer

from motor_comp.errors import InputFileError
from motor_comp.logs import McapRecorder, Run, read_run, write_run
from motor_comp.logs import cdr, schemas


def _js(stamp_ns: int, pos: list[float], vel: list[float] = (), eff: list[float] = (),
        names: list[str] = ('axis',), frame: str = '') -> dict:
    return {'header': {'stamp': {'sec': stamp_ns // 10**9, 'nanosec': stamp_ns % 10**9},
                       'frame_id': frame},
            'name': list(names), 'position': list(pos), 'velocity': list(vel),
            'effort': list(eff)}


def _sample_run(n: int = 2000, dt: float = 1e-3) -> Run:
    t = np.arange(n) * dt
    ref = 0.01 * np.sin(2 * np.pi * t)
    return Run(t=t, position=ref - 3e-6 * np.cos(7 * t), velocity=np.gradient(ref, t),
               reference=ref, reference_velocity=0.02 * np.pi * np.cos(2 * np.pi * t),
               voltage=np.sin(3 * t), effort=5 * np.cos(t),
               metadata={'plant': 'pmlm', 'kp': 4.5}, name='sample')


def test_round_trip_exact(tmp_path: Path) -> None:
    run = _sample_run()
    write_run(tmp_path / 'r.mcap', run, metadata={'controller': 'pid'})
    back = read_run(tmp_path / 'r.mcap')
    assert back.name == 'r'
    for s in Run.SIGNALS:
        np.testing.assert_array_equal(getattr(back, s), getattr(run, s))
    np.testing.assert_allclose(back.t, run.t, atol=1e-12)
    assert back.metadata == {'plant': 'pmlm', 'kp': '4.5', 'controller': 'pid'}


def test_files_open_in_rosbags_and_mcap(tmp_path: Path) -> None:
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    run = _sample_run(300)
    path = tmp_path / 'r.mcap'
    write_run(path, run)
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as ar:
        counts = {c.topic: c.msgcount for c in ar.connections}
        assert counts == {'/axis/reference': 300, '/axis/joint_states': 300,
                          '/axis/voltage': 300}
        pos = [ar.deserialize(raw, c.msgtype).position[0]
               for c, _, raw in ar.messages() if c.topic == '/axis/joint_states']
        np.testing.assert_array_equal(pos, run.position)
    with open(path, 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        header = reader.get_header()
        assert header.profile == 'ros2'
        summary = reader.get_summary()
        for ch in summary.channels.values():
            assert ch.message_encoding == 'cdr'
            assert 'offered_qos_profiles' in ch.metadata
            assert ch.metadata['topic_type_hash'].startswith('RIHS01_')
            assert summary.schemas[ch.schema_id].encoding == 'ros2msg'
        volts = [m.data for _, ch, _, m in reader.iter_decoded_messages(topics=['/axis/voltage'])]
        np.testing.assert_array_equal(volts, run.voltage)
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
        assert meta['motor_comp']['plant'] == 'pmlm'


def test_schema_text_concatenates_dependencies() -> None:
    text = schemas.DEFINITIONS[schemas.JOINT_STATE]
    assert text.count('=' * 80 + '\nMSG: ') == 2
    assert '\nMSG: std_msgs/Header\n' in text and '\nMSG: builtin_interfaces/Time\n' in text


def _other_tool_file(path: Path) -> None:
    """joint_states at 1 kHz, reference at 250 Hz stamped 0.5 ms later, voltage at 500 Hz."""
    with open(path, 'wb') as f:
        w = Ros2Writer(f)
        js = w.register_msgdef(schemas.JOINT_STATE, schemas.DEFINITIONS[schemas.JOINT_STATE])
        fl = w.register_msgdef(schemas.FLOAT64, schemas.DEFINITIONS[schemas.FLOAT64])
        for k in range(1000):
            t = 1_000_000 * k
            if k % 4 == 0:
                ts = t + 500_000
                w.write_message('/axis/reference', js, _js(ts, [k * 1e-3], [1.0]),
                                log_time=ts + 7)
            if k % 2 == 0:
                w.write_message('/axis/voltage', fl, {'data': float(k)}, log_time=t)
            w.write_message('/axis/joint_states', js,
                            _js(t, [9.0, k * 1e-3 - 1e-6], [9.0, 1.0], [9.0, 0.5],
                                names=['other', 'axis'],
                                frame='base'), log_time=t + 123)
        w.finish()


def test_alignment_of_different_rates_and_stamps(tmp_path: Path) -> None:
    path = tmp_path / 'other.mcap'
    _other_tool_file(path)
    run = read_run(path)
    # reference starts at 0.5 ms: the measurement at 0 has no reference yet and is dropped
    assert run.t[0] == pytest.approx(1e-3)
    k = np.round(run.t * 1e3).astype(int)
    np.testing.assert_allclose(run.position, k * 1e-3 - 1e-6)
    # sample-and-hold of the latest reference stamped at or before each measurement
    last_ref = ((k - 1) // 4) * 4
    np.testing.assert_allclose(run.reference, last_ref * 1e-3)
    np.testing.assert_allclose(run.voltage, (k // 2) * 2.0)
    np.testing.assert_allclose(run.effort, 0.5)
    assert run.velocity is not None and run.reference_velocity is not None


def test_indexed_numpy_path_equals_scanning_path(tmp_path: Path, monkeypatch) -> None:
    """Fast path (message indexes, byte matrices) and compiled scanner decode alike."""
    from motor_comp.logs import mcap_io
    path = tmp_path / 'other.mcap'
    _other_tool_file(path)
    fast = read_run(path)
    calls = []
    monkeypatch.setattr(mcap_io._Reader, '_indexed_chunk',
                        lambda self, buf, index: calls.append(1) or False)
    slow = read_run(path)
    assert calls
    for s in ('t',) + Run.SIGNALS:
        np.testing.assert_array_equal(getattr(fast, s), getattr(slow, s))


def test_layouts_varying_within_a_chunk(tmp_path: Path) -> None:
    """Frame ids, joint order and present arrays change from message to message."""
    path = tmp_path / 'vary.mcap'
    with open(path, 'wb') as f:
        w = Ros2Writer(f)
        js = w.register_msgdef(schemas.JOINT_STATE, schemas.DEFINITIONS[schemas.JOINT_STATE])
        for k in range(200):
            t = k * 10**6
            if k % 3 == 0:
                msg = _js(t, [k * 1.0], [2.0 * k], [], frame='base_link')
            elif k % 3 == 1:
                msg = _js(t, [-1.0, k * 1.0], [0.0, 2.0 * k], [0.0, 3.0],
                          names=['x', 'axis'])
            else:
                msg = _js(t, [k * 1.0])
            w.write_message('/axis/joint_states', js, msg, log_time=t)
        w.finish()
    run = read_run(path)
    # effort is first published at k = 1: the run starts where every signal has a value
    k = np.arange(1, 200)
    np.testing.assert_array_equal(run.position, k * 1.0)
    held = np.where(k % 3 == 2, 2.0 * (k - 1), 2.0 * k)    # no velocity: last one held
    np.testing.assert_array_equal(run.velocity, held)
    np.testing.assert_array_equal(run.effort, 3.0)


def test_clock_domains_are_reconciled(tmp_path: Path) -> None:
    """Sim-time stamps in the header, wall-clock log times: voltage is shifted onto stamps."""
    wall = 1_700_000_000 * 10**9
    path = tmp_path / 'clk.mcap'
    with McapRecorder(path) as rec:
        rec.add_channel('/axis/joint_states', schemas.JOINT_STATE)
        rec.add_channel('/axis/voltage', schemas.FLOAT64)
        t = np.arange(100) * 1_000_000
        js = cdr.encode_joint_states(t, t * 1e-9)
        u = cdr.encode_float64(np.arange(100.0))
        for k in range(100):
            rec.write_cdr('/axis/voltage', u[k].tobytes(), wall + int(t[k]))
            rec.write_cdr('/axis/joint_states', js[k].tobytes(), wall + int(t[k]) + 50_000)
    run = read_run(path)
    assert run.t[0] == 0.0 and len(run) == 100
    np.testing.assert_array_equal(run.voltage, np.arange(100.0))


def test_unsorted_duplicate_and_nan_samples(tmp_path: Path, capsys) -> None:
    path = tmp_path / 'messy.mcap'
    stamps = [0, 2, 1, 3, 3, 4, 5]
    pos = [0.0, 2.0, 1.0, 30.0, 3.0, np.nan, 5.0]
    with McapRecorder(path) as rec:
        rec.add_channel('/axis/joint_states', schemas.JOINT_STATE)
        rec.add_channel('/axis/reference', schemas.JOINT_STATE)
        for s, p in zip(stamps, pos):
            ns = s * 10**8
            rec.write_cdr('/axis/joint_states',
                          cdr.encode_joint_states(np.array([ns]), np.array([p]))[0].tobytes(), ns)
            rec.write_cdr('/axis/reference',
                          cdr.encode_joint_states(np.array([ns]), np.array([s * 1.0]))[0]
                          .tobytes(), ns)
    run = read_run(path)
    np.testing.assert_allclose(run.t, [0.0, 0.1, 0.2, 0.3, 0.5])
    np.testing.assert_array_equal(run.position, [0.0, 1.0, 2.0, 3.0, 5.0])  # last of dup kept
    np.testing.assert_array_equal(run.error, 0.0)
    err = capsys.readouterr().err
    assert '1 non-finite' in err
    assert '1 out-of-order stamps sorted, 1 duplicate stamps dropped' in err


def test_big_endian_payload_uses_general_decoder(tmp_path: Path) -> None:
    """A CDR_BE message is not for the fast path; the mcap_ros2 decoder takes over."""
    def be_joint_state(sec: int, pos: float) -> bytes:
        body = struct.pack('>iI', sec, 0) + struct.pack('>I', 1) + b'\0' + b'\0' * 3
        body += struct.pack('>II', 1, 5) + b'axis\0' + b'\0' * 3          # names
        body += struct.pack('>I', 1) + b'\0' * 4 + struct.pack('>d', pos)  # position
        body += struct.pack('>I', 0) + struct.pack('>I', 0)               # velocity, effort
        return b'\x00\x00\x00\x00' + body
    path = tmp_path / 'be.mcap'
    with McapRecorder(path) as rec:
        rec.add_channel('/axis/joint_states', schemas.JOINT_STATE)
        for k in range(3):
            rec.write_cdr('/axis/joint_states', be_joint_state(k, 0.25 * k), k * 10**9)
    run = read_run(path)
    np.testing.assert_array_equal(run.position, [0.0, 0.25, 0.5])
    np.testing.assert_array_equal(run.t, [0.0, 1.0, 2.0])


def test_unchunked_lz4_and_namespace(tmp_path: Path) -> None:
    from mcap.writer import CompressionType, Writer
    path = tmp_path / 'flat.mcap'
    with open(path, 'wb') as f:
        w = Writer(f, use_chunking=False, compression=CompressionType.NONE)
        w.start(profile='ros2')
        sid = w.register_schema(schemas.JOINT_STATE, 'ros2msg',
                                schemas.DEFINITIONS[schemas.JOINT_STATE].encode())
        cid = w.register_channel('/x/joint_states', 'cdr', sid)
        pl = cdr.encode_joint_states(np.arange(5) * 10**6, np.arange(5.0))
        for k in range(5):
            w.add_message(cid, log_time=k * 10**6, data=pl[k].tobytes(), publish_time=0)
        w.finish()
    assert list(read_run(path, namespace='x').position) == [0, 1, 2, 3, 4]
    write_run(tmp_path / 'l.mcap', _sample_run(50), compression='lz4')
    assert len(read_run(tmp_path / 'l.mcap')) == 50


@pytest.mark.parametrize('content, message', [
    (None, 'no such file'), (b'', 'empty file'), (b'hello world, not mcap', 'not an MCAP'),
])
def test_bad_files(tmp_path: Path, content: bytes | None, message: str) -> None:
    path = tmp_path / 'bad.mcap'
    if content is not None:
        path.write_bytes(content)
    with pytest.raises(InputFileError, match=message):
        read_run(path)


def test_missing_topic_names_what_is_there(tmp_path: Path) -> None:
    path = tmp_path / 'v.mcap'
    with McapRecorder(path) as rec:
        rec.add_channel('/axis/voltage', schemas.FLOAT64)
        rec.write_cdr('/axis/voltage', cdr.encode_float64(np.array([1.0]))[0].tobytes(), 0)
    with pytest.raises(InputFileError, match=r'no /axis/joint_states .*topics: '
                                             r'/axis/voltage'):
        read_run(path)


def test_truncated_file_recovers_complete_chunks(tmp_path: Path, capsys) -> None:
    path = tmp_path / 'full.mcap'
    write_run(path, _sample_run(3000), chunk_size=16 * 1024)
    data = path.read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(data[:len(data) // 2])
    run = read_run(cut)
    assert 500 < len(run) < 3000
    np.testing.assert_array_equal(run.position, _sample_run(3000).position[:len(run)])
    err = capsys.readouterr().err
    assert 'recovered' in err and 'samples' in err and 'stopped at byte' in err
    cut.write_bytes(data[:20])
    with pytest.raises(InputFileError, match='no messages could be read'):
        read_run(cut)


_KILL_SCRIPT = """
import os, signal, sys
import numpy as np
from motor_comp.logs import McapRecorder, cdr, schemas
rec = McapRecorder(sys.argv[1], chunk_size=8192)
rec.add_channel('/axis/joint_states', schemas.JOINT_STATE)
rec.add_metadata('motor_comp', {'controller': 'npid'})
pl = cdr.encode_joint_states(np.arange(5000) * 10**6, np.arange(5000) * 1e-3)
for k in range(5000):
    rec.write_cdr('/axis/joint_states', pl[k].tobytes(), k * 10**6)
os.kill(os.getpid(), signal.SIGKILL)
"""


def test_recorder_killed_with_sigkill_is_readable(tmp_path: Path, capsys) -> None:
    path = tmp_path / 'killed.mcap'
    proc = subprocess.run([sys.executable, '-c', _KILL_SCRIPT, str(path)], timeout=60)
    assert proc.returncode == -signal.SIGKILL
    run = read_run(path)
    # everything but the last open chunk (8 KiB / 103 B per message ≈ 80 messages) is there
    assert 4800 < len(run) <= 5000
    np.testing.assert_allclose(run.position, np.arange(len(run)) * 1e-3)
    assert run.metadata == {'controller': 'npid'}
    assert 'unfinished file' in capsys.readouterr().err


def test_recorder_flushes_on_interval(tmp_path: Path) -> None:
    path = tmp_path / 'slow.mcap'
    rec = McapRecorder(path, flush_interval=1e-9)
    rec.add_channel('/axis/joint_states', schemas.JOINT_STATE)
    rec.write_cdr('/axis/joint_states',
                  cdr.encode_joint_states(np.array([0]), np.array([1.5]))[0].tobytes(), 0)
    rec.write_cdr('/axis/joint_states',
                  cdr.encode_joint_states(np.array([10**6]), np.array([2.5]))[0].tobytes(), 10**6)
    snapshot = tmp_path / 'snap.mcap'
    shutil.copy(path, snapshot)                # the file as a crash would leave it
    rec.close()
    assert list(read_run(snapshot).position) == [1.5, 2.5]
    assert os.path.getsize(path) > os.path.getsize(snapshot)


def test_progress_only_when_asked(tmp_path: Path, capsys) -> None:
    path = tmp_path / 'p.mcap'
    write_run(path, _sample_run(500))
    read_run(path)
    assert capsys.readouterr().err == ''
    read_run(path, progress=True)
    err = capsys.readouterr().err
    assert 'p.mcap:' in err and '100.0 %' in err and 'MB' in err


@settings(max_examples=25, deadline=None)
@given(frame=st.text(max_size=12),
       others=st.lists(st.text(min_size=1, max_size=6), max_size=3),
       where=st.integers(0, 3), with_vel=st.booleans(), with_eff=st.booleans(),
       values=st.lists(st.floats(-1e3, 1e3), min_size=3, max_size=40))
def test_any_joint_state_layout_decodes(frame, others, where, with_vel, with_eff,
                                        values) -> None:
    """Fast path, scanner and mcap_ros2's encoder agree for arbitrary layouts."""
    others = [o for o in others if o != 'axis']
    names = list(others)
    j = min(where, len(names))
    names.insert(j, 'axis')
    import io
    buf = io.BytesIO()
    w = Ros2Writer(buf)
    js = w.register_msgdef(schemas.JOINT_STATE, schemas.DEFINITIONS[schemas.JOINT_STATE])
    for k, v in enumerate(values):
        arr = [7.0] * len(names)
        arr[j] = v
        vel = [a * 2 for a in arr] if with_vel else []
        eff = [a * 3 for a in arr] if with_eff else []
        w.write_message('/axis/joint_states', js,
                        _js(k * 10**6, arr, vel, eff, names=names, frame=frame),
                        log_time=k * 10**6)
    w.finish()
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / 'h.mcap'
        path.write_bytes(buf.getvalue())
        run = read_run(path)
    np.testing.assert_array_equal(run.position, values)
    if with_vel:
        np.testing.assert_array_equal(run.velocity, np.array(values) * 2)
    else:
        assert run.velocity is None
    if with_eff:
        np.testing.assert_array_equal(run.effort, np.array(values) * 3)
    else:
        assert run.effort is None


def test_recorder_rejects_misuse_with_named_errors(tmp_path: Path) -> None:
    from motor_comp.errors import ParameterError
    with McapRecorder(tmp_path / 'r.mcap') as rec:
        with pytest.raises(ParameterError, match='/x: no message definition known'):
            rec.add_channel('/x', 'my_msgs/msg/Thing')
        with pytest.raises(ParameterError, match='add_channel'):
            rec.write_cdr('/axis/voltage', b'\0\1\0\0' + bytes(8), 0)
        cid = rec.add_channel('/x', 'my_msgs/Thing', definition='float64 a\n')
        assert rec.add_channel('/x', 'my_msgs/Thing') == cid
    with pytest.raises(InputFileError, match='cannot write'):
        McapRecorder(tmp_path / 'missing_dir' / 'r.mcap')


def test_only_requested_signals_are_kept(tmp_path: Path) -> None:
    from motor_comp.errors import ParameterError
    path = tmp_path / 's.mcap'
    run = _sample_run(300)
    write_run(path, run)
    part = read_run(path, signals=('reference_velocity', 'voltage'))
    assert part.velocity is None and part.effort is None and part.reference is None
    np.testing.assert_array_equal(part.position, run.position)
    np.testing.assert_array_equal(part.reference_velocity, run.reference_velocity)
    np.testing.assert_array_equal(part.voltage, run.voltage)
    assert read_run(path, signals=()).voltage is None
    with pytest.raises(ParameterError, match='unknown'):
        read_run(path, signals=('torque',))
