"""Fixtures shared by every test layer."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from typing import Any, Callable

import pytest


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
