"""``table`` trajectories (DESIGN.md §4): a CSV ``t, x[, v, a]`` played by the simulator.

The reference meets every row exactly; between rows it is one smooth (C²) curve whose
velocity and acceleration are its own derivatives; a missing ``v``/``a`` is derived by
differentiation that recovers an analytic motion; ``simulate --trajectory table --set
traj.file=F.csv`` plays it (the recorded reference is the CSV); bad tables give one-line
errors that name the row or column and never quote the file.
"""
from __future__ import annotations

import json

import numpy as np
import pytest

import motor_comp.cli.main as cli
from motor_comp.control.trajectories import Table, make_trajectory, parse_table, \
    table_from_arrays, write_table
from motor_comp.errors import ParameterError
from motor_comp.logs import read_run

W = 2 * np.pi * 1.5      # rad/s of the test motion
A = 0.01                 # m


def _motion(t):
    return A * np.sin(W * t) + 0.02 * t, A * W * np.cos(W * t) + 0.02, -A * W * W * np.sin(W * t)


def _cli(capsys, *argv):
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def test_position_only_table_derives_velocity_and_acceleration():
    t = np.arange(0.0, 2.0, 1e-3)
    x, v, a = _motion(t)
    data = table_from_arrays(t, x)
    assert data.derived == ('v', 'a')
    inner = slice(20, -20)   # a spline's end conditions are free: judge the interior
    assert np.max(np.abs(data.v - v)[inner]) < 1e-9 * W * 1e3
    assert np.max(np.abs(data.a - a)[inner]) < 1e-5 * A * W * W
    np.testing.assert_array_equal(data.x, x)          # positions as given


def test_between_rows_one_smooth_curve():
    """Coarse rows (20 ms): x, v, a are each other's derivatives; rows met exactly."""
    t = np.arange(0.0, 1.0, 0.02)
    x, v, a = _motion(t)
    traj = Table(data=table_from_arrays(t, x, v, a))
    ref = traj.at(t)
    np.testing.assert_array_equal(ref.position, x)
    np.testing.assert_array_equal(ref.velocity, v)
    np.testing.assert_array_equal(ref.acceleration, a)
    fine = np.arange(0.0, t[-1], 1e-5)
    r = traj.at(fine)
    # the velocity is the derivative of the position, the acceleration of the velocity
    np.testing.assert_allclose(np.gradient(r.position, fine)[1:-1], r.velocity[1:-1],
                               atol=1e-6)
    np.testing.assert_allclose(np.gradient(r.velocity, fine)[1:-1], r.acceleration[1:-1],
                               atol=1e-3)
    # and a quintic through 20 ms rows follows the motion closely
    xt, vt, at = _motion(fine)
    assert np.max(np.abs(r.position - xt)) < 1e-9
    assert np.max(np.abs(r.acceleration - at)) < 1e-3 * A * W * W
    # played from its first row; after the last, held there at rest
    late = traj.at(5.0)
    assert (late.position, late.velocity, late.acceleration) == (x[-1], 0.0, 0.0)
    shifted = Table(data=table_from_arrays(t + 3.0, x, v, a))
    assert shifted.at(0.1).position == traj.at(0.1).position


def test_simulate_plays_the_table(capsys, tmp_path):
    t = np.arange(0.0, 1.5, 1e-3)
    x, v = A * (1.0 - np.cos(W * t)), A * W * np.sin(W * t)     # from rest
    csv = tmp_path / 'motion.csv'
    rows = ''.join(f'{float(ti)!r},{float(xi)!r}\n' for ti, xi in zip(t, x))
    csv.write_text('# a test motion\nt,x\n' + rows)
    run_file = tmp_path / 'run.mcap'
    code, out, err = _cli(capsys, 'simulate', '--plant', 'pmlm', '--trajectory', 'table',
                          '--set', f'traj.file={csv}', '--duration', '1.5', '-o', run_file,
                          '--json')
    assert code == 0, err
    metrics = json.loads(out)['runs'][0]
    assert metrics['rms_error'] < 5e-5       # the PID tracked it (peak speed 94 mm/s)
    run = read_run(run_file)
    assert len(run) == len(t)
    np.testing.assert_array_equal(run.reference, x)
    inner = slice(20, -20)
    np.testing.assert_allclose(run.reference_velocity[inner], v[inner], atol=1e-8)
    assert json.loads(run.metadata['trajectory']) == {'kind': 'table', 'file': str(csv)}


