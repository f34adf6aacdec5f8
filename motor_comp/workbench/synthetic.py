"""Runs with a known hidden effect, from the project's closed-loop simulator.

Used by the hidden-effect test suite, ``bench/workbench.py`` and the tutorial: a PMLM
axis (DESIGN.md §3 stand-in values; Coulomb 10 N and viscous 10 N·s/m as the known
base friction) tracks a chirp under the PID baseline (``motor_comp.control.simulate``,
gains :data:`PID_GAINS`), with a
quantized encoder and measurement noise; one effect (or several) is present in the
plant and absent from the model handed to the workbench.

Parameters are drawn from physical ranges (:data:`RANGES`).  The excitation is a
chirp from 0.2 to 1.5 Hz over ±50 mm: many reversals at different accelerations
(friction sign, pre-sliding, backlash, delay), speeds from 0 to ~0.4 m/s (viscous and
Stribeck curves) and a travel of several ripple periods.
"""
from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from motor_comp.logs.run import Run
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import make_effect

#: Chiew's 4-element GMS distribution (normalised slip limits and relative stiffness)
GMS_ALPHA = (0.45, 0.30, 0.15, 0.10)
GMS_K_SHAPE = tuple(k / 12.3e6 for k in (8e6, 3e6, 1e6, 3e5))

#: the base model the workbench starts from (and the plant before hiding an effect)
BASE_FC = 10.0      # N
BASE_FV = 10.0      # N·s/m

#: a moderately tuned PID [V/m, V/(m·s), V·s/m]: about half the default bandwidth, so the
#: loop stays stable with up to 5 ms of hidden dead time
PID_GAINS = {'kp': 15000.0, 'ki': 3e5, 'kd': 60.0}

#: physical ranges the hidden parameters are drawn from (SI)
RANGES: dict[str, dict[str, tuple[float, float]]] = {
    'coulomb': {'fc': (5.0, 20.0)},
    'viscous': {'fv': (20.0, 80.0)},
    'stribeck': {'ratio': (1.6, 2.5), 'vs': (0.004, 0.02), 'delta': (1.0, 2.0)},
    'presliding': {'stiffness': (2e5, 1e6)},
    'ripple': {'period': (0.008, 0.025), 'amplitude': (3.0, 10.0)},
    'offset': {'f0': (3.0, 10.0)},
    'spring': {'k': (100.0, 500.0), 'x0': (-0.02, 0.02)},
    'asymmetry': {'dfc': (2.0, 6.0), 'dfv': (20.0, 60.0)},
    'delay': {'tau': (0.001, 0.005)},
    'backlash': {'width': (2e-5, 1e-4)},
    # efficiency losses of a screw or gear: 3–25 % more dry friction per newton driven
    'load_friction': {'mu': (0.03, 0.25)},
    # a tight spot: the level rises by `rise` [N] over ±3 cm around `x` (the chirp's
    # ±50 mm crosses it both ways many times)
    'position_friction': {'rise': (4.0, 10.0), 'x': (-0.02, 0.02)},
}


@dataclasses.dataclass(frozen=True)
class Scenario:
    """A plant with hidden effects and the model that lacks them."""

    name: str
    plant: AxisModel
    model: AxisModel
    truth: dict

    def run(self, *, duration: float = 20.0, seed: int = 0, noise_std: float = 2e-7,
            encoder: float = 1e-6) -> Run:
        """Closed-loop run of the plant (see module docstring)."""
        return closed_loop_run(self.plant, duration=duration, seed=seed,
                               noise_std=noise_std, encoder=encoder, name=self.name)


def base_model() -> AxisModel:
    """PMLM drive (Tan 2002 eq. 1–7 stand-ins) with Coulomb and viscous friction only."""
    from motor_comp.physics.config import load_plant
    m = load_plant('pmlm').model
    return m.without(*m.names).with_effect(make_effect('coulomb', {'fc': BASE_FC})) \
        .with_effect(make_effect('viscous', {'fv': BASE_FV}))


