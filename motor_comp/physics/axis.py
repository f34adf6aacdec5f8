"""The axis model: rigid mass, force input, and a composition of effects.

``M·ẍ = F_in − Σ F_k(x, ẋ, state_k)`` with ``F_in = input_gain·(u − back_emf·ẋ) −
damping·ẋ`` (DESIGN.md §3).  This one form covers both plants of the source papers:

* PMLM (Tan 2002 eq. 1–7): ``input_gain = k_f/R`` [N/V], ``back_emf = k_e`` [V·s/m];
* ball-screw (Chiew eq. 1): ``mass = k_f/A``, ``input_gain = k_f``, ``damping = B·k_f/A``,
  ``C`` as a ``spring`` effect, ``τ`` as a ``delay`` effect.

It is also the model file of the workbench (DESIGN.md §6): :meth:`AxisModel.to_dict`
and :func:`AxisModel.from_dict` are its YAML form.

Linear or rotary (``axis: linear | rotary``, DESIGN.md §6): the equations are the same;
on a rotary axis position is an angle [rad], ``mass`` the inertia [kg·m²] and every force
a torque [N·m].  :attr:`AxisModel.units` names the units of each quantity for reports.
"""
from __future__ import annotations

import dataclasses
import enum
import math
import sys
from pathlib import Path
from typing import Any, Iterable, Mapping

import numpy as np
import yaml

from motor_comp.errors import ModelFileError, ParameterError, check_nonnegative, \
    check_positive
from motor_comp.physics.effects import EFFECTS, VOCABULARY, AxisKind, Effect, EffectKind, \
    make_effect
from motor_comp.physics.effects.presliding import upgrade_legacy_params

__all__ = ['MODEL_FIELDS', 'AxisKind', 'AxisModel', 'InputKind', 'Units', 'effects_from',
           'warn_legacy']


#: top-level fields of a model file (DESIGN.md §6)
MODEL_FIELDS = ('axis', 'input', 'input_gain', 'back_emf', 'damping', 'mass', 'effects')


class InputKind(enum.Enum):
    """What the logged command is; ``input_gain`` converts it to newtons."""

    VOLTAGE = 'voltage'
    CURRENT = 'current'
    FORCE = 'force'


@dataclasses.dataclass(frozen=True)
class Units:
    """Unit strings of one axis kind, for tables, reports and plots (DESIGN.md §6).

    Attributes
    ----------
    kind : AxisKind
        The axis kind these units belong to.
    position, velocity, acceleration : str
        ``m, m/s, m/s²`` or ``rad, rad/s, rad/s²``.
    force : str
        ``N`` or ``N·m`` (every effect force is a torque on a rotary axis).
    mass : str
        ``kg`` or ``kg·m²`` (the ``mass`` field is the inertia on a rotary axis).
    viscous : str
        ``N·s/m`` or ``N·m·s/rad`` (``viscous.fv``, ``damping``, GMS ``sigma``).
    spring : str
        ``N/m`` or ``N·m/rad`` (``spring.k``, GMS ``k``).
    back_emf : str
        ``V·s/m`` or ``V·s/rad``.
    attraction : str
        GMS slip attraction ``C``: ``N/s`` or ``N·m/s``.
    """

    kind: AxisKind
    position: str
    velocity: str
    acceleration: str
    force: str
    mass: str
    viscous: str
    spring: str
    back_emf: str
    attraction: str

    @classmethod
    def of(cls, kind: AxisKind | str) -> 'Units':
        """Units of the axis kind ``kind``."""
        return _UNITS[AxisKind(kind)]

    @property
    def rotary(self) -> bool:
        """Whether these are rotary units."""
        return self.kind is AxisKind.ROTARY

    def cycles_per_revolution(self, period: float) -> float | None:
        """Ripple/cogging cycles per revolution ``2π/period`` (rotary), None (linear).

        Parameters
        ----------
        period : float
            Spatial period of the first harmonic [rad] on a rotary axis.
        """
        if not self.rotary:
            return None
        return 2.0 * math.pi / check_positive('ripple.period [rad]', period)

    def period_text(self, period: float) -> str:
        """Format a ripple period for reports, e.g. ``'0.02 m'`` or ``'0.785 rad (8 /rev)'``."""
        cpr = self.cycles_per_revolution(period)
        text = f'{period:.4g} {self.position}'
        return text if cpr is None else f'{text} ({cpr:.4g} /rev)'

    def input_gain(self, input_kind: 'InputKind | str') -> str:
        """Return the unit of ``input_gain`` for a command kind: N/V, N/A, 1 (or N·m/V, N·m/A)."""
        kind = InputKind(input_kind)
        if kind is InputKind.FORCE:
            return '1'
        return f'{self.force}/{"V" if kind is InputKind.VOLTAGE else "A"}'


