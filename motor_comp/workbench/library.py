"""The term library: a model's effects composed into one regressor (inverse dynamic model).

``F_in(u(t − τ)) = M·ẍ + Σ_g Φ_g(x, ẋ; η_g)·θ_g`` (``../shared/IDENTIFICATION.md`` §1;
Gautier & Janot's IDIM for robot joints and EMPS-class axes): each effect's term
(:data:`motor_comp.physics.effects.TERMS`, declared next to its law) gives its named
columns, and a model's design is their concatenation — PySINDy's composable feature
libraries are the model, with what physics adds: a term may carry another's columns
(pre-sliding carries the Coulomb level), share a column with another (an offset and a
spring's constant: the first in vocabulary order owns it), and bound its coefficients.

Nothing here names an effect: an input effect (a dead time) sets the view's delay, an
output effect (a gap) its motion, and the rest is what each term declares.
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping, Sequence

import numpy as np

from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import TERMS, VOCABULARY, EffectKind
from motor_comp.physics.effects.identification import MASS, Column, Context, Signal, Term
from motor_comp.workbench.bands import SpeedWeights
from motor_comp.workbench.dataset import Dataset, View
from motor_comp.workbench.lsq import Bounds, solve_gram
from motor_comp.workbench.processing import Processing

#: candidate effects in vocabulary order
ORDER = VOCABULARY


def term(name: str) -> Term:
    """Return the term of effect ``name``."""
    return TERMS[name]


@dataclasses.dataclass(frozen=True)
class Spec:
    """An effect set with its nonlinear parameters: what a design is built from.

    Parameters
    ----------
    names : tuple of str
        Effects present (vocabulary order).
    eta : Mapping[str, Mapping]
        Nonlinear parameters per effect (``{'tau': 0.001}`` …; linear effects: ``{}``).
    mass_free : bool
        Whether the mass is a column (else fixed at ``mass``).
    mass : float
        The fixed mass when not free [kg or kg·m²].
    """

    names: tuple
    eta: Mapping
    mass_free: bool = True
    mass: float = 1.0

    def with_(self, name: str, eta: Mapping | None = None) -> 'Spec':
        """Return a copy with ``name`` added or its nonlinear parameters replaced."""
        e = dict(self.eta)
        e[name] = dict(eta) if eta is not None else dict(e.get(name, {}))
        present = set(self.names)
        present.add(name)
        names = tuple(n for n in ORDER if n in present)
        return Spec(names, e, self.mass_free, self.mass)

    def without(self, name: str) -> 'Spec':
        """Return a copy without ``name``."""
        e = {k: v for k, v in self.eta.items() if k != name}
        return Spec(tuple(n for n in self.names if n != name), e, self.mass_free, self.mass)

    def of(self, name: str) -> dict:
        """Return the nonlinear parameters of ``name`` (empty when linear or absent)."""
        return dict(self.eta.get(name, {}))


def spec_key(spec: Spec) -> tuple:
    """Return a hashable key of ``spec`` (its nonlinear values by their exact ``repr``)."""
    eta = tuple((n, repr(sorted(spec.eta.get(n, {}).items()))) for n in spec.names)
    return spec.names, eta, spec.mass_free, spec.mass


def candidates(spec: Spec, data: Dataset) -> list[str]:
    """Return the terms that can be added to ``spec`` on this data (declared needs met)."""
    present = set(spec.names)
    out = []
    for n in ORDER:
        t = TERMS[n]
        if n in present or t.applicable(data.summary) is not None:
            continue
        if not set(t.requires) <= present:
            continue
        if t.requires_any and not set(t.requires_any) & present:
            continue
        if set(t.excludes) & present or any(n in TERMS[m].excludes for m in present):
            continue
        out.append(n)
    return out


def sticks(spec: Spec, data: Dataset) -> bool:
    """Whether the stuck samples at a turn carry the drive force into the friction.

    A stuck axis's friction is exactly the drive force (it neither accelerates nor
    moves), so with a dry friction term and no term that models sticking itself the
    stuck share of each sample is left out of the force balance.
    """
    ts = [TERMS[n] for n in spec.names]
    return (not data.direction and any(t.dry_friction for t in ts)
            and not any(t.models_sticking for t in ts))


def rests(spec: Spec) -> bool:
    """Whether the samples at rest are out of the force balance (a dry friction holds them).

    At rest the dry friction balances every other force, so no law is seen there; a
    model without a dry friction level has to explain the rest (it cannot: that is
    the evidence that it needs one).
    """
    return any(TERMS[n].dry_friction for n in spec.names)


def reaches_stops(spec: Spec) -> bool:
    """Whether ``spec``'s fits reach the stops (a term's evidence lies in those transitions)."""
    from motor_comp.physics.effects.identification import Evidence
    return any(TERMS[n].evidence & Evidence.STOPS for n in spec.names)


def processing_for(spec: Spec, base: Processing = Processing()) -> Processing:
    """Return the processing ``spec`` is judged with: its rows reach the stops or not."""
    return dataclasses.replace(base, turns=reaches_stops(spec))


def dataset_for(kins: Sequence[Any], model: AxisModel, **kw: Any) -> Dataset:
    """Return the dataset a model is judged on (one rule for every command)."""
    return Dataset(kins, model, processing=processing_for(spec_of(model)), **kw)


def context(spec: Spec, data: Dataset | None = None) -> Context:
    """Return the :class:`Context` the terms' columns of ``spec`` see."""
    return Context(present=frozenset(spec.names), eta=spec.eta,
                   sticks=sticks(spec, data) if data is not None else False,
                   direction=int(data.direction) if data is not None else 0,
                   rests=rests(spec))


