"""Validated controller parameter sets with units and ranges (shared by CLI and ROS nodes).

Each controller has a frozen ``Params`` dataclass whose fields are plain floats; every
field carries ``unit``, ``description``, ``min`` and ``max`` in its metadata so that the
ROS ``controller_node`` can declare parameter descriptors from
:meth:`ParamsBase.fields_with_ranges` and the CLI can validate ``--set name=value``.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

from motor_comp.errors import ParameterError, check_finite


@dataclasses.dataclass(frozen=True)
class FieldSpec:
    """One tunable: name, unit, description and the closed range [min, max]."""

    name: str
    unit: str
    description: str
    min: float
    max: float
    default: float


def spec(default: float, unit: str, description: str, lo: float = 0.0,
         hi: float = math.inf) -> Any:
    """Declare a dataclass field with its unit, description and valid range as metadata."""
    return dataclasses.field(default=default, metadata={
        'unit': unit, 'description': description, 'min': lo, 'max': hi})


@dataclasses.dataclass(frozen=True)
class ParamsBase:
    """Base of the controller parameter sets: validation, ranges, replace, dict form."""

    #: prefix used in error messages (the controller mode)
    label = 'controller'

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            name = f'{self.label}.{f.name} [{f.metadata["unit"]}]'
            try:
                v = float(value)
            except (TypeError, ValueError):
                raise ParameterError(f'{name} must be a number, got {value!r}') from None
            if math.isinf(v) and v == f.metadata['max']:
                pass  # an unbounded limit such as u_max = inf
            else:
                check_finite(name, v)
            if not f.metadata['min'] <= v <= f.metadata['max']:
                raise ParameterError(f'{name} must be in [{f.metadata["min"]:g}, '
                                     f'{f.metadata["max"]:g}], got {v:g}')
            object.__setattr__(self, f.name, v)

    @classmethod
    def fields_with_ranges(cls) -> list[FieldSpec]:
        """Every tunable with unit, description, range and default."""
        return [FieldSpec(f.name, f.metadata['unit'], f.metadata['description'],
                          f.metadata['min'], f.metadata['max'], f.default)
                for f in dataclasses.fields(cls)]

    def replace(self, **changes: Any) -> 'ParamsBase':
        """Return a validated copy; unknown names raise :class:`ParameterError` naming them."""
        names = {f.name for f in dataclasses.fields(self)}
        for key in changes:
            if key not in names:
                raise ParameterError(f'{self.label}: unknown parameter {key!r} '
                                     f'(known: {", ".join(sorted(names))})')
        return dataclasses.replace(self, **changes)

    def as_dict(self) -> dict[str, float]:
        """Field name → value."""
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @classmethod
    def from_mapping(cls, data: Mapping[str, Any]) -> 'ParamsBase':
        """Build from a mapping, validating names and values."""
        return cls().replace(**dict(data))
