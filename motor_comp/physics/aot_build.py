"""Build the compiled entry kernels: ``python -m motor_comp.physics.aot_build``.

Compiles every kernel declared with :func:`motor_comp.physics.aot.ahead` into one
extension module next to :mod:`motor_comp.physics.aot`, with a stamp of the sources it
was built from (the reasons and the runtime side are in that module).  ``make setup``
runs it; it needs a C compiler and takes about 20 s with numba's cache warm, 60 s from
a fresh clone (each entry is JIT-compiled first, for its return type; half of that is
the plant kernel, once per law).  On failure it says
so in one line and exits 1, and the commands keep using the JIT.
"""
from __future__ import annotations

import argparse
import contextlib
import importlib
import pkgutil
import shutil
import sys
import tempfile
import time
import warnings
from pathlib import Path

from motor_comp.physics import aot
from motor_comp.physics.aot import HERE, MODULE, REGISTRY, SOURCES


def import_all() -> None:
    """Import every module of the subpackages so that each :func:`ahead` has run."""
    for sub in SOURCES:
        pkg = importlib.import_module(f'motor_comp.{sub}')
        for info in pkgutil.walk_packages(pkg.__path__, pkg.__name__ + '.'):
            importlib.import_module(info.name)


@contextlib.contextmanager
def _own_flags(dispatchers: list):
    """Compile each exported function with its own dispatcher's options, as the JIT does.

    ``numba.pycc`` gives every export one default set of compiler flags, while the JIT
    compiles each dispatcher with the options of its ``@njit`` (``error_model='numpy'``
    on some laws: a division by zero gives inf, not an exception).  The same code needs
    the same flags, so pycc's call of numba's compiler is wrapped, for this build only,
    to start from each function's own flags and keep only pycc's wrapper settings.
    """
    from numba.core.compiler import Flags
    from numba.pycc import compiler as pycc_compiler
    own = {d.py_func: d for d in dispatchers}
    original = pycc_compiler.compile_extra

    def compile_extra(typingctx, targetctx, func, args, return_type, flags, *a, **kw):
        d = own.get(func)
        if d is not None:
            mine = Flags()
            d.targetdescr.options.parse_as_flags(mine, d.targetoptions)
            for name in ('no_compile', 'no_cpython_wrapper', 'no_cfunc_wrapper', 'nrt'):
                setattr(mine, name, getattr(flags, name))
            flags = mine
        return original(typingctx, targetctx, func, args, return_type, flags, *a, **kw)

    pycc_compiler.compile_extra = compile_extra
    try:
        yield
    finally:
        pycc_compiler.compile_extra = original


def build(folder: Path = HERE) -> tuple[Path, int]:
    """Compile every declared entry into the extension module in ``folder``.

    The stamp is computed before compiling (a source edited meanwhile makes the result
    stale, never wrongly current) and written only after the module is in place.

    Returns
    -------
    (Path, int)
        The module's path and the number of entries compiled.
    """
    text = aot.stamp_text()
    import_all()
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # pycc's pending-deprecation notice
        from numba.pycc import CC
    lib, stamp = aot.paths(folder)
    stamp.unlink(missing_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        cc = CC(MODULE)
        cc.output_dir = tmp
        cc.verbose = False
        dispatchers = []
        for (module, name), spec in sorted(REGISTRY.items()):
            dispatcher = getattr(importlib.import_module(module), name)
            dispatchers.append(dispatcher)
            dispatcher.compile(spec.argtypes)
            ret = dispatcher.overloads[spec.argtypes].signature.return_type
            cc.export(spec.symbol, ret(*spec.argtypes))(dispatcher.py_func)
        with warnings.catch_warnings(), _own_flags(dispatchers):
            warnings.simplefilter('ignore')
            cc.compile()
        built = next(Path(tmp).glob(MODULE + '*'))
        shutil.move(str(built), lib)
    stamp.write_text(text)
    return lib, len(REGISTRY)


def main(argv: list[str] | None = None) -> int:
    """``python -m motor_comp.physics.aot_build``: build the compiled entries (see module doc)."""
    p = argparse.ArgumentParser(prog='python -m motor_comp.physics.aot_build',
                                description='compile the entry kernels ahead of time')
    p.add_argument('--check', action='store_true',
                   help='only say whether the compiled module is present and current')
    args = p.parse_args(argv)
    if args.check:
        ok = aot.compiled_module() is not None
        print('compiled kernels: ' + ('current' if ok else 'absent or stale (the JIT is used)'))
        return 0 if ok else 1
    t0 = time.monotonic()
    try:
        lib, n = build()
    except Exception as exc:  # noqa: BLE001 - any build failure leaves the JIT in use
        print(f'error: compiling the kernels ahead of time failed ({type(exc).__name__}: '
              f'{str(exc).splitlines()[0] if str(exc) else ""}); the JIT will be used',
              file=sys.stderr)
        return 1
    print(f'compiled {n} entry kernels ahead of time into {lib.name} '
          f'in {time.monotonic() - t0:.0f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
