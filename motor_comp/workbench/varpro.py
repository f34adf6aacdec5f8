"""Nonlinear parameters by variable projection, for any term's declared search space.

At each trial of a term's nonlinear parameters ``η`` every linear coefficient is
re-solved (bounded least squares on the cached Gram: Golub & Pereyra 1973), so the
search is over the few numbers the term declares (:class:`~motor_comp.physics.effects.
identification.Param`), never over everything.  The procedure is the same for every
term and reads only its declarations:

1. **start**: the term's own starts from the current residual (a spectral peak) or the
   Cartesian grid of its parameters' trial values;
2. **local**: one free scalar by a bounded Brent search between the grid cells around
   the best trial (or the term's bracket); several by Levenberg–Marquardt on the
   variable-projection residual over the (log) parameters, inside their bounds (Golub
   & Pereyra's method: from a start near the optimum — the previous round's — it needs
   about 20 residuals where the Nelder–Mead simplex it replaced took 70–96 costs, on
   the ball-screw's Stribeck searches, each trial recomputing its pre-sliding
   elements);
3. **order**: a term with a structural order (ripple harmonics, knots) takes the count
   with the best information criterion, every count scored — on the sum of squares
   weighted by speed band when the residual's variance differs between bands
   (:class:`.bands.SpeedBands`: then that is the likelihood) — and is refined again if
   it changed;
4. **vector parameters** (the GMS element distances, one element per column): a common
   scale first (all a screen needs); for a candidate past the screen every element
   freed (by Nelder–Mead, whose first steps of 5 % leave the basin a local method
   stays in: freed by Levenberg–Marquardt instead, two of the independent generator's
   pre-sliding sine runs kept a curve that left 3.7 % and 2.5 % force NRMSE and no
   room for the viscous slope, against 0.04 % and 0.18 %), elements whose coefficient
   ends at its bound or that do not pay for their two parameters (BIC) dropped, a
   further element grown where the term proposes one and it pays, and each element
   polished by a scan and Brent.  An element the search pushes
   onto its lower bound (the sensor's resolution) is not grown: it is no curve the run
   resolves.

**The simplex stops at the data's resolution.**  With ``n_eff`` independent samples
(:attr:`.dataset.Dataset.n_eff`, the count the information criterion uses) the
−2·log-likelihood of a least-squares fit is ``n_eff·log SSE``, so a relative fall of the
SSE of ``1/n_eff`` is one unit: the one-standard-error contour of one parameter.  Points
whose costs differ by a tenth of that (:data:`RESOLUTION`) lie within about a third of a
standard error of each other, and no choice the selection makes (a BIC that charges
``log n_eff`` units a parameter) turns on the difference.  So Nelder–Mead stops once its
simplex's costs agree to it, however far apart its vertices.  It went on contracting
until they were within ``xatol``: in the ball-screw's ``fit --auto``, four of its eight
simplex searches never saw two costs differ (140 costs), a fifth started with its
costs within 1e-5 of each other and took 141, the other three 162 where 65 now do:
443 costs in all, 86 now, with the same fitted model to the last digit and every
list's verdict unchanged.  Brent's search keeps its tolerance on the point: a
stop where its parabola predicts no larger fall missed narrow minima between its points
(a ripple's period: two of the suite's ripple chirps then left 20× the true model's
NRMSE).  Levenberg–Marquardt keeps its own: stopped the same way it left the
ball-screw's unresolved ``C`` at half the value, and the noise floor its twin gives
moved from 0.40 to 0.46 %.

Choices made from data are made inside each validation fold when a held-out score is
wanted (:func:`.heldout.cv_candidate`): each fold takes, on its own training rows, the best of
the grid and a neighbourhood of the all-data choice.  A term that claims to repeat
along the travel (``Term.repeats_every``: the ripple) is first held to that claim on
stretches of the travel it was not fitted on (:func:`.repeats.block_cv`); one that does
not repeat has no held-out gain.
"""
from __future__ import annotations

