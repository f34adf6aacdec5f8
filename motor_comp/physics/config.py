"""Plant descriptions: the two paper plants and their representative defaults.

``config/pmlm.yaml`` and ``config/ballscrew.yaml`` hold the DESIGN.md §3 stand-in values
(the papers' parameter tables did not survive); :func:`load_plant` turns a plant name
or a YAML path into an :class:`AxisModel` plus sensors and rates.
"""
from __future__ import annotations

import dataclasses
import enum
from importlib import resources
from pathlib import Path
from typing import Any, Mapping

import yaml

from motor_comp.errors import InputFileError, ModelFileError, ParameterError, \
    check_finite, check_nonnegative, check_positive
from motor_comp.physics.axis import AxisKind, AxisModel, warn_legacy
from motor_comp.physics.effects import make_effect
from motor_comp.physics.effects.presliding import upgrade_legacy_params
from motor_comp.physics.plant import Sensors


class PlantKind(enum.Enum):
    """The two plants of the source papers."""

    PMLM = 'pmlm'
    BALLSCREW = 'ballscrew'


def pmlm_model(*, mass_kg: float, resistance_ohm: float, force_constant_N_per_A: float,
               back_emf_V_s_per_m: float, effects: tuple = (),
               axis: AxisKind | str = AxisKind.LINEAR) -> AxisModel:
    """PMLM voltage model (Tan 2002 eq. 1–7): ``ẍ = −a·ẋ + b·u − F/M``.

    ``b = k_f/(R·M)`` and ``a = k_f·k_e/(R·M)``, i.e. ``input_gain = k_f/R`` [N/V] and
    ``back_emf = k_e`` [V·s/m] in the axis form.  With ``axis='rotary'`` the same numbers
    are read as a rotary motor (kg·m², N·m/A, V·s/rad).
    """
    r = check_positive('resistance_ohm', resistance_ohm)
    kf = check_positive('force_constant_N_per_A', force_constant_N_per_A)
    return AxisModel(mass=mass_kg, input_gain=kf / r,
                     back_emf=check_nonnegative('back_emf_V_s_per_m', back_emf_V_s_per_m),
                     effects=tuple(effects), axis=axis)


def ballscrew_model(*, A_m_per_V_s2: float, B_per_s: float, C_per_s2: float,
                    force_constant_N_per_V: float, effects: tuple = (),
                    axis: AxisKind | str = AxisKind.LINEAR) -> AxisModel:
    """Ball-screw model (Chiew eq. 1): ``ẍ = A·u(t−τ) − B·ẋ − C·x − (A/k_f)·F``.

    In the axis form ``M = k_f/A`` [kg], ``input_gain = k_f`` [N/V], ``damping = B·M``
    [N·s/m]; a non-zero ``C`` becomes a ``spring`` effect ``k = C·M`` [N/m] and ``τ`` is the
    ``delay`` effect.
    """
    a = check_positive('A_m_per_V_s2', A_m_per_V_s2)
    kf = check_positive('force_constant_N_per_V', force_constant_N_per_V)
    mass = kf / a
    effects = tuple(effects)
    c = check_finite('C_per_s2', C_per_s2)
    if c != 0.0:
        if any(e.name == 'spring' for e in effects):
            raise ParameterError('C_per_s2 and a spring effect both set the stiffness')
        effects += (make_effect('spring', {'k': c * mass}),)
    return AxisModel(mass=mass, input_gain=kf,
                     damping=check_nonnegative('B_per_s', B_per_s) * mass, effects=effects,
                     axis=axis)


@dataclasses.dataclass(frozen=True)
class PlantConfig:
    """A plant ready to simulate: model, sensors and rates."""

    kind: PlantKind
    model: AxisModel
    sensors: Sensors
    physics_rate: float = 10_000.0   #: [Hz]
    control_rate: float = 1_000.0    #: [Hz]
    source: str = ''

    def with_model(self, model: AxisModel) -> 'PlantConfig':
        """Return a copy with another axis model."""
        return dataclasses.replace(self, model=model)


#: the keys of a plant file and of its sections (a typo must not fall back to a default)
_PLANT_KEYS = ('plant', 'axis', 'motor', 'effects', 'sensors', 'rates')
_SECTION_KEYS = {'sensors': ('encoder_resolution_m', 'noise_std_m', 'saturation_V'),
                 'rates': ('physics_hz', 'control_hz')}


