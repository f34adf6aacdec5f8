"""What the workbench needs to know of an effect to identify it (DESIGN.md §2, §6).

Every effect module declares, next to its force law, one :class:`Term`: the regressor
columns its force is linear in (inverse-dynamic-model identification,
``../shared/IDENTIFICATION.md`` §1), its nonlinear parameters with their search space
and bounds (from its own definition and from the sensor: a pre-sliding distance is at
least the encoder's resolution, a dead time at most a tenth of the record), the bounds
and linear constraints on its coefficients (``fc ≥ 0``, ``fs ≥ fc``, ``fc ± dfc/2 ≥ 0``),
what it needs from the data (reversals, both directions, an axis kind), where its
evidence lies (while sliding, or around reversals and at rest), and its encoding to and
from the model file.  The workbench composes the terms of a model into one regressor
(PySINDy's composable feature libraries are the model: each library names its own
features) and never names an effect in its selection: adding an effect means adding
its module's term.

This module is numpy only: the processing that turns a run into the signals a column
is computed from (:class:`Path`, :class:`Summary`) and every search are the
workbench's.  Columns are *pointwise*: the workbench smooths each with the same
zero-phase filter as the drive force.
"""
from __future__ import annotations

import dataclasses
import enum
import math
from typing import Any, Callable, ClassVar, Mapping, Protocol

import numpy as np

from motor_comp.physics.effects.base import BOTH_AXES, Effect, EffectKind

#: the moving mass/inertia's coefficient label (always a column unless not excited)
MASS = ('mass', 'mass')


class Evidence(enum.Flag):
    """Where the data carry the evidence of an effect."""

    #: while the axis slides (friction levels, ripple, springs, gravity, a dead time)
    SLIDING = enum.auto()
    #: while it slides slowly, around the turns (the Stribeck rise): rows there must
    #: not be weighted down
    SLOW = enum.auto()
    #: at reversals (a backlash gap, pre-sliding): the run needs reversals to show it
    TURNS = enum.auto()
    #: in the transitions into and out of a rest (pre-sliding hysteresis): the fitted
    #: rows reach the stops
    STOPS = enum.auto()


class Signal(enum.Enum):
    """Columns the processing provides itself (not a pointwise law smoothed)."""

    #: the velocity the acceleration stencil sees (the hat average of ẋ)
    VELOCITY = 'velocity'
    #: the acceleration: the second difference of the smoothed position
    ACCELERATION = 'acceleration'


@dataclasses.dataclass(frozen=True)
class Summary:
    """What a term may know of the data to set its search space and its needs.

    Attributes
    ----------
    dt : float
        Sample step [s] (the coarsest of the runs).
    duration : float
        Length of the shortest run [s].
    quantum : float
        Encoder resolution [m or rad] (0 when unknown).
    noise : float
        Position noise σ [m or rad].
    span : tuple of float
        Lowest and highest position seen [m or rad].
    speeds : Mapping[int, float]
        Percentiles (1, 10, 50, 90, 95) of |ẋ| over the fitted samples [m/s or rad/s].
    accel90 : float
        90th percentile of |ẍ| over the fitted samples [m/s² or rad/s²].
    reversals : int
        Reversals of the motion within the runs.
    direction : int
        0 when the runs slide both ways, else the one direction (+1 or −1).
    rotary : bool
        Positions are angles.
    shared_span : tuple of float
        The positions crossed in both directions (1st–99th percentile of each
        direction's fitted positions, intersected) [m or rad]; ``()`` when none is.
    """

    dt: float
    duration: float
    quantum: float
    noise: float
    span: tuple
    speeds: Mapping
    accel90: float
    reversals: int
    direction: int
    rotary: bool
    shared_span: tuple = ()

    @property
    def travel(self) -> float:
        """Range of positions seen [m or rad]."""
        return float(self.span[1] - self.span[0])

    @property
    def resolution(self) -> float:
        """Smallest displacement the sensor resolves: the quantum or the noise [m or rad]."""
        return max(self.quantum, self.noise)


class Path(Protocol):
    """One run's pointwise signals, as the workbench's processing gives them.

    ``position`` is the motor position (reconstructed across a backlash gap when the
    model has one), ``x``/``v`` its pointwise (short-window) position and velocity,
    ``xg`` the position the pre-sliding elements are driven by, ``fwd``/``bwd``/
    ``stuck`` the share of each sample's acceleration kernel spent sliding forward,
    backward and stuck at a turn (the turn model), ``rest`` 1 where the axis rests
    (outside a turn; its friction balances every force there), ``f_in`` the pointwise drive force
    [N] with the model's dead time, ``dt`` the step [s] and ``direction`` as in
    :class:`Summary`.
    """

    position: np.ndarray
    x: np.ndarray
    v: np.ndarray
    xg: np.ndarray
    fwd: np.ndarray
    bwd: np.ndarray
    stuck: np.ndarray
    rest: np.ndarray
    f_in: np.ndarray
    dt: float
    direction: int

    def memo(self, key: tuple, make: Callable[[], Any]) -> Any:
        """Return ``make()`` computed once per path and ``key`` (a signal columns share)."""


