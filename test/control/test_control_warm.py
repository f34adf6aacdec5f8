"""``python -m motor_comp.control.warm``: the simulator's and the controller's kernels cached."""
from __future__ import annotations

import subprocess
import sys

import pytest

from motor_comp.control import controller, simulator, warm


def test_warm_compiles_the_loop_and_the_step(capsys):
    """After it, the closed loop and the node's controller step are compiled kernels."""
    assert warm.main([]) == 0
    out = capsys.readouterr()
    assert out.out.startswith('cached the simulator and controller kernels in ')
    assert out.out.count('\n') == 1 and out.err == ''
    assert simulator._loop.signatures           # the closed loop the simulator runs
    assert controller.controller_step.signatures  # the step a controller node calls


def test_a_failure_is_one_line_and_exit_1(capsys, monkeypatch):
    def broken() -> None:
        raise RuntimeError('LLVM failed')
    monkeypatch.setattr(warm, 'warm', broken)
    assert warm.main([]) == 1
    err = capsys.readouterr().err
    assert err.count('\n') == 1 and err.startswith('error: filling the kernel cache failed')
    assert 'Traceback' not in err


def test_a_later_process_loads_them_from_the_disk_cache():
    """What it compiled outlives the process: the next one loads, it does not compile."""
    code = ('from motor_comp.control import controller, simulator, warm; warm.warm(); '
            's, c = simulator._loop.stats, controller.controller_step.stats; '
            'print(*(sum(n.values()) for n in (s.cache_hits, s.cache_misses, c.cache_hits, '
            'c.cache_misses)))')
    warm.warm()
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout.split()
    hits, misses, step_hits, step_misses = (int(v) for v in out)
    assert hits >= 1 and step_hits >= 1 and misses == 0 and step_misses == 0, out


def test_an_unknown_argument_is_refused(capsys):
    with pytest.raises(SystemExit) as exc:
        warm.main(['--bogus'])
    assert exc.value.code == 2
    assert 'unrecognized arguments: --bogus' in capsys.readouterr().err