def owned_columns(spec: Spec, ctx: Context) -> list[tuple[str, Column]]:
    """Return ``(term, column)`` of the design: replaced terms out, shared bases once."""
    present = set(spec.names)
    replaced = {r for n in spec.names for r in TERMS[n].replaces if r in present}
    owners: set[str] = set()
    out = []
    for n in spec.names:
        if n in replaced:
            continue
        for col in TERMS[n].columns(spec.of(n), ctx):
            if col.basis:
                if col.basis in owners:
                    continue
                owners.add(col.basis)
            out.append((n, col))
    return out


def labels(spec: Spec, ctx: Context | None = None) -> list[tuple[str, str]]:
    """Return the coefficient labels of ``spec``'s design, in column order."""
    ctx = ctx or context(spec)
    out = [MASS] if spec.mass_free else []
    return out + [(n, c.label) for n, c in owned_columns(spec, ctx)]


def n_params(spec: Spec) -> int:
    """Return the fitted parameters of ``spec`` (columns + free nonlinear ones)."""
    ctx = context(spec)
    return len(labels(spec, ctx)) + sum(len(TERMS[n].nonlinear(spec.of(n)))
                                        for n in spec.names)


def view_for(data: Dataset, spec: Spec, model: AxisModel | None = None,
             weights: SpeedWeights | None = None) -> View:
    """Return the view ``spec`` assumes: its input effect's delay, its output effect's gap."""
    width = tau = 0.0
    for n in spec.names:
        t = TERMS[n]
        if t.kind is EffectKind.INPUT and t.params:
            tau = float(spec.of(n)[t.params[0]])
        elif t.kind is EffectKind.OUTPUT and t.params:
            width = float(spec.of(n)[t.params[0]])
    return data.at(width=width, tau=tau, model=model if width > 0 else None, weights=weights)


