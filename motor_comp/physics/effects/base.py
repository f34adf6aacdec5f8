"""The effect protocol shared by every physical effect of DESIGN.md §3.

An effect is a frozen dataclass of validated SI parameters plus its force law.  The
model file (DESIGN.md §6) stores each effect as ``name: {param: value, ...}``;
:meth:`Effect.params` and :meth:`Effect.from_params` convert to and from that form.
"""
from __future__ import annotations

import dataclasses
import enum
from typing import Any, ClassVar, Mapping

from motor_comp.errors import ParameterError


class AxisKind(enum.Enum):
    """Linear axis (m, N, kg) or rotary axis (rad, N·m, kg·m²); DESIGN.md §6 ``axis:``."""

    LINEAR = 'linear'
    ROTARY = 'rotary'


#: both axis kinds: what an effect supports unless it says otherwise
BOTH_AXES = frozenset(AxisKind)


class EffectKind(enum.Enum):
    """Where an effect acts on the axis."""

    FORCE = 'force'    #: a force subtracted in ``M·ẍ = F_in − Σ F_k``
    INPUT = 'input'    #: acts on the command before it becomes force (delay)
    OUTPUT = 'output'  #: acts between motor and measured load position (backlash)


@dataclasses.dataclass(frozen=True)
class Effect:
    """Base class: one physical effect with validated SI parameters."""

    name: ClassVar[str] = ''
    kind: ClassVar[EffectKind] = EffectKind.FORCE
    #: human wording used in diagnose output, e.g. "Coulomb friction"
    title: ClassVar[str] = ''
    #: the axis kinds the law is physical on.  Every friction, ripple, spring, offset,
    #: delay and backlash law reads the same in rad/N·m as in m/N, so all effects take
    #: both kinds except ``gravity`` (rotary only: on a linear axis gravity is an
    #: ``offset``).  No effect is linear-only today; the check in ``AxisModel`` is general.
    axes: ClassVar[frozenset] = BOTH_AXES
    #: whether the force law reads the absolute position (a ripple, a spring, a friction
    #: along the travel, gravity).  Without such a force the axis moves the same from
    #: every start: a flight across a backlash gap is one path for every width
    #: (:func:`motor_comp.workbench.motion.motor_position`).
    position_dependent: ClassVar[bool] = False

    def params(self) -> dict[str, Any]:
        """Parameters in model-file form (DESIGN.md §6 table), SI units."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if isinstance(v, tuple):
                v = [list(e) if isinstance(e, tuple) else float(e) for e in v]
            else:
                v = float(v)
            out[f.name] = v
        return out

    @classmethod
    def from_params(cls, params: Mapping[str, Any] | None) -> 'Effect':
        """Build from a model-file mapping; unknown or missing keys raise ParameterError."""
        params = dict(params or {})
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(params) - names, key=str)
        if unknown:
            raise ParameterError(
                f'{cls.name}: unknown parameter {unknown[0]!r} (expected {sorted(names)})')
        try:
            return cls(**params)
        except TypeError as exc:  # missing required field
            missing = [n for n in names if n not in params]
            raise ParameterError(
                f'{cls.name}: missing parameter {missing[0] if missing else ""!r}') from exc

    def replace(self, **changes: Any) -> 'Effect':
        """Return a copy with some parameters changed (validated again)."""
        return dataclasses.replace(self, **changes)