import itertools
import math
from typing import Any, Callable, Mapping, Sequence, Union

import numpy as np

from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import TERMS
from motor_comp.physics.effects.identification import Param, Signal, Term
from motor_comp.workbench.bands import PROTECTED, WEIGHT_CONTRAST, SpeedBands, SpeedWeights
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.library import Spec, context, design, values_of
from motor_comp.workbench.lsq import bic, solve_gram
from motor_comp.workbench.optim import Minimum, brent_bounded, levenberg_marquardt, \
    nelder_mead


#: the simplex stops when its costs agree to this many units of −2·log-likelihood,
#: ``n_eff·ΔSSE/SSE`` (module docstring): one unit is the one-standard-error contour of
#: one parameter, a tenth of it about a third of a standard error
RESOLUTION = 0.1


def searched(t: Term) -> bool:
    """Whether a term has anything to search: nonlinear parameters or a structure."""
    return bool(t.params) or type(t).orders is not Term.orders


def vp_sse(data: Dataset, spec: Spec, model: AxisModel | None,
           rows: np.ndarray | None = None, weights: SpeedWeights | None = None) -> float:
    """Return the SSE of ``spec`` at its nonlinear parameters, every coefficient re-solved."""
    d = design(data, spec, model, weights=weights)
    return solve_gram(d.gram(rows), d.bounds)[1]


def _n_eff(data: Dataset, rows: np.ndarray | None) -> float:
    if rows is None:
        return data.n_eff
    return max(data.n_eff * np.count_nonzero(rows) / data.n, 2.0)


def _nelder_mead(cost: Any, q0: np.ndarray, **options: Any) -> Minimum:
    """Run Nelder–Mead from ``q0`` with a first simplex of 5 % of each coordinate.

    A coordinate at 0 steps by 0.05 (scipy's 0.00025 would barely move a log-parameter
    at 1).
    """
    q0 = np.asarray(q0, dtype=float)
    sim = np.tile(q0, (len(q0) + 1, 1))
    for i in range(len(q0)):
        sim[i + 1, i] += 0.05 * q0[i] if q0[i] != 0.0 else 0.05
    return nelder_mead(cost, sim, **options)


def _least_squares(residual: Callable[[np.ndarray], np.ndarray], q0: np.ndarray,
                   params: Sequence[Param], *, xatol: float, fatol: float) -> Minimum:
    """Run Levenberg–Marquardt from ``q0`` on coordinates ``_to(p, ·)`` of ``params``.

    The differences step 1e-4 in a log-parameter (a relative 1e-4, far above the
    rounding of a smoothed column, far below any parameter's resolution) and 1e-4 of
    the range in a linear one.
    """
    lo = np.array([_to(p, p.lo) for p in params])
    hi = np.array([_to(p, p.hi) for p in params])
    step = np.array([1e-4 if p.log else 1e-4 * (p.hi - p.lo) for p in params])
    return levenberg_marquardt(residual, q0, lo=lo, hi=hi, step=step, xatol=xatol,
                               fatol=fatol)


#: a bar a search's best start must not be above: a number, or a function giving one
Bar = Union[float, Callable[[], float]]


def _to(p: Param, v: float) -> float:
    return math.log(max(v, 1e-300)) if p.log else float(v)


def _from(p: Param, q: float) -> float:
    return p.clip(math.exp(min(q, 700.0)) if p.log else q)