@dataclasses.dataclass(frozen=True)
class Context:
    """What a term's columns may depend on besides its own nonlinear parameters.

    Attributes
    ----------
    present : frozenset of str
        Terms in the design.
    eta : Mapping[str, Mapping]
        Every present term's nonlinear parameters.
    sticks : bool
        The samples stuck at a turn carry the drive force into the friction (a dry
        friction model without a model of sticking): their sign columns are 0 there.
    direction : int
        As :attr:`Summary.direction`.
    rests : bool
        The samples at rest are out of the force balance (a dry friction holds them).
    """

    present: frozenset
    eta: Mapping
    sticks: bool = False
    direction: int = 0
    rests: bool = False


@dataclasses.dataclass(frozen=True)
class LocalBasis:
    """A block of columns written as ``B = L·mix``, ``L`` a basis local in the samples.

    Each sample touches few functions of ``L`` (a spline's pieces: the Hermite value
    and slope weights of the interval it lies in), so the workbench smooths ``L``
    sample by sample at the cost of those few and maps the result by ``mix`` (its
    smoother is linear): a block of many dense columns is then smoothed in the time of
    a few.

    Parameters
    ----------
    index : ndarray of int64, shape (n, m)
        The local functions sample ``i`` touches (``0 <= index < mix.shape[0]``).
    value : ndarray, shape (n, m)
        Their values at sample ``i``.
    mix : ndarray, shape (size, width)
        The block's columns in terms of the local functions.
    """

    index: np.ndarray
    value: np.ndarray
    mix: np.ndarray


@dataclasses.dataclass(frozen=True)
class Column:
    """One regressor column: a coefficient and the pointwise signal it multiplies.

    Parameters
    ----------
    label : str
        The coefficient's name within its term (``fc``, ``a1`` …).
    key : tuple
        What the column's values are computed from; equal keys mean equal columns
        (the workbench caches by it).
    fn : callable, optional
        ``fn(path) -> ndarray`` of the pointwise column along one run; with ``width``
        > 1 it returns ``(n, width)`` and the column is one of a block computed in one
        pass (``index`` selects it).
    signal : Signal, optional
        A processed signal instead of ``fn``.
    lo, hi : float
        Bounds on the coefficient, enforced inside the estimator.
    frequency : float
        Spatial frequency [rad/m] of a position-periodic column (the acceleration
        stencil sees such a force averaged over its kernel; the workbench applies it).
    basis : str
        A column several terms share (``'constant'``: the constant force while the
        axis moves): the first term in vocabulary order owns it, the others' copies
        are left out and their coefficient reads 0.
    width, index : int
        Block size and this column's place in the block (for a vector parameter's
        columns, the element).
    uses_input : bool
        The column depends on the drive input (``path.f_in``), hence on a dead time.
    local : callable, optional
        ``local(path) -> LocalBasis``: the same block as ``fn`` on a basis local in the
        samples, which the workbench smooths in its place (:class:`LocalBasis`).
    """

    label: str
    key: tuple
    fn: Callable[[Any], np.ndarray] | None = None
    signal: Signal | None = None
    lo: float = -math.inf
    hi: float = math.inf
    frequency: float = 0.0
    basis: str = ''
    width: int = 1
    index: int = 0
    uses_input: bool = False
    local: Callable[[Any], LocalBasis] | None = None


@dataclasses.dataclass(frozen=True)
class Param:
    """A nonlinear parameter: its search space, searched by variable projection.

    Parameters
    ----------
    name : str
        Name within the term (``tau``, ``period`` …).
    lo, hi : float
        Bounds [SI].
    grid : tuple of float
        Trial values of the global search.
    log : bool
        Search on the logarithm (a scale parameter).
    steps : tuple of float
        Relative (``log``) or absolute offsets around the all-data optimum tried
        inside each validation fold (the in-fold choice is then not grid-bound).
    vector : int
        0 for a scalar; else the parameter is a vector of at most ``vector`` elements
        (its length is the term's order, e.g. the GMS element distances), one per
        column of the term, in order.
    profile : bool
        Its standard error is (at least) half its profile-likelihood interval: for a
        parameter whose SSE profile is one-sided, which the local curvature understates.
    resolved : bool
        ``lo`` is the least value the run resolves (set from the sensor or the
        sampling): an estimate within two standard errors of it is not evidence of
        the effect — the data cannot tell it from less than the run can show.
    tol : float
        The step at which its local search of one scalar stops [its unit] (0: a
        millionth of the value; a hundredth of the logarithm for a ``log`` parameter).
    """

    name: str
    lo: float
    hi: float
    grid: tuple = ()
    log: bool = False
    steps: tuple = ()
    vector: int = 0
    profile: bool = False
    resolved: bool = False
    tol: float = 0.0

    def clip(self, v: float) -> float:
        """Return ``v`` within the bounds."""
        return float(min(max(v, self.lo), self.hi))