_UNITS = {
    AxisKind.LINEAR: Units(AxisKind.LINEAR, position='m', velocity='m/s',
                           acceleration='m/s²', force='N', mass='kg', viscous='N·s/m',
                           spring='N/m', back_emf='V·s/m', attraction='N/s'),
    AxisKind.ROTARY: Units(AxisKind.ROTARY, position='rad', velocity='rad/s',
                           acceleration='rad/s²', force='N·m', mass='kg·m²',
                           viscous='N·m·s/rad', spring='N·m/rad', back_emf='V·s/rad',
                           attraction='N·m/s'),
}


@dataclasses.dataclass(frozen=True)
class AxisModel:
    """A rigid single axis with effects.

    Parameters
    ----------
    mass : float
        Moving mass [kg], > 0.
    input_gain : float
        Force per unit of command [N/V] (or N/A, or 1 for a force input), > 0.
    back_emf : float
        Back-EMF constant [V·s/m] (PMLM ``k_e``); 0 for force-input drives.
    damping : float
        Linear plant damping [N·s/m] that belongs to the drive, not to friction
        (ball-screw ``B·M``); 0 by default.
    effects : tuple of Effect
        The effects, at most one of each name, in vocabulary order.
    input : InputKind
        The kind of logged command.
    axis : AxisKind
        Linear (default) or rotary.  On a rotary axis read every unit above in its
        rotary form (see :class:`Units`): inertia [kg·m²], torque [N·m], angle [rad].
        Every effect declares the axis kinds it is valid on (``Effect.axes``); only
        ``gravity`` is restricted (rotary only), and no effect is linear-only.
    """

    mass: float = 1.0
    input_gain: float = 1.0
    back_emf: float = 0.0
    damping: float = 0.0
    effects: tuple = ()
    input: InputKind = InputKind.VOLTAGE
    axis: AxisKind = AxisKind.LINEAR

    def __post_init__(self) -> None:
        object.__setattr__(self, 'mass', check_positive('mass [kg]', self.mass))
        object.__setattr__(self, 'input_gain', check_positive('input_gain', self.input_gain))
        object.__setattr__(self, 'back_emf', check_nonnegative('back_emf [V·s/m]',
                                                               self.back_emf))
        object.__setattr__(self, 'damping', check_nonnegative('damping [N·s/m]',
                                                              self.damping))
        effects = tuple(self.effects)
        for e in effects:
            if not isinstance(e, Effect):
                raise ParameterError(f'effects must be Effect instances, got {e!r}')
        names = [e.name for e in effects]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise ParameterError(f'effect {sorted(dup)[0]!r} appears twice')
        effects = tuple(sorted(effects, key=lambda e: VOCABULARY.index(e.name)))
        object.__setattr__(self, 'effects', effects)
        if not isinstance(self.input, InputKind):
            try:
                object.__setattr__(self, 'input', InputKind(self.input))
            except ValueError:
                raise ParameterError(
                    f'input must be one of {[k.value for k in InputKind]}, '
                    f'got {self.input!r}') from None
        if not isinstance(self.axis, AxisKind):
            try:
                object.__setattr__(self, 'axis', AxisKind(self.axis))
            except ValueError:
                raise ParameterError(
                    f'axis must be one of {[k.value for k in AxisKind]}, '
                    f'got {self.axis!r}') from None
        for e in effects:
            if self.axis not in e.axes:
                allowed = ' or '.join(sorted(k.value for k in e.axes))
                hint = '; on a linear axis gravity is an offset' if e.name == 'gravity' \
                    else ''
                raise ParameterError(
                    f'effect {e.name!r} is not valid on a {self.axis.value} axis '
                    f'({allowed} only{hint})')
        st = self.get('stribeck')
        if st is not None and st.fs < self.fc:
            raise ParameterError(
                f'stribeck.fs [N] ({st.fs:g}) must be >= coulomb.fc [N] ({self.fc:g})')
        if self.has('load_friction') and not self.has('coulomb'):
            raise ParameterError("effect 'load_friction' needs 'coulomb': it raises the "
                                 "Coulomb level fc by mu·|F_in|")
        pf = self.get('position_friction')
        if pf is not None:
            x_low, low = pf.lowest
            if self.fc + low < -1e-12 * (self.fc + float(np.max(np.abs(pf.values)))):
                raise ParameterError(
                    f'position_friction: the friction level fc + dfc(x) must be >= 0 on the '
                    f'knots\' span, but it is {self.fc + low:.6g} {self.units.force} at x = '
                    f'{x_low:.6g} {self.units.position} (coulomb.fc = {self.fc:g}; the '
                    f'spline through dfc dips to {low:.6g} there)')

    # -- composition ---------------------------------------------------------------
    @property
    def names(self) -> tuple[str, ...]:
        """Names of the effects present."""
        return tuple(e.name for e in self.effects)

    def get(self, name: str) -> Effect | None:
        """Return the effect called ``name``, or None."""
        for e in self.effects:
            if e.name == name:
                return e
        return None

    def has(self, name: str) -> bool:
        """Whether the model has the effect ``name``."""
        return self.get(name) is not None

    def with_effect(self, effect: Effect) -> 'AxisModel':
        """Return a copy with ``effect`` added or replacing the one of the same name."""
        rest = tuple(e for e in self.effects if e.name != effect.name)
        return dataclasses.replace(self, effects=rest + (effect,))

    def without(self, *names: str) -> 'AxisModel':
        """Return a copy without the named effects."""
        return dataclasses.replace(
            self, effects=tuple(e for e in self.effects if e.name not in names))

    def replace(self, **changes: Any) -> 'AxisModel':
        """Return a copy with some top-level fields changed."""
        return dataclasses.replace(self, **changes)

    @property
    def units(self) -> Units:
        """Unit strings of this axis kind (m, N, kg or rad, N·m, kg·m²)."""
        return _UNITS[self.axis]

    @property
    def rotary(self) -> bool:
        """Whether the axis is rotary."""
        return self.axis is AxisKind.ROTARY

    # -- convenience views used by controllers and the workbench -------------------
    @property
    def fc(self) -> float:
        """Coulomb level [N] (0 without a coulomb effect)."""
        e = self.get('coulomb')
        return e.fc if e is not None else 0.0

    @property
    def fv(self) -> float:
        """Viscous coefficient [N·s/m] (0 without a viscous effect)."""
        e = self.get('viscous')
        return e.fv if e is not None else 0.0

    def stribeck_curve_params(self) -> tuple[float, float, float, float]:
        """``(fc, fs, vs, delta)`` of the static curve; fs = fc without stribeck."""
        st = self.get('stribeck')
        if st is None:
            return self.fc, self.fc, 1e-3, 1.0
        return self.fc, st.fs, st.vs, st.delta

    def input_force(self, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Drive force [N] ``input_gain·(u − back_emf·v) − damping·v``."""
        u = np.asarray(u, dtype=float)
        v = np.asarray(v, dtype=float)
        return self.input_gain * (u - self.back_emf * v) - self.damping * v

    def dry_friction_shift(self, x: np.ndarray, *,
                           f_in: np.ndarray | None = None) -> np.ndarray:
        """Rise of the dry-friction level [N]: ``mu·|F_in| + dfc(x)`` (0 without both).

        The load-dependent (``load_friction``) and position-dependent
        (``position_friction``) friction raise ``fc`` and ``fs`` alike, here as in the
        plant kernel.  Compensation and inverse models that know the level of the rest
        of their friction law add this to it.

        Parameters
        ----------
        x : ndarray
            Positions [m].
        f_in : ndarray, optional
            Drive force at each sample [N], :meth:`input_force` of the applied (delayed)
            command; required when the model has ``load_friction``.
        """
        x = np.asarray(x, dtype=float)
        shift = np.zeros(np.shape(x))
        lf = self.get('load_friction')
        if lf is not None:
            if f_in is None:
                raise ParameterError('load_friction: the friction level needs the drive '
                                     'force F_in [N] (f_in = AxisModel.input_force(u, v))')
            shift = shift + lf.level(np.broadcast_to(np.asarray(f_in, dtype=float),
                                                     np.shape(x)))
        pf = self.get('position_friction')
        if pf is not None:
            shift = shift + pf.level(x.ravel()).reshape(np.shape(x))
        return shift

    # -- model file ----------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Return the model-file mapping of DESIGN.md §6 (SI units)."""
        return {
            'axis': self.axis.value,
            'input': self.input.value,
            'input_gain': float(self.input_gain),
            'back_emf': float(self.back_emf),
            'damping': float(self.damping),
            'mass': float(self.mass),
            'effects': {e.name: e.params() for e in self.effects},
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any], *, source: str = 'model') -> 'AxisModel':
        """Build from a model-file mapping; errors name ``source`` and the field."""
        if not isinstance(data, Mapping):
            raise ModelFileError(f'{source}: expected a mapping at top level')
        known = set(MODEL_FIELDS)
        unknown = sorted(set(data) - known)
        if unknown:
            raise ModelFileError(f'{source}: unknown field {unknown[0]!r} '
                                 f'(expected {sorted(known)})')
        if 'mass' not in data:
            raise ModelFileError(f'{source}: missing field \'mass\'')
        effects_data = data.get('effects') or {}
        if not isinstance(effects_data, Mapping):
            raise ModelFileError(f'{source}: effects must be a mapping name -> parameters')
        try:
            effects_data, note = upgrade_legacy_params(effects_data)
            if note:
                warn_legacy(f'{source}: {note}')
            effects = []
            for name, params in effects_data.items():
                if name not in EFFECTS:
                    raise ModelFileError(f'{source}: unknown effect {name!r} '
                                         f'(known: {", ".join(VOCABULARY)})')
                if params is not None and not isinstance(params, Mapping):
                    raise ModelFileError(f'{source}: effects.{name} must be a mapping')
                effects.append(make_effect(name, params))
            return cls(mass=data['mass'], input_gain=data.get('input_gain', 1.0),
                       back_emf=data.get('back_emf', 0.0), damping=data.get('damping', 0.0),
                       effects=tuple(effects), input=data.get('input', 'voltage'),
                       axis=data.get('axis', 'linear'))
        except ParameterError as exc:
            raise ModelFileError(f'{source}: {exc}') from None

    @classmethod
    def load(cls, path: str | Path) -> 'AxisModel':
        """Read a model YAML file (one-line :class:`ModelFileError` on any problem)."""
        path = Path(path)
        try:
            with path.open('r', encoding='utf-8') as fh:
                text = fh.read()
        except FileNotFoundError:
            raise ModelFileError(f'{path}: no such model file') from None
        except IsADirectoryError:
            raise ModelFileError(f'{path}: is a directory, expected a model YAML file') \
                from None
        except UnicodeDecodeError as exc:
            raise ModelFileError(f'{path}: not valid YAML ({exc})') from None
        return cls.from_text(text, source=str(path))

    @classmethod
    def from_text(cls, text: str, *, source: str = 'model') -> 'AxisModel':
        """Build from the text of a model YAML file (already read); errors name ``source``.

        The entry point for text read under rules of its own (a node reads a file a
        parameter names with :mod:`motor_comp.param_files`, then parses it here: the
        path is never opened twice).
        """
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            line = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
            raise ModelFileError(f'{source}: not valid YAML ({line})') from exc
        if data is None:
            raise ModelFileError(f'{source}: empty model file')
        return cls.from_dict(data, source=source)

    def save(self, path: str | Path) -> None:
        """Write the model YAML file."""
        with Path(path).open('w', encoding='utf-8') as fh:
            yaml.safe_dump(self.to_dict(), fh, sort_keys=False)

    # -- memoryless force sum (workbench inverse model) ----------------------------
    def static_force(self, x: np.ndarray, v: np.ndarray, *,
                     f_in: np.ndarray | None = None) -> np.ndarray:
        """Σ of the memoryless effect forces [N] at (x, v).

        The sliding friction of a model with ``presliding`` is carried by its GMS
        elements (see :meth:`effect_forces`); here it is replaced by the static curve,
        which the GMS force equals at constant velocity.  ``f_in`` [N] as in
        :meth:`effect_forces` (required with ``load_friction``).
        """
        return sum(self.effect_forces(x, v, dt=None, f_in=f_in).values(),
                   np.zeros(np.shape(x)))

    def effect_forces(self, x: np.ndarray, v: np.ndarray, *, dt: float | None = None,
                      f_in: np.ndarray | None = None) -> dict[str, np.ndarray]:
        """Force [N] of each force effect along samples (x [m], v [m/s]).

        On a rotary axis read torque [N·m] at angles [rad] and rates [rad/s].

        With ``dt`` [s] the samples are taken as a trajectory and ``presliding`` is
        simulated along it (its force then replaces coulomb + stribeck, which it
        contains, and the load- and position-dependent friction, which raise the level
        of its Stribeck curve); without ``dt``, presliding contributes its steady-state
        curve.

        ``f_in`` [N] is the drive force at each sample, :meth:`input_force` of the
        applied command (delayed, when the model has a ``delay``): ``load_friction``'s
        law ``mu·|F_in|·sgn(v)`` needs it, so a model with that effect raises
        :class:`ParameterError` without it.
        """
        x = np.asarray(x, dtype=float)
        v = np.asarray(v, dtype=float)
        fc, fs, vs, delta = self.stribeck_curve_params()
        out: dict[str, np.ndarray] = {}
        gms = self.get('presliding')
        lf = self.get('load_friction')
        if lf is not None and f_in is None:
            raise ParameterError('load_friction: its force mu·|F_in|·sgn(v) needs the drive '
                                 'force F_in [N] (f_in = AxisModel.input_force(u, v))')
        for e in self.effects:
            if e.kind is not EffectKind.FORCE:
                continue
            if e.name == 'stribeck':
                f = e.force(x, v, fc=fc)
            elif e.name == 'presliding':
                continue
            elif e.name == 'load_friction':
                f = e.force(x, v, f_in=f_in)
            else:
                f = e.force(x, v)
            out[e.name] = f
        if gms is not None and dt is not None:
            shift = None
            if lf is not None or self.has('position_friction'):
                shift = self.dry_friction_shift(x, f_in=f_in)
            f_gms = gms.force_along(x, dt, fc=fc, fs=fs, vs=vs, delta=delta, shift=shift)
            for name in ('coulomb', 'stribeck', 'load_friction', 'position_friction'):
                out.pop(name, None)
            out['presliding'] = f_gms
        return out


def warn_legacy(message: str) -> None:
    """Print a one-line ``motor-comp: warning:`` about a converted old parameter on stderr.

    (The physics layer sits below ``motor_comp.logs``; this is the same line format.)
    """
    print(f'motor-comp: warning: {message}', file=sys.stderr, flush=True)


def effects_from(items: Iterable[tuple[str, Mapping[str, Any]]]) -> tuple[Effect, ...]:
    """Effects from ``(name, params)`` pairs."""
    return tuple(make_effect(n, p) for n, p in items)
