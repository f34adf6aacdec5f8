"""Which effects the data show: stepwise selection by principle, never by effect name.

``../shared/IDENTIFICATION.md`` §3 on the term library of :mod:`.library`:

* **H0 is the current model refitted** (its nonlinear parameters re-searched).
* **Candidates** are the terms a run can judge: their declared needs met (reversals,
  both directions, an axis kind), what they require present, what they exclude absent.
* **Pays** — a candidate is supported when, on held-out folds, it removes at least
  ``min_gain`` of the residual, improves the held-out BIC, and lowers the force NRMSE,
  down to the noise floor (:mod:`.floor`: what a perfect model would leave on this
  run), by what matters: ``min_drop`` of the drive force — or half the floor when that
  is smaller and the term removes most (:data:`MOST_OF_EXCESS`) of what the model
  leaves above the floor.  A fall below the floor does not count: it is what the
  processing leaves at the turns, fitted.  A floor at or above what the model being
  extended leaves on the run is no floor of this run (its twin departed from it: a
  force-input axis without viscous friction runs away on its own run): it is left out,
  and the fall must reach ``min_drop``.  A candidate judged on the rows that reach
  the stops must also explain more of the run, by ``min_gain``, than of the model's own
  twin (the floor's run of the model without it, processed alike): what it explains
  there is the processing's (a GMS on a hard-braking run without pre-sliding explained
  59 % of the twin and 46 % of the run; on runs with it, 4–5 % and 100 %).  So on a
  clean run a dead time of a fraction of a millisecond that is most of what is left
  pays, far from the floor a flexible term taking a small bite of a structure the
  library lacks does not, and nothing pays once the model is within
  :data:`~.scan.NEAR_FLOOR` times its floor — where the scan calls it complete unless
  a structure stands — unless the run refutes the floor: a term that removes most of
  the residual itself on held-out rows (:data:`MOST_OF_EXCESS` of it, not only of its
  excess over the floor) beyond the share it removes of the model's own twin (what the
  floor's run leaves is noise and the processing's, which the term would take there
  too) takes what the floor only seemed to hold (a load friction of mu 0.036 on a
  braking chirp: 54 % of a residual 1.41× the floor, none of the twin's; a stand-in
  backlash on a chirp without one: 73 % of the run's, but 62 % of the twin's).  It is
  judged on the sliding rows only, where the twin replicates the run.  Its
  fitted values must lie in the term's declared domain (one fitted outside it is
  scored at its all-data fit, not chosen again in each fold: nothing it explains could
  make it pay), and bounds hold inside the estimator.  Work whose only use is a
  verdict is not done where no verdict could turn on it: a candidate whose all-data
  share is below half the least held-out share any term could pay with in its round
  (:meth:`Engine.least_share`: ``min_gain``, or most of the residual once the model is
  within its floor's reach, or nothing on rows where the run cannot refute the floor)
  is scored at its all-data fit, and its local search stops at the starts.
* **Forward** adds the supported candidate with the best held-out BIC — or the first of
  two simpler ones that together beat a flexible one with its own best simpler
  follow-up (two steps against two); when none pays alone, two strong ones that pay
  together are looked for (**look-ahead**, both in :mod:`.lookahead`); after an
  addition the other terms' nonlinear parameters are searched again (**re-search**) and
  every term whose removal no longer hurts is dropped (**backward**), or replaced by a
  term its columns contain (an offset inside a spring's constant) when its own extra
  parameters are within two standard errors of zero.  On the final model each removal
  is judged once more against the smaller model with every other term searched again,
  structures too (**prune**; both in :mod:`.elimination`).
* **Reweighting**: when the residual variance differs between speed bands by more than
  :data:`.reweight.WEIGHT_CONTRAST`, the final parameters are re-estimated by weighted least
  squares (feasible GLS) — unless a term of the model has its evidence at the turns,
  which the weights would suppress; a sliding term that then pays only through the
  turns is dropped, and so is one whose shape parameter sits within two standard
  errors of the value at which it vanishes.

Where today's rules came from (issue 22): a rotary spring over a revolution — the
spring's declared need; "an asymmetry within 2 SE tried as an offset" and "a spring
tried as an offset" — the nested replacement above (a term whose columns contain
another's); the reweighting skipping Stribeck, GMS and backlash — their declared
evidence at the turns; "delay, backlash and GMS pay below the 1 % force threshold if
their relative SE is under 5/5/25 %" — the noise floor, which replaced that threshold
for every effect; "GMS only when
its longest distance exceeds 2·a₉₀·dt²" — the pre-sliding term's declared domain;
bounds clipped after scoring — bounds inside the estimator (:mod:`.lsq`); Coulomb kept
while Stribeck or GMS need it — their declared requirement; pre-sliding and backlash
exclusive — their declared exclusion.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Sequence

import numpy as np

from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisKind, AxisModel
from motor_comp.physics.effects import TERMS
from motor_comp.workbench.dataset import Dataset, model_signature
from motor_comp.workbench.floor import Floor, noise_floor
from motor_comp.workbench.scan import NEAR_FLOOR
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.library import Spec, candidates, given_sse, n_params, \
    processing_for, spec_key, spec_of
from motor_comp.workbench.lookahead import pair, simpler
from motor_comp.workbench.lsq import bic
from motor_comp.workbench.result import CandidateResult, Estimate, Lazy, estimate
from motor_comp.workbench.elimination import Step, backward, prune, vector as _vector
from motor_comp.workbench.heldout import cv_candidate, cv_design
from motor_comp.workbench.varpro import refine_structure, search
from motor_comp.workbench.wording import MASS, REFIT, ParameterChange, axis_units, \
    common_scale, model_scalars, params_text, scale_forces, significant_changes

#: share of the residual above the noise floor a term must remove for the floor, not
#: ``min_drop``, to set how far the NRMSE must fall
MOST_OF_EXCESS = 0.5


@dataclasses.dataclass(frozen=True)
class Verdicts:
    """Candidates scored in the forward rounds: each round's results by the model's terms.

    The last round may have been scored on terms the model no longer has (one added,
    then removed again): the verdicts on the final terms are those of the last round
    scored on exactly them.
    """

    rounds: dict = dataclasses.field(default_factory=dict)

    def on(self, spec: Spec) -> dict:
        """Return the results of the last round scored on ``spec``'s terms, else none."""
        return self.rounds.get(tuple(spec.names), {})

    def with_round(self, names: Sequence[str], results: dict) -> 'Verdicts':
        """Return these verdicts with a round scored on ``names`` (replacing an older one)."""
        return Verdicts({**self.rounds, tuple(names): results})


