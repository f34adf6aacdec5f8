"""A simulation scenario from flat ``name=value`` settings (CLI ``--set``, sweep grids).

Setting names:

* ``<controller parameter>`` (e.g. ``kp``, ``lambda1``, ``phi``) — the controller's
  :class:`~motor_comp.control.params.ParamsBase` fields;
* ``plant.<effect>.<param>`` (e.g. ``plant.coulomb.fc``) or ``plant.mass`` /
  ``plant.input_gain`` / ``plant.back_emf`` / ``plant.damping`` — the *true* plant only;
  the controller keeps its nominal model (the feedforward and the adaptive initial
  estimates, leakage target and projection box use the nominal values, as on a real
  machine).  Ripple harmonics: ``ripple.a1``, ``ripple.b1`` (``a<h>``/``b<h>``) [N];
* ``nominal.start`` (``half | zero | identified | exact``) and ``nominal.mass_factor``,
  ``nominal.friction_factor``, ``nominal.ripple_factor``, ``nominal.stiffness_factor`` —
  how the nominal model is derived from the plant file
  (:func:`~motor_comp.control.nominal.derive_nominal`; default: PMLM ``half`` = mass
  +20 %, friction and ripple at 50 %; ball-screw ``identified``); then
  ``nominal.<effect>.<param>`` / ``nominal.mass`` … set single nominal values (e.g.
  ``nominal.ripple.period``, ``nominal.ripple.a1``);
* ``sensors.noise_std`` / ``sensors.encoder_resolution`` / ``sensors.saturation``,
  ``rates.control_hz`` / ``rates.physics_hz`` — both;
* ``traj.<param>`` (e.g. ``traj.period``; lists as ``a;b;c``) — the trajectory;
* ``load.force`` [N], ``load.t_start`` [s] — a step load.
"""
from __future__ import annotations

import dataclasses
import re
from typing import Any, Mapping

from motor_comp.control.controller import Controller, make_controller
from motor_comp.control.nominal import NominalSpec, NominalStart, default_start, \
    derive_nominal
from motor_comp.control.simulator import SimResult, simulate
from motor_comp.control.trajectories import Trajectory, default_trajectory, make_trajectory
from motor_comp.errors import ParameterError, check_finite
from motor_comp.physics.config import PlantConfig, load_plant
from motor_comp.physics.effects import make_effect
from motor_comp.physics.plant import Sensors, StepLoad

_MODEL_FIELDS = ('mass', 'input_gain', 'back_emf', 'damping')
_HARMONIC = re.compile(r'([ab])([1-9][0-9]*)$')
_NOMINAL_FACTORS = tuple(f.name for f in dataclasses.fields(NominalSpec))


def parse_value(text: str) -> Any:
    """``'3'`` → 3.0, ``'0.1;0.2'`` → [0.1, 0.2], anything else stays a string."""
    text = text.strip()
    if ';' in text:
        return [parse_value(p) for p in text.split(';') if p.strip()]
    try:
        return float(text)
    except ValueError:
        return text


def parse_assignment(item: str) -> tuple[str, Any]:
    """``'name=value'`` → (name, parsed value); one-line error otherwise."""
    name, sep, value = item.partition('=')
    if not sep or not name.strip() or not value.strip():
        raise ParameterError(f'expected name=value, got {item!r}')
    return name.strip(), parse_value(value)


def _override_model(plant: PlantConfig, key: str, value: Any, where: str) -> PlantConfig:
    model = plant.model
    if key in _MODEL_FIELDS:
        return plant.with_model(model.replace(**{key: check_finite(f'{where}.{key}', value)}))
    effect, dot, param = key.partition('.')
    if not dot:
        raise ParameterError(f'{where}.{key}: expected {where}.<effect>.<param> or one of '
                             f'{", ".join(where + "." + f for f in _MODEL_FIELDS)}')
    current = model.get(effect)
    params = current.params() if current is not None else {}
    harmonic = _HARMONIC.match(param) if effect == 'ripple' else None
    if harmonic:
        # one ripple coefficient [N]: ripple.a1 = sine, ripple.b1 = cosine of harmonic 1
        h = int(harmonic.group(2))
        pairs = [list(p) for p in params.get('harmonics', [])]
        pairs += [[0.0, 0.0] for _ in range(h - len(pairs))]
        pairs[h - 1]['ab'.index(harmonic.group(1))] = check_finite(f'{where}.{key}', value)
        params['harmonics'] = pairs
    else:
        params[param] = value
    try:
        return plant.with_model(model.with_effect(make_effect(effect, params)))
    except ParameterError as exc:
        raise ParameterError(f'{where}.{key}: {exc}') from None


