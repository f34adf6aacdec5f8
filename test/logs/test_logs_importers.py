"""CSV/MAT import: column selection, scaling, round trip through MCAP, bad tables, CLI."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import scipy.io

from motor_comp.cli import main as cli
from motor_comp.errors import InputFileError
from motor_comp.logs import read_run
from motor_comp.logs.importers import import_table

N = 500
T = 0.002 * np.arange(N) + 1.0
COUNTS = np.round(4000 * np.sin(2 * np.pi * 0.5 * T))
REF_COUNTS = 4000 * np.sin(2 * np.pi * 0.5 * T)
VOLT = 0.3 * np.cos(T)
SCALE = 1e-6          # metres per count


def _write_csv(path: Path, *, delim: str = ',', header: bool = True) -> None:
    lines = ['# rig log, t in ms'] if header else []
    if header:
        lines.append(delim.join(['t_ms', 'u', 'enc', 'enc_ref']))
    lines += [delim.join(repr(float(x)) for x in row)
              for row in zip(T * 1e3, VOLT, COUNTS, REF_COUNTS)]
    path.write_text('\n'.join(lines) + '\n')


@pytest.fixture(autouse=True)
def _only_my_commands(monkeypatch):
    # the dispatcher imports every registered subcommand; test ours in isolation
    monkeypatch.setattr(cli, 'SUBCOMMANDS', ('analyze', 'import_cmd'))


def test_csv_round_trip_by_name(tmp_path: Path) -> None:
    src = tmp_path / 'rig.csv'
    _write_csv(src)
    out = tmp_path / 'rig.mcap'
    assert cli.main([
        'import', str(src), '--time', 't_ms', '--time-scale', '1e-3', '--input', 'u',
        '--position', 'enc', '--reference', 'enc_ref', '--position-scale', str(SCALE),
        '-o', str(out)]) == 0
    run = read_run(out)
    np.testing.assert_allclose(run.t, T, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.position, COUNTS * SCALE, rtol=1e-12)
    np.testing.assert_allclose(run.reference, REF_COUNTS * SCALE, rtol=1e-12)
    np.testing.assert_allclose(run.voltage, VOLT, rtol=1e-12)
    assert run.metadata['import.position'] == 'enc'
    assert run.metadata['source'] == str(src)


@pytest.mark.parametrize('delim', [';', '\t', ' '])
def test_csv_by_index_and_delimiters(tmp_path: Path, delim: str) -> None:
    src = tmp_path / 'rig.txt'
    _write_csv(src, delim=delim, header=False)
    run = import_table(src, time='0', input='1', position='2', time_scale=1e-3,
                       position_scale=SCALE)
    assert len(run) == N
    np.testing.assert_allclose(run.position, COUNTS * SCALE)
    assert run.reference is None


@pytest.mark.parametrize('orient, data', [('auto', 'rows'), ('columns', 'cols')])
def test_mat_variables_and_indices(tmp_path: Path, orient: str, data: str) -> None:
    block = np.vstack([T, COUNTS, VOLT])                     # ODrive layout: rows
    src = tmp_path / 'rig.mat'
    scipy.io.savemat(src, {'data': block if data == 'rows' else block.T, 'ref': REF_COUNTS})
    run = import_table(src, time='data:0', input='data[2]', position='data:1',
                       reference='ref', position_scale=SCALE, mat_orient=orient)
    np.testing.assert_allclose(run.position, COUNTS * SCALE)
    np.testing.assert_allclose(run.reference, REF_COUNTS * SCALE)
    np.testing.assert_allclose(run.voltage, VOLT)
    only = tmp_path / 'only.mat'
    scipy.io.savemat(only, {'data': block})
    assert len(import_table(only, time='0', input='2', position='1')) == N


def test_real_odrive_log_imports() -> None:
    src = Path('/work/shared/data/odrive_cogging/slow2/nocomp_0.mat')
    if not src.exists():
        pytest.skip('shared data not present')
    run = import_table(src, time='0', input='2', position='1',
                       position_scale=2 * np.pi / 8192)
    assert len(run) > 4000 and np.all(np.diff(run.t) > 0)
    # 0.1 rev/s for ~10 s: about one revolution
    assert 0.8 * 2 * np.pi < abs(run.position[-1] - run.position[0]) < 1.2 * 2 * np.pi


def test_unsorted_duplicate_and_nan_rows_warn(tmp_path: Path, capsys) -> None:
    src = tmp_path / 'messy.csv'
    src.write_text('t,u,x\n0,1,0\n2,1,2\n1,1,1\n2,1,20\n3,nan,3\n4,1,4\n')
    run = import_table(src, time='t', input='u', position='x')
    np.testing.assert_array_equal(run.t, [0, 1, 2, 4])
    np.testing.assert_array_equal(run.position, [0, 1, 20, 4])
    err = capsys.readouterr().err
    assert "input (column 'u'): 1 NaN/Inf" in err and '1 duplicate' in err


@pytest.mark.parametrize('text, args, message', [
    ('t,u,x\n0,1,0\n1,1,1\n', {'position': 'pos'}, r"no column 'pos' .*columns: t, u, x"),
    ('t,u,x\n0,1,0\n1,abc,1\n', {}, r"line 3, column 'u': 'abc' is not a number"),
    ('t,u,x\n0,1,0\n1,,1\n', {}, r"line 3, column 'u': empty cell"),
    ('t,u,x\n0,1,0\n1,1,1\n', {'position': '7'}, r'column 7 out of range'),
    ('t,u,x\n', {}, 'header but no data rows'),
    ('', {}, 'empty file'),
])
def test_bad_csv_errors_name_file_and_field(tmp_path: Path, text: str, args: dict,
                                            message: str) -> None:
    src = tmp_path / 'bad.csv'
    src.write_text(text)
    kw = {'time': 't', 'input': 'u', 'position': 'x', **args}
    with pytest.raises(InputFileError, match=message):
        import_table(src, **kw)


def test_cli_errors_are_one_line(tmp_path: Path, capsys) -> None:
    src = tmp_path / 'bad.csv'
    src.write_text('t,u,x\n0,1,0\n1,oops,1\n')
    code = cli.main(['import', str(src), '--time', 't', '--input', 'u', '--position', 'x',
                     '-o', str(tmp_path / 'o.mcap')])
    err = capsys.readouterr().err
    assert code == 2 and err.count('\n') == 1 and "'oops' is not a number" in err
    assert not (tmp_path / 'o.mcap').exists()
    with pytest.raises(SystemExit) as exc:
        cli.main(['import', str(src), '--time', 't', '--bogus'])
    assert exc.value.code == 2
    assert capsys.readouterr().err.startswith('motor-comp: error:')
    cell = tmp_path / 'cell.mat'
    scipy.io.savemat(cell, {'data': np.array([[np.zeros(3), np.ones(3)]], dtype=object)})
    assert cli.main(['import', str(cell), '--time', 'data:0', '--input', 'data:1',
                     '--position', 'data:1', '-o', str(tmp_path / 'c.mcap')]) == 2
    assert 'cell array' in capsys.readouterr().err