@dataclasses.dataclass(frozen=True)
class Design:
    """One design at the rows: columns, their labels and cache keys, bounds, target."""

    cols: list
    labels: list
    keys: list
    bounds: Bounds
    y: np.ndarray
    ykey: tuple
    ctx: Context
    view: View

    @property
    def X(self) -> np.ndarray:
        """Regressor matrix (rows × columns)."""
        return np.stack(self.cols, axis=1) if self.cols else np.zeros((len(self.y), 0))

    def gram(self, rows: np.ndarray | None = None) -> np.ndarray:
        """Return the augmented Gram ``[X y]ᵀ[X y]`` over ``rows`` (cached entries reused)."""
        return self.view.data.gram(self.cols + [self.y], self.keys + [self.ykey], rows)

    def part_grams(self) -> np.ndarray:
        """Return the per-part augmented Gram, shape (parts, q, q) (cached entries reused)."""
        return self.view.data.part_grams_of(self.cols + [self.y], self.keys + [self.ykey])

    def solve(self, rows: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """Return θ and the SSE of the bounded least squares over ``rows``."""
        return solve_gram(self.gram(rows), self.bounds)


def design(data: Dataset, spec: Spec, model: AxisModel | None = None, *,
           weights: SpeedWeights | None = None) -> Design:
    """Build ``spec``'s design on ``data`` (``model``: the dynamics across a gap)."""
    view = view_for(data, spec, model, weights)
    ctx = context(spec, data)
    owned = owned_columns(spec, ctx)
    cols: list[Any] = []
    labs: list[tuple[str, str]] = []
    keys: list[tuple] = []
    bound_cols: list[Column] = []
    if spec.mass_free:
        cols.append(view.signal(Signal.ACCELERATION))
        labs.append(MASS)
        keys.append(view.key(('signal', Signal.ACCELERATION.value)))
        # a mass is positive: held inside the estimator, so what is scored is what the
        # model file can hold (a negative mass was scored and silently not written)
        bound_cols.append(Column('mass', ('mass',), lo=0.0))
    cols += view.columns([c for _, c in owned], rests=ctx.rests)
    for n, c in owned:
        labs.append((n, c.label))
        keys.append(view.ckey(c, ctx.rests))
        bound_cols.append(c)
    y, ykey = target(view, spec, ctx)
    return Design(cols, labs, keys, _bounds(labs, bound_cols, spec, ctx), y, ykey, ctx, view)


def _bounds(labs: Sequence[tuple], cols: Sequence[Column], spec: Spec, ctx: Context) \
        -> Bounds:
    p = len(labs)
    lo = np.array([c.lo for c in cols], dtype=float)
    hi = np.array([c.hi for c in cols], dtype=float)
    index = {lab: i for i, lab in enumerate(labs)}
    rows, rhs = [], []
    for n in spec.names:
        for coef, b in TERMS[n].constraints(ctx):
            if all(k in index for k in coef):
                a = np.zeros(p)
                for k, v in coef.items():
                    a[index[k]] = v
                rows.append(a)
                rhs.append(b)
    A = np.array(rows) if rows else np.zeros((0, p))
    return Bounds(lo, hi, A, np.array(rhs, dtype=float))


def target(view: View, spec: Spec, ctx: Context) -> tuple[np.ndarray, tuple]:
    """Return the left-hand side and its cache key: drive force (delayed), adjusted.

    Minus the stuck samples' drive force when they carry it into the friction
    (:func:`sticks`), minus ``M·ẍ`` when the mass is fixed; weighted like the columns.
    """
    def make() -> np.ndarray:
        y = view.y(rests=ctx.rests)
        if ctx.sticks:
            y = y - view.stuck_force()
        if not spec.mass_free:
            base = view.data.at(width=view.width, tau=view.tau, model=view.model)
            y = y - spec.mass * base.signal(Signal.ACCELERATION)
        sw = view.sw
        return y if sw is None else y * sw
    key = view.key(('target', spec.mass_free, 0.0 if spec.mass_free else float(spec.mass),
                    ctx.sticks, ctx.rests), uses_input=True)
    return view.data.cached(key, make), key


def spec_of(model: AxisModel) -> Spec:
    """Return the spec of an existing model (its nonlinear parameters as given)."""
    eta = {}
    names = []
    for e in model.effects:
        t = TERMS.get(e.name)
        if t is None:
            continue
        names.append(e.name)
        eta[e.name] = t.decode(model)[1]
    return Spec(tuple(n for n in ORDER if n in names), eta, True, model.mass)


def theta_of(model: AxisModel, spec: Spec, ctx: Context) -> np.ndarray:
    """Return the coefficients ``model`` gives the columns of its own ``spec``.

    A coefficient on a shared column another term owns is added to the owner's (a
    spring's ``−k·x0`` to the offset), and a replaced term's coefficients are its
    replacement's to give.
    """
    coef: dict[tuple, float] = {MASS: model.mass}
    for n in spec.names:
        for k, v in TERMS[n].decode(model)[0].items():
            # a term may hand part of its law to another's coefficient (a position
            # friction's level at its first knot is the Coulomb level)
            lab = k if isinstance(k, tuple) else (n, k)
            coef[lab] = coef.get(lab, 0.0) + float(v)
    owned = owned_columns(spec, ctx)
    owner: dict[str, tuple] = {c.basis: (n, c.label) for n, c in owned if c.basis}
    out_labels = labels(spec, ctx)
    present = {lab for lab in out_labels}
    extra: dict[tuple, float] = {}
    replaced = {r for n in spec.names for r in TERMS[n].replaces if r in spec.names}
    for n in spec.names:
        if n in replaced:
            continue
        for col in TERMS[n].columns(spec.of(n), ctx):
            lab = (n, col.label)
            if col.basis and lab not in present and col.basis in owner:
                extra[owner[col.basis]] = extra.get(owner[col.basis], 0.0) + coef.get(lab, 0.0)
    return np.array([coef.get(lab, 0.0) + extra.get(lab, 0.0) for lab in out_labels])


def given_residual(data: Dataset, model: AxisModel) -> np.ndarray:
    """Return the residual of ``model`` as given at the rows (no fitting) [N or N·m]."""
    spec = spec_of(model)
    d = design(data, spec, model)
    return d.y - d.X @ theta_of(model, spec, d.ctx)


def given_sse(data: Dataset, model: AxisModel) -> float:
    """Return the SSE of ``model`` as given on the rows (no fitting)."""
    r = given_residual(data, model)
    return float(r @ r)


def encode(spec: Spec, values: Mapping, model: AxisModel) -> AxisModel:
    """Return the model-file form of fitted ``values`` (``{(term, label): value}``).

    The drive constants stay ``model``'s; a replaced term is encoded by its
    replacement.
    """
    ctx = context(spec)
    mass = float(values.get(MASS, spec.mass)) if spec.mass_free else float(spec.mass)
    out = model.without(*model.names).replace(mass=mass if mass > 0 else model.mass)
    replaced = {r for n in spec.names for r in TERMS[n].replaces if r in spec.names}
    effects: dict[str, Any] = {}
    for n in spec.names:
        if n in replaced:
            continue
        for e in TERMS[n].encode(values, spec.of(n), ctx):
            effects[e.name] = e
    for n in ORDER:
        if n in effects:
            out = out.with_effect(effects[n])
    return out


def values_of(spec: Spec, labs: Sequence[tuple], theta: np.ndarray) -> dict:
    """Return ``{(term, label): value}`` of coefficients and free nonlinear parameters."""
    vals = {lab: float(v) for lab, v in zip(labs, theta)}
    for n in spec.names:
        for name, j, v in TERMS[n].nonlinear(spec.of(n)):
            vals[(n, name if j is None else f'{name}{j}')] = v
    return vals


__all__ = ['Design', 'ORDER', 'Spec', 'candidates', 'context', 'dataset_for', 'design', 'encode',
           'given_residual', 'given_sse', 'labels', 'processing_for', 'reaches_stops',
           'n_params', 'owned_columns', 'spec_key', 'spec_of', 'sticks', 'target', 'term',
           'theta_of', 'values_of', 'view_for']
