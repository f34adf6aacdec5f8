"""Kernels compiled ahead of time, so that a command need not start numba's JIT.

Why: the first call of any numba-compiled function in a process initialises numba's CPU
target (LLVM, the target context, a BLAS probe that imports ``scipy.linalg``).  Measured
on the project's machine that is 0.41 s of CPU per process, plus ~0.1 s to load the
cached kernels: more than a 60× real-time ``diagnose`` of a 20 s run may spend in all
(issue 22, item 6; ``bench/README.md``).  ``numba.pycc`` compiles the *same* Python
functions (each dispatcher's ``py_func``, through the same numba pipeline) into one
extension module that loads in under a millisecond and needs neither.  So each law keeps
one implementation; the compiled module is a build product, like numba's own cache.

How:

- a kernel that Python code calls directly (an *entry*) declares its argument types with
  :func:`ahead` above its ``@njit``; kernels it calls are compiled into it by numba;
- Python call sites call the entry through :func:`entry`, which returns the compiled
  function behind a guard, or the JIT dispatcher when the module is absent, stale or
  ``NUMBA_DISABLE_JIT`` is set;
- the guard passes a call to the compiled code only when every argument has exactly the
  declared type (dtype, dimensions, C order, writable where the kernel may write).  The
  compiled wrappers check nothing themselves (a strided or float32 array would be read
  wrongly or crash), and converting an argument could drop a kernel's output written
  into it; so any other call goes to the JIT, which compiles it as before;
- ``python -m motor_comp.physics.aot_build`` (run by ``make setup``) builds the module next to
  this file with a stamp of the sources it was built from (physics and workbench: every
  file an entry may inline).  A source edited since makes it stale: the JIT is used
  until it is rebuilt.  Building needs a C compiler; without one the JIT is used.

``numba.pycc`` has been pending deprecation since numba 0.57 (a replacement is being
developed) and is present in 0.68, the version measured; if a numba drops it, the build
fails in one line and :func:`entry` keeps returning the JIT.
"""
from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import numpy as np

#: name of the compiled extension module (file ``_aot_kernels<EXT_SUFFIX>`` here)
MODULE = '_aot_kernels'
#: the folder the module and its stamp live in
HERE = Path(__file__).resolve().parent
#: the subpackages whose sources an entry may inline (the stamp's digest covers them)
SOURCES = ('physics', 'workbench')
#: environment switch: ``off`` always uses the JIT (tests compare the two)
ENV = 'MOTOR_COMP_AOT'


@dataclass(frozen=True)
class Entry:
    """One kernel compiled ahead of time: where it lives and its declared argument types."""

    module: str
    name: str
    argtypes: tuple

    @property
    def symbol(self) -> str:
        """Exported name in the compiled module (unique across the package)."""
        return self.module.replace('motor_comp.', '').replace('.', '__') + '__' + self.name


#: every declared entry, by (module, function name); filled at import by :func:`ahead`
REGISTRY: dict[tuple[str, str], Entry] = {}


def ahead(*argtypes: Any) -> Callable:
    """Declare a numba dispatcher an entry compiled ahead of time for ``argtypes``.

    Parameters
    ----------
    *argtypes
        numba types of the positional arguments, exactly as the Python callers pass them
        (see :data:`F8`, :data:`I8`, :data:`BOOL`, :func:`array`).

    Returns
    -------
    Callable
        A decorator that registers the dispatcher and returns it unchanged, so compiled
        callers keep calling it as before.
    """
    def register(dispatcher):
        fn = getattr(dispatcher, 'py_func', dispatcher)
        key = (fn.__module__, fn.__name__)
        REGISTRY[key] = Entry(key[0], key[1], tuple(argtypes))
        return dispatcher
    return register


def array(ndim: int, dtype: str = 'float64', *, readonly: bool = False):
    """Return a C-ordered numpy array type of ``ndim`` dimensions for :func:`ahead`."""
    from numba import types
    return types.Array(getattr(types, dtype), ndim, 'C', readonly=readonly)


