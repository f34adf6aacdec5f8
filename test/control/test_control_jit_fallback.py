"""The compiled closed loop equals its pure-Python run (``NUMBA_DISABLE_JIT=1``).

Issue 7: the loop is one compiled function built from inlined step kernels; with numba
disabled the very same source runs as plain Python (the fallback).  Both must give the
same run on the PMLM with the adaptive controller (ripple and Stribeck δ = 2 in the
plant, sin/cos regressors in the controller) and on a reversing sine with static
feedforward, to the last bits that libm and numpy's scalar functions may differ in.
"""
from __future__ import annotations

import numpy as np
import pytest

_RUN = r'''
from motor_comp.control import make_controller, make_trajectory, default_trajectory, simulate
from motor_comp.physics import load_plant
plant = load_plant('pmlm')
traj = TRAJ
ctrl = make_controller(MODE, plant=plant, feedforward=FF)
res = simulate(plant, ctrl, traj, duration=0.25, seed=3)
result = {'u': res.voltage.tolist(), 'y': res.position.tolist(),
          'x': res.true_position.tolist(), 'f': res.friction.tolist(),
          'rip': res.ripple.tolist(), 'th': res.estimates.tolist()}
'''


@pytest.mark.parametrize('mode,ff,traj', [
    ('adaptive_sliding', 'none', None),
    ('pid', 'static', ('sine', {'amplitude': 2e-4, 'period': 0.1}))])
def test_compiled_loop_equals_pure_python_loop(mode, ff, traj, jit_and_pure):
    make = "default_trajectory('pmlm')" if traj is None else \
        f'make_trajectory({traj[0]!r}, **{traj[1]!r})'
    src = _RUN.replace('MODE', repr(mode)).replace('FF', repr(ff)).replace('TRAJ', make)
    jit, pure = jit_and_pure(src)
    for key in ('u', 'y', 'x', 'f', 'rip', 'th'):
        np.testing.assert_allclose(jit[key], pure[key], rtol=1e-9, atol=1e-12, err_msg=key)
    x = np.array(jit['x'])
    assert np.ptp(x) > 1e-4                              # the axis moved
    if traj is not None:                                 # and reversed under the sine
        assert np.count_nonzero(np.diff(np.sign(np.diff(x))) != 0) >= 3
