"""Without ROS 2 installed, ``run``/``replay``/``demo`` say so in one line, start nothing.

Absence is simulated in a subprocess by a meta-path finder that refuses ``rclpy`` and
the ROS message packages, as on a ``pip install -e .`` without the ``[ros]`` extra.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from motor_comp.logs import Run, write_run

pytestmark = pytest.mark.timeout(120)

_BLOCK = '''
import sys
from importlib.abc import MetaPathFinder

class NoRos(MetaPathFinder):
    """Refuse the ROS 2 Python packages, as when they are not installed."""

    BLOCKED = {BLOCKED!r}

    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in self.BLOCKED:
            raise ModuleNotFoundError(f"No module named {{name!r}}", name=name)
        return None

sys.meta_path.insert(0, NoRos())
from motor_comp.cli.main import main
sys.exit(main(sys.argv[1:]))
'''


def _cli(tmp_path: Path, blocked: set[str], *args: str) -> subprocess.CompletedProcess:
    script = _BLOCK.replace('{BLOCKED!r}', repr(sorted(blocked)))
    return subprocess.run([sys.executable, '-c', script, *args], capture_output=True,
                          text=True, timeout=100, cwd=tmp_path)


@pytest.fixture(scope='module')
def recorded(tmp_path_factory) -> Path:
    """A small valid run to replay."""
    t = np.arange(100) * 1e-3
    path = tmp_path_factory.mktemp('noros') / 'r.mcap'
    write_run(path, Run(t=t, position=t, velocity=t, reference=t, reference_velocity=t,
                        voltage=t, name='r'))
    return path


@pytest.mark.parametrize('blocked, missing', [
    ({'rclpy', 'rcl_interfaces', 'lifecycle_msgs', 'std_msgs', 'sensor_msgs',
      'rosgraph_msgs'}, 'rclpy'),
    ({'rcl_interfaces'}, 'rcl_interfaces'),      # the case: a partial install
])
def test_run_and_replay_without_ros_one_line(tmp_path: Path, recorded: Path, blocked,
                                             missing: str) -> None:
    """One line naming the missing package and both remedies; exit 2; nothing started."""
    out_file = tmp_path / 'out.mcap'
    cases = {'run': ('run', '--duration', '0.1', '-o', str(out_file)),
             'replay': ('replay', str(recorded)),
             'demo': ('demo', '--out', str(tmp_path / 'demo'), '--only', 'pmlm_pid')}
    for name, args in cases.items():
        res = _cli(tmp_path, blocked, *args)
        assert res.returncode == 2, (name, res.stderr)
        assert res.stdout == ''
        lines = res.stderr.splitlines()
        assert len(lines) == 1, (name, res.stderr)
        line = lines[0]
        assert line.startswith('motor-comp: error: ') and 'Traceback' not in line
        assert f'missing: {missing}' in line, line
        assert "pip install -e '.[ros]'" in line and 'ROS 2 Jazzy setup' in line, line
        assert 'motor-comp' in line
    # nothing was started or written: no node logs, no output file
    assert not out_file.exists()
    assert not (tmp_path / 'demo' / 'pmlm_pid.mcap').exists()


def test_offline_commands_still_work_without_ros(tmp_path: Path, recorded: Path) -> None:
    """The offline library needs no ROS: ``analyze`` reads the run with rclpy blocked."""
    res = _cli(tmp_path, {'rclpy', 'rcl_interfaces', 'std_msgs', 'sensor_msgs'},
               'analyze', str(recorded), '--json')
    assert res.returncode == 0, res.stderr
    assert '"rms_error"' in res.stdout
