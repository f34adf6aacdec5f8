"""Packaging of the nodes: colcon build, parameter files, launch file."""
from __future__ import annotations

import py_compile
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from motor_comp.nodes import controller_node, plant_node, recorder_node, trajectory_node
from motor_comp.nodes.common import AUTOSTART

ROOT = Path(__file__).resolve().parents[2]
NODES = {'plant_node': plant_node.PARAMS + (AUTOSTART,),
         'trajectory_node': trajectory_node.PARAMS,
         'controller_node': controller_node.BASE_PARAMS + (AUTOSTART,),
         'recorder_node': recorder_node.PARAMS + (AUTOSTART,)}


@pytest.mark.timeout(120)
def test_colcon_build_installs_nodes_and_config(tmp_path: Path) -> None:
    """``colcon build --packages-select motor_comp`` works from the venv alone.

    colcon-ros builds an ``ament_python`` package with setup.py; no system ROS (no
    ament_index C++ tooling) is needed.  Built from a copy so the source stays clean.
    """
    src = tmp_path / 'src' / 'motor_comp'
    src.mkdir(parents=True)
    for name in ('setup.py', 'setup.cfg', 'package.xml'):
        shutil.copy2(ROOT / name, src / name)
    for name in ('resource', 'launch', 'motor_comp'):
        shutil.copytree(ROOT / name, src / name, symlinks=True,
                        ignore=shutil.ignore_patterns('__pycache__', '*.nbi', '*.nbc'))
    (src / 'config').symlink_to('motor_comp/config')
    colcon = Path(sys.executable).with_name('colcon')
    out = subprocess.run([str(colcon), '--log-base', str(tmp_path / 'log'), 'build',
                          '--base-paths', str(tmp_path / 'src'),
                          '--packages-select', 'motor_comp',
                          '--build-base', str(tmp_path / 'build'),
                          '--install-base', str(tmp_path / 'install')],
                         cwd=tmp_path, capture_output=True, text=True, timeout=110)
    assert out.returncode == 0, out.stdout + out.stderr
    prefix = tmp_path / 'install' / 'motor_comp'
    for node in NODES:
        exe = prefix / 'lib' / 'motor_comp' / node
        assert exe.is_file() and exe.stat().st_mode & 0o111, exe
    share = prefix / 'share' / 'motor_comp'
    installed = {p.name for p in (share / 'config').glob('*.yaml')}
    assert {f'{n}.yaml' for n in NODES} | {'pmlm.yaml', 'ballscrew.yaml'} <= installed
    assert (share / 'launch' / 'axis_launch.py').is_file()
    assert (share / 'package.xml').is_file()
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
            / 'motor_comp').is_file()
    # the installed executable runs the node: an invalid parameter is a one-line error
    run = subprocess.run([str(prefix / 'lib' / 'motor_comp' / 'plant_node'), '--ros-args',
                          '-p', 'timing:=sometimes'], capture_output=True, text=True,
                         timeout=60)
    assert run.returncode == 2
    assert "timing: 'sometimes' is not one of lockstep, realtime" in run.stderr
    assert 'Traceback' not in run.stderr


@pytest.mark.parametrize('node', sorted(NODES))
def test_parameter_files_match_declared_parameters(node: str) -> None:
    """``config/<node>.yaml``: ``/**/<node>: ros__parameters:`` with declared names only."""
    data = yaml.safe_load((ROOT / 'config' / f'{node}.yaml').read_text())
    assert list(data) == [f'/**/{node}']
    params = data[f'/**/{node}']['ros__parameters']
    specs = {s.name: s for s in NODES[node]}
    assert params and set(params) <= set(specs)
    for name, value in params.items():
        specs[name].check(tuple(value) if isinstance(value, list) else value)
        # the file documents the defaults (except run-specific choices like output)
        if name != 'output':
            assert specs[name].convert(value) == specs[name].default, name


def test_launch_file_compiles(tmp_path: Path) -> None:
    """No ``ros2 launch`` on PyPI: the launch file must at least be valid Python."""
    py_compile.compile(str(ROOT / 'launch' / 'axis_launch.py'),
                       cfile=str(tmp_path / 'axis_launch.pyc'), doraise=True)