def test_written_table_reads_back_exactly(tmp_path):
    t = np.arange(0.0, 0.5, 1e-3)
    data = table_from_arrays(t, *_motion(t))
    write_table(tmp_path / 'e.csv', data, comments=('designed by a test',))
    again = make_trajectory('table', file=str(tmp_path / 'e.csv'))
    for name in ('t', 'x', 'v', 'a'):
        np.testing.assert_array_equal(getattr(again.data, name), getattr(data, name))
    assert again.data.derived == ()
    assert again.duration == pytest.approx(0.499)


def test_header_forms(tmp_path):
    rows = ''.join(f'{i * 0.01},{i * 1e-3},{0.1},{0.0}\n' for i in range(8))
    for header in ('t,x,v,a', 'time_s, position [m], velocity (m/s), acceleration',
                   'x,t,v,a', ''):
        text = (header + '\n' if header else '') + rows
        data = parse_table(text, source='F')
        if header.startswith('x'):
            np.testing.assert_allclose(data.t, np.arange(8) * 1e-3)
        else:
            np.testing.assert_allclose(data.t, np.arange(8) * 0.01)


MARKER = 'SECRET-MARKER-7f3a'
GOOD = ''.join(f'{i * 0.01},{i * 1e-3}\n' for i in range(8))


@pytest.mark.parametrize('text, needle', [
    ('t,x\n' + GOOD.replace('0.03,', '0.01,'), 'not strictly increasing at data row 4'),
    ('t,x\n' + GOOD.replace('0.003\n', 'nan\n'), 'column x is not finite'),
    ('t,x\n' + GOOD.replace('0.003\n', f'{MARKER}\n'), 'data row 4, column x: not a number'),
    ('t,v\n' + GOOD, 'missing column x'),
    ('t,x\n0,0\n0.1,0.1\n0.2,0.2\n', 'too short: 3 rows'),
    (f't,{MARKER}\n' + GOOD, 'header column 2 is not one of t, x, v, a'),
    ('t,x,x\n' + GOOD, 'header names column x twice'),
    ('t,x\n' + GOOD + f'0.5,0.1,{MARKER}\n', 'data row 9 has 3 columns'),
    ('# only a comment\n', 'empty trajectory table'),
    ('1,2,3,4,5\n', 'expected the columns t, x[, v, a]'),
])
def test_bad_tables_one_line_without_content(capsys, tmp_path, text, needle):
    csv = tmp_path / 'bad.csv'
    csv.write_text(f'# {MARKER}\n' + text)
    with pytest.raises(ParameterError, match=needle.replace('[', r'\[').replace(']', r'\]')):
        make_trajectory('table', file=str(csv))
    code, out, err = _cli(capsys, 'simulate', '--trajectory', 'table', '--set',
                          f'traj.file={csv}', '--duration', '0.1')
    assert code == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('motor-comp: error: traj.file:'), err
    assert needle in lines[0] and str(csv) in lines[0]
    assert MARKER not in err and 'Traceback' not in err


@pytest.mark.parametrize('setting, needle', [
    ([], 'needs a file'),
    (['--set', 'traj.file={d}/missing.csv'], 'no such file'),
    (['--set', 'traj.file={d}'], 'is a directory'),
])
def test_table_file_errors(capsys, tmp_path, setting, needle):
    argv = [s.format(d=tmp_path) for s in setting]
    code, out, err = _cli(capsys, 'simulate', '--trajectory', 'table', '--duration', '0.1',
                          *argv)
    assert code == 2 and needle in err and len(err.strip().splitlines()) == 1, err


def test_fifo_is_refused_without_blocking(capsys, tmp_path):
    fifo = tmp_path / 'pipe.csv'
    import os
    os.mkfifo(fifo)
    code, out, err = _cli(capsys, 'simulate', '--trajectory', 'table', '--duration', '0.1',
                          '--set', f'traj.file={fifo}')
    assert code == 2 and 'a FIFO' in err