class Engine:
    """Shared state of one diagnose/fit session: the data, H0 and the scoring rule."""

    def __init__(self, kins: Sequence[Kinematics], model: AxisModel, *, folds: int,
                 min_gain: float, min_drop: float = 0.01, rotary: bool = False) -> None:
        if folds < 2:
            raise ParameterError(f'folds must be >= 2, got {folds}')
        if not 0.0 <= min_gain < 1.0:
            raise ParameterError(f'min_gain must be in [0, 1), got {min_gain}')
        if rotary and not model.units.rotary:
            model = model.replace(axis=AxisKind.ROTARY)
        self.kins = list(kins)
        self.model = model
        self.units = axis_units(model, rotary)
        self.folds = folds
        #: the fitted samples of every model but those whose evidence is at the stops
        self.data = Dataset(self.kins, model, folds=folds)
        #: the datasets of specs judged with another processing, by that processing
        self._other: dict = {}
        D = self.data
        if D.n < folds * 8:
            raise ParameterError(f'{kins[0].name}: only {D.n} samples in motion, too few to '
                                 'identify anything: the axis barely moves; record motion '
                                 'over the travel at several speeds')
        self.min_gain, self.min_drop = float(min_gain), float(min_drop)
        #: the candidates of each forward round, by the terms they were scored on
        self.verdicts = Verdicts()
        self._floors: dict = {}
        #: the floors' anchored runs of the models, by run and model (kins live as long)
        self._runs: dict = {}
        self._placebos: dict = {}
        self._warm: dict = {}
        #: candidates scored, by the spec they were scored on and their name (:meth:`score`)
        self._scored: dict = {}
        #: models after a term joined and the others were searched again (:meth:`joined`)
        self._joined: dict = {}
        #: the least held-out share that could pay, by spec and rows (:meth:`_least_share`)
        self._least: dict = {}
        #: the given model on the rows it is judged on (the figure ``compare`` reports)
        self.given_data = self.data_for(spec_of(model))
        self.sse_given = given_sse(self.given_data, model)
        self.nrmse_given = self.nrmse(self.sse_given, self.given_data)
        f = D.at().y()
        acc = D.at().signal(_acc())
        self.mass_excited = bool(model.mass * np.sqrt(np.mean(acc ** 2))
                                 > 0.01 * np.sqrt(np.mean((f - f.mean()) ** 2)))

    def data_for(self, spec: Spec) -> Dataset:
        """Return the dataset ``spec`` is judged on (its terms' processing, one per kind)."""
        proc = processing_for(spec)
        if proc == self.data.processing:
            return self.data
        hit = self._other.get(proc)
        if hit is None:
            hit = self._other[proc] = Dataset(self.kins, self.model, folds=self.folds,
                                              processing=proc)
        return hit

    @property
    def summary(self) -> Any:
        """The data's :class:`~motor_comp.physics.effects.identification.Summary`."""
        return self.data.summary

    def nrmse(self, sse: float, data: Dataset | None = None) -> float:
        """Return the force NRMSE of a sum of squared residuals over ``data``'s rows."""
        den = (data or self.data).den
        return math.sqrt(sse / den) if den > 0 else float('inf')

    def _floor(self, est: Estimate, D: Dataset, bar: bool) -> Floor:
        """Return :func:`.floor.noise_floor` of ``est``'s model on ``D`` (cached)."""
        key = (id(D), model_signature(est.model), bar)
        hit = self._floors.get(key)
        if hit is None:
            hit = self._floors[key] = noise_floor(D, est.model, sensor_share=False, bar=bar,
                                                  runs=self._runs)
        return hit

    def floor_sse(self, est: Estimate, data: Dataset | None = None) -> float:
        """Return the SSE the noise floor of ``est``'s model leaves on its rows (cached).

        ``data``: other rows to judge it on (a candidate's that reach the stops: the
        floor there is the turns' too).  This is the selection's bar
        (:func:`.floor.noise_floor` with ``bar=True``: what a model still missing terms
        leaves must not raise it).
        """
        D = data if data is not None else self.data_for(est.spec)
        f = self._floor(est, D, True)
        return f.nrmse ** 2 * D.den if math.isfinite(f.nrmse) else 0.0

    def floor(self, est: Estimate) -> Floor:
        """Return the reported noise floor of ``est``'s model (:func:`.floor.noise_floor`)."""
        return self._floor(est, self.data_for(est.spec), False)

    def pays(self, sse0: float, sse1: float, dp: int, data: Dataset | None = None, *,
             floor: float | Callable[[], float] = 0.0,
             placebo: Callable[[], float] | None = None) -> tuple[bool, float, float]:
        """Return (supported, explained, BIC change) of going from ``sse0`` to ``sse1``.

        ``floor`` is the SSE the noise floor leaves on the same rows (see the module
        docstring for the rule), or a function returning it: it is then called only
        when it can decide, i.e. when the held-out gain and the BIC both pass.
        """
        data = data or self.data
        explained = 1.0 - sse1 / sse0 if sse0 > 0 else 0.0
        b = bic(data.n_eff, sse0, sse1, dp)
        if not (explained >= self.min_gain and b < 0):
            # fails whatever the floor: do not simulate the model's run for it
            return False, float(explained), float(b)
        if callable(floor):
            floor = floor()
        f = self._floor_nrmse(sse0, data, floor)
        # the floor lowers the bar only for a term that removes most of what the
        # model leaves above the floor: far from it, a small fall is a flexible term
        # taking a bite of a structure the library lacks (a 1/rev gravity on HSM150's
        # 3.9 %, 0.25 % down, with a 0.21 % floor)
        excess = sse0 - floor
        most = excess > 0 and (sse0 - sse1) >= MOST_OF_EXCESS * excess
        need = self._least_fall(f) if most else self.min_drop
        fall = self.nrmse(sse0, data) - max(self.nrmse(sse1, data), f)
        ok = fall >= need
        if not ok and most and placebo is not None and explained >= MOST_OF_EXCESS:
            # the floor estimate, refuted by the run: a term that removes most of the
            # residual itself on held-out rows — not only of its excess over the floor —
            # beyond what it removes of the model's own twin (the floor's run, processed
            # alike: noise and the processing's error) takes what is neither
            ok = explained - placebo() >= MOST_OF_EXCESS
        return bool(ok), float(explained), float(b)

    def _floor_nrmse(self, sse0: float, data: Dataset, floor: float) -> float:
        """Return the floor's NRMSE :meth:`pays` holds a fall from ``sse0`` to (0: none)."""
        f = self.nrmse(floor, data) if floor > 0 else 0.0
        # what the model leaves on its own run (the twin) is no floor of a run on
        # which it leaves less: the twin departed from it (HSM150 without viscous
        # friction: 15.5 % on the runs, more on its twin)
        return 0.0 if f >= self.nrmse(sse0, data) else f

    def _least_fall(self, f: float) -> float:
        """Return the least fall of the NRMSE :meth:`pays` asks of a term removing most."""
        return min(self.min_drop, (NEAR_FLOOR - 1.0) * f) if f > 0 else self.min_drop

    def can_pay(self, sse0: float, data: Dataset, *,
                floor: float | Callable[[], float] = 0.0,
                placebo: Callable[[], float] | None = None) -> bool:
        """Whether any model leaving less than ``sse0`` on ``data`` could pass :meth:`pays`.

        An upper bound, for work whose only use is a verdict (a re-search, a
        look-ahead's second step): the largest fall :meth:`pays` can see is to the
        floor, against the smallest fall it asks.  With a ``placebo`` the run may refute
        the floor, which no bound settles: True.
        """
        if placebo is not None:
            return True
        if callable(floor):
            floor = floor()
        f = self._floor_nrmse(sse0, data, floor)
        return self.nrmse(sse0, data) - f >= self._least_fall(f)

    def least_share(self, sse0: float, data: Dataset, *,
                    floor: float | Callable[[], float] = 0.0,
                    placebo: Callable[[], float] | None = None) -> float:
        """Return the least held-out share a model leaving less than ``sse0`` could pay with.

        The dual of :meth:`can_pay`, for the same use (work whose only use is a
        verdict: a candidate's in-fold choices and local search, skipped when its
        all-data share is below half of this, :func:`.heldout.cv_candidate`).  It is
        ``min_gain`` while some fall could pass :meth:`pays`; else only a term that
        removes most of the residual and refutes the floor could pay
        (:data:`MOST_OF_EXCESS`), and only with a ``placebo`` to refute it with;
        without one nothing could (infinite).
        """
        if self.can_pay(sse0, data, floor=floor):
            return self.min_gain
        if placebo is not None:
            return max(self.min_gain, MOST_OF_EXCESS)
        return math.inf

    def h0(self, model: AxisModel) -> Estimate:
        """Refit the model's own terms, every parameter (nonlinear ones re-searched)."""
        spec = spec_of(model)
        D = self.data_for(spec)
        for n in spec.names:
            t = TERMS[n]
            if t.params and not _vector(t, D):
                spec = spec.with_(n, search(D, spec, n, model))
        if not self.mass_excited:
            spec = dataclasses.replace(spec, mass_free=False, mass=model.mass)
        return estimate(D, spec, model)

    def score(self, base: Estimate, name: str) -> CandidateResult:
        """Score H0 + ``name``: all jointly refit, nonlinear parameters chosen in-fold.

        A candidate whose evidence lies at the stops is judged, with the model it joins,
        on the rows that reach the stops.  The same question has one answer: a
        candidate scored again on the same terms with the same nonlinear parameters (the
        look-ahead's first step, then the forward round that took it) is the result of
        the first scoring.  The key is the spec, not the fitted model: the linear
        parameters are its fit on the same rows, equal but for the rounding of a Gram
        assembled from cached products or afresh (1e-13).
        """
        key = (spec_key(base.spec), name)
        hit = self._scored.get(key)
        if hit is None:
            hit = self._scored[key] = self._score(base, name)
        return hit

    def joined(self, cand: CandidateResult, fitted: Estimate | None = None) -> Estimate:
        """Return the model ``cand`` makes when the forward step takes it (:func:`research`).

        The look-ahead (:func:`.lookahead.simpler`) scores a candidate's follow-ups on the
        model the step would make, so the round after the step finds them scored.
        ``fitted``: ``cand``'s spec already estimated on its rows (not fitted again).
        """
        key = spec_key(cand.spec)
        hit = self._joined.get(key)
        if hit is None:
            new = fitted if fitted is not None else \
                estimate(self.data_for(cand.spec), cand.spec, cand.model)
            hit = self._joined[key] = research(self, new, cand.effect)
        return hit

    def _score(self, base: Estimate, name: str) -> CandidateResult:
        D = self.data_for(base.spec.with_(name, {}))
        sse0 = base.sse_cv if D is self.data_for(base.spec) else \
            cv_design(D, base.spec, base.model)[0]
        # its fit on all rows, which says whether its values are in the term's domain
        fits: dict = {}

        def fitted(eta: dict) -> Estimate:
            key = spec_key(base.spec.with_(name, eta))
            hit = fits.get(key)
            if hit is None:
                hit = fits[key] = estimate(D, base.spec.with_(name, eta), base.model, cv=False)
            return hit
        # a candidate scored in an earlier round starts from its optimum there; one
        # fitted outside its domain is refused whatever it explains: not chosen in-fold
        cand = cv_candidate(D, base.spec, name, base.model, screen=0.5 * self.min_gain,
                            least=lambda: self._least_share(base, D, sse0),
                            start=self._warm.get(name),
                            refused=lambda eta: bool(fitted(eta).inadmissible.get(name)))
        sse, eta = cand.sse_cv, cand.eta
        if eta:
            self._warm[name] = eta
        spec = base.spec.with_(name, eta)
        est = fitted(eta)
        dp = n_params(spec) - n_params(base.spec)
        why_not = est.inadmissible.get(name, '')
        # the noise floor (a simulation of the run) only when the rule needs it: not for
        # a term fitted outside its domain, which no floor makes pay (its share and BIC
        # do not depend on the floor)
        floor = (lambda: self.floor_sse(base, D)) if not why_not else 0.0
        null = self.refuter(base, D, name) if not why_not else None
        ok, explained, b = self.pays(sse0, sse, dp, D, floor=floor, placebo=null)
        if not ok and not why_not and explained >= self.min_gain and any(
                TERMS[n].params and not _vector(TERMS[n], D) for n in base.spec.names) \
                and self.can_pay(sse0, D, floor=floor, placebo=null):
            # its gain is judged at the model's best nonlinear parameters with it, not
            # at those chosen without it: a viscous slope under a Stribeck curve whose
            # vs and delta had stretched to imitate it pays only once they move back
            # (not searched when no fall could pay: the model is within its floor)
            full = research(self, estimate(D, spec, base.model), name)
            if full.sse_cv < sse:
                ok2, explained2, b2 = self.pays(sse0, full.sse_cv, dp, D, floor=floor,
                                                placebo=null)
                if ok2 and not full.inadmissible.get(name, ''):
                    ok, explained, b, sse, spec = ok2, explained2, b2, full.sse_cv, full.spec
                    est = estimate(D, spec, base.model, cv=False)
        why_not = est.inadmissible.get(name, '') or cand.why_not
        if ok and not why_not and D is not self.data_for(base.spec):
            # judged on the rows that reach the stops, where the processing's own error at
            # the turns is most of the floor: it must explain more of the run than of the
            # model's own twin, measured the same way (what it explains there is the
            # processing's, not the axis's)
            twin = self.placebo(base, D, name)
            if explained - twin < self.min_gain:
                why_not = (f'it explains {100 * twin:.0f} % of a run of the model without '
                           f'it, processed the same way, against {100 * explained:.0f} % of '
                           'this run: what it finds at the turns is the processing\'s')
        if why_not:
            ok = False
        eff = est.model.get(name)
        before = {g: v for g, v in model_scalars(self.model).items() if g != name}

        # read when shown: most candidates' standard errors never are
        def details() -> tuple[dict, tuple, tuple]:
            return ({k: float(v) for k, v in est.se.get(name, {}).items()},
                    tuple(significant_changes(before, est)), tuple(est.correlations))
        return CandidateResult(
            effect=name, explained=explained, force_nrmse=self.nrmse(sse, D),
            params=eff.params() if eff is not None else {},
            scalars=dict(est.scalars.get(name, {})), n_params=dp, bic_delta=b,
            supported=ok, model=est.model, details=Lazy(details),
            units=self.units, spec=est.spec,
            at_bound=bool(est.at_bound.get(name)), why_not=why_not,
            estimate=est, base_nrmse=self.nrmse(sse0, D), stops=D.processing.turns)

    def _least_share(self, base: Estimate, D: Dataset, sse0: float) -> float:
        """Return :meth:`least_share` against ``base`` on ``D`` (cached: one per round)."""
        key = (spec_key(base.spec), id(D))
        hit = self._least.get(key)
        if hit is None:
            # whether the run can refute the floor on these rows is all it asks of the
            # placebo (never run here), the same for every candidate of the round
            hit = self._least[key] = self.least_share(
                sse0, D, floor=lambda: self.floor_sse(base, D),
                placebo=self.refuter(base, D, ''))
        return hit

    def refuter(self, base: Estimate, D: Dataset, name: str) -> Callable[[], float] | None:
        """Return the placebo :meth:`pays` may refute the floor with, or None.

        The run refutes a floor only where the floor's twin replicates it: on the
        model's sliding rows, not on the rows that reach the stops (the turns, where
        integrators differ most).
        """
        return (lambda: self.placebo(base, D, name)) if D is self.data else None

    def placebo(self, base: Estimate, D: Dataset, name: str) -> float:
        """Return the held-out share ``name`` explains of ``base``'s own twin on ``D``'s rows.

        The twin is the noise floor's (:func:`.floor.noise_floor`): the base model's run,
        anchored to the measurement, measured and processed like it, with no such effect
        in it.  What the candidate removes there it takes from the processing and the
        sensor alone (a placebo); 0 when there is no twin.
        """
        key = (id(D), model_signature(base.model), name)
        hit = self._placebos.get(key)
        if hit is not None:
            return hit
        twin = self._floor(base, D, True).data
        share = 0.0
        if twin is not None:
            sse0 = cv_design(twin, base.spec, base.model)[0]
            cand = cv_candidate(twin, base.spec, name, base.model,
                                screen=0.5 * self.min_gain)
            share = max(1.0 - cand.sse_cv / sse0, 0.0) if sse0 > 0 else 0.0
        self._placebos[key] = share
        return share

    def refit_result(self, est: Estimate) -> CandidateResult:
        """Turn the refit of the given model into a finding (``mass`` or ``refit``)."""
        D = self.data_for(est.spec)
        sse_given = self.sse_given if D is self.given_data else given_sse(D, self.model)
        ok, explained, b = self.pays(sse_given, est.sse_cv, est.n_params, D,
                                     floor=lambda: self.floor_sse(est, D))
        changes = tuple(significant_changes(model_scalars(self.model), est))
        s = common_scale(self.model, est)
        model = est.model
        if s is not None:
            g = self.model.input_gain
            changes = (ParameterChange('input_gain', 'input_gain', g, g / s, float('nan')),)
            model = scale_forces(est.model, s)
        only_mass = bool(changes) and all(c.effect == MASS for c in changes)
        key = lambda c: f'{c.effect}.{c.name}' if c.effect != MASS else 'mass'  # noqa: E731
        return CandidateResult(
            effect=MASS if only_mass else REFIT, explained=explained,
            force_nrmse=self.nrmse(est.sse_cv, D),
            params={'mass': model.mass, 'effects': {e.name: e.params() for e in model.effects}},
            scalars={key(c): c.fitted for c in changes}, n_params=est.n_params, bic_delta=b,
            supported=ok and bool(changes), model=model,
            details=Lazy(lambda: ({key(c): c.se for c in changes}, changes,
                                  tuple(est.correlations))),
            units=self.units, spec=est.spec, estimate=est,
            base_nrmse=self.nrmse(sse_given, D), stops=D.processing.turns)


