"""The controller's nominal model: what a user knows of the plant, never the plant itself.

Every controller and feedforward is built from a *nominal* plant (:func:`derive_nominal`),
derived from the true plant the way the source papers' controllers knew theirs:

* **mass** from the data sheet, off by ``mass_factor`` (default ×1.2, i.e. +20 %; the
  data sheet's forcer plus an estimated payload).  The ball-screw's linear model
  (Chiew eq. 1: A, B, τ) is identified from a frequency response, not read off a data
  sheet, so its ``identified`` preset keeps the mass;
* **friction and ripple** levels (``coulomb.fc``, ``stribeck.fs``, ``viscous.fv``,
  ``asymmetry.dfc/dfv``, ``offset.f0``, ``load_friction.mu``, the knot values
  ``position_friction.dfc``; ripple harmonics) scaled by ``friction_factor``
  and ``ripple_factor``: Tan, Huang & Lee 2002 start their adaptive estimates at 50 % of
  the truth in simulation (:attr:`NominalStart.HALF`) and at zero in the experiment
  (:attr:`NominalStart.ZERO`);
* the **ripple period** is kept: it is the magnet pitch, which a user knows;
* the GMS pre-sliding **stiffness** scaled by ``stiffness_factor`` (for a friction model
  identified off-line, Chiew et al., whose pre-sliding stiffness is the hardest part to
  identify); element fractions and attraction kept;
* the linear structure (input gain, back-EMF, drive damping, delay, spring, backlash,
  gravity) is kept: motor constants come from the data sheet and the dead time from a
  step response.

Presets (:class:`NominalStart`), and the default per plant (:func:`default_start`):

============  =====  ========  ======  ==========  =========================================
start         mass   friction  ripple  stiffness   use
============  =====  ========  ======  ==========  =========================================
exact         1.0    1.0       1.0     1.0         the *oracle* only (a bench reference)
half          1.2    0.5       0.5     1.0         Tan's simulation; PMLM default
zero          1.2    0.0       0.0     1.0         Tan's experiment (nothing known)
identified    1.0    0.8       0.8     0.7         Chiew's identified friction; ball-screw
============  =====  ========  ======  ==========  =========================================

The adaptive law's initial estimates, its σ-leakage target and its projection box are
all built from this nominal model (:mod:`.adaptive_sliding`), so nothing pulls an
estimate towards the truth.  In a :class:`~motor_comp.control.scenario.Scenario` the
derivation is chosen with ``nominal.start=…`` and the factors with
``nominal.mass_factor=…`` etc.; ``nominal.<effect>.<param>=…`` then sets single values.
"""
from __future__ import annotations

import dataclasses
import enum
from typing import Any

from motor_comp.errors import ParameterError, check_nonnegative, check_positive
from motor_comp.physics.config import PlantConfig, PlantKind
from motor_comp.physics.effects import make_effect

#: force-level parameters scaled by ``friction_factor`` (effect → parameter names)
FRICTION_LEVELS = {'coulomb': ('fc',), 'stribeck': ('fs',), 'viscous': ('fv',),
                   'asymmetry': ('dfc', 'dfv'), 'offset': ('f0',), 'load_friction': ('mu',),
                   'position_friction': ('dfc',)}


class NominalStart(enum.Enum):
    """How the nominal model is derived from the true plant (module table)."""

    EXACT = 'exact'
    HALF = 'half'
    ZERO = 'zero'
    IDENTIFIED = 'identified'

    @classmethod
    def parse(cls, value: 'str | NominalStart') -> 'NominalStart':
        """From ``exact | half | zero | identified``."""
        if isinstance(value, NominalStart):
            return value
        try:
            return cls(str(value))
        except ValueError:
            raise ParameterError(f'nominal.start must be one of '
                                 f'{", ".join(s.value for s in cls)}, got {value!r}') from None


