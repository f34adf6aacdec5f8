"""A spec fitted on all rows: the model, its parameters, uncertainties and held-out score.

:class:`CandidateResult` is one candidate effect scored by the selection and fitted in.

:func:`estimate` is the one place a design becomes a result: bounded least squares on
all rows, the held-out score over the validation folds, the jackknife covariance and
the reported parameters with their standard errors (:mod:`.uncertainty`), the model-file
form (:func:`.library.encode`), and what the fit says about itself — coefficients that
ended on a declared bound, and values outside a term's declared domain.

The standard errors and correlations are computed when first read (:class:`Lazy`): a
selection fits every candidate of every round and reads them for the few it reports or
whose admissibility depends on them (the ball-screw's ``fit --auto`` makes 62 estimates;
their Jacobians and jackknives were 0.2 s of it).  Read or not, they are the same numbers.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Generic, Mapping, TypeVar

import numpy as np

from motor_comp.physics.axis import AxisKind, AxisModel, Units
from motor_comp.physics.effects import TERMS
from motor_comp.workbench.bands import SpeedWeights
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.library import Spec, context, design, encode, n_params, values_of
from motor_comp.workbench.lsq import solve_gram
from motor_comp.workbench.uncertainty import block_sandwich, correlations, jacobian, \
    sandwich, scalars_of, standard_errors
from motor_comp.workbench.heldout import cv_design
from motor_comp.workbench.wording import MASS, REFIT, ROTARY_UNITS, TITLES, fmt_param, more_words


T = TypeVar('T')


class Lazy(Generic[T]):
    """A value computed by ``make()`` when first read, then kept (:meth:`get`)."""

    __slots__ = ('_make', '_value', '_done')

    def __init__(self, make: Callable[[], T]) -> None:
        self._make = make
        self._done = False

    @classmethod
    def of(cls, value: T) -> 'Lazy[T]':
        """Return a :class:`Lazy` already holding ``value``."""
        out = cls(lambda: value)
        out._value, out._done = value, True
        return out

    def get(self) -> T:
        """Return the value (computed on the first call)."""
        if not self._done:
            self._value = self._make()
            self._done = True
            self._make = None          # what it closed over is no longer needed
        return self._value


@dataclasses.dataclass(frozen=True)
class Estimate:
    """A spec fitted on all rows, with its held-out score and uncertainties.

    Parameters
    ----------
    spec : Spec
        Effects and nonlinear parameters.
    model : AxisModel
        The fitted model (model-file form).
    values : dict
        ``{(term, label): value}`` of every coefficient and free nonlinear parameter.
    scalars : dict[str, dict[str, float]]
        Reported physical parameters per effect (and ``mass``).
    at_bound : dict[str, list[str]]
        Coefficients the estimator held on a declared bound (``fc ≥ 0`` …).
    at_limit : dict[str, list[str]]
        Those held on a declared upper limit: the data want the effect beyond what the
        term declares physical (a fit there is not that effect).
    sse_cv, sse_fit : float
        Held-out and in-sample sums of squared residuals [N²].
    n_params : int
        Fitted parameters (linear and nonlinear).
    nrmse_cv : float
        Held-out force NRMSE.
    inadmissible : dict[str, str]
        Why a term's fitted values lie outside its declared domain, per term.
    details : Lazy
        ``(se, correlations)``, computed when first read: see :attr:`se` and
        :attr:`correlations`.
    """

    spec: Spec
    model: AxisModel
    values: dict
    scalars: dict
    at_bound: dict
    sse_cv: float
    sse_fit: float
    n_params: int
    nrmse_cv: float
    inadmissible: dict = dataclasses.field(default_factory=dict)
    at_limit: dict = dataclasses.field(default_factory=dict)
    details: Lazy = dataclasses.field(default_factory=lambda: Lazy.of(({}, [])),
                                      compare=False, repr=False)

    @property
    def se(self) -> dict:
        """Standard errors of :attr:`scalars` (stretch jackknife + delta method)."""
        return self.details.get()[0]

    @property
    def correlations(self) -> list:
        """Strongly correlated parameter pairs ``(group.name, group.name, ρ)``."""
        return self.details.get()[1]


def estimate(data: Dataset, spec: Spec, model: AxisModel, *, cv: bool = True,
             weights: SpeedWeights | None = None) -> Estimate:
    """Fit ``spec`` on all rows: θ, covariance, reported parameters, model, score."""
    d = design(data, spec, model, weights=weights)
    th, sse_fit = solve_gram(d.gram(), d.bounds)
    vals = values_of(spec, d.labels, th)
    sc = scalars_of(spec, vals, data)

    def uncertainty() -> tuple[dict, list]:
        jac = jacobian(data, spec, model, weights)
        se = standard_errors(spec, dict(jac.values), jac.labels,
                             sandwich(data, jac.J, jac.e), data)
        return se, correlations(block_sandwich(data, jac.J, jac.e), jac.labels)
    unc = Lazy(uncertainty)
    at_bound: dict[str, list[str]] = {}
    at_limit: dict[str, list[str]] = {}
    for lab, hit, v, hi in zip(d.labels, d.bounds.at_bound(th), th, d.bounds.hi):
        if hit:
            at_bound.setdefault(lab[0], []).append(lab[1])
            if np.isfinite(hi) and abs(v - hi) <= 1e-9 * max(abs(hi), 1.0):
                at_limit.setdefault(lab[0], []).append(lab[1])
    sse_cv = cv_design(data, spec, model, weights)[0] if cv else float('nan')
    nr = math.sqrt(sse_cv / data.den) if data.den > 0 and np.isfinite(sse_cv) else float('nan')
    why = {}
    for n in spec.names:
        reason = TERMS[n].admissible(vals, spec.of(n), data.summary) or \
            _unresolved(data, spec, n, lambda: unc.get()[0])
        if reason:
            why[n] = reason
        elif n in at_limit:
            why[n] = (f'{", ".join(at_limit[n])} at the limit the effect declares physical: '
                      'the data want it beyond what it can be')
    return Estimate(spec=spec, model=encode(spec, vals, model), values=vals, scalars=sc,
                    at_bound=at_bound, sse_cv=sse_cv, sse_fit=sse_fit,
                    n_params=n_params(spec), nrmse_cv=nr, inadmissible=why,
                    at_limit=at_limit, details=unc)


def _unresolved(data: Dataset, spec: Spec, name: str, se: Callable[[], Mapping]) -> str:
    """Return why ``name`` is not resolved: a parameter within 2 SE of what the run resolves.

    ``se()`` returns the standard errors (called only for a parameter that declares it
    must be resolved and is not at its least value already).
    """
    eta = spec.of(name)
    for p in TERMS[name].space(data.summary, context(spec, data)):
        if not p.resolved or p.vector or p.name not in eta:
            continue
        v = float(eta[p.name])
        near = v <= p.lo * (1.0 + 1e-6)
        if not near:
            s = se().get(name, {}).get(p.name, float('nan'))
            near = math.isfinite(s) and v - 2.0 * s <= p.lo
        if near:
            return (f'{p.name} {v:.3g} is within two standard errors of the least this run '
                    f'resolves ({p.lo:.3g})')
    return ''


def replace(est: Estimate, **changes: Any) -> Estimate:
    """Return ``est`` with some fields changed (a frozen dataclass)."""
    return dataclasses.replace(est, **changes)


@dataclasses.dataclass(frozen=True)
class CandidateResult:
    """One candidate's held-out score and its joint fit on all data.

    Parameters
    ----------
    effect : str
        Vocabulary name, ``'mass'`` (only the mass was wrong) or ``'refit'``.
    explained : float
        Held-out fraction of the refitted baseline's residual energy removed.
    force_nrmse : float
        Held-out force NRMSE with the candidate.
    params : dict
        Physical parameters of the effect (model-file form, SI).
    scalars : dict[str, float]
        Reported parameters.
    n_params : int
        Parameters it adds.
    bic_delta : float
        Held-out BIC change (< 0 pays for the parameters).
    supported : bool
        Whether it pays for its parameters.
    model : AxisModel
        The jointly refitted model with the candidate.
    details : Lazy
        ``(uncertainty, changes, correlations)``, computed when first read: the
        reported parameters' standard errors, the parameters of the model that moved
        significantly in the joint refit (:class:`~.wording.ParameterChange`), and
        strongly correlated pairs (:attr:`uncertainty`, :attr:`changes`,
        :attr:`correlations`).
    why_not : str
        Why it is outside its declared domain ('' when inside).
    base_nrmse : float
        Held-out force NRMSE of the model it joins, on the same rows as ``force_nrmse``.
    stops : bool
        Whether it is judged on the rows that reach the stops (a term with its evidence
        at the turns), not on the sliding rows the model without it is judged on.
    """

    effect: str
    explained: float
    force_nrmse: float
    params: dict
    scalars: dict
    n_params: int
    bic_delta: float
    supported: bool
    model: AxisModel
    details: Lazy = dataclasses.field(default_factory=lambda: Lazy.of(({}, (), ())),
                                      compare=False, repr=False)
    units: Units = Units.of(AxisKind.LINEAR)
    spec: Any = None
    at_bound: bool = False
    why_not: str = ''
    estimate: Any = None
    base_nrmse: float = float('nan')
    stops: bool = False

    @property
    def uncertainty(self) -> dict:
        """Standard errors of :attr:`scalars`."""
        return self.details.get()[0]

    @property
    def changes(self) -> tuple:
        """Parameters of the model that moved significantly in the joint refit."""
        return self.details.get()[1]

    @property
    def correlations(self) -> tuple:
        """Strongly correlated parameter pairs of the joint refit."""
        return self.details.get()[2]

    @property
    def title(self) -> str:
        """Human name of the candidate."""
        return TITLES.get(self.effect, self.effect)

    def sentence(self, *, rotary: bool | None = None) -> str:
        """Return the finding in plain words, e.g. 'force ripple, period 7.25 mm, …'."""
        u = ROTARY_UNITS if rotary else self.units
        if self.effect in (MASS, REFIT):
            what = '; '.join(ch.sentence(u) for ch in self.changes) or 'parameters refitted'
            body = f'{self.title}: {what}'
        else:
            parts = [fmt_param(self.effect, k, v, self.uncertainty.get(k), u)
                     for k, v in self.scalars.items()]
            parts.append(more_words(self.effect, self.model, u))
            body = f'{self.title}, {", ".join(p for p in parts if p)}'
        verdict = ''
        if self.supported and self.why_not:
            verdict = f' ({self.why_not})'
        elif not self.supported:
            verdict = (f' (not supported: {self.why_not})' if self.why_not else
                       ' (not supported: does not pay for its parameters on held-out data)')
        return f'{body}, removes {100 * self.explained:.0f} % of the residual{verdict}'

    def as_dict(self) -> dict[str, Any]:
        """Return the JSON form (DESIGN.md §6 ``candidates`` entry)."""
        return {'effect': self.effect, 'title': self.title,
                'explained': float(self.explained), 'force_nrmse': float(self.force_nrmse),
                'base_force_nrmse': float(self.base_nrmse),
                'rows': 'stops' if self.stops else 'sliding',
                'params': self.params, 'uncertainty': self.uncertainty,
                'n_params': self.n_params, 'bic_delta': float(self.bic_delta),
                'supported': bool(self.supported), 'summary': self.sentence(),
                'changes': [ch.as_dict() for ch in self.changes],
                'model': self.model.to_dict()}


__all__ = ['CandidateResult', 'Estimate', 'Lazy', 'estimate', 'replace']