class Search:
    """The search of one term's nonlinear parameters in one spec, on some rows."""

    def __init__(self, data: Dataset, spec: Spec, name: str, model: AxisModel | None,
                 rows: np.ndarray | None = None, weights: SpeedWeights | None = None) -> None:
        self.data, self.name, self.model, self.rows = data, name, model, rows
        self.weights = weights
        self.term: Term = TERMS[name]
        self.base = spec.without(name)
        self.spec = spec
        self.space = {p.name: p for p in self.term.space(data.summary, context(spec, data))}
        self.seen: dict = {}

    # -- costs -------------------------------------------------------------------------
    def _resolution(self, f: float) -> float:
        """Return the fall of a cost ``f`` the data cannot tell from none (:data:`RESOLUTION`)."""
        return RESOLUTION / _n_eff(self.data, self.rows) * f

    def cost(self, eta: Mapping) -> float:
        """Return the SSE of the spec with the term at ``eta`` (memoised)."""
        key = _freeze(eta)
        hit = self.seen.get(key)
        if hit is None:
            hit = self.seen[key] = vp_sse(self.data, self.spec.with_(self.name, eta),
                                          self.model, self.rows, self.weights)
        return hit

    def residual(self, eta: Mapping) -> np.ndarray:
        """Return the residual at the rows of the spec with the term at ``eta``.

        The vector whose squares :meth:`cost` sums (its SSE memoised the same way):
        every coefficient re-solved, weighted as the search is.
        """
        d = design(self.data, self.spec.with_(self.name, eta), self.model,
                   weights=self.weights)
        th, sse = solve_gram(d.gram(self.rows), d.bounds)
        self.seen.setdefault(_freeze(eta), sse)
        r = d.y - d.X @ th
        return r if self.rows is None else r[self.rows]

    def coefficients(self, eta: Mapping) -> dict:
        """Return the fitted values of the spec with the term at ``eta``."""
        s = self.spec.with_(self.name, eta)
        d = design(self.data, s, self.model, weights=self.weights)
        th, _ = solve_gram(d.gram(self.rows), d.bounds)
        return values_of(s, d.labels, th)

    def base_fit(self) -> tuple[dict, np.ndarray, np.ndarray]:
        """Return the fitted values of the spec without the term, its residual and x."""
        d = design(self.data, self.base, self.model, weights=self.weights)
        th, _ = solve_gram(d.gram(self.rows), d.bounds)
        r = d.y - d.X @ th
        x = d.view.gather(lambda p, mo: mo.x)
        if self.rows is not None:
            r, x = r[self.rows], x[self.rows]
        return values_of(self.base, d.labels, th), r, x

    # -- the procedure ---------------------------------------------------------------
    def starts(self, eta0: Mapping) -> list[dict]:
        """Return the start points: the term's own from the residual, else the grid.

        A start that already holds every parameter (the term's optimum in the previous
        round of a selection) joins the grid as one more trial.
        """
        warm = [dict(eta0)] if self.holds_all(eta0) else []
        vals, r, x = self.base_fit() if self._needs_base() else ({}, None, None)
        eta0 = self.term.derive(eta0, vals) if vals else dict(eta0)
        if r is not None:
            own = self.term.initial(self.data.summary, context(self.spec, self.data), (x, r))
            if own:
                return warm + [dict(eta0, **e) for e in own]
        grids = [(p.name, p.grid) for p in self.space.values() if p.grid]
        if not grids:
            return warm or [dict(eta0)]
        out = list(warm)
        for combo in itertools.product(*[g for _, g in grids]):
            e = dict(eta0)
            for (n, _), v in zip(grids, combo):
                e[n] = tuple(v) if isinstance(v, tuple) else float(v)
            out.append(e)
        return out

    def holds_all(self, eta: Mapping) -> bool:
        """Whether ``eta`` gives every searched parameter (a start of its own)."""
        return bool(self.space) and all(p in eta for p in self.space)

    def _needs_base(self) -> bool:
        t = type(self.term)
        return t.initial is not Term.initial or t.derive is not Term.derive

    def run(self, eta0: Mapping, *, stop_above: Bar | Sequence[Bar] = math.inf,
            refine: bool = True, local: bool = False) -> dict:
        """Return the best nonlinear parameters found (see the module docstring).

        When even the best start is above ``stop_above`` (a screened candidate that
        cannot pay), it is returned without the local search.  Several bars are tried
        in turn, a function returning one only when the best start is at or below
        every bar before it (the cheap bars first).  ``refine=False`` leaves out the growth
        and polish of vector parameters; ``local=True`` starts from ``eta0`` alone when
        it holds every parameter (a term's optimum in a model that changed a little),
        not from the grid.
        """
        trials = [dict(eta0)] if local and self.holds_all(eta0) else self.starts(eta0)
        costs = [self.cost(e) for e in trials]
        i = int(np.argmin(costs))
        eta = trials[i]
        bars = stop_above if isinstance(stop_above, (tuple, list)) else (stop_above,)
        if any(costs[i] > (b() if callable(b) else b) for b in bars):
            return eta
        if not self.term.nonlinear(eta):
            # a structure without continuous parameters (the knots of a friction along
            # the travel): only its order is chosen
            lo, hi = self.term.orders(self.data.summary, eta)
            return self._order(eta, lo, hi) if hi > lo else eta
        vector = [p for p in self.space.values() if p.vector]
        if vector:
            return self._vector(eta, vector[0], refine)
        eta = self._local(eta, trials, costs)
        lo, hi = self.term.orders(self.data.summary, eta)
        if hi > lo:
            best = self._order(eta, lo, hi)
            if self.term.order_of(best) != self.term.order_of(eta):
                eta = self._local(best, [best], [self.cost(best)])
        return eta

    def _local(self, eta: dict, trials: Sequence[dict], costs: Sequence[float]) -> dict:
        free = [(n, j) for n, j, _ in self.term.nonlinear(eta)]
        params = [self.space[n] for n, _ in free]
        if len(free) == 1 and free[0][1] is None:
            p = params[0]
            v0 = float(eta[p.name])
            br = self.term.bracket(v0, self.data.summary)
            if br is None:
                grid = sorted({float(e[p.name]) for e in trials})
                k = grid.index(v0) if v0 in grid else 0
                br = (grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)])
            lo, hi = (_to(p, max(br[0], p.lo)), _to(p, min(br[1], p.hi)))
            if not hi > lo:
                return eta
            xatol = p.tol or (0.01 if p.log else 1e-6 * abs(v0))
            opt = brent_bounded(lambda q: self.cost(dict(eta, **{p.name: _from(p, q)})),
                                lo, hi, xatol=xatol)
            new = dict(eta, **{p.name: _from(p, float(opt.x))})
            return new if self.cost(new) <= self.cost(eta) else eta
        q0 = np.array([_to(p, float(eta[p.name])) for p in params])

        def unpack(q: np.ndarray) -> dict:
            return dict(eta, **{p.name: _from(p, float(v)) for p, v in zip(params, q)})
        f0 = self.cost(eta)
        opt = _least_squares(lambda q: self.residual(unpack(q)), q0, params, xatol=1e-3,
                             fatol=1e-9 * f0)
        new = unpack(opt.x)
        return new if self.cost(new) <= f0 else eta

    def _order(self, eta: dict, lo: int, hi: int) -> dict:
        # every count: the criterion is not unimodal in it (joint100's friction along
        # the travel: odd knot counts 5 / 9 / 13 at BIC +7.4 / +0.1 / 0, the even ones
        # between 17-57 above), so a ladder of counts refined around its best missed 13
        n_eff = _n_eff(self.data, self.rows)
        sse = self._likelihood_sse(eta)
        best = None
        for k in range(lo, hi + 1):
            e = self.term.with_order(eta, k)
            s = sse(e)
            crit = n_eff * math.log(max(s, 1e-300)) + 2 * k * math.log(n_eff)
            if best is None or crit < best[0]:
                best = (crit, e)
        return best[1]

    def _likelihood_sse(self, eta: dict) -> Callable[[dict], float]:
        """Return the SSE an information criterion judges orders of the term by.

        The criterion is a likelihood: with the residual variance of ``eta``'s fit
        differing between speed bands by more than :data:`.bands.WEIGHT_CONTRAST`, the
        plain SSE is not one, and the rows at the turns choose the order (bench60's
        Coulomb + viscous + ripple: residual variance 163× the median band's at the
        turns, one harmonic planted, six chosen on the plain SSE at BIC −196 against
        one, whose five extra amplitudes came out 0.0003–0.002 N once weighted).  So
        each order is then judged by its sum of squares weighted by band (feasible GLS,
        :class:`.bands.SpeedBands`): the likelihood up to one common scale.  Not for a
        term whose evidence is where the weights would suppress it, nor inside a
        weighted search (whose cost is weighted already).
        """
        if self.weights is not None or self.term.evidence & PROTECTED:
            return self.cost
        d = design(self.data, self.spec.with_(self.name, eta), self.model)
        th, _ = solve_gram(d.gram(self.rows), d.bounds)
        e = d.y - d.X @ th
        speed = self.data.at().signal(Signal.VELOCITY)
        if self.rows is not None:
            e, speed = e[self.rows], speed[self.rows]
        bands = SpeedBands.of(speed, e)
        if bands is None or bands.contrast < WEIGHT_CONTRAST:
            return self.cost
        sw = np.sqrt(bands.row_weights(speed))

        def weighted(trial: dict) -> float:
            dt = design(self.data, self.spec.with_(self.name, trial), self.model)
            Z = np.column_stack(dt.cols + [dt.y])    # not via dt.X: one stack, not two
            if self.rows is not None:
                Z = Z[self.rows]
            Z *= sw[:, None]
            return solve_gram(Z.T @ Z, dt.bounds)[1]
        return weighted

    # -- vector parameters -------------------------------------------------------------
    def _vector(self, eta: dict, vp: Param, refine: bool) -> dict:
        # the family's scale with every declared scalar (a flat direction costs a few
        # evaluations; the path through it decides which of the rugged basins is found)
        scalars = [(p.name, p) for p in self.space.values() if not p.vector]
        f0 = self.cost(eta)

        # the common scale keeps the vector's median within the bounds (the family's
        # shortest element may start below the resolution; freeing them clips each)
        # (searched on the log of the median: Nelder–Mead's first simplex is 5 % of
        # each coordinate, so a coordinate that starts at 0 would barely move)
        med = float(np.median(eta[vp.name]))

        def unpack(q: np.ndarray) -> dict:
            s = math.exp(float(np.clip(q[0], _to(vp, vp.lo), _to(vp, vp.hi)))) / med
            e = dict(eta, **{vp.name: tuple(v * s for v in eta[vp.name])})
            for (n, p), v in zip(scalars, q[1:]):
                e[n] = _from(p, float(v))
            return e
        q0 = np.array([math.log(med)] + [_to(p, float(eta[n])) for n, p in scalars])
        opt = _nelder_mead(lambda q: self.cost(unpack(q)), q0, xatol=2e-2, fatol=1e-6 * f0,
                           maxiter=30, resolution=self._resolution(f0))
        if opt.fun < f0:
            eta = unpack(opt.x)
        eta = self._prune(eta, vp)
        if refine:
            eta = self._polish(self._grow(self._free(eta, vp), vp), vp)
        return eta

    def _levels(self, eta: dict) -> list[float]:
        """Return the fitted coefficients of the term's own columns (one per element)."""
        sp = self.spec.with_(self.name, eta)
        d = design(self.data, sp, self.model, weights=self.weights)
        th, _ = solve_gram(d.gram(self.rows), d.bounds)
        return [float(v) for lab, v in zip(d.labels, th) if lab[0] == self.name]

    def _prune(self, eta: dict, vp: Param) -> dict:
        """Drop elements whose coefficient ends at its bound (zero: no friction)."""
        while len(eta[vp.name]) > 1:
            levels = self._levels(eta)
            worst = int(np.argmin(levels))
            if levels[worst] > 0.0:
                break
            eta = dict(eta, **{vp.name: tuple(v for j, v in enumerate(eta[vp.name])
                                              if j != worst)})
        return eta

    def _free(self, eta: dict, vp: Param) -> dict:
        """Free every element (and the free scalars); prune; drop what does not pay."""
        m = len(eta[vp.name])
        scalars = [(n, self.space[n]) for n, j, _ in self.term.nonlinear(eta)
                   if j is None and n in self.space]

        def unpack(q: np.ndarray) -> dict:
            e = dict(eta, **{vp.name: tuple(sorted(_from(vp, float(v)) for v in q[:m]))})
            for (n, p), v in zip(scalars, q[m:]):
                e[n] = _from(p, float(v))
            return e
        q0 = np.array([_to(vp, float(v)) for v in eta[vp.name]]
                      + [_to(p, float(eta[n])) for n, p in scalars])
        f0 = self.cost(eta)
        opt = _nelder_mead(lambda q: self.cost(unpack(q)), q0, xatol=1e-2, fatol=1e-6 * f0,
                           maxiter=60 * len(q0), resolution=self._resolution(f0))
        if not opt.fun < f0:
            return eta
        return self._drop(self._prune(unpack(opt.x), vp), vp)

    def _drop(self, eta: dict, vp: Param) -> dict:
        """Drop elements that do not pay for their distance and level (BIC, repeated)."""
        n_eff = _n_eff(self.data, self.rows)
        sse = self.cost(eta)
        while len(eta[vp.name]) > 1:
            best = None
            for j in range(len(eta[vp.name])):
                e = dict(eta, **{vp.name: tuple(v for i, v in enumerate(eta[vp.name])
                                                if i != j)})
                s1 = self.cost(e)
                d = bic(n_eff, sse, s1, -2)
                if best is None or d < best[0]:
                    best = (d, e, s1)
            if best[0] >= 0:
                break
            _, eta, sse = best
        return eta

    def _grow(self, eta: dict, vp: Param) -> dict:
        """Grow the elements the term proposes while each pays (BIC, two parameters)."""
        n_eff = _n_eff(self.data, self.rows)
        sse = self.cost(eta)
        while len(eta[vp.name]) < vp.vector:
            prop = self.term.grow(eta)
            if prop is None or min(prop[vp.name]) < vp.lo:
                break
            trial = self._free(prop, vp)
            k = len(trial[vp.name]) - len(eta[vp.name])
            s1 = self.cost(trial)
            # an element the search pushes to the resolution floor is no curve the run
            # resolves: a stick
            if k <= 0 or min(trial[vp.name]) <= 1.05 * vp.lo or bic(n_eff, sse, s1, 2 * k) >= 0:
                break
            eta, sse = trial, s1
        return eta

    def _polish(self, eta: dict, vp: Param) -> dict:
        """Refine each element, one at a time: a scan over 0.22–4.5×, then Brent, twice.

        The free search stops at about 1 % and can sit in a local minimum where one
        element is off by a factor: a pre-sliding curve's residual is steep and rugged
        in its distances (an element 2.4 % long doubled the NRMSE on the independent
        generator).
        """
        d = list(eta[vp.name])
        lo_q, hi_q = _to(vp, vp.lo), _to(vp, vp.hi)

        def with_d(ds: list) -> dict:
            return dict(eta, **{vp.name: tuple(sorted(ds))})
        best = self.cost(with_d(d))
        steps = np.linspace(-1.5, 1.5, 13)
        h = float(steps[1] - steps[0])
        for _ in range(2):
            improved = False
            for j in range(len(d)):
                def cost(q: float, j: int = j) -> float:
                    trial = list(d)
                    trial[j] = math.exp(q)
                    return self.cost(with_d(trial))
                # an element outside the declared domain (a start beyond it) is
                # searched from the domain's nearest end
                q0 = min(max(_to(vp, d[j]), lo_q), hi_q)
                grid = [q for q in q0 + steps if lo_q <= q <= hi_q] or [q0]
                vals = [cost(q) for q in grid]
                qb = grid[int(np.argmin(vals))]
                cand = [(float(min(vals)), qb)]
                a, b = max(qb - h, lo_q), min(qb + h, hi_q)
                if b > a:
                    opt = brent_bounded(cost, a, b, xatol=1e-4)
                    cand.append((float(opt.fun), float(opt.x)))
                f, q = min(cand)
                if f < best * (1.0 - 1e-9):
                    best, d[j], improved = f, math.exp(q), True
            d = sorted(d)
            if not improved:
                break
        return with_d(d)


