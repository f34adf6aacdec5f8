"""Fixtures shared by every test layer."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import Any, Callable

import pytest

#: the test files that take longest, longest first (seconds on two workers, measured
#: 2026-11-28 with ``--durations``): ``make test`` hands whole files to two workers
#: (``--dist loadfile --no-loadscope-reorder``) in collection order, so these start
#: first and the many short files fill in behind them.  xdist's own order (most tests
#: first) started them last: one worker ran the autotune loop alone for the last
#: ~90 s.  The node tests keep their place (they wait on DDS more than they compute,
#: and are not put beside the suites' two-process pools on purpose).  A stale entry
#: only makes the split less even, never a test different.
LONGEST_FIRST = (
    'tuning/test_tuning_autotune.py',           # 180 s: three autotune loops in lockstep
    'workbench/test_workbench_independent.py',  # 172 s: the suite's fits, two processes
    'workbench/test_workbench_diagnosis.py',    # 121 s
    'workbench/test_workbench_coverage.py',     # 83 s
)


def pytest_collection_modifyitems(config: pytest.Config, items: list) -> None:
    """Put the files of :data:`LONGEST_FIRST` first, in that order (a stable sort)."""
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}

    def key(item: pytest.Item) -> int:
        path = item.nodeid.split('::', 1)[0]
        rel = path[len('test/'):] if path.startswith('test/') else path
        return rank.get(rel, len(rank))
    items.sort(key=key)


def _jit_and_pure(src: str) -> tuple[Any, Any]:
    """Run ``src`` (which sets a JSON-able ``result``) compiled here and pure in a child.

    The child runs with ``NUMBA_DISABLE_JIT=1``, i.e. every ``@njit`` function as plain
    Python; the same source is executed in this process with the compiled kernels.
    Returns ``(compiled_result, pure_result)``.
    """
    child = src + '\nimport json, sys\njson.dump(result, sys.stdout)\n'
    env = dict(os.environ, NUMBA_DISABLE_JIT='1')
    out = subprocess.run([sys.executable, '-c', child], env=env, capture_output=True,
                         text=True, timeout=240, check=True)
    pure = json.loads(out.stdout)
    ns: dict = {}
    exec(compile(src, '<jit-run>', 'exec'), ns)   # the same source, compiled
    return ns['result'], pure


@pytest.fixture
def jit_and_pure() -> Callable[[str], tuple[Any, Any]]:
    """Compare a compiled run with its pure-Python (``NUMBA_DISABLE_JIT``) run."""
    return _jit_and_pure
