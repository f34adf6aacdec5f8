"""Metrics match analytically known values on files written by other tools; CLI; report."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from motor_comp.analysis import compute_metrics
from motor_comp.cli import main as cli
from motor_comp.logs import Run, read_run, write_run

# --- an analytic run: 1 kHz, 4 s, sine reference with 8 reversals ------------------
MS = np.arange(4000)                     # integer milliseconds: exact sample times
T = MS * 1e-3
A = 0.01
REF = A * np.sin(2 * np.pi * T)
REF_V = 2 * np.pi * A * np.cos(2 * np.pi * T)
REV_MS = np.array([250, 750, 1250, 1750, 2250, 2750, 3250, 3750])
G = np.arange(1, 9) * 1e-6               # glitch heights [m], one per reversal
ERR = np.zeros(4000)
for ms, g, s in zip(REV_MS, G, np.resize([1, -1], 8)):
    j = np.arange(-50, 51)               # triangle, half-width 50 ms, peak 50 ms after t_r
    ERR[ms + 50 + j] += s * g * (1 - np.abs(j) / 50)
U = 2 * np.sin(2 * np.pi * 3 * T) + 0.2 * np.sin(2 * np.pi * 250 * T)

EXPECTED = {
    'rms_error': np.sqrt(np.sum(G ** 2) * 0.1 / 3 / 4.0),   # ∫ triangle² = g²·2w/3
    'max_error': 8e-6, 'max_glitch': 8e-6, 'mean_glitch': 4.5e-6,
    'rms_voltage': np.sqrt(2.0 + 0.02), 'chattering': 0.2 / np.sqrt(2),
}


def _header(ns: int) -> dict:
    return {'stamp': {'sec': ns // 10**9, 'nanosec': ns % 10**9}, 'frame_id': ''}


def _write_with_mcap_ros2(path: Path) -> None:
    from mcap_ros2.writer import Writer

    from motor_comp.logs import schemas
    with open(path, 'wb') as f:
        w = Writer(f)
        js = w.register_msgdef(schemas.JOINT_STATE, schemas.DEFINITIONS[schemas.JOINT_STATE])
        fl = w.register_msgdef(schemas.FLOAT64, schemas.DEFINITIONS[schemas.FLOAT64])
        for k in range(MS.size):
            ns = int(MS[k]) * 10**6
            w.write_message('/axis/reference', js, {
                'header': _header(ns), 'name': ['axis'], 'position': [REF[k]],
                'velocity': [REF_V[k]], 'effort': []}, log_time=ns)
            w.write_message('/axis/joint_states', js, {
                'header': _header(ns), 'name': ['axis'], 'position': [REF[k] - ERR[k]],
                'velocity': [], 'effort': []}, log_time=ns + 20_000)
            w.write_message('/axis/voltage', fl, {'data': U[k]}, log_time=ns)
        w.finish()


def _write_with_rosbags(bag: Path) -> Path:
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_JAZZY)
    JointState = ts.types['sensor_msgs/msg/JointState']
    Header = ts.types['std_msgs/msg/Header']
    Time = ts.types['builtin_interfaces/msg/Time']
    Float64 = ts.types['std_msgs/msg/Float64']
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        cref = w.add_connection('/axis/reference', JointState.__msgtype__, typestore=ts)
        cjs = w.add_connection('/axis/joint_states', JointState.__msgtype__, typestore=ts)
        cu = w.add_connection('/axis/voltage', Float64.__msgtype__, typestore=ts)
        empty = np.empty(0)
        for k in range(MS.size):
            ns = int(MS[k]) * 10**6
            h = Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id='')
            for conn, pos, vel in ((cref, REF[k], np.array([REF_V[k]])),
                                   (cjs, REF[k] - ERR[k], empty)):
                msg = JointState(header=h, name=['axis'], position=np.array([pos]),
                                 velocity=vel, effort=empty)
                w.write(conn, ns, ts.serialize_cdr(msg, JointState.__msgtype__))
            w.write(cu, ns, ts.serialize_cdr(Float64(data=float(U[k])), Float64.__msgtype__))
    return next(bag.glob('*.mcap'))


@pytest.mark.parametrize('writer', ['mcap_ros2', 'rosbags'])
def test_metrics_exact_on_files_from_other_writers(tmp_path: Path, writer: str) -> None:
    if writer == 'mcap_ros2':
        path = tmp_path / 'a.mcap'
        _write_with_mcap_ros2(path)
    else:
        _write_with_rosbags(tmp_path / 'bag')
        path = tmp_path / 'bag'                  # the rosbag2 directory itself
    m = compute_metrics(read_run(path), glitch_window=0.2)
    for key, value in EXPECTED.items():
        assert getattr(m, key) == pytest.approx(value, rel=0.01), key
    assert m.glitch_count == 8
    np.testing.assert_allclose([g.t for g in m.glitches], REV_MS * 1e-3, atol=1e-9)
    np.testing.assert_allclose([g.magnitude for g in m.glitches], G, rtol=0.01)
    np.testing.assert_allclose([g.t_peak for g in m.glitches], (REV_MS + 50) * 1e-3)
    # strokes between reversals: each holds one triangle (first/last partial strokes none)
    assert len(m.segments) == 9
    np.testing.assert_allclose([s.max_error for s in m.segments[1:]], G, rtol=1e-9)
    assert m.segments[0].max_error == 0.0


def test_point_to_point_overshoot_and_settling() -> None:
    t = np.arange(0, 4.0, 1e-3)
    D, O, tau = 1e-3, 50e-6, 0.2
    s = np.clip((t - 0.5) / 0.5, 0, 1) - np.clip((t - 2.0) / 0.5, 0, 1)
    ref = D * (1 - np.cos(np.pi * s)) / 2
    x = ref.copy()
    for t_end, sign, stop in ((1.0, 1, 2.0), (2.5, -1, 4.0)):
        m = (t >= t_end - 1e-9) & (t < stop - 1e-9)
        x[m] += sign * O * np.exp(-(t[m] - t_end) / tau)
    ref_v = np.gradient(ref, t)
    m = compute_metrics(Run(t=t, position=x, reference=ref, reference_velocity=ref_v))
    assert len(m.moves) == 2
    for mv, dist in zip(m.moves, (D, -D)):
        assert mv.distance == pytest.approx(dist, rel=1e-6)
        assert mv.overshoot == pytest.approx(O, rel=0.01)
        assert mv.overshoot_ratio == pytest.approx(O / D, rel=0.01)
        assert mv.settling_time == pytest.approx(tau * np.log(O / (0.02 * D)), rel=0.01)
    tight = compute_metrics(Run(t=t, position=x, reference=ref, reference_velocity=ref_v),
                            settle_band=1e-9)
    assert tight.moves[0].settling_time is None       # never within 1 nm in the dwell


@pytest.fixture()
def two_runs(tmp_path: Path) -> tuple[Path, Path]:
    paths = []
    for name, scale in (('baseline', 1.0), ('improved', 0.5)):
        run = Run(t=T, position=REF - scale * ERR, reference=REF, reference_velocity=REF_V,
                  voltage=U, name=name)
        paths.append(tmp_path / f'{name}.mcap')
        write_run(paths[-1], run)
    return paths[0], paths[1]


@pytest.fixture(autouse=True)
def _only_my_commands(monkeypatch):
    monkeypatch.setattr(cli, 'SUBCOMMANDS', ('analyze', 'import_cmd'))


def test_cli_json_compares_runs(two_runs, capsys) -> None:
    assert cli.main(['analyze', str(two_runs[0]), str(two_runs[1]), '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    a, b = out['runs']
    for key in ('rms_error', 'max_error', 'max_glitch', 'mean_glitch', 'glitches'):
        assert key in a
    assert set(a['glitches'][0]) >= {'t', 'magnitude'}
    assert b['max_glitch'] == pytest.approx(0.5 * a['max_glitch'])
    assert b['relative_to_first']['rms_error'] == pytest.approx(-0.5, abs=1e-9)
    assert b['relative_to_first']['rms_voltage'] == pytest.approx(0.0, abs=1e-12)
    assert out['glitch_window'] == 0.2


def test_cli_table_and_report(two_runs, tmp_path: Path, capsys) -> None:
    rep = tmp_path / 'report'
    assert cli.main(['analyze', *map(str, two_runs), '--glitch-window', '0.1',
                     '--report', str(rep)]) == 0
    table = capsys.readouterr().out
    assert 'baseline' in table and 'improved' in table and '(-50.0%)' in table
    page = (rep / 'index.html').read_text()
    for png in ('error_vs_time.png', 'error_vs_position.png',
                'error_vs_reference_velocity.png', 'voltage.png'):
        assert (rep / png).read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
        assert f'href="{png}"' in page
    assert page.count('data:image/png;base64,') == 4
    assert 'within 0.1 s' in page


@pytest.mark.parametrize('argv, message', [
    (['analyze', 'missing.mcap'], 'no such file'),
    (['analyze', 'RUN', '--glitch-window', '-1'], 'must be a finite number > 0'),
    (['analyze', 'RUN', '--frobnicate'], 'unrecognized arguments'),
    (['analyze', 'NOREF'], 'missing reference'),
])
def test_cli_bad_input_one_line(tmp_path: Path, two_runs, capsys, argv, message) -> None:
    noref = tmp_path / 'noref.mcap'
    write_run(noref, Run(t=T, position=REF))
    argv = [str(two_runs[0]) if a == 'RUN' else str(noref) if a == 'NOREF' else a
            for a in argv]
    try:
        code = cli.main(argv)
    except SystemExit as exc:       # argparse errors exit from the parser
        code = exc.code
    err = capsys.readouterr().err
    assert code == 2
    assert err.startswith('motor-comp: error:') and message in err
    assert err.count('\n') == 1 and 'Traceback' not in err