def _freeze(eta: Mapping) -> tuple:
    return tuple(sorted((k, tuple(v) if isinstance(v, (tuple, list)) else v)
                        for k, v in eta.items()))


def search(data: Dataset, spec: Spec, name: str, model: AxisModel | None,
           rows: np.ndarray | None = None, *, stop_above: Bar | Sequence[Bar] = math.inf,
           refine: bool = True, weights: SpeedWeights | None = None,
           local: bool = False) -> dict:
    """Return the nonlinear parameters of ``name`` in ``spec`` fitted on ``rows``."""
    s = Search(data, spec, name, model, rows, weights)
    return s.run(spec.of(name), stop_above=stop_above, refine=refine, local=local)


def refine_structure(data: Dataset, spec: Spec, name: str, model: AxisModel | None,
                     rows: np.ndarray | None = None) -> dict:
    """Free, grow and polish a vector parameter of ``name`` (a candidate past the screen).

    The screen scores a vector parameter at its family's fit (one common scale); only a
    candidate that passes it gets the search of every element.
    """
    s = Search(data, spec, name, model, rows)
    vector = [p for p in s.space.values() if p.vector]
    eta = spec.of(name)
    if not vector:
        return eta
    vp = vector[0]
    return s._polish(s._grow(s._free(eta, vp), vp), vp)