def _acc() -> Any:
    from motor_comp.physics.effects.identification import Signal
    return Signal.ACCELERATION


# -- forward / backward ------------------------------------------------------------------
def select(eng: Engine, est: Estimate, step: Step, say: Callable[[str], None],
           max_steps: int) -> Estimate:
    """Forward selection by held-out gain + BIC, backward elimination after each add."""
    removed_once: set[str] = set()
    for _ in range(max_steps):
        names = [n for n in candidates(est.spec, eng.data) if n not in removed_once]
        scored = [eng.score(est, n) for n in names]
        eng.verdicts = eng.verdicts.with_round(est.spec.names,
                                               {c.effect: c for c in scored})
        ok = [c for c in scored if c.supported]
        if ok:
            best = simpler(eng, est, min(ok, key=lambda c: c.bic_delta), scored)
        else:
            best = pair(eng, est, scored)
            if best is None:
                say('nothing else pays for its parameters: done')
                break
            say(f'{best.effect} pays together with another effect (neither alone)')
        D = eng.data_for(best.spec)
        new = estimate(D, best.spec, best.model)
        base_sse = est.sse_cv if D is eng.data_for(est.spec) else \
            cv_design(D, est.spec, est.model)[0]
        if not new.sse_cv < base_sse:
            say(f'{best.effect}: the held-out error did not fall: stopping')
            break
        est = eng.joined(best, new)
        step(best.effect, 'add', est, '')
        est = backward(eng, est, best.effect, step, removed_once)
    return prune(eng, restructure(eng, est, step), step)


