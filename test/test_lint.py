"""Linters over the tree: flake8 (code style) and pep257 (docstrings).

flake8 runs through the ament_flake8 API (the ``ros-jazzy-ament-flake8`` wheel of the
``test`` extra), as ``colcon test`` would, but with the project's [flake8] settings from
``setup.cfg`` (max line 99); without the wheel, plain flake8 runs.  Docstrings are
checked by pydocstyle with the [pydocstyle] section of ``setup.cfg`` (pep257
convention), exactly as ``make lint`` does.  ament_pep257 is not used: it drops
pydocstyle's property-decorator rule and would demand imperative-mood docstrings on
``@property`` getters, disagreeing with ``make lint`` and numpydoc.
"""
from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
SETUP_CFG = ROOT / 'setup.cfg'
FLAKE8_PATHS = ('motor_comp', 'test', 'bench', 'launch', 'setup.py')
PEP257_PATHS = ('motor_comp',)


def _existing(paths: tuple[str, ...]) -> list[str]:
    return [str(ROOT / p) for p in paths if (ROOT / p).exists()]


def flake8_errors(paths: list[str]) -> list[str]:
    """flake8 findings (``file:line:col: code message``) over ``paths`` with setup.cfg."""
    try:
        import ament_flake8.main  # noqa: F401
    except ImportError:
        proc = subprocess.run([sys.executable, '-m', 'flake8', '--config', str(SETUP_CFG),
                               *paths], cwd=ROOT, capture_output=True, text=True)
        return proc.stdout.splitlines() + ([proc.stderr] if proc.returncode > 1 else [])
    # A fresh interpreter: flake8 forks a worker pool, and forking this test process
    # (which holds threads from earlier tests, e.g. a Dask client's) can deadlock the
    # pool -- seen once in CI as a 300 s hang.  ament scans its working directory for
    # AMENT_IGNORE markers: keep that scan to the package tree, not the venv beside it.
    proc = subprocess.run([sys.executable, '-m', 'ament_flake8.main', '--config',
                           str(SETUP_CFG), *paths], cwd=ROOT / 'motor_comp',
                          capture_output=True, text=True, timeout=240)
    if proc.returncode == 0:
        return []
    # ament prints each finding as "path:line:col: code message" followed by context
    found = [ln for ln in proc.stdout.splitlines() if re.match(r'^\S+:\d+:\d+: [A-Z]\d+ ', ln)]
    return found or [proc.stderr.strip() or f'ament_flake8 exit status {proc.returncode}']


def pep257_errors(paths: list[str]) -> list[str]:
    """pydocstyle findings over ``paths``, configured by setup.cfg like ``make lint``."""
    proc = subprocess.run([sys.executable, '-m', 'pydocstyle', *paths], cwd=ROOT,
                          capture_output=True, text=True)
    if proc.returncode == 0:
        return []
    lines = proc.stdout.splitlines()
    # pydocstyle prints "file:line in def:" then an indented "Dnnn: message" line
    found = [f'{a.strip()} {b.strip()}' for a, b in zip(lines[::2], lines[1::2])]
    return found or [proc.stderr.strip() or f'pydocstyle exit status {proc.returncode}']


def test_flake8():
    errors = flake8_errors(_existing(FLAKE8_PATHS))
    assert not errors, f'{len(errors)} flake8 problems:\n' + '\n'.join(errors[:50])


def test_pep257():
    errors = pep257_errors(_existing(PEP257_PATHS))
    assert not errors, f'{len(errors)} docstring problems:\n' + '\n'.join(errors[:50])


@pytest.mark.parametrize('check, bad', [
    (flake8_errors, 'import os\nx = 1\n'),                       # F401 unused import
    (pep257_errors, 'def f():\n    return 1\n'),                 # D103 missing docstring
])
def test_linters_detect_a_planted_problem(tmp_path, check, bad):
    # guards against a harness that silently checks nothing
    path = tmp_path / 'planted_problem.py'
    path.write_text(bad)
    assert check([str(path)])
