"""Kernels compiled ahead of time (:mod:`motor_comp.physics.aot`).

The claim behind them: ``fit`` and ``diagnose`` run without numba's JIT (its start costs
more CPU than a 60× real-time diagnosis of a 20 s run may spend) and compute the same
numbers to the bit.  Checked by running both commands on a run the simulator made, in a
fresh interpreter, then replaying each entry's calls on the JIT (``aot_probe.py``).
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from motor_comp.physics import aot
from motor_comp.physics.aot_build import import_all
from motor_comp.physics.effects import stribeck

REPO = Path(__file__).resolve().parents[2]
PROBE = Path(__file__).with_name('aot_probe.py')
#: a C compiler is what building needs; without one the JIT is used and that is correct
HAS_CC = any(shutil.which(c) for c in (os.environ.get('CC', 'cc'), 'gcc', 'cc'))
needs_module = pytest.mark.skipif(not HAS_CC, reason='no C compiler: kernels stay on the JIT')


@needs_module
def test_the_compiled_module_is_built_from_todays_sources():
    # `make setup` / `make test` build it; stale or absent means the commands run slower
    assert aot.compiled_module() is not None, \
        'compiled kernels absent or stale: run `python -m motor_comp.physics.aot_build`'


@needs_module
def test_a_stamp_from_other_sources_is_not_loaded(tmp_path):
    lib, stamp = aot.paths()
    assert lib.is_file(), 'compiled kernels absent: run `python -m motor_comp.physics.aot_build`'
    shutil.copy(lib, tmp_path / lib.name)
    (tmp_path / stamp.name).write_text(aot.stamp_text())
    assert aot.load(tmp_path) is not None
    (tmp_path / stamp.name).write_text(aot.stamp_text().replace('numpy', 'numpy 0'))
    assert aot.load(tmp_path) is None
    (tmp_path / stamp.name).unlink()
    assert aot.load(tmp_path) is None


@needs_module
def test_arguments_of_another_type_go_to_the_jit():
    # the compiled wrappers check nothing: a strided view would be read as if contiguous
    # (a float32 array as float64, a crash); the guard sends every other type to the JIT
    call = stribeck.stribeck_shape_entry
    assert hasattr(call, 'compiled')
    x = np.linspace(0.0, 3.0, 41)
    exact = stribeck.stribeck_shape.py_func(x, 1.3)
    np.testing.assert_allclose(call(x, 1.3), exact, rtol=1e-12)
    np.testing.assert_allclose(call(x[::2], 1.3), exact[::2], rtol=1e-12)
    frozen = x.copy()
    frozen.flags.writeable = False
    np.testing.assert_allclose(call(frozen, 1.3), exact, rtol=1e-12)
    np.testing.assert_allclose(call(x, 2), stribeck.stribeck_shape.py_func(x, 2), rtol=1e-12)
    with pytest.raises(Exception):
        call(x)  # a missing argument is the JIT's error, not a crash


def test_every_declared_entry_has_its_call_and_types():
    import_all()
    assert len(aot.REGISTRY) >= 14
    for (module, name), spec in aot.REGISTRY.items():
        mod = sys.modules[module]
        assert callable(getattr(mod, name + '_entry')), (module, name)
        assert spec.argtypes, (module, name)


@pytest.fixture(scope='module')
def ballscrew(tmp_path_factory):
    """The ball-screw's N-PID run (10 s, ``motor-comp simulate``) and its bare model."""
    import yaml

    from motor_comp.control.nominal import derive_nominal
    from motor_comp.physics.config import load_plant
    out = tmp_path_factory.mktemp('aot')
    run = out / 'run.mcap'
    subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', 'simulate', '--plant',
                    'ballscrew', '--controller', 'npid', '--duration', '10', '-o', str(run)],
                   cwd=REPO, check=True, capture_output=True, timeout=300)
    bare = derive_nominal(load_plant('ballscrew')).model.to_dict()
    bare['effects'] = {}
    model = out / 'bare.yaml'
    model.write_text(yaml.safe_dump(bare))
    return run, model


@needs_module
def test_fit_and_diagnose_use_no_jit_and_equal_it_to_the_bit(ballscrew, tmp_path):
    run, model = ballscrew
    out = tmp_path / 'probe.json'
    env = {k: v for k, v in os.environ.items() if k != aot.ENV}
    subprocess.run([sys.executable, str(PROBE), str(out),
                    '--', 'fit', str(run), '--model', str(model), '--auto', '--json',
                    '--', 'diagnose', str(run), '--model', str(model), '--json'],
                   cwd=REPO, env=env, check=True, timeout=600)
    got = json.loads(out.read_text())
    assert got['codes'] == [0, 0]
    # every entry is compiled, and this run reaches each of them
    assert got['compiled'] == got['declared']
    assert got['called'] == got['declared']
    # no JIT dispatcher of the package compiled or loaded anything: numba never started
    assert got['jit_used'] == []
    # and the JIT, given the same arguments, returns the same bits and writes the same
    assert got['mismatches'] == []
