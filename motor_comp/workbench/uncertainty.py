"""Standard errors you can trust: jackknife over stretches, spreads, profiles (IDENTIFICATION §5).

Residuals are coloured, so ``σ²(ΦᵀΦ)⁻¹`` is too small.  The covariance here is a
delete-one-stretch jackknife of the (Gauss–Newton) fit over a few contiguous stretches
of each run, with the nonlinear parameters entering through their linearised columns;
reported parameters by the delta method, and scaled by the jackknife's Student factor
(:func:`t_scale`) so that ± 2 SE is the 95 % interval a reader takes it for.  Three
further terms each widen an SE to what the coverage test
(``test/workbench/test_workbench_coverage.py``) shows it must be:

* the **processing spread** — how far each parameter moves when the smoother is twice
  as long (a choice of processing, not a property of the axis);
* the **measurement spread** — the same samples refitted from positions measured again
  with a second error of the measured size (errors in the regressors, SIMEX, Cook &
  Stefanski 1994);
* a **profile interval** for a parameter whose SSE profile is one-sided (declared on
  the parameter: a backlash width), Venzon & Moolgavkar 1988.

Correlations near ±1, from the block sandwich, name the pairs this run cannot separate.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable, Mapping

import numpy as np

from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import TERMS
from motor_comp.physics.effects.identification import MASS
from motor_comp.workbench.bands import SpeedWeights
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.library import Spec, context, design, values_of
from motor_comp.workbench.lsq import solve_gram
from motor_comp.workbench.varpro import vp_sse

#: contiguous stretches of each run the standard errors are jackknifed over: each a
#: regime of a time-ordered experiment, still 7 degrees of freedom
SE_CLUSTERS = 8
#: correlation beyond which two parameters are named as not separable
CORRELATED = 0.97
#: halvings of a Gauss–Newton step that does not lower the SSE before none is taken
STEP_HALVINGS = 6
#: least share of the linearly predicted SSE reduction a Gauss–Newton step must realise
TRUSTED = 0.25


@dataclasses.dataclass(frozen=True)
class Jacobian:
    """A fit's linearisation: coefficients, labels, Jacobian, residual, design."""

    theta: np.ndarray
    labels: list
    J: np.ndarray
    e: np.ndarray
    sse: float
    values: dict
    #: each nonlinear column's ``(term, parameter, index, value)``, in ``labels``' order
    nonlinear: tuple = ()


def jacobian(data: Dataset, spec: Spec, model: AxisModel | None,
             weights: SpeedWeights | None = None) -> Jacobian:
    """Return the fit of ``spec`` on all rows and the Jacobian of every parameter.

    The columns of the linear coefficients are the design's; those of the nonlinear
    parameters are the derivative of the fitted residual (one-sided differences of
    the design at a perturbed parameter, every column and the target rebuilt).
    """
    d = design(data, spec, model, weights=weights)
    th, sse = solve_gram(d.gram(), d.bounds)
    X = d.X
    e = d.y - X @ th
    J = [X]
    labels = list(d.labels)
    nl = []
    for n in spec.names:
        t = TERMS[n]
        eta = spec.of(n)
        for name, j, val in t.nonlinear(eta):
            h = 1e-3 * abs(val) if val else 1e-6
            s1 = spec.with_(n, t.perturbed(eta, name, j, val + h))
            d1 = design(data, s1, model, weights=weights)
            if d1.X.shape[1] != X.shape[1]:
                continue
            J.append(((e - (d1.y - d1.X @ th)) / h)[:, None])
            labels.append((n, name if j is None else f'{name}{j}'))
            nl.append((n, name, j, val))
    return Jacobian(th, labels, np.column_stack(J), e, sse, values_of(spec, d.labels, th),
                    tuple(nl))