def _scalar(name: str):
    from numba import types
    return getattr(types, name)


#: scalar argument types for :func:`ahead` (Python float / int / bool, or numpy's)
F8 = _scalar('float64')
I8 = _scalar('int64')
BOOL = _scalar('boolean')
#: the array types most kernels take: float64 vectors and matrices, int64 index vectors
F8_1D = array(1)
F8_2D = array(2)
I8_1D = array(1, 'int64')


def stamp_text() -> str:
    """Return what the compiled module must be built from to be used: sources, ABI."""
    from motor_comp.physics._jitcache import source_digest
    return '\n'.join((source_digest(SOURCES), f'numpy {np.__version__}',
                      f'python {sys.version_info[0]}.{sys.version_info[1]}')) + '\n'


def paths(folder: Path = HERE) -> tuple[Path, Path]:
    """Return the compiled module's file and its stamp's file in ``folder``."""
    suffix = importlib.machinery.EXTENSION_SUFFIXES[0]
    return folder / (MODULE + suffix), folder / (MODULE + '.stamp')


def load(folder: Path = HERE):
    """Return the compiled module in ``folder`` if built from today's sources, else None."""
    lib, stamp = paths(folder)
    try:
        if not lib.is_file() or stamp.read_text() != stamp_text():
            return None
        spec = importlib.util.spec_from_file_location(MODULE, lib)
        mod = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(mod)
    except (OSError, ImportError):
        return None
    return mod


_loaded: list = []  # [module or None], resolved once per process


def compiled_module():
    """Return the package's compiled module (once per process), or None.

    None when it is absent or stale, or when the environment sets ``MOTOR_COMP_AOT=off``.
    """
    if not _loaded:
        off = os.environ.get(ENV, '').lower() in ('off', '0', 'no')
        _loaded.append(None if off else load())
    return _loaded[0]


def _check(t) -> Callable[[Any], bool]:
    """Return a test that an argument has exactly the numba type ``t`` (no conversion)."""
    from numba import types
    if isinstance(t, types.Array):
        dt, nd, ro = np.dtype(str(t.dtype)), t.ndim, t.mutable is False

        if ro:
            def ok(a) -> bool:
                return (type(a) is np.ndarray and a.dtype == dt and a.ndim == nd
                        and a.flags.c_contiguous)
            return ok

        def ok_w(a) -> bool:
            # one flags object for both tests (each attribute read builds one)
            if type(a) is not np.ndarray or a.dtype != dt or a.ndim != nd:
                return False
            f = a.flags
            return f.c_contiguous and f.writeable
        return ok_w
    kinds = {'float64': (float, np.float64), 'int64': (int, np.int64),
             'bool': (bool, np.bool_)}[str(t)]
    return lambda a: type(a) in kinds


def entry(dispatcher: Callable) -> Callable:
    """Return the function Python code should call for a declared entry kernel.

    Returns the compiled function behind a type guard when the compiled module is
    present and current, else ``dispatcher`` itself (the JIT, or plain Python under
    ``NUMBA_DISABLE_JIT``).  Arguments of any other type than declared go to
    ``dispatcher``.
    """
    fn = getattr(dispatcher, 'py_func', None)
    if fn is None:  # NUMBA_DISABLE_JIT: njit returned the Python function
        return dispatcher
    spec = REGISTRY.get((fn.__module__, fn.__name__))
    mod = compiled_module() if spec is not None else None
    fast = getattr(mod, spec.symbol, None) if mod is not None else None
    if fast is None:
        return dispatcher
    checks = tuple(_check(t) for t in spec.argtypes)
    n = len(checks)

    def call(*args):
        # a plain loop, not all() over a generator: the guard is most of a small
        # kernel's call (~10⁴ calls a fit)
        if len(args) == n:
            for c, a in zip(checks, args):
                if not c(a):
                    break
            else:
                return fast(*args)
        return dispatcher(*args)
    call.__name__ = call.__qualname__ = fn.__name__
    call.__doc__ = fn.__doc__
    call.compiled = fast
    return call
