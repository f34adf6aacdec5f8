"""Run workbench commands on the compiled entries, then replay their calls on the JIT.

Run as a script in a fresh interpreter (numba's state is per process):
``python aot_probe.py OUT.json -- ARGS [-- ARGS ...]``, each ARGS a ``motor-comp``
command line.  Every entry declared with :func:`motor_comp.physics.aot.ahead` is wrapped
to record its first calls (arguments before and after, result).  After the commands it
notes which of the package's JIT dispatchers compiled or loaded code, then calls each
JIT dispatcher on copies of the recorded arguments and compares everything bit for bit.
Writes a JSON summary to OUT.json.
"""
from __future__ import annotations

import contextlib
import copy
import importlib
import io
import json
import sys

import numpy as np

#: calls recorded per entry (the first ones: each kernel's typical arguments)
CALLS = 3


def same(a, b) -> bool:
    """Whether two results are equal to the bit (arrays, tuples of them, scalars)."""
    if isinstance(a, tuple) or isinstance(b, tuple):
        return (isinstance(a, tuple) and isinstance(b, tuple) and len(a) == len(b)
                and all(same(x, y) for x, y in zip(a, b)))
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        bits = [np.ascontiguousarray(c).view(np.uint8) for c in (a, b)]
        return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(*bits)
    return a == b or (a != a and b != b)


def jitted() -> set[str]:
    """Names of the package's numba dispatchers that compiled or loaded any code."""
    from numba.core.dispatcher import Dispatcher
    used = set()
    for name, mod in list(sys.modules.items()):
        if not name.startswith('motor_comp'):
            continue
        for attr, obj in vars(mod).items():
            if isinstance(obj, Dispatcher) and obj.overloads:
                used.add(f'{name}.{attr}')
    return used


def main(argv: list[str]) -> int:
    out_path, rest = argv[0], argv[1:]
    commands, cur = [], None
    for a in rest:
        if a == '--':
            cur = []
            commands.append(cur)
        else:
            cur.append(a)
    from motor_comp.cli import main as cli
    from motor_comp.physics import aot
    from motor_comp.physics.aot_build import import_all
    import_all()  # every declared entry registered, as the build sees them
    records: dict[str, list] = {}
    wrapped = {}
    for (module, name), spec in aot.REGISTRY.items():
        mod = importlib.import_module(module)
        ent = getattr(mod, name + '_entry')
        wrapped[spec.symbol] = (mod, name, hasattr(ent, 'compiled'))

        def rec(*args, _ent=ent, _key=spec.symbol):
            calls = records.setdefault(_key, [])
            if len(calls) >= CALLS:
                return _ent(*args)
            before = copy.deepcopy(args)
            res = _ent(*args)
            calls.append((before, copy.deepcopy(args), copy.deepcopy(res)))
            return res
        setattr(mod, name + '_entry', rec)
    codes = []
    for cmd in commands:
        with contextlib.redirect_stdout(io.StringIO()), \
                contextlib.redirect_stderr(io.StringIO()):
            try:
                codes.append(cli.main(cmd))
            except SystemExit as exc:
                codes.append(exc.code)
    jit_used = sorted(jitted())
    mismatches = []
    for key, calls in records.items():
        mod, name, _ = wrapped[key]
        dispatcher = getattr(mod, name)
        for before, after, res in calls:
            args = copy.deepcopy(before)
            again = dispatcher(*args)
            if not same(res, again) or not all(same(x, y) for x, y in zip(after, args)):
                mismatches.append(key)
    with open(out_path, 'w') as f:
        json.dump({'codes': codes, 'compiled': sorted(k for k, v in wrapped.items() if v[2]),
                   'declared': sorted(wrapped), 'called': sorted(records),
                   'jit_used': jit_used, 'mismatches': sorted(set(mismatches))}, f)
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