@dataclasses.dataclass(frozen=True)
class NominalSpec:
    """Factors that turn the true plant into the nominal one (all [-], >= 0).

    Attributes
    ----------
    mass_factor : float
        Nominal mass / true mass (> 0).
    friction_factor : float
        Scale of every friction level (module docstring); 0 = no friction known.
    ripple_factor : float
        Scale of the ripple harmonics (the period is kept).
    stiffness_factor : float
        Scale of the GMS element stiffnesses (> 0).
    """

    mass_factor: float = 1.2
    friction_factor: float = 0.5
    ripple_factor: float = 0.5
    stiffness_factor: float = 1.0

    def __post_init__(self) -> None:
        check_positive('nominal.mass_factor [-]', self.mass_factor)
        check_nonnegative('nominal.friction_factor [-]', self.friction_factor)
        check_nonnegative('nominal.ripple_factor [-]', self.ripple_factor)
        check_positive('nominal.stiffness_factor [-]', self.stiffness_factor)

    @classmethod
    def preset(cls, start: 'str | NominalStart') -> 'NominalSpec':
        """Return the factors of a :class:`NominalStart`."""
        return PRESETS[NominalStart.parse(start)]

    def replace(self, **changes: Any) -> 'NominalSpec':
        """Return a validated copy; unknown names are a one-line error."""
        names = {f.name for f in dataclasses.fields(self)}
        for key in changes:
            if key not in names:
                raise ParameterError(f'unknown setting nominal.{key} (nominal.start, '
                                     f'{", ".join("nominal." + n for n in sorted(names))})')
        try:
            values = {k: float(v) for k, v in changes.items()}
        except (TypeError, ValueError):
            raise ParameterError(f'nominal factors must be numbers, got {changes}') from None
        return dataclasses.replace(self, **values)


PRESETS = {
    NominalStart.EXACT: NominalSpec(1.0, 1.0, 1.0, 1.0),
    NominalStart.HALF: NominalSpec(1.2, 0.5, 0.5, 1.0),
    NominalStart.ZERO: NominalSpec(1.2, 0.0, 0.0, 1.0),
    NominalStart.IDENTIFIED: NominalSpec(1.0, 0.8, 0.8, 0.7),
}


def default_start(kind: PlantKind) -> NominalStart:
    """Return the default derivation: PMLM ``half`` (Tan), ball-screw ``identified``."""
    return NominalStart.IDENTIFIED if kind is PlantKind.BALLSCREW else NominalStart.HALF


def derive_nominal(true: PlantConfig,
                   spec: 'NominalSpec | NominalStart | str | None' = None) -> PlantConfig:
    """Return the nominal plant a controller of ``true`` is built from.

    Parameters
    ----------
    true : PlantConfig
        The plant that is simulated.
    spec : NominalSpec, NominalStart, str or None
        Factors or a preset name; None = :func:`default_start` of the plant kind.

    Returns
    -------
    PlantConfig
        Same sensors, rates and kind; model with the factors of the module docstring
        applied.  Its ``source`` records the derivation (run metadata).
    """
    if spec is None:
        spec = default_start(true.kind)
    if not isinstance(spec, NominalSpec):
        spec = NominalSpec.preset(spec)
    effects = []
    for effect in true.model.effects:
        params = effect.params()
        if effect.name in FRICTION_LEVELS:
            # the whole dry level fc + dfc(x) + mu·|F_in| scales: a known fraction of it
            for p in FRICTION_LEVELS[effect.name]:
                params[p] = _scaled(params[p], spec.friction_factor)
        elif effect.name == 'ripple':
            params['harmonics'] = [[spec.ripple_factor * a, spec.ripple_factor * b]
                                   for a, b in params['harmonics']]
        elif effect.name == 'presliding':
            params['k'] = [spec.stiffness_factor * k for k in params['k']]
        else:
            effects.append(effect)
            continue
        effects.append(make_effect(effect.name, params))
    # all at once: the model checks fs >= fc and fc + dfc(x) >= 0, which hold only for
    # the scaled set
    model = true.model.replace(mass=true.model.mass * spec.mass_factor, effects=tuple(effects))
    tag = ', '.join(f'{f.name}={getattr(spec, f.name):g}' for f in dataclasses.fields(spec))
    return dataclasses.replace(true, model=model,
                               source=f'nominal of {true.source or true.kind.value} ({tag})')


def _scaled(value: Any, factor: float) -> Any:
    """``factor·value`` for a number or elementwise for a list of numbers."""
    if isinstance(value, list):
        return [factor * v for v in value]
    return factor * value


__all__ = ['FRICTION_LEVELS', 'NominalSpec', 'NominalStart', 'PRESETS', 'default_start',
           'derive_nominal']