def restructure(eng: Engine, est: Estimate, step: Step) -> Estimate:
    """Search each vector parameter's structure once more, against the final model.

    A vector parameter (GMS element distances) is structured when its term joins; the
    terms that join after it leave another residual (a 2-element GMS added before a
    ripple kept one element, 1.27× the true model's NRMSE).  The expensive search runs
    once here, kept when the held-out error falls.
    """
    D = eng.data_for(est.spec)
    for n in est.spec.names:
        if not _vector(TERMS[n], D):
            continue
        eta = refine_structure(D, est.spec, n, est.model)
        if eta == est.spec.of(n):
            continue
        new = estimate(D, est.spec.with_(n, eta), est.model)
        if new.sse_cv < est.sse_cv:
            est = new
            step(REFIT, REFIT, est, f'{n} searched again against the final model: '
                 + params_text(est, n, eng.units))
    return est


def research(eng: Engine, est: Estimate, just: str) -> Estimate:
    """Search the nonlinear parameters of the terms already in once more, as H0 does.

    They were chosen against the residual of a smaller model; with ``just`` added they
    are chosen again (not the expensive vector searches), kept when the held-out error
    does not rise, and ``just`` itself once more when any of them moved.
    """
    moved = False
    D = eng.data_for(est.spec)
    for n in [m for m in est.spec.names if m != just] + [just]:
        t = TERMS[n]
        if not t.params or _vector(t, D) or (n == just and not moved):
            continue
        eta = search(D, est.spec, n, est.model)
        if eta == est.spec.of(n):
            continue
        new = estimate(D, est.spec.with_(n, eta), est.model)
        if new.sse_cv <= est.sse_cv:
            est, moved = new, True
    return est


__all__ = ['CandidateResult', 'Engine', 'Verdicts', 'candidates', 'pair', 'research',
           'restructure', 'select', 'simpler']
