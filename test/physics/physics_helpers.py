"""Shared helpers of the physics tests: small models and a fine-grained plant driver.

Imported by the test modules of this folder (pytest puts the folder on ``sys.path``);
the unique module name avoids clashes with other layers' helpers.
"""
from __future__ import annotations

import numpy as np

from motor_comp.physics import AxisModel, Plant, Sensors, make_effect
from motor_comp.physics import kernel as K

#: physics step used by the fine-grained tests [s]
DT = 1e-4

IDEAL = Sensors(encoder_resolution=0.0, noise_std=0.0)


def model(*effects: tuple[str, dict], mass: float = 1.0, input_gain: float = 1.0,
          back_emf: float = 0.0, damping: float = 0.0) -> AxisModel:
    """An axis from ``(name, params)`` pairs; force input (1 N per unit command) by default."""
    return AxisModel(mass=mass, input_gain=input_gain, back_emf=back_emf, damping=damping,
                     effects=tuple(make_effect(n, p) for n, p in effects))


def plant(m: AxisModel, *, sensors: Sensors = IDEAL, x0: float = 0.0, v0: float = 0.0,
          seed: int = 0) -> Plant:
    """A 10 kHz plant, optionally launched with velocity ``v0`` [m/s] (not stuck)."""
    p = Plant(m, sensors=sensors, physics_rate=1.0 / DT, x0=x0, seed=seed)
    if v0 != 0.0:
        p.state[K.S_V] = v0
        p.state[K.S_STUCK] = 0.0
    return p


def trace(p: Plant, u, n: int, *, f_ext: float = 0.0) -> dict[str, np.ndarray]:
    """Run ``n`` physics steps with command ``u`` (float or callable of time [s]).

    Returns arrays of the state after each step: t, x, v, xl (load), friction, ueff.
    """
    out = {k: np.empty(n) for k in ('t', 'x', 'v', 'xl', 'friction', 'ueff')}
    S, P = p.state, p.params
    for j in range(n):
        uj = u(S[K.S_T]) if callable(u) else u
        K.plant_advance(P, S, float(uj), f_ext, 1)
        out['t'][j] = S[K.S_T]
        out['x'][j] = S[K.S_X]
        out['v'][j] = S[K.S_V]
        out['xl'][j] = S[K.S_XL]
        out['friction'][j] = S[K.S_FRICTION]
        out['ueff'][j] = S[K.S_UEFF]
    return out