def fold_trials(data: Dataset, spec: Spec, name: str, eta_all: Mapping) -> list[dict]:
    """Return the values each fold chooses among: the grid and the all-data neighbourhood.

    The neighbourhood is the Cartesian product of each free parameter's declared steps
    around the all-data value (a vector parameter by a common factor), and one order
    up and down for a term with a structural order; the in-fold choice is then not
    bound to the grid.
    """
    t = TERMS[name]
    ctx = context(spec.with_(name, eta_all), data)
    space = {p.name: p for p in t.space(data.summary, ctx)}

    def value(v: Any) -> Any:
        return tuple(v) if isinstance(v, (tuple, list)) else float(v)
    out = []
    grids = [(p.name, p.grid) for p in space.values() if p.grid]
    if grids:
        for combo in itertools.product(*[g for _, g in grids]):
            out.append(dict(eta_all, **{n: value(v) for (n, _), v in zip(grids, combo)}))
    free = {n for n, _, _ in t.nonlinear(eta_all)}
    axes = []
    for p in space.values():
        if p.name not in free:
            continue
        v = eta_all[p.name]
        if p.vector:
            axes.append([(p.name, tuple(p.clip(e * math.exp(st)) for e in v))
                         for st in (p.steps or (0.0,))])
            continue
        own = t.fold_steps(float(v), data.summary)
        if own is not None:
            axes.append([(p.name, p.clip(x)) for x in own])
        else:
            axes.append([(p.name, _from(p, _to(p, float(v)) + st))
                         for st in (p.steps or (0.0,))])
    near = [dict(eta_all, **dict(combo)) for combo in itertools.product(*axes)]
    lo, hi = t.orders(data.summary, eta_all)
    if hi > lo and not any(p.vector for p in space.values()):
        k = t.order_of(eta_all)
        near += [t.with_order(e, k + dk) for e in list(near) for dk in (-1, 1)
                 if lo <= k + dk <= hi]
    uniq: dict = {}
    for e in out + near:
        uniq.setdefault(_freeze(e), e)
    return list(uniq.values())


__all__ = ['Search', 'fold_trials', 'refine_structure', 'search', 'searched', 'vp_sse']
