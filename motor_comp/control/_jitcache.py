"""Drop stale numba caches of the control kernels when any source they inline changes.

Numba keys a function's on-disk cache on its *own* file only; a compiled loop that
inlines kernels from other files (the simulator loop calls the plant kernel, the
controller step, the trajectory evaluator) would silently keep the old code after one of
those files is edited.  At import, a hash of every source the control kernels depend on
is compared with the one stored next to the cache; on a mismatch the control caches are
deleted so numba recompiles them.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent.parent
_DEPENDS = ('physics', 'control')
_STAMP = 'motor_comp_control_deps.stamp'


def _digest() -> str:
    h = hashlib.sha256()
    for sub in _DEPENDS:
        for path in sorted((_PACKAGE / sub).rglob('*.py')):
            h.update(str(path.relative_to(_PACKAGE)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def refresh_stale_caches() -> bool:
    """Delete the control package's numba cache files if a dependency changed.

    Returns whether caches were dropped.  Read-only installs are left alone (numba then
    caches elsewhere or compiles in memory).
    """
    cache_dir = Path(__file__).resolve().parent / '__pycache__'
    stamp = cache_dir / _STAMP
    try:
        digest = _digest()
        if stamp.exists() and stamp.read_text() == digest:
            return False
        cache_dir.mkdir(exist_ok=True)
        for f in list(cache_dir.glob('*.nbi')) + list(cache_dir.glob('*.nbc')):
            f.unlink()
        stamp.write_text(digest)
    except OSError:
        return False
    return True


#: numba options of every control kernel: cached on disk; numpy error model, i.e. no
#: ZeroDivisionError checks in the hot loop (every divisor is validated > 0 up front)
JIT_OPTIONS = {'cache': True, 'error_model': 'numpy'}