#: a linear constraint ``Σ_i a_i·θ_i ≥ b`` on coefficients named ``(term, label)``
Constraint = tuple


@dataclasses.dataclass(frozen=True)
class Shape:
    """How a term's force shows in the structure scan of a residual (its "shape").

    The scan (:mod:`motor_comp.workbench.scan`) describes what a model leaves as step
    functions against position, speed, drive force, time…; a feature with the shape
    a term declares is said to have that term's shape (and which term is the user's
    to add, or the model's own that does not follow it).

    Attributes
    ----------
    against : str or None
        ``position``, ``velocity`` or ``force``: what the force is a function of;
        None for a constant level, seen the same against anything.
    odd : bool
        It flips with the direction of motion (a friction).
    trend : int
        Along ``|against|`` for an odd shape, ``against`` for an even one: +1 the
        force grows (a viscous slope with speed), −1 it falls (a Stribeck excess above
        the Coulomb level, largest at low speed), 0 no direction (a structure along the
        travel).
    """

    against: str | None
    odd: bool
    trend: int = 0

    def __post_init__(self) -> None:
        if self.against not in (None, 'position', 'velocity', 'force'):
            raise ValueError(f'a shape is against position, velocity or force, not '
                             f'{self.against!r}')
        if self.trend not in (-1, 0, 1):
            raise ValueError(f'a shape\'s trend is -1, 0 or +1, not {self.trend!r}')

    def matches(self, against: str, odd: bool, trend: int, level: bool) -> bool:
        """Whether a feature seen ``against`` with this parity, trend and level has it."""
        if level or self.against is None:
            return level and self.against is None and self.odd == odd
        return self.against == against and self.odd == odd and self.trend in (0, trend)