def sandwich(data: Dataset, J: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Return the delete-a-stretch jackknife covariance of the (Gauss–Newton) fit [CR3].

    Each run is cut into :data:`SE_CLUSTERS` contiguous stretches of validation blocks;
    the covariance is ``(G−1)/G·Σ_g (δ_g − δ̄)(δ_g − δ̄)ᵀ`` with
    ``δ_g = (JᵀJ − J_gᵀJ_g)⁻¹J_gᵀe_g``.  A stretch of a time-ordered experiment is a
    regime, so regime-to-regime disagreement of a model that does not quite fit counts
    as uncertainty; with few unequally informative clusters the jackknife is not biased
    low where the plain sandwich is (MacKinnon, Nielsen & Webb 2023, "CV3").
    """
    p = J.shape[1]
    cl = np.zeros(len(e), dtype=int)
    G = 0
    for i in np.unique(data.run_id):
        m = data.run_id == i
        b = data.block[m]
        b0, nb = int(b.min()), int(b.max() - b.min()) + 1
        g = min(SE_CLUSTERS, nb)
        cl[m] = G + ((b - b0) * g) // nb
        G += g
    if G < 2 or len(e) <= p:
        return np.full((p, p), np.nan)
    A = J.T @ J
    # the rows are in time order, so each stretch is a slice (no mask and copy per stretch)
    Acs = np.empty((G, p, p))
    rhs = np.empty((G, p))
    for c, (a, b) in enumerate(_stretches(cl)):
        Jc = J[a:b]
        Acs[c] = A - Jc.T @ Jc
        rhs[c] = Jc.T @ e[a:b]
    d = np.sqrt(np.maximum(np.diagonal(Acs, axis1=1, axis2=2), 1e-300))
    dd = d[:, :, None] * d[:, None, :]
    try:
        # every stretch's pseudo-inverse in one stacked call (the same routine per matrix)
        Ai = np.linalg.pinv(Acs / dd, rcond=1e-12) / dd
    except np.linalg.LinAlgError:
        return np.full((p, p), np.nan)
    deltas = np.einsum('gij,gj->gi', Ai, rhs)
    # a cluster without which the columns are (nearly) singular throws its estimate
    # out of range: no standard error can be read from such a jackknife
    with np.errstate(over='ignore', invalid='ignore'):
        deltas -= deltas.mean(axis=0)
        cov = (G - 1) / G * deltas.T @ deltas * t_scale(G - 1) ** 2
    return cov if np.all(np.isfinite(cov)) else np.full((p, p), np.nan)


#: Student's t quantile at 0.975 for 1–64 degrees of freedom (``scipy.special.stdtrit``'s
#: values to the bit, tested): a jackknife over the stretches of up to eight runs needs no
#: ``scipy.special`` import (0.03 s of CPU in every fit and diagnose)
T975 = (
    12.706204736174694, 4.302652729749462, 3.1824463052837078, 2.7764451051977934,
    2.5705818356363146, 2.4469118511449786, 2.364624251592784, 2.306004135204166,
    2.262157162798205, 2.228138851986274, 2.200985160091639, 2.1788128296672284,
    2.1603686564627913, 2.144786687917804, 2.131449545559776, 2.1199052992212546,
    2.1098155778333156, 2.1009220402410382, 2.0930240544083087, 2.085963447265864,
    2.0796138447276795, 2.0738730679040254, 2.0686576104190486, 2.0638985616280245,
    2.0595385527532972, 2.0555294386428735, 2.0518305164802846, 2.0484071417952454,
    2.045229642132703, 2.0422724563012378, 2.039513446396408, 2.0369333434601016,
    2.0345152974493383, 2.0322445093177186, 2.030107928250343, 2.0280940009804502,
    2.0261924630291093, 2.0243941639119694, 2.022690920036761, 2.021075390306273,
    2.019540970441376, 2.0180817028184443, 2.016692199227824, 2.0153675744437636,
    2.014103388880846, 2.012895598919429, 2.0117405137297655, 2.010634757624232,
    2.0095752371292392, 2.008559112100761, 2.007583770315836, 2.006646805061688,
    2.0057459953178687, 2.0048792881880564, 2.0040447832891455, 2.003240718847872,
    2.002465459291007, 2.0017174841452356, 2.000995378088267, 2.0002978220142604,
    1.999623584994939, 1.9989715170333788, 1.998340542520741, 1.997729654317693,
)


def t_scale(dof: int) -> float:
    """Return ``t_dof(0.975)/z(0.975)``: how much wider a jackknife's 95 % interval is.

    A delete-one-stretch jackknife over ``G`` stretches has ``G − 1`` degrees of
    freedom, so its interval is Student's, not the normal one a reader assumes from
    "± 2 SE" (MacKinnon, Nielsen & Webb 2023 use ``t(G − 1)`` critical values with
    CV3).  With the 8 stretches of one run ± 2 unscaled SE cover 91.5 %, not 95 %;
    the reported SE is scaled by this factor (1.207 at 7 degrees of freedom) so that
    ± 1.96 SE is the 95 % interval.
    """
    z = 1.959963984540054
    dof = max(int(dof), 1)
    if dof <= len(T975):
        return T975[dof - 1] / z
    from scipy.special import stdtrit
    return float(stdtrit(dof, 0.975)) / z


def _stretches(ids: np.ndarray) -> list[tuple[int, int]]:
    """Return ``(start, stop)`` of each run of equal ``ids`` (0, 1, … in row order)."""
    cut = np.flatnonzero(np.diff(ids)) + 1
    edges = [0] + cut.tolist() + [len(ids)]
    if len(edges) - 1 != int(ids[-1]) + 1 or ids[0] != 0:
        raise ValueError('cluster ids must be 0, 1, … in row order')
    return list(zip(edges[:-1], edges[1:]))


def block_sandwich(data: Dataset, J: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Return the cluster-robust sandwich with the validation blocks as clusters (CR1).

    Used for the correlations only (full rank while there are more blocks than
    parameters; the jackknife's covariance has rank ≤ stretches − 1).
    """
    G = J.T @ J
    d = np.sqrt(np.maximum(np.diag(G), 1e-300))
    try:
        Ginv = np.linalg.pinv(G / np.outer(d, d), rcond=1e-12) / np.outer(d, d)
    except np.linalg.LinAlgError:
        return np.full(G.shape, np.nan)
    nb = int(data.block.max()) + 1
    # each block a slice of the rows (time order): its sums in one pass (np.add.at took
    # half of this function's time)
    S = np.add.reduceat(J * e[:, None], [a for a, _ in _stretches(data.block)], axis=0)
    c = nb / max(nb - 1, 1) * (len(e) - 1) / max(len(e) - J.shape[1], 1)
    # a fit at the bounds a term declares (levels of 2.5e8 N on near-collinear knots)
    # overflows here: no correlation can be read from it (as for the jackknife)
    with np.errstate(over='ignore', invalid='ignore'):
        cov = c * Ginv @ (S.T @ S) @ Ginv
    return cov if np.all(np.isfinite(cov)) else np.full(G.shape, np.nan)


def correlations(cov: np.ndarray, labels: list) -> list[tuple[str, str, float]]:
    """Return pairs of parameters of different terms correlated beyond ±0.97."""
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    out = []
    for i in range(len(labels)):
        for j in range(i + 1, len(labels)):
            if labels[i][0] == labels[j][0] or sd[i] == 0 or sd[j] == 0:
                continue
            rho = float(cov[i, j] / (sd[i] * sd[j]))
            # beyond ±1 the covariance is not positive semi-definite there (a singular
            # block): no correlation can be read from it
            if CORRELATED <= abs(rho) <= 1.0 + 1e-9:
                out.append((f'{labels[i][0]}.{labels[i][1]}',
                            f'{labels[j][0]}.{labels[j][1]}', rho))
    return out


def delta_se(fn: Callable[[Mapping], float], vals: Mapping, idx: Mapping,
             cov: np.ndarray) -> float:
    """Return the standard error of ``fn(vals)`` by the delta method.

    Infinite when ``fn`` depends on the parameters but the covariance gives it no
    spread at all: no stretch of the run moved them (their Jacobian column is zero —
    a GMS attraction rate so fast that every element relaxes within a sample), so the
    run does not resolve it.  NaN when no standard error applies (``fn`` depends on
    no fitted parameter, e.g. a structure's element count) or none could be computed.
    """
    base = fn(vals)
    g = np.zeros(cov.shape[0])
    for lab, i in idx.items():
        h = 1e-6 * max(abs(vals[lab]), 1e-12)
        v2 = dict(vals)
        v2[lab] = vals[lab] + h
        g[i] = (fn(v2) - base) / h
    with np.errstate(over='ignore', invalid='ignore'):
        var = float(g @ cov @ g)
    if var == 0.0 and np.any(g != 0.0) and np.all(np.isfinite(g)):
        return math.inf
    return math.sqrt(var) if var > 0 and np.isfinite(var) else float('nan')


def reported(spec: Spec, data: Dataset | None = None) \
        -> dict[tuple, Callable[[Mapping], float]]:
    """Return the reported parameters ``{(group, name): f(values)}`` of ``spec``."""
    ctx = context(spec, data)
    out: dict[tuple, Callable[[Mapping], float]] = {}
    out[('mass', 'mass')] = (lambda v: float(v.get(MASS, spec.mass)))
    replaced = {r for n in spec.names for r in TERMS[n].replaces if r in spec.names}
    for n in spec.names:
        if n in replaced:
            continue
        out.update(TERMS[n].scalars(spec.of(n), ctx))
    return out


def scalars_of(spec: Spec, vals: Mapping, data: Dataset | None = None) -> dict:
    """Return the reported parameters grouped by effect."""
    sc: dict[str, dict[str, float]] = {}
    for (g, k), fn in reported(spec, data).items():
        sc.setdefault(g, {})[k] = float(fn(vals))
    if not spec.mass_free:
        sc['mass'] = {'mass': float(spec.mass)}
    return sc


def standard_errors(spec: Spec, vals: Mapping, labels: list, cov: np.ndarray,
                    data: Dataset | None = None) -> dict:
    """Return the SEs of :func:`scalars_of`'s parameters (delta method), grouped by effect."""
    idx = {lab: i for i, lab in enumerate(labels)}
    se: dict[str, dict[str, float]] = {}
    for (g, k), fn in reported(spec, data).items():
        se.setdefault(g, {})[k] = delta_se(fn, vals, idx, cov) if idx else float('nan')
    if not spec.mass_free:
        se['mass'] = {'mass': float('nan')}
    return se


def _gauss_newton_values(data: Dataset, spec: Spec, model: AxisModel | None,
                         weights: SpeedWeights | None) -> dict:
    """Every parameter one Gauss–Newton step from (linear optimum, ``spec``'s η) on ``data``.

    The step of the nonlinear parameters, kept in their declared bounds
    (:meth:`Param.clip`), is halved until the SSE, every coefficient re-solved, falls
    by at least :data:`TRUSTED` of the linearly predicted reduction (at most
    :data:`STEP_HALVINGS` times, else no step): a linearisation holds only near the
    optimum, and a parameter whose SSE profile is not quadratic (a backlash gap's,
    flat on one side) took one step twice its own size on the independent
    generator's runs.
    """
    jac = jacobian(data, spec, model, weights)
    d = np.sqrt(np.maximum(np.sum(jac.J * jac.J, axis=0), 1e-300))
    step = np.linalg.lstsq(jac.J / d, jac.e, rcond=1e-10)[0] / d
    base = dict(jac.values)
    if not jac.nonlinear:
        phi = np.array([base.get(lab, 0.0) for lab in jac.labels]) + step
        return {lab: float(v) for lab, v in zip(jac.labels, phi)}
    nl_step = step[len(step) - len(jac.nonlinear):]
    ctx = context(spec, data)
    bounds = {(n, p.name): p for n in spec.names
              for p in TERMS[n].space(data.summary, ctx)}

    def value(n: str, name: str, val: float, dv: float, lam: float) -> float:
        p = bounds.get((n, name))     # a step stays in the domain the effect declares
        return p.clip(val + lam * dv) if p is not None else val + lam * dv

    def moved(lam: float) -> Spec:
        s = spec
        for (n, name, j, val), dv in zip(jac.nonlinear, nl_step):
            s = s.with_(n, TERMS[n].perturbed(s.of(n), name, j, value(n, name, val, dv, lam)))
        return s

    lam = 1.0
    for _ in range(STEP_HALVINGS):
        try:
            s2 = moved(lam)
            # the ratio of the actual to the linearly predicted reduction (trust region)
            pred = jac.sse - float(np.sum((jac.e - lam * (jac.J @ step)) ** 2))
            if jac.sse - vp_sse(data, s2, model, weights=weights) >= TRUSTED * pred:
                break
        except ValueError:   # a step out of the parameter's domain
            pass
        lam *= 0.5
    else:
        return dict(base)
    d2 = design(data, s2, model, weights=weights)
    th2 = solve_gram(d2.gram(), d2.bounds)[0]
    out = dict(values_of(s2, d2.labels, th2))
    for (n, name, j, val), dv in zip(jac.nonlinear, nl_step):
        out[(n, name if j is None else f'{name}{j}')] = value(n, name, val, dv, lam)
    return out


def _spread(data: Dataset, data2: Dataset, spec: Spec, model: AxisModel | None,
            weights: SpeedWeights | None) -> dict[str, dict[str, float]]:
    """Return ``|φ(data2) − φ(data)|`` per reported parameter (one GN step each)."""
    try:
        v1 = _gauss_newton_values(data, spec, model, weights)
        v2 = _gauss_newton_values(data2, spec, model, weights)
    except (np.linalg.LinAlgError, ValueError):
        return {}
    out: dict[str, dict[str, float]] = {}
    for (g, k), fn in reported(spec, data).items():
        a, b = fn(v1), fn(v2)
        if np.isfinite(a) and np.isfinite(b):
            out.setdefault(g, {})[k] = abs(float(b) - float(a))
    return out


def processing_spread(data: Dataset, spec: Spec, model: AxisModel | None,
                      weights: SpeedWeights | None = None) -> dict[str, dict[str, float]]:
    """Return how far each parameter moves when the smoothers are twice as long [SI].

    On nearly noise-free runs the jackknife standard errors fall below the bias this
    choice leaves (0.05–0.3 % on the independent generator's runs), so the fit
    reports ``√(SE² + spread²)``.  Both smoothers: the force balance's, and the one
    the pre-sliding elements are driven through (it rounds each reversal: Σk came out
    1–4 % low with SEs of 0.3–1 %, 25 of 30 runs within 2 SE).
    """
    p = data.processing
    d2 = Dataset(data.kins, data.model, folds=data.folds,
                 processing=dataclasses.replace(p, smoother_scale=2.0 * p.smoother_scale,
                                                gms_scale=2.0 * p.gms_scale))
    return _spread(data, d2, spec, model, weights)


def measurement_spread(data: Dataset, spec: Spec, model: AxisModel | None,
                       weights: SpeedWeights | None = None, *,
                       seed: int = 0) -> dict[str, dict[str, float]]:
    """Return how far each parameter moves when the position is measured again [SI].

    Every column is built from the measured position, so its error (quantisation,
    noise) sits in the regressors as well as the target: an errors-in-variables bias
    the jackknife does not see (a GMS element a few counts long carries most of
    ``Σk``).  The same samples are refitted from positions with a second error of the
    measured size, ``σ = max(noise, quantum/√12)`` (a fixed ``seed`` keeps a fit
    reproducible).
    """
    rng = np.random.default_rng(seed)
    kins = []
    for kin in data.kins:
        sigma = max(kin.noise_std(), kin.quantum() / math.sqrt(12.0))
        pos = kin.position + rng.normal(0.0, sigma, len(kin.position)) if sigma > 0 \
            else kin.position
        k2 = dataclasses.replace(kin, position=pos)
        x, v, a = k2.derivatives(pos)
        kins.append(dataclasses.replace(k2, x=x, v=v, a=a))
    d2 = Dataset(kins, data.model, folds=data.folds, processing=data.processing,
                 masks=data.masks)
    return _spread(data, d2, spec, model, weights)


def profile_se(data: Dataset, spec: Spec, model: AxisModel | None, name: str, param: str, *,
               level: float = 4.0) -> float:
    """Return a parameter's SE from its profile-likelihood interval (half-width / 2).

    The interval is where the SSE, every linear coefficient re-solved, stays within
    ``1 + level/n_eff`` of the fit's (``level`` 4 ≈ the χ²₁ 95 % point, the noise
    variance ``SSE/n_eff``), found by doubling steps and bisection on each side.  A
    backlash gap's force residual bounds it sharply from below and only weakly from
    above (the SSE rose 7 % one per cent under the truth and 0.4 % three per cent over
    it on the independent generator), so the local curvature understates it.
    """
    eta = spec.of(name)
    w = float(eta[param])

    def sse(v: float) -> float:
        return vp_sse(data, spec.with_(name, dict(eta, **{param: v})), model)
    thr = sse(w) * (1.0 + level / max(data.n_eff, 2.0))

    def edge(sign: float) -> float:
        inside, outside, step = w, None, 0.005
        while step <= 0.64:
            v = w * (1.0 + sign * step)
            if sse(v) > thr:
                outside = v
                break
            inside, step = v, 2.0 * step
        if outside is None:
            return abs(inside - w)
        for _ in range(4):
            mid = 0.5 * (inside + outside)
            if sse(mid) > thr:
                outside = mid
            else:
                inside = mid
        return abs(inside - w)
    return 0.25 * (edge(-1.0) + edge(1.0))


__all__ = ['CORRELATED', 'Jacobian', 'SE_CLUSTERS', 'block_sandwich', 'correlations',
           'delta_se', 'jacobian', 'measurement_spread', 'processing_spread', 'profile_se',
           'reported', 'sandwich', 'scalars_of', 'standard_errors', 'T975', 't_scale']
