"""``/diagnostics`` in a recording: the schema other tools read, the summaries of a run.

Files are written with ``mcap_ros2``'s own writer from :mod:`motor_comp.logs.schemas`'
``DiagnosticArray`` definition (so the definition is one a general ROS 2 encoder
accepts), read back with :func:`read_diagnostics` and with rosbags, and summarised
(:mod:`motor_comp.analysis.diagnostics`).  A run recorded by the nodes is in
``test/nodes/test_nodes_run_monitor.py``.
"""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from motor_comp.analysis.diagnostics import format_summary, summarise
from motor_comp.logs import schemas
from motor_comp.logs.diagnostics import read_diagnostics

MON = 'motor_comp/axis: model monitor'
LIM = 'motor_comp/axis: limits'


def _status(name: str, level: int, message: str, **values: str) -> dict:
    return {'level': level, 'name': name, 'message': message, 'hardware_id': 'axis',
            'values': [{'key': k, 'value': v} for k, v in values.items()]}


def _verdict(level: int, nrmse: float, candidate: str | None = None) -> dict:
    extra = {'candidate': candidate, 'candidate_status': 'changed'} if candidate else {}
    return _status(MON, level, f'force NRMSE {nrmse}', force_nrmse=f'{nrmse:.6g}', **extra)


#: (stamp [s], statuses): an armed limit, five verdicts, a trip
ARRAYS = [
    (0.001, [_status(LIM, 0, 'limits armed: travel [-0.05, 0.05] m',
                     limits='travel [-0.05, 0.05] m')]),
    (0.5, [_verdict(0, 0.05)]),
    (1.0, [_verdict(1, 0.31, 'ripple')]),
    (1.5, [_verdict(2, 0.62, 'coulomb')]),
    (2.0, [_verdict(1, 0.30, 'ripple')]),
    (2.5, [_verdict(3, float('nan'))]),
    (2.7, [_status(LIM, 2, 'travel limit: position 0.0523 m beyond [-0.05, 0.05] m at '
                           't = 2.700 s', cause='travel limit', value='0.0523', t='2.7')]),
]


def _write(path: Path, arrays=ARRAYS) -> None:
    from mcap_ros2.writer import Writer as Ros2Writer
    with open(path, 'wb') as f:
        w = Ros2Writer(f, chunk_size=256)   # about a chunk per message: damage is local
        schema = w.register_msgdef(schemas.DIAGNOSTIC_ARRAY,
                                   schemas.DEFINITIONS[schemas.DIAGNOSTIC_ARRAY])
        for t, statuses in arrays:
            ns = int(round(t * 1e9))
            w.write_message('/diagnostics', schema,
                            {'header': {'stamp': {'sec': ns // 10**9,
                                                  'nanosec': ns % 10**9},
                                        'frame_id': ''},
                             'status': statuses}, log_time=ns, publish_time=ns)
        w.finish()


def test_read_back_with_stamps_levels_and_values(tmp_path: Path) -> None:
    path = tmp_path / 'd.mcap'
    _write(path)
    recs = read_diagnostics(path)
    assert [r.t for r in recs] == pytest.approx([t for t, _ in ARRAYS])
    assert [r.level for r in recs] == ['OK', 'OK', 'WARN', 'ERROR', 'WARN', 'STALE', 'ERROR']
    assert recs[2].values == {'force_nrmse': '0.31', 'candidate': 'ripple',
                              'candidate_status': 'changed'}
    assert recs[-1].name == LIM and recs[-1].hardware_id == 'axis'
    # rosbags (another tool) decodes the same messages from the ros2msg schema
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as ar:
        (conn,) = ar.connections
        assert conn.msgtype == schemas.DIAGNOSTIC_ARRAY
        levels = [ar.deserialize(raw, conn.msgtype).status[0].level
                  for _, _, raw in ar.messages()]
    assert levels == [0, 0, 1, 2, 1, 3, 2]


def test_summaries_of_monitor_and_limits(tmp_path: Path) -> None:
    path = tmp_path / 'd.mcap'
    _write(path)
    s = summarise(read_diagnostics(path))
    assert s['monitor'] == {
        'statuses': {'OK': 1, 'WARN': 2, 'ERROR': 1, 'STALE': 1}, 'verdicts': 5,
        'worst_nrmse': 0.62, 'last_nrmse': 0.30, 'last_level': 'STALE',
        'candidate': 'ripple', 'candidate_status': 'changed', 'candidate_verdicts': 2}
    assert s['limits'] == {'tripped': True, 'limits': 'travel [-0.05, 0.05] m',
                           'cause': 'travel limit', 't': 2.7, 'value': 0.0523,
                           'message': 'travel limit: position 0.0523 m beyond '
                                      '[-0.05, 0.05] m at t = 2.700 s'}
    json.dumps(s, allow_nan=False)                     # plain JSON, no NaN
    assert format_summary(s) == [
        'monitor: 5 verdicts (OK 1, WARN 2, ERROR 1, STALE 1), worst force NRMSE 0.620, '
        'candidate ripple (changed)',
        'limits: TRIPPED: travel limit: position 0.0523 m beyond [-0.05, 0.05] m at '
        't = 2.700 s']


def test_a_tie_of_candidates_goes_to_the_latest(tmp_path: Path) -> None:
    path = tmp_path / 't.mcap'
    _write(path, [(0.5, [_verdict(1, 0.2, 'offset')]), (1.0, [_verdict(1, 0.2, 'ripple')])])
    mon = summarise(read_diagnostics(path))['monitor']
    assert (mon['candidate'], mon['candidate_verdicts']) == ('ripple', 1)
    assert 'limits' not in summarise(read_diagnostics(path))


def test_no_diagnostics_and_damaged_files(tmp_path: Path) -> None:
    from motor_comp.logs import Run, write_run
    import numpy as np
    plain = tmp_path / 'plain.mcap'
    t = np.arange(10) * 1e-3
    write_run(plain, Run(t=t, position=t, velocity=t, reference=t, reference_velocity=t,
                         voltage=t, name='plain'))
    assert read_diagnostics(plain) == [] and summarise([]) == {}
    path = tmp_path / 'd.mcap'
    _write(path)
    whole = path.read_bytes()
    cut = tmp_path / 'cut.mcap'
    cut.write_bytes(whole[:len(whole) // 4])      # inside the data: no index, no footer
    recs = read_diagnostics(cut)                        # read in order up to the damage
    assert 0 < len(recs) < len(ARRAYS)
    assert [r.level for r in recs] == ['OK', 'OK', 'WARN', 'ERROR', 'WARN',
                                       'STALE', 'ERROR'][:len(recs)]