class Term:
    """Base class of the identification declarations of one effect.

    Subclasses set the class attributes and override what differs; every method has
    a default for a term with no nonlinear parameters and no constraints.  Values of
    coefficients and nonlinear parameters travel as ``{(term, label): value}``
    mappings (``values``), nonlinear parameters of one term as a dict (``eta``).
    """

    #: vocabulary name (the effect's)
    name: ClassVar[str] = ''
    #: the effect class it identifies
    effect: ClassVar[type[Effect]] = Effect
    #: where its evidence lies
    evidence: ClassVar[Evidence] = Evidence.SLIDING
    #: terms it is defined relative to (all must be present)
    requires: ClassVar[tuple] = ()
    #: at least one of these must be present
    requires_any: ClassVar[tuple] = ()
    #: terms it cannot stand beside (two models of one phenomenon)
    excludes: ClassVar[tuple] = ()
    #: terms whose columns its own carry when both are present
    replaces: ClassVar[tuple] = ()
    #: a dry friction level: stuck samples carry the drive force into it
    dry_friction: ClassVar[bool] = False
    #: models sticking itself (pre-sliding): stuck samples are its to explain
    models_sticking: ClassVar[bool] = False
    #: least reversals within the runs for the run to judge it
    min_reversals: ClassVar[int] = 0
    #: told from the canonical friction only by the other direction of motion
    both_directions: ClassVar[bool] = False
    #: names of the free nonlinear parameters in ``eta`` (vectors count per element)
    params: ClassVar[tuple] = ()
    #: reported scalars ``(group, name)`` that scale with the force: an input-gain
    #: error multiplies each by one factor
    force_scaled: ClassVar[tuple] = ()
    #: reported scalar that sets the effect's shape and the value at which the effect
    #: vanishes, e.g. ``('tau', 0.0)`` (None: the effect vanishes with its coefficients)
    null: ClassVar[tuple | None] = None
    #: how its force shows in a residual's structure scan (None: no step function's)
    shape: ClassVar[Shape | None] = None

    @property
    def kind(self) -> EffectKind:
        """Where the effect acts (force, input, output)."""
        return self.effect.kind

    def applicable(self, s: Summary) -> str | None:
        """Return why this run cannot judge the term, or None when it can."""
        axes = {a.value for a in getattr(self.effect, 'axes', BOTH_AXES)}
        if ('rotary' if s.rotary else 'linear') not in axes:
            return f'{self.name} is not physical on a {"rotary" if s.rotary else "linear"} axis'
        if s.reversals < self.min_reversals:
            return (f'{self.name} acts at reversals: {s.reversals} in the run(s), at least '
                    f'{self.min_reversals} needed')
        if self.both_directions and s.direction:
            return f'{self.name} is told from friction only by motion both ways'
        return None

    def space(self, s: Summary, ctx: Context) -> tuple[Param, ...]:
        """Return the nonlinear parameters with their bounds and grids; by default none."""
        return ()

    def orders(self, s: Summary, eta: Mapping) -> tuple[int, int]:
        """Return the range of the term's structural order (0, 0: none)."""
        return (0, 0)

    def order_of(self, eta: Mapping) -> int:
        """Return the structural order of ``eta`` (harmonics, elements; 0: none)."""
        return 0

    def with_order(self, eta: Mapping, order: int) -> dict:
        """Return ``eta`` at another structural order."""
        return dict(eta)

    def repeats_every(self, eta: Mapping) -> float | None:
        """Return the length of the position blocks it must predict unseen, or None.

        A structure periodic in position claims that what it fits on some stretches of
        the travel repeats on the others: it pays only when, fitted without each block
        of this length [m or rad], it predicts that block
        (:func:`~motor_comp.workbench.repeats.block_cv`), so a shape at one place (a bump
        the library lacks) is not taken for it.  None: no such claim.
        """
        return None

    def grow(self, eta: Mapping) -> dict | None:
        """Return ``eta`` with one more structural element to try (None: no growth)."""
        return None

    def bracket(self, value: float, s: Summary) -> tuple[float, float] | None:
        """Return the local search interval of a lone scalar start (None: grid cells)."""
        return None

    def fold_steps(self, value: float, s: Summary) -> tuple[float, ...] | None:
        """Return the values tried inside each fold (None: the parameter's ``steps``)."""
        return None

    def aliases(self, s: Summary) -> list[dict]:
        """Return parameters at which the term could stand for another's force.

        Used to say which effects a run cannot tell apart, not to fit: a term without
        a search is itself; a searched term declares the values outside its fitting
        space that mimic others (a ripple longer than the travel); none by default.
        """
        searched = bool(self.params) or type(self).orders is not Term.orders
        return [] if searched else [{}]

    def initial(self, s: Summary, ctx: Context, profile: Any) -> list[dict]:
        """Return starts of the search from the current residual (empty: the grid)."""
        return []

    def derive(self, eta: Mapping, base: Mapping) -> dict:
        """Return ``eta`` with the entries derived from the fit without the term."""
        return dict(eta)

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return the regressor columns at nonlinear parameters ``eta``."""
        return []

    def constraints(self, ctx: Context) -> list[Constraint]:
        """Return linear constraints ``({(term, label): a}, b)`` meaning ``Σ a·θ ≥ b``."""
        return []

    def admissible(self, values: Mapping, eta: Mapping, s: Summary) -> str | None:
        """Return why fitted values lie outside the term's domain, or None."""
        return None

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the model-file effects of the fitted ``values``."""
        raise NotImplementedError(self.name)

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return ``({label: coefficient}, eta)`` of the effect in ``model``."""
        raise NotImplementedError(self.name)

    def scalars(self, eta: Mapping, ctx: Context) -> dict[tuple, Callable[[Mapping], float]]:
        """Return the reported parameters ``{(group, name): f(values)}``."""
        return {}

    def nonlinear(self, eta: Mapping) -> list[tuple[str, int | None, float]]:
        """Return the free nonlinear parameters as ``(name, element or None, value)``."""
        out: list[tuple[str, int | None, float]] = []
        for name in self.params:
            v = eta.get(name)
            if isinstance(v, tuple):
                out += [(name, j, float(e)) for j, e in enumerate(v)]
            elif v is not None:
                out.append((name, None, float(v)))
        return out

    def perturbed(self, eta: Mapping, name: str, element: int | None, value: float) -> dict:
        """Return ``eta`` with one free nonlinear parameter (or vector element) set."""
        e = dict(eta)
        if element is None:
            e[name] = value
        else:
            v = list(e[name])
            v[element] = value
            e[name] = tuple(v)
        return e


__all__ = ['MASS', 'Column', 'Constraint', 'Context', 'Evidence', 'LocalBasis', 'Param', 'Path',
           'Shape', 'Signal', 'Summary', 'Term']
