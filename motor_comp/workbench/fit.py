"""Refit a model, add effects to it, or build it from ``effects: {}`` (``--auto``).

Every fit is the joint inverse-dynamic-model least squares of
:mod:`~motor_comp.workbench.ident`: the mass/inertia and every coefficient that enters
linearly are re-estimated together each time the effect set changes, the nonlinear
parameters by variable projection.  ``input_gain``, ``back_emf`` and ``damping`` stay
fixed (the drive's data: a gain error scales every force and is reported by
``diagnose`` as such).

``--auto`` is stepwise selection with a way back (``../shared/IDENTIFICATION.md`` §3):
H0 is the starting model refitted; the forward step adds the candidate with the
largest held-out gain if it pays (held-out gain, NRMSE drop and BIC, as in
:mod:`.diagnose`); the backward step then drops every effect whose removal no longer
hurts (a step with ``action: "remove"``).  When no single candidate pays, two strong
ones that pay together are looked for (:func:`_pair`: a Stribeck curve and a dead time
on a speed sweep each hide the other's worth).  Held-out errors come from the
interleaved hv-block folds of :class:`~motor_comp.workbench.ident.Data`.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Sequence

import numpy as np

from motor_comp.threads import single_threaded_blas
from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel
from motor_comp.workbench import ident as idm
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.diagnose import MASS, REFIT, Engine, as_list, available, \
    common_scale, experiment_notes, fmt_param, identifiability_notes, model_scalars, \
    scale_forces, significant_changes


@dataclasses.dataclass(frozen=True)
class FitStep:
    """One step: the effect added/removed (None = starting model) and its held-out error."""

    effect: str | None
    force_nrmse: float
    model: AxisModel
    summary: str = ''
    action: str = 'add'

    def as_dict(self) -> dict[str, Any]:
        """JSON form (DESIGN.md §6 ``steps`` entry)."""
        return {'effect': self.effect, 'action': self.action,
                'force_nrmse': float(self.force_nrmse), 'summary': self.summary}


@dataclasses.dataclass(frozen=True)
class FitResult:
    """Steps from the starting model to the fitted one, with uncertainties."""

    steps: tuple
    model: AxisModel
    uncertainty: dict = dataclasses.field(default_factory=dict)
    identifiability: tuple = ()
    experiment: tuple = ()
    at_bound: dict = dataclasses.field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """JSON form of DESIGN.md §6 (``steps``, ``model``, ``uncertainty``, notes)."""
        return {'steps': [s.as_dict() for s in self.steps], 'model': self.model.to_dict(),
                'uncertainty': self.uncertainty,
                'identifiability': list(self.identifiability),
                'experiment': list(self.experiment), 'at_bound': self.at_bound}


def _check_add_list(model: AxisModel, names: Sequence[str], rotary: bool) -> None:
    """Check a whole ``add`` list before any fitting, effect by effect in order."""
    present = set(model.names)
    for name in names:
        if name == MASS:
            continue
        if name not in idm.ORDER:
            raise ParameterError(f'unknown effect {name!r} (known: {", ".join(idm.ORDER)})')
        if name in present:
            raise ParameterError(f'the model already has {name!r}; it is refit anyway'
                                 if model.has(name) else f'{name!r} is added twice')
        if name in ('stribeck', 'presliding') and 'coulomb' not in present:
            raise ParameterError(f'cannot add {name!r} to this model (add coulomb first)')
        present.add(name)


def _params_text(est: idm.Estimate, name: str, units: Any) -> str:
    vals = est.scalars.get(name, {})
    se = est.se.get(name, {})
    return ', '.join(fmt_param(name, k, v, se.get(k), units) for k, v in vals.items())


@single_threaded_blas()
def fit(kin: Kinematics | Sequence[Kinematics], model: AxisModel, *,
        add: Sequence[str] = (), auto: bool = False, folds: int = 5,
        min_gain: float = 0.1, min_drop: float = 0.01, max_steps: int = 10,
        progress: Callable[[str], None] | None = None, rotary: bool = False) -> FitResult:
    """Refit ``model``; add ``add`` (a step each); with ``auto``, stepwise selection.

    Parameters
    ----------
    kin : Kinematics or sequence of Kinematics
        One run or several (one experiment, one model).
    model : AxisModel
        The starting model (``effects: {}`` and a rough mass are fine with ``auto``).
    add : sequence of str
        Effects to add, in order (``mass`` is always refit and accepted as a no-op).
    auto : bool
        Forward selection with backward elimination until nothing pays.
    folds, min_gain, min_drop : int, float, float
        Validation folds and the "pays for its parameters" thresholds (see diagnose).
    max_steps : int
        Most selection changes with ``auto``.
    progress : callable, optional
        Called with one line per step.
    rotary : bool
        Treat the position as an angle even if the model file says linear.

    Returns
    -------
    FitResult
        Steps (the first is the starting model, ``effect=None``, its NRMSE without any
        fitting); every later NRMSE is held-out.
    """
    say = progress or (lambda s: None)
    kins = as_list(kin)
    _check_add_list(model, add, rotary)
    eng = Engine(kins, model, folds=folds, min_gain=min_gain, min_drop=min_drop,
                 rotary=rotary)
    model = eng.model
    u = eng.units
    steps = [FitStep(None, eng.nrmse(eng.sse_given), model, 'starting model', 'start')]
    say(f'start: force NRMSE {100 * steps[0].force_nrmse:.1f} % (as given)')
    est = eng.h0(model)
    refit = eng.refit_result(est)
    if not add and not auto:
        steps.append(FitStep(REFIT, est.nrmse_cv, est.model,
                             'refit of all parameters: ' + _changes_text(refit, u), REFIT))
        say(f'refit: force NRMSE {100 * est.nrmse_cv:.1f} % ({_changes_text(refit, u)})')
    elif auto and refit.supported:
        steps.append(FitStep(REFIT, est.nrmse_cv, est.model,
                             'own parameters refitted: ' + _changes_text(refit, u), REFIT))
        say(f'refit pays: {_changes_text(refit, u)}; force NRMSE '
            f'{100 * est.nrmse_cv:.1f} %')
    for name in add:
        if name == MASS:
            continue
        eta = None if name in idm.LINEAR else idm.best_eta(
            eng.D, est.spec.with_(name, _seed_eta(eng, est, name)), name, est.model)
        est = idm.estimate(eng.D, est.spec.with_(name, eta), est.model)
        # the nonlinear parameters of the effects added before were chosen without this
        # one (a ripple period picked before the offset was in): choose them again
        est = _research(eng, est, name)
        text = f'added {name}: {_params_text(est, name, u)}'
        steps.append(FitStep(name, est.nrmse_cv, est.model, text, 'add'))
        say(f'{text}; force NRMSE {100 * est.nrmse_cv:.1f} %')
    if auto:
        est = _select(eng, est, steps, say, max_steps)
    exp = experiment_notes(eng.D, model)
    unweighted = est
    rw = _reweighted(eng, est)
    if rw is not None:
        est, text, removed = rw
        for name in removed:
            steps.append(FitStep(name, est.nrmse_cv, est.model,
                                 f'removed {name}: it pays only through the turns (no '
                                 'longer once the rows are weighted by speed band)',
                                 'remove'))
        steps.append(FitStep(REFIT, est.nrmse_cv, est.model, text, REFIT))
        say(f'{text}; force NRMSE {100 * est.nrmse_cv:.1f} %')
    # the weighted fit's own SEs come out 2–3× smaller while its errors shrink ~1.5×
    # (independent generator, coverage of the gravity runs: 25/30 on them alone), the
    # weights being estimated from the same residuals: each SE is the larger of the
    # weighted and the plain fit's
    unc = _uncertainty(eng, est, floor=unweighted.se if rw is not None else None)
    final = est.model
    s = common_scale(model, est)
    if s is not None and set(final.names) >= set(model.names):
        # every force parameter of the given model moved by one factor: the simpler
        # explanation is one wrong number, the input gain (see diagnose.common_scale)
        final = scale_forces(final, s)
        unc = {g: {k: v / s for k, v in d.items()} for g, d in unc.items()}
        exp.insert(0, f'every force parameter moved by ×{s:.3f}: input_gain corrected '
                      f'from {model.input_gain:.4g} to {final.input_gain:.4g}')
        steps.append(FitStep('input_gain', est.nrmse_cv, final,
                             f'input_gain is {final.input_gain:.4g}, not '
                             f'{model.input_gain:.4g}', REFIT))
        say(steps[-1].summary)
    return FitResult(steps=tuple(steps), model=final, uncertainty=unc,
                     identifiability=tuple(identifiability_notes(est.correlations)),
                     experiment=tuple(exp), at_bound=dict(est.at_bound))


#: effects that are a model of the turns themselves: their evidence is where the
#: residual is largest, so the final fit of a model with one of them is not reweighted
TURN_EFFECTS = ('stribeck', 'presliding', 'backlash')
#: speed bands of the reweighting (equal numbers of rows)
WEIGHT_BANDS = 20
#: reweight only when the worst band's residual variance is this many times the median
#: band's (otherwise the rows are nearly homoscedastic and OLS is as good)
WEIGHT_CONTRAST = 10.0


def _reweighted(eng: Engine, est: idm.Estimate) \
        -> tuple[idm.Estimate, str, list[str]] | None:
    """Re-estimate the final model by weighted least squares over speed bands.

    On a run with many turns (a chirp on an axis with strong Coulomb friction), the
    rows near a turn carry residuals 10–50× those of the sliding rows: how a turn is
    resolved between samples (its instant, a short stick) is modelled, but not
    exactly.  Ordinary least squares lets those few rows set the parameters that
    trade with them — a dead time came out 0.2–0.3 ms long on the independent
    generator's Coulomb + ripple + delay chirps, whose sliding rows put it within
    0.01 ms.  The residual variance is estimated per speed band (equal-count bands
    of ``|ẋ|``) and the parameters re-estimated with weights 1/variance (feasible
    generalised least squares, the standard remedy for heteroscedastic errors), the
    dead time searched again under the weights (a ``refit`` step that names the band
    and what moved by more than its standard error).  The effects are not chosen again,
    and models with an effect of the turns themselves (:data:`TURN_EFFECTS`) keep
    their unweighted fit.  The held-out NRMSE reported is unweighted: each fold's
    parameters by the weighted fit of its training rows, scored on its held-out rows.
    """
    D = eng.D
    if set(est.spec.names) & set(TURN_EFFECTS) or D.n < 4 * WEIGHT_BANDS:
        return None
    speed = np.abs(D.vl())
    edges = np.quantile(speed, np.linspace(0.0, 1.0, WEIGHT_BANDS + 1)[:-1])
    edges[0] = 0.0
    band = np.clip(np.searchsorted(edges, speed, side='right') - 1, 0, WEIGHT_BANDS - 1)
    spec = est.spec
    first = None
    # iterated: the variances from the plain fit's residual, then from the weighted
    # fit's (a dead time that the turns had set moves under the weights, and so does
    # the residual the variances come from)
    for _ in range(2):
        weights = D.speed_weights
        idm.sync(D, spec, est.model)
        th = idm.solve_spec(D, spec)             # under the current weights, if any
        D.set_speed_weights(None)
        X, _ = idm.columns(D, spec)
        e = idm.target(D, spec) - X @ th         # the residual itself, unweighted
        count = np.bincount(band, minlength=WEIGHT_BANDS)
        var = np.bincount(band, e * e, minlength=WEIGHT_BANDS) / np.maximum(count, 1)
        if np.any(count == 0) or np.min(var) <= 0:
            D.set_speed_weights(weights)
            break
        med = float(np.median(var))
        if first is None:
            if np.max(var) < WEIGHT_CONTRAST * med:
                idm.sync(D, est.spec, est.model)
                return None
            first = (var, med)
        D.set_speed_weights((edges, med / var))
        if 'delay' in spec.names:
            spec = spec.with_('delay', idm.best_eta(D, spec, 'delay', est.model))
    if first is None:
        idm.sync(D, est.spec, est.model)
        return None
    var, med = first
    spec, removed = _weighted_elimination(D, spec, est.model)
    new = idm.estimate(D, spec, est.model, cv=False)
    sse = idm.cv_unweighted(D, spec)
    new = dataclasses.replace(new, sse_cv=sse, nrmse_cv=eng.nrmse(sse))
    worst = int(np.argmax(var))
    lo_v = edges[worst]
    hi_v = edges[worst + 1] if worst + 1 < WEIGHT_BANDS else float(np.max(speed))
    u = eng.units
    moved = '; '.join(f'{g}.{k} {v:.4g} (was {est.scalars[g][k]:.4g})'
                      for g, d in new.scalars.items() for k, v in d.items()
                      if k in est.scalars.get(g, {}) and est.se.get(g, {}).get(k)
                      and abs(v - est.scalars[g][k]) > est.se[g][k])
    text = (f'weighted by speed band: residual {math.sqrt(var[worst] / med):.0f}× the typical '
            f'at |v| {lo_v:.3g}–{hi_v:.3g} {u.velocity}; '
            + (moved or 'no parameter moved by more than its standard error'))
    if removed:
        text += '; ' + ', '.join(removed) + ' removed: it pays only through the turns'
    return new, text, removed


def _weighted_elimination(D: idm.Data, spec: idm.Spec, model: AxisModel) \
        -> tuple[idm.Spec, list[str]]:
    """Drop a dead time or ripple that no longer pays once the rows are weighted.

    Chosen by the unweighted held-out score, a nonlinear effect can pay only by fitting
    how the model misses the turns: a 1.2 ms dead time on the independent generator's
    Coulomb + viscous + spring chirp (seed 3, no delay planted) moved to 0.3 ms under
    the weights and then cost held-out SSE (mass 15 % low with it in).  Each of them is
    scored out under the weights, the BIC on the weighted held-out SSE, and the worst
    dropped while one does not pay; a dead time within two standard errors of zero is
    dropped too.  The effects of the turns themselves are never weighted
    (:data:`TURN_EFFECTS`), and the linear ones stay.
    """
    removed: list[str] = []

    def cv_sse(s: idm.Spec) -> float:
        idm.sync(D, s, model)
        X, _ = idm.columns(D, s)
        return idm.cv_design(D, X, idm.target(D, s)).sse_cv
    while True:
        base = cv_sse(spec)
        worst = None
        for n in spec.names:
            if n not in idm.NONLINEAR or n in TURN_EFFECTS:
                continue
            s1 = spec.without(n)
            dp = idm.n_params(spec) - idm.n_params(s1)
            bic = D.n_eff * math.log(max(base, 1e-300) / max(cv_sse(s1), 1e-300)) \
                + dp * math.log(D.n_eff)
            if bic > 0 and (worst is None or bic > worst[0]):
                worst = (bic, n)
        if worst is None:
            break
        spec = spec.without(worst[1])
        removed.append(worst[1])
    if 'delay' in spec.names:
        # a dead time the weighted fit puts within two standard errors of zero (0.02
        # ms ± 0.03 on that chirp) is no dead time the run shows
        est = idm.estimate(D, spec, model, cv=False)
        tau, se = est.scalars['delay']['tau'], est.se['delay']['tau']
        if math.isfinite(se) and tau < 2.0 * se:
            spec = spec.without('delay')
            removed.append('delay')
    idm.sync(D, spec, model)
    return spec, removed


def _uncertainty(eng: Engine, est: idm.Estimate, *,
                 floor: dict | None = None) -> dict[str, dict[str, float]]:
    """Return the standard errors with the processing's and the measurement's share [SI].

    √(SE² + spread²) for each spread: how far each parameter moves with a smoother
    twice as long (:func:`ident.processing_spread`) and with the position measured
    again (:func:`ident.measurement_spread`); the backlash width's is at least half
    its profile interval (:func:`ident.gap_profile_se`: the jackknife's local
    curvature understates how far above the fit a one-sided SSE profile allows it).
    With ``floor`` (another fit's SEs), each SE is at least that.
    """
    spreads = (idm.processing_spread(eng.D, est.spec, est.model),
               idm.measurement_spread(eng.D, est.spec, est.model))
    floor = floor or {}

    def se_of(g: str, k: str, v: float) -> float:
        f = floor.get(g, {}).get(k)
        return max(v, f) if f is not None and math.isfinite(f) else v
    unc = {g: {k: float(math.hypot(se_of(g, k, v),
                                   *(s.get(g, {}).get(k, 0.0) for s in spreads)))
               for k, v in d.items()}
           for g, d in est.se.items()}
    if 'backlash' in est.spec.names and 'width' in unc.get('backlash', {}):
        prof = idm.gap_profile_se(eng.D, est.spec, est.model)
        if math.isfinite(prof):
            unc['backlash']['width'] = max(unc['backlash']['width'], prof)
    return unc


def _seed_eta(eng: Engine, est: idm.Estimate, name: str) -> Any:
    """Return placeholder nonlinear parameters (best_eta searches from scratch)."""
    return {'ripple': (1.0, 1), 'stribeck': (1e-3, 1.0), 'delay': 0.0,
            'backlash': 1e-6, 'presliding': idm.gms_eta(1e-6, 1e3, 0.0)}[name]


def _changes_text(refit: Any, u: Any) -> str:
    return '; '.join(c.sentence(u) for c in refit.changes) or 'no parameter moved'


def _select(eng: Engine, est: idm.Estimate, steps: list, say: Callable[[str], None],
            max_steps: int) -> idm.Estimate:
    """Forward selection by held-out gain + BIC, backward elimination after each add."""
    removed_once: set[str] = set()
    for _ in range(max_steps):
        names = [n for n in available(est.spec, est.model, eng.units,
                                      reversals=eng.reversals, both_ways=eng.both_ways)
                 if n not in removed_once]
        scored = [eng.score(est, n) for n in names]
        ok = [c for c in scored if c.supported]
        if ok:
            # the held-out BIC ranks: between two that explain the same, the one with
            # fewer parameters (viscous before a Stribeck curve stretched over every speed)
            best = min(ok, key=lambda c: c.bic_delta)
        else:
            best = _pair(eng, est, scored)
            if best is None:
                say('nothing else pays for its parameters: done')
                break
            say(f'{best.effect} pays together with another effect (neither alone)')
        new = idm.estimate(eng.D, best.spec, best.model)
        if not new.sse_cv < est.sse_cv:
            say(f'{best.effect}: the held-out error did not fall: stopping')
            break
        est = _research(eng, new, best.effect)
        steps.append(FitStep(best.effect, est.nrmse_cv, est.model,
                             f'added {best.effect}: {_params_text(est, best.effect, eng.units)}',
                             'add'))
        say(f'added {best.effect}: {_params_text(est, best.effect, eng.units)}; force NRMSE '
            f'{100 * est.nrmse_cv:.1f} %')
        est = _backward(eng, est, best.effect, steps, say, removed_once)
    return est


#: a candidate that does not pay alone is tried in a pair when it removes at least this
#: held-out share of the residual (it describes most of what is left, but the part it
#: cannot describe hides its worth, and the effect that describes that part is hidden
#: by it in turn — a Stribeck curve and a dead time on a speed sweep, each blurred by the
#: other and by the mass that stands in for the delay)
PAIR_GAIN = 0.5
#: most candidates tried in pairs (the strongest by held-out BIC)
PAIR_TOP = 3


def _pair(eng: Engine, est: idm.Estimate, scored: Sequence[Any]) -> Any:
    """Return the first of two effects that pay together when neither pays alone.

    Each strong candidate (held-out gain ``PAIR_GAIN``, BIC improving, no parameter at a
    physical bound) is fitted in, and the others are scored on top of it; the pair is
    taken when the second then pays by the usual rule and the two together pay against
    the current model for both their parameters.  The first is returned (the second is
    added by the next forward step, and backward elimination still judges both).
    """
    strong = sorted((c for c in scored if not c.supported and not c.at_bound
                     and c.explained >= max(PAIR_GAIN, eng.min_gain) and c.bic_delta < 0),
                    key=lambda c: c.bic_delta)[:PAIR_TOP]
    names = [c.effect for c in scored if not c.at_bound
             and c.explained >= eng.min_gain and c.bic_delta < 0]
    best = None
    for c in strong:
        first = idm.estimate(eng.D, c.spec, c.model)
        for n in names:
            if n == c.effect or n in first.spec.names:
                continue
            if n in ('stribeck', 'presliding') and 'coulomb' not in first.spec.names:
                continue
            second = eng.score(first, n)
            if not second.supported:
                continue
            sse = first.sse_cv * (1.0 - second.explained)
            dp = idm.n_params(second.spec) - idm.n_params(est.spec)
            ok, _, bic = eng.pays(est.sse_cv, sse, dp)
            if ok and (best is None or bic < best[0]):
                best = (bic, c)
    idm.sync(eng.D, est.spec, est.model)
    return None if best is None else best[1]


def _research(eng: Engine, est: idm.Estimate, just: str) -> idm.Estimate:
    """Re-search the nonlinear parameters of the effects already in, as H0 does.

    They were chosen against the residual of a smaller model (a ripple harmonic count
    picked before the friction was modelled is picked against the friction's residual);
    with ``just`` added they are chosen again by variable projection, and the new
    choice is kept when the held-out error does not rise; when any of them moved,
    ``just`` itself is searched once more against their new values.
    """
    moved = False
    # the others first, then the one just added again when any of them moved (its
    # parameters were chosen against their old values: a dead time found before the
    # Stribeck curve was re-searched trades against it through the mass)
    for n in [m for m in est.spec.names if m != just] + [just]:
        if n not in idm.NONLINEAR or n == 'presliding' or (n == just and not moved):
            continue
        eta = idm.best_eta(eng.D, est.spec, n, est.model)
        if eta == est.spec.eta.get(n):
            continue
        new = idm.estimate(eng.D, est.spec.with_(n, eta), est.model)
        if new.sse_cv <= est.sse_cv:
            est = new
            moved = True
    idm.sync(eng.D, est.spec, est.model)
    return est


#: effects that carry the model's constant force when there is no offset (a spring's
#: ``c``): backward elimination also tries them replaced by an offset, the constant
#: alone.  Not the asymmetry, whose ``dfc`` is a constant while sliding too: on the
#: HSM150 runs its direction-dependent viscous term is real (|dfv| > 2 SE) but explains
#: less than the held-out gain a new effect must show, so the swap dropped it.
CONSTANT_CARRIERS = ('spring',)


def _flat_asymmetry(est: idm.Estimate) -> bool:
    """Whether the asymmetry's speed-dependent part is within 2 SE of zero.

    While the axis slides, ``dfc`` is a constant like an offset; only ``dfv`` (the
    direction-dependent viscous term) is the asymmetry's own.  When the run does not
    support it, the asymmetry is tried as an offset in backward elimination too (an
    asymmetry added before gravity had stood in for the load's constant torque).  On
    the HSM150 runs |dfv| > 2 SE, so that real asymmetry is not offered the swap.
    """
    dfv = est.scalars.get('asymmetry', {}).get('dfv')
    se = est.se.get('asymmetry', {}).get('dfv')
    if dfv is None or se is None or not math.isfinite(se):
        return False
    return abs(dfv) < 2.0 * se


def _backward(eng: Engine, est: idm.Estimate, just: str, steps: list,
              say: Callable[[str], None], removed_once: set) -> idm.Estimate:
    """Drop effects whose removal no longer hurts (once each), worst first.

    An effect that carries the constant force (:data:`CONSTANT_CARRIERS`, or an
    asymmetry whose ``dfv`` the run does not support) is also tried as an offset: a
    spring added early for a constant force (or for gravity, before the ``gravity``
    term was in) is replaced by the offset once its slope no longer pays.
    """
    while True:
        worst = None
        for n in est.spec.names:
            if n == just:
                continue
            if n == 'coulomb' and ({'stribeck', 'presliding'} & set(est.spec.names)):
                continue
            trials = [est.spec.without(n)]
            carrier = n in CONSTANT_CARRIERS or (n == 'asymmetry' and _flat_asymmetry(est))
            if carrier and 'offset' not in est.spec.names:
                trials.append(est.spec.without(n).with_('offset'))
            for spec in trials:
                idm.sync(eng.D, spec, est.model)
                X, _ = idm.columns(eng.D, spec)
                sc = idm.cv_design(eng.D, X, idm.target(eng.D, spec))
                dp = idm.n_params(est.spec) - idm.n_params(spec)
                ok, explained, bic = eng.pays(sc.sse_cv, est.sse_cv, dp)
                ok = ok or eng.resolved(n, est, explained, bic)
                if not ok and (worst is None or explained < worst[1]):
                    worst = (n, explained, spec)
        idm.sync(eng.D, est.spec, est.model)
        if worst is None:
            return est
        n, _, spec = worst
        swapped = 'offset' in spec.names and 'offset' not in est.spec.names
        est = idm.estimate(eng.D, spec, est.model)
        removed_once.add(n)
        if swapped:
            why = f'replaced {n} by an offset: only its constant force still pays'
            steps.append(FitStep(n, est.nrmse_cv, est.model, why, 'remove'))
            steps.append(FitStep('offset', est.nrmse_cv, est.model,
                                 f'added offset: {_params_text(est, "offset", eng.units)}',
                                 'add'))
            say(f'{why}; force NRMSE {100 * est.nrmse_cv:.1f} %')
            continue
        steps.append(FitStep(n, est.nrmse_cv, est.model,
                             f'removed {n}: no longer pays once the others are in', 'remove'))
        say(f'removed {n}: no longer pays once the others are in; force NRMSE '
            f'{100 * est.nrmse_cv:.1f} %')


def refit_linear(kin: Kinematics | Sequence[Kinematics], model: AxisModel) -> AxisModel:
    """Return the model with every parameter jointly refit (no effect added/removed)."""
    eng = Engine(as_list(kin), model, folds=5, min_gain=0.1, min_drop=0.01)
    return eng.h0(model).model


def add_effects(kin: Kinematics | Sequence[Kinematics], model: AxisModel,
                names: Sequence[str]) -> AxisModel:
    """``model`` with the named effects added (nonlinear parameters searched), all refit."""
    return fit(kin, model, add=names).model


__all__ = ['FitResult', 'FitStep', 'add_effects', 'fit', 'refit_linear',
           'significant_changes', 'model_scalars']