def _check_keys(data: Mapping[str, Any], known: tuple[str, ...], where: str) -> None:
    unknown = sorted(str(k) for k in data if k not in known)
    if unknown:
        raise ModelFileError(f'{where}: unknown field {unknown[0]!r} (expected {list(known)})')


def _section(data: Mapping[str, Any], key: str, source: str) -> Mapping[str, Any]:
    sec = data.get(key) or {}
    if not isinstance(sec, Mapping):
        raise ModelFileError(f'{source}: {key} must be a mapping')
    if key in _SECTION_KEYS:
        _check_keys(sec, _SECTION_KEYS[key], f'{source}: {key}')
    return sec


def plant_from_dict(data: Mapping[str, Any], *, source: str = 'plant') -> PlantConfig:
    """Build a :class:`PlantConfig` from the plant YAML layout of ``config/``."""
    if not isinstance(data, Mapping):
        raise ModelFileError(f'{source}: expected a mapping at top level')
    _check_keys(data, _PLANT_KEYS, source)
    try:
        kind = PlantKind(data.get('plant'))
    except ValueError:
        raise ModelFileError(f'{source}: plant must be one of '
                             f'{[k.value for k in PlantKind]}, got {data.get("plant")!r}') \
            from None
    try:
        effects_data, note = upgrade_legacy_params(_section(data, 'effects', source))
        if note:
            warn_legacy(f'{source}: {note}')
        effects = tuple(make_effect(n, p) for n, p in effects_data.items())
        motor = dict(_section(data, 'motor', source))
        axis = data.get('axis', 'linear')
        if kind is PlantKind.PMLM:
            model = pmlm_model(effects=effects, axis=axis, **motor)
        else:
            model = ballscrew_model(effects=effects, axis=axis, **motor)
        sens = _section(data, 'sensors', source)
        sensors = Sensors(encoder_resolution=sens.get('encoder_resolution_m', 1e-6),
                          noise_std=sens.get('noise_std_m', 0.0),
                          saturation=sens.get('saturation_V', float('inf')))
        rates = _section(data, 'rates', source)
        physics = check_positive('rates.physics_hz', rates.get('physics_hz', 10_000.0))
        control = check_positive('rates.control_hz', rates.get('control_hz', 1_000.0))
    except TypeError as exc:
        raise ModelFileError(f'{source}: bad motor parameters ({exc})') from None
    except ParameterError as exc:
        raise ModelFileError(f'{source}: {exc}') from None
    return PlantConfig(kind=kind, model=model, sensors=sensors, physics_rate=physics,
                       control_rate=control, source=source)


def load_plant(name_or_path: str | Path) -> PlantConfig:
    """Load ``'pmlm'``, ``'ballscrew'`` (the packaged defaults) or a plant YAML path."""
    name = str(name_or_path)
    if name in {k.value for k in PlantKind}:
        return packaged_plant(name)
    path = Path(name)
    try:
        text = path.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise InputFileError(f'{path}: no such plant file (or use pmlm / ballscrew)') \
            from None
    except (IsADirectoryError, UnicodeDecodeError) as exc:
        raise InputFileError(f'{path}: cannot read plant file ({exc})') from None
    return plant_from_text(text, source=str(path))


def packaged_plant(name: str) -> PlantConfig:
    """Return the packaged plant ``pmlm`` or ``ballscrew`` (``config/<name>.yaml``)."""
    text = resources.files('motor_comp').joinpath('config', f'{name}.yaml').read_text(
        encoding='utf-8')
    return plant_from_text(text, source=f'config/{name}.yaml')


def plant_from_text(text: str, *, source: str = 'plant') -> PlantConfig:
    """Build a :class:`PlantConfig` from the text of a plant YAML file (already read).

    The entry point for text read under rules of its own (a node reads the file its
    ``plant`` parameter names with :mod:`motor_comp.param_files`); errors name ``source``.
    """
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        raise ModelFileError(f'{source}: not valid YAML ({str(exc).splitlines()[0]})') \
            from exc
    return plant_from_dict(data, source=source)


def plant_names() -> tuple[str, ...]:
    """Return the field names a plant file may hold (its schema's vocabulary)."""
    import inspect
    motor = set()
    for build in (pmlm_model, ballscrew_model):
        motor.update(inspect.signature(build).parameters)
    return tuple(sorted(set(_PLANT_KEYS) | motor | {k for keys in _SECTION_KEYS.values()
                                                    for k in keys}))
