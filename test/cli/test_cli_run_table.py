"""``motor-comp run --trajectory table --trajectory-file F.csv``: the table reaches the node.

The run's parameter file gives ``trajectory_node`` the table's path and its directory in
``model_dir`` (the node reads files only inside it), the plant starts on the table's
first position, and a missing option or file is a one-line error before any process.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

import motor_comp.cli.main as cli
from motor_comp.control.trajectories import table_from_arrays, write_table
from motor_comp.errors import ParameterError


def _cli(capsys, *argv):
    try:
        code = cli.main([str(a) for a in argv])
    except SystemExit as exc:
        code = exc.code
    out, err = capsys.readouterr()
    return code, out, err


def _motion(t):
    w = 2 * np.pi * 1.5
    return 0.01 * np.sin(w * t) + 0.002, 0.01 * w * np.cos(w * t), -0.01 * w * w * np.sin(w * t)


def test_run_spec_passes_the_table_to_the_node(tmp_path):
    """``motor-comp run --trajectory table``: the node gets the file and its directory."""
    from motor_comp.cli.run import RunSpec
    t = np.arange(0.0, 0.5, 1e-3)
    write_table(tmp_path / 'e.csv', table_from_arrays(t, *_motion(t)))
    spec = RunSpec(output=tmp_path / 'r.mcap', trajectory='table',
                   trajectory_file=str(tmp_path / 'e.csv'))
    params = spec.node_params()
    assert params['trajectory_node']['file'] == str((tmp_path / 'e.csv').resolve())
    # the run's one model_dir (every node's) holds the table's directory
    dirs = params['trajectory_node']['model_dir'].split(os.pathsep)
    assert str(tmp_path.resolve()) in dirs
    assert params['controller_node']['model_dir'] == params['trajectory_node']['model_dir']
    assert params['plant_node']['x0'] == 0.002
    bad = RunSpec(output=tmp_path / 'r.mcap', trajectory='table',
                  trajectory_file=str(tmp_path / 'none.csv'))
    with pytest.raises(ParameterError, match='no such file'):
        bad.node_params()


def test_run_needs_both_table_options(capsys, tmp_path):
    pytest.importorskip('rclpy')
    code, out, err = _cli(capsys, 'run', '--trajectory', 'table', '-o', tmp_path / 'r.mcap')
    assert code == 2 and '--trajectory table and --trajectory-file' in err
    code, out, err = _cli(capsys, 'run', '--trajectory', 'table', '--trajectory-file',
                          tmp_path / 'none.csv', '-o', tmp_path / 'r.mcap')
    assert code == 2 and 'no such file' in err and len(err.strip().splitlines()) == 1
    assert not Path(tmp_path / 'r.mcap').exists()
