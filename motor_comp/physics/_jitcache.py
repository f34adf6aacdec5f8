"""Drop stale numba caches when a source they were compiled from changes.

Numba keys a function's on-disk cache on its *own* file only.  The plant kernel inlines
the effect laws (numba-IR inlining, for speed), and compiled callers in the other layers
(the control loop, the workbench predictors) embed the kernel in their cached code, so
an edit to an effect module would otherwise leave them running the old law.  At import
of :mod:`motor_comp.physics` a hash of the physics sources is compared with the one
stored next to the caches; on a mismatch every numba cache file of the package is
deleted so numba recompiles (the control layer does the same for its own sources).
"""
from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Iterable

#: the ``motor_comp`` package directory
PACKAGE = Path(__file__).resolve().parent.parent


def source_digest(subpackages: Iterable[str]) -> str:
    """SHA-256 over the paths and contents of every ``*.py`` in the given subpackages."""
    h = hashlib.sha256()
    for sub in subpackages:
        for path in sorted((PACKAGE / sub).rglob('*.py')):
            h.update(str(path.relative_to(PACKAGE)).encode())
            h.update(path.read_bytes())
    return h.hexdigest()


def drop_caches_if_stale(stamp: Path, digest: str, roots: Iterable[Path]) -> bool:
    """Delete the numba cache files under ``roots`` unless ``stamp`` holds ``digest``.

    Returns whether caches were dropped.  Read-only installs are left alone (numba then
    caches elsewhere or compiles in memory).
    """
    try:
        if stamp.exists() and stamp.read_text() == digest:
            return False
        stamp.parent.mkdir(exist_ok=True)
        for root in roots:
            for pattern in ('*.nbi', '*.nbc'):
                for f in root.rglob(pattern):
                    f.unlink(missing_ok=True)
        stamp.write_text(digest)
    except OSError:
        return False
    return True


def refresh_stale_caches() -> bool:
    """Drop every numba cache of the package if a physics source changed since the last run.

    Physics is the bottom layer: any compiled function of any layer may embed its
    kernels, so all of them go.
    """
    stamp = PACKAGE / 'physics' / '__pycache__' / 'motor_comp_physics_deps.stamp'
    return drop_caches_if_stale(stamp, source_digest(('physics',)), (PACKAGE,))
