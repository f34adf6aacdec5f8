"""Drop stale numba caches of the control kernels when any source they inline changes.

Numba keys a function's on-disk cache on its *own* file only; a compiled loop that
inlines kernels from other files (the simulator loop calls the plant kernel, the
controller step, the trajectory evaluator) would silently keep the old code after one of
those files is edited.  At import, a hash of every source the control kernels depend on
is compared with the one stored next to the cache; on a mismatch the control caches are
deleted so numba recompiles them (:mod:`motor_comp.physics._jitcache` does the same for
the physics sources, for every layer).
"""
from __future__ import annotations

from pathlib import Path

from motor_comp.physics._jitcache import drop_caches_if_stale, source_digest

_DEPENDS = ('physics', 'control')
_STAMP = 'motor_comp_control_deps.stamp'


def refresh_stale_caches() -> bool:
    """Delete the control package's numba cache files if a dependency changed.

    Returns whether caches were dropped.  Read-only installs are left alone (numba then
    caches elsewhere or compiles in memory).
    """
    cache_dir = Path(__file__).resolve().parent / '__pycache__'
    try:
        digest = source_digest(_DEPENDS)
    except OSError:
        return False
    return drop_caches_if_stale(cache_dir / _STAMP, digest, (cache_dir,))


#: numba options of every control kernel: cached on disk; numpy error model, i.e. no
#: ZeroDivisionError checks in the hot loop (every divisor is validated > 0 up front)
JIT_OPTIONS = {'cache': True, 'error_model': 'numpy'}
#: options of the per-step helpers: also inlined into their callers at numba-IR level, so
#: the compiled loop is one function (a cached callee is linked as object code, which
#: LLVM cannot inline, and every call passing arrays costs atomic reference counting)
JIT_INLINE = dict(JIT_OPTIONS, inline='always')