def _override_both(plant: PlantConfig, key: str, value: Any) -> PlantConfig:
    group, _, name = key.partition('.')
    if group == 'sensors':
        fields = {f.name for f in dataclasses.fields(Sensors)}
        if name not in fields:
            raise ParameterError(f'unknown setting {key!r} (sensors: {", ".join(sorted(fields))})')
        return dataclasses.replace(plant, sensors=dataclasses.replace(
            plant.sensors, **{name: value}))
    rates = {'control_hz': 'control_rate', 'physics_hz': 'physics_rate'}
    if name not in rates:
        raise ParameterError(f'unknown setting {key!r} (rates: control_hz, physics_hz)')
    return dataclasses.replace(plant, **{rates[name]: check_finite(key, value)})


@dataclasses.dataclass(frozen=True)
class Scenario:
    """Everything one closed-loop simulation needs, as plain values.

    Parameters
    ----------
    plant : str
        ``pmlm``, ``ballscrew`` or a plant YAML path.
    controller : str
        ``pid | adaptive_sliding | npid``.
    feedforward : str
        ``none | static | gms | static+gms``.
    duration : float
        Simulated time [s].
    seed : int
        Measurement-noise seed.
    trajectory : str or None
        Trajectory kind; None = the plant's study trajectory.
    settings : tuple of (name, value)
        Overrides, see the module docstring.
    """

    plant: str = 'pmlm'
    controller: str = 'pid'
    feedforward: str = 'none'
    duration: float = 10.0
    seed: int = 0
    trajectory: str | None = None
    settings: tuple = ()

    def build(self) -> tuple[PlantConfig, PlantConfig, Controller, Trajectory, StepLoad]:
        """Return (true plant, nominal plant, controller, trajectory, load).

        The nominal plant is derived from the plant file by ``nominal.start`` and the
        ``nominal.*_factor`` settings (:func:`~motor_comp.control.nominal.derive_nominal`),
        then ``nominal.<effect>.<param>`` settings apply, in order.
        """
        true = load_plant(self.plant)
        start: str | NominalStart = default_start(true.kind)
        factors: dict[str, Any] = {}
        for key, value in self.settings:
            if key == 'nominal.start':
                start = NominalStart.parse(value)
            elif key.startswith('nominal.') and key[8:] in _NOMINAL_FACTORS:
                factors[key[8:]] = value
        nominal = derive_nominal(true, NominalSpec.preset(start).replace(**factors))
        ctrl_params: dict[str, Any] = {}
        traj_params: dict[str, Any] = {}
        load = {'force': 0.0, 't_start': 0.0}
        for key, value in self.settings:
            group, dot, rest = key.partition('.')
            if dot and group == 'plant':
                true = _override_model(true, rest, value, 'plant')
            elif dot and group == 'nominal':
                if rest != 'start' and rest not in _NOMINAL_FACTORS:
                    nominal = _override_model(nominal, rest, value, 'nominal')
            elif dot and group in ('sensors', 'rates'):
                true = _override_both(true, key, value)
                nominal = _override_both(nominal, key, value)
            elif dot and group == 'traj':
                traj_params[rest] = value
            elif dot and group == 'load':
                if rest not in load:
                    raise ParameterError(f'unknown setting {key!r} (load.force, load.t_start)')
                load[rest] = value
            elif not dot:
                ctrl_params[key] = value
            else:
                raise ParameterError(f'unknown setting {key!r} (groups: plant., nominal., '
                                     f'sensors., rates., traj., load.)')
        kind = self.trajectory or default_trajectory(nominal.kind.value).name
        traj = make_trajectory(kind, **traj_params)
        ctrl = make_controller(self.controller, plant=nominal, feedforward=self.feedforward,
                               **ctrl_params)
        return true, nominal, ctrl, traj, StepLoad(**load)

    def run(self, *, engine: str = 'jit') -> tuple[SimResult, Controller]:
        """Simulate; returns the result and the controller in its final state."""
        true, nominal, ctrl, traj, load = self.build()
        res = simulate(true, ctrl, traj, duration=self.duration, seed=self.seed, load=load,
                       engine=engine)
        meta = dict(res.metadata)
        meta['settings'] = {k: v for k, v in self.settings}
        meta['plant'] = self.plant
        meta['nominal'] = nominal.source
        return dataclasses.replace(res, metadata=meta), ctrl

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> 'Scenario':
        """Build from a flat mapping: the field names plus any settings."""
        fields = {f.name for f in dataclasses.fields(cls)} - {'settings'}
        kw = {k: v for k, v in data.items() if k in fields}
        settings = tuple((k, v) for k, v in data.items() if k not in fields)
        if 'duration' in kw:
            kw['duration'] = float(kw['duration'])
        if 'seed' in kw:
            kw['seed'] = int(kw['seed'])
        return cls(settings=settings, **kw)