def _u(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(rng.uniform(*lo_hi))


def hidden_effect(name: str, rng: np.random.Generator) -> tuple[Any, dict]:
    """Draw an effect of the vocabulary with parameters in :data:`RANGES`; return its truth."""
    r = RANGES[name]
    sign = 1.0 if rng.random() < 0.5 else -1.0
    if name == 'coulomb':
        p = {'fc': _u(rng, r['fc'])}
    elif name == 'viscous':
        p = {'fv': _u(rng, r['fv'])}
    elif name == 'stribeck':
        p = {'fs': BASE_FC * _u(rng, r['ratio']), 'vs': _u(rng, r['vs']),
             'delta': _u(rng, r['delta'])}
    elif name == 'presliding':
        k = _u(rng, r['stiffness'])
        p = {'alpha': list(GMS_ALPHA), 'k': [s * k for s in GMS_K_SHAPE],
             'C': 1000.0 * BASE_FC}
        return make_effect(name, p), {'stiffness': k}
    elif name == 'ripple':
        amp, ph = _u(rng, r['amplitude']), float(rng.uniform(0, 2 * np.pi))
        p = {'period': _u(rng, r['period']),
             'harmonics': [[amp * np.cos(ph), amp * np.sin(ph)]]}
        return make_effect(name, p), {'period': p['period'], 'amplitude_1': amp}
    elif name == 'offset':
        p = {'f0': sign * _u(rng, r['f0'])}
    elif name == 'spring':
        p = {'k': _u(rng, r['k']), 'x0': _u(rng, r['x0'])}
    elif name == 'asymmetry':
        p = {'dfc': sign * _u(rng, r['dfc']), 'dfv': sign * _u(rng, r['dfv'])}
    elif name == 'delay':
        p = {'tau': _u(rng, r['tau'])}
    elif name == 'backlash':
        p = {'width': _u(rng, r['width'])}
    elif name == 'load_friction':
        p = {'mu': _u(rng, r['mu'])}
    elif name == 'position_friction':
        xc, rise = _u(rng, r['x']), _u(rng, r['rise'])
        p = {'x': [xc + d for d in (-0.03, -0.015, 0.0, 0.015, 0.03)],
             'dfc': [0.0, 0.3 * rise, rise, 0.3 * rise, 0.0]}
        return make_effect(name, p), {'x_peak': xc, 'rise': rise}
    else:
        raise KeyError(name)
    return make_effect(name, p), dict(p)


def recovered(model: AxisModel, name: str) -> dict[str, float]:
    """Scalar parameters of a fitted effect, named like :func:`hidden_effect`'s truth."""
    e = model.get(name)
    if name == 'presliding':
        return {'stiffness': e.stiffness}
    if name == 'ripple':
        return {'period': e.period, 'amplitude_1': float(e.amplitudes[0])}
    if name == 'position_friction':
        lo, hi = e.span
        grid = np.linspace(lo, hi, 4001)
        level = e.level(grid)
        return {'x_peak': float(grid[int(np.argmax(level))]), 'rise': float(np.ptp(level))}
    return e.params()


def scenario(names: tuple[str, ...] | str, *, seed: int = 0) -> Scenario:
    """Plant = base (+ hidden effects); model = base without them.

    ``coulomb`` and ``viscous`` are part of the base, so hiding them means removing them
    from the model (the plant keeps a drawn value).
    """
    names = (names,) if isinstance(names, str) else tuple(names)
    rng = np.random.default_rng(seed)
    plant = model = base_model()
    truth: dict[str, dict] = {}
    for n in names:
        eff, t = hidden_effect(n, rng)
        plant = plant.with_effect(eff)
        truth[n] = t
        if n in ('coulomb', 'viscous'):
            model = model.without(n)
    return Scenario(name='+'.join(names) or 'none', plant=plant, model=model, truth=truth)


def closed_loop_run(plant_model: AxisModel, *, duration: float = 20.0, seed: int = 0,
                    noise_std: float = 2e-7, encoder: float = 1e-6,
                    amplitude: float = 0.05, name: str = 'synthetic') -> Run:
    """PID-controlled chirp run of ``plant_model`` with a quantized, noisy encoder."""
    from motor_comp.control import simulator
    from motor_comp.control.controller import make_controller
    from motor_comp.control.trajectories import make_trajectory
    from motor_comp.physics.config import load_plant
    from motor_comp.physics.plant import Sensors
    cfg = load_plant('pmlm')
    cfg = dataclasses.replace(cfg, model=plant_model,
                              sensors=Sensors(encoder_resolution=encoder, noise_std=noise_std))
    traj = make_trajectory('chirp', amplitude=amplitude, f_start=0.2, f_end=1.5,
                           duration=max(duration, 1.0), fade=1.0)
    ctrl = make_controller('pid', plant=cfg, **PID_GAINS)
    res = simulator.simulate(cfg, ctrl, traj, duration=duration, seed=seed)
    return res.to_run(name=name)
