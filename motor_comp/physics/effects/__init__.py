"""The physical effects of DESIGN.md §3, one module each, and their name registry."""
from __future__ import annotations

from typing import Any, Mapping

from motor_comp.errors import ParameterError
from motor_comp.physics.effects.asymmetry import Asymmetry
from motor_comp.physics.effects.backlash import Backlash
from motor_comp.physics.effects.base import BOTH_AXES, AxisKind, Effect, EffectKind
from motor_comp.physics.effects.coulomb import Coulomb
from motor_comp.physics.effects.delay import Delay
from motor_comp.physics.effects.gravity import Gravity
from motor_comp.physics.effects.load_friction import LoadFriction
from motor_comp.physics.effects.offset import Offset
from motor_comp.physics.effects.position_friction import PositionFriction
from motor_comp.physics.effects.presliding import Presliding
from motor_comp.physics.effects.ripple import Ripple
from motor_comp.physics.effects.spring import Spring
from motor_comp.physics.effects.stribeck import Stribeck
from motor_comp.physics.effects.viscous import Viscous

#: the effect vocabulary of DESIGN.md §6, in canonical order
EFFECTS: dict[str, type[Effect]] = {
    cls.name: cls for cls in (Coulomb, Viscous, Stribeck, Presliding, Ripple, Offset,
                              Spring, Asymmetry, Delay, Backlash, Gravity, LoadFriction,
                              PositionFriction)
}

VOCABULARY: tuple[str, ...] = tuple(EFFECTS)


def make_effect(name: str, params: Mapping[str, Any] | None = None) -> Effect:
    """Build the effect called ``name`` from model-file parameters."""
    try:
        cls = EFFECTS[name]
    except KeyError:
        raise ParameterError(
            f'unknown effect {name!r} (known: {", ".join(VOCABULARY)})') from None
    return cls.from_params(params)


__all__ = ['EFFECTS', 'VOCABULARY', 'AxisKind', 'BOTH_AXES', 'Effect', 'EffectKind',
           'make_effect', 'Asymmetry', 'Backlash', 'Coulomb', 'Delay', 'Gravity',
           'LoadFriction', 'Offset', 'PositionFriction', 'Presliding', 'Ripple', 'Spring',
           'Stribeck', 'Viscous']
