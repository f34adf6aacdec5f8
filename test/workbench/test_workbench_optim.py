"""The hand-written minimisers and constrained least squares against scipy.optimize's.

``optim`` and the active-set solvers of ``lsq`` are written in the package only to keep
``scipy.optimize``'s import out of every ``fit`` and ``diagnose`` (issue 22's speed
goal); the points they find must be scipy's: the same iterates for Brent's and
Nelder–Mead's methods, the minimum ``least_squares`` finds for Levenberg–Marquardt's,
the same minimiser (to rounding) for the quadratic programmes.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import least_squares, lsq_linear, minimize, minimize_scalar, nnls

from motor_comp.workbench.lsq import Bounds, box_qp, solve_gram, solve_grams
from motor_comp.workbench.optim import brent_bounded, levenberg_marquardt, nelder_mead, \
    next_fast_len


def _bumpy(a: float, b: float, c: float):
    """A scalar cost with a few local minima (what a period or a delay search sees)."""
    return lambda x: (x - a) ** 2 + b * math.sin(c * x) + 0.1 * abs(x)


@settings(max_examples=80, deadline=None)
@given(a=st.floats(-3, 3), b=st.floats(0, 2), c=st.floats(0.5, 8), lo=st.floats(-5, 0),
       width=st.floats(1e-3, 8), xatol=st.sampled_from([1e-8, 1e-5, 1e-3, 0.05]))
def test_brent_takes_scipys_iterates(a, b, c, lo, width, xatol):
    f = _bumpy(a, b, c)
    ours, theirs = [], []
    got = brent_bounded(lambda x: ours.append(x) or f(x), lo, lo + width, xatol=xatol)
    want = minimize_scalar(lambda x: theirs.append(x) or f(x), bounds=(lo, lo + width),
                           method='bounded', options={'xatol': xatol})
    assert ours == [float(x) for x in theirs]
    assert got.x == float(want.x) and got.fun == float(want.fun) and got.nfev == want.nfev


def _rosen_like(scale: np.ndarray):
    def f(q: np.ndarray) -> float:
        z = q * scale
        return float(np.sum(100.0 * (z[1:] - z[:-1] ** 2) ** 2 + (1.0 - z[:-1]) ** 2)
                     + 0.01 * np.sum(z ** 2))
    return f


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 4), seed=st.integers(0, 2 ** 16),
       xatol=st.sampled_from([1e-3, 2e-2]), maxiter=st.integers(5, 120))
def test_nelder_mead_takes_scipys_iterates(n, seed, xatol, maxiter):
    rng = np.random.default_rng(seed)
    f = _rosen_like(rng.uniform(0.5, 2.0, n))
    q0 = rng.normal(size=n)
    sim = np.tile(q0, (n + 1, 1))
    for i in range(n):
        sim[i + 1, i] += 0.05 * q0[i] if q0[i] != 0.0 else 0.05
    fatol = 1e-9 * f(q0)
    got = nelder_mead(f, sim, xatol=xatol, fatol=fatol, maxiter=maxiter)
    want = minimize(f, q0, method='Nelder-Mead',
                    options={'initial_simplex': sim, 'xatol': xatol, 'fatol': fatol,
                             'maxiter': maxiter})
    np.testing.assert_array_equal(got.x, want.x)
    assert got.fun == want.fun and got.nfev == want.nfev


def test_nelder_mead_finds_a_bowls_minimum():
    w, c = np.array([1.0, 30.0, 0.2]), np.array([0.3, -1.2, 2.0])
    f = lambda q: float(np.sum(w * (q - c) ** 2))  # noqa: E731
    sim = np.vstack([np.zeros(3), 0.05 * np.eye(3)])
    got = nelder_mead(f, sim, xatol=1e-8, fatol=1e-14, maxiter=5000)
    np.testing.assert_allclose(got.x, c, atol=1e-5)
    assert got.fun < 1e-9


@settings(max_examples=40, deadline=None)
@given(n=st.integers(1, 4), seed=st.integers(0, 2 ** 16), resolution=st.floats(1e-8, 1e-1))
def test_nelder_mead_at_a_resolution_takes_the_same_iterates_and_stops_sooner(
        n, seed, resolution):
    """A resolution only ends the search: the costs it takes are the first ones without."""
    rng = np.random.default_rng(seed)
    f = _rosen_like(rng.uniform(0.5, 2.0, n))
    sim = np.vstack([np.zeros(n), 0.05 * np.eye(n)]) + rng.normal(size=n)
    full, short = [], []
    want = nelder_mead(lambda q: full.append(f(q)) or full[-1], sim, xatol=1e-6,
                       fatol=1e-12, maxiter=300)
    got = nelder_mead(lambda q: short.append(f(q)) or short[-1], sim, xatol=1e-6,
                      fatol=1e-12, maxiter=300, resolution=resolution)
    assert short == full[:len(short)] and got.nfev == len(short) <= want.nfev
    assert got.fun == min(short)


def test_nelder_mead_stops_where_the_costs_agree_to_the_resolution():
    """A direction the cost barely sees is not searched to ``xatol`` (one the run never resolves).

    The first coordinate is resolved, the second changes the cost by 1e-9 over its
    range: at a resolution of 1e-6 the search ends once the first is within about
    √1e-6 of its minimum, in a fraction of the costs the points' tolerance takes.
    """
    f = lambda q: float((q[0] - 0.3) ** 2 + 1e-9 * np.tanh(q[1]) ** 2)  # noqa: E731
    sim = np.array([[1.0, 1.0], [1.05, 1.0], [1.0, 1.05]])
    full = nelder_mead(f, sim, xatol=1e-4, fatol=1e-14, maxiter=2000)
    got = nelder_mead(f, sim, xatol=1e-4, fatol=1e-14, maxiter=2000, resolution=1e-6)
    assert abs(got.x[0] - 0.3) <= 2e-3 and got.fun <= 2e-6
    assert got.nfev < 0.5 * full.nfev


def _decays(rng: np.random.Generator, k: int):
    """A sum of ``k`` decays ``a_j·exp(−t/τ_j)`` on log-rates: what a search of shapes sees.

    The residual of the linear amplitudes projected out (variable projection), as the
    workbench's searches pose it; returns the residual of ``q = log τ`` and the truth.
    """
    t = np.linspace(0.0, 10.0, 200)
    q_true = np.sort(rng.uniform(-1.0, 2.0, k)) + np.arange(k) * 0.7
    a = rng.uniform(0.5, 2.0, k)
    y = np.exp(-t[:, None] / np.exp(q_true)) @ a + 1e-3 * rng.normal(size=t.size)

    def residual(q: np.ndarray) -> np.ndarray:
        X = np.exp(-t[:, None] / np.exp(np.asarray(q)))
        th, *_ = np.linalg.lstsq(X, y, rcond=None)
        return y - X @ th
    return residual, q_true


@settings(max_examples=60, deadline=None)
@given(k=st.integers(1, 2), seed=st.integers(0, 2 ** 16), near=st.floats(0.02, 0.4))
def test_levenberg_marquardt_reaches_scipys_least_squares(k, seed, near):
    """From a start near the optimum it ends where scipy's least_squares ends, at its cost.

    One or two shape parameters, as the workbench's searches have (a Stribeck curve's
    ``vs`` and ``delta``).  Three decays are ill-conditioned enough that 30 Jacobians
    of forward differences stop 0.1 % above scipy's minimum (seed 2060): the search
    it serves is not asked to resolve such a valley.
    """
    rng = np.random.default_rng(seed)
    residual, q_true = _decays(rng, k)
    q0 = q_true + near * rng.choice([-1.0, 1.0], k)
    lo, hi = np.full(k, -3.0), np.full(k, 5.0)
    got = levenberg_marquardt(residual, q0, lo=lo, hi=hi, step=np.full(k, 1e-4),
                              xatol=1e-8, fatol=1e-16)
    want = least_squares(residual, q0, bounds=(lo, hi), xtol=1e-12, ftol=1e-14, gtol=1e-14)
    assert got.fun <= 2.0 * want.cost * (1.0 + 1e-6) + 1e-14
    np.testing.assert_allclose(np.sort(got.x), np.sort(want.x), atol=1e-3)
    assert got.fun == pytest.approx(float(residual(got.x) @ residual(got.x)), rel=1e-12)


def test_levenberg_marquardt_holds_a_bound_the_minimum_lies_beyond():
    """A coordinate whose optimum is outside the box ends on the bound, as scipy's."""
    residual, q_true = _decays(np.random.default_rng(3), 2)
    lo, hi = np.array([-3.0, -3.0]), np.array([q_true[0] - 0.3, 5.0])
    q0 = np.array([q_true[0] - 0.5, q_true[1] + 0.2])
    got = levenberg_marquardt(residual, q0, lo=lo, hi=hi, step=np.full(2, 1e-4),
                              xatol=1e-8, fatol=1e-16)
    want = least_squares(residual, q0, bounds=(lo, hi), xtol=1e-12, ftol=1e-14, gtol=1e-14)
    assert got.x[0] == hi[0] and want.x[0] == pytest.approx(hi[0], abs=1e-9)
    assert got.x[1] == pytest.approx(want.x[1], abs=1e-4)
    assert got.fun <= 2.0 * want.cost * (1.0 + 1e-6)


@pytest.mark.parametrize('seed', range(8))
def test_levenberg_marquardt_needs_few_residuals_from_a_near_start(seed):
    """Why it replaced Nelder–Mead: a warm start converges in a few Jacobians.

    Two log-rates 10 % off, to the workbench's tolerances (xatol 1e-3, fatol 1e-9 of
    the start's cost): at most 25 residuals, where the Nelder–Mead simplex of 5 % it
    replaced takes 69–98 costs on these eight problems (scipy's, the same tolerances).
    """
    rng = np.random.default_rng(seed)
    residual, q_true = _decays(rng, 2)
    q0 = q_true + 0.1
    r0 = residual(q0)
    got = levenberg_marquardt(residual, q0, lo=np.full(2, -3.0), hi=np.full(2, 5.0),
                              step=np.full(2, 1e-4), xatol=1e-3, fatol=1e-9 * float(r0 @ r0))
    best = least_squares_cost(residual, q0)
    assert got.nfev <= 25
    assert got.fun <= best * (1.0 + 1e-4) + 1e-12


def least_squares_cost(residual, q0) -> float:
    """Return ‖r‖² at scipy's least_squares minimum from ``q0`` (tight tolerances)."""
    return 2.0 * float(least_squares(residual, q0, xtol=1e-12, ftol=1e-14, gtol=1e-14).cost)


def _order_search(crit_of):
    """A Search whose cost makes the information criterion of order k ``crit_of(k)``."""
    from types import SimpleNamespace
    from motor_comp.workbench.varpro import Search
    n_eff = 100.0
    s = object.__new__(Search)
    s.data, s.rows = SimpleNamespace(n_eff=n_eff), None
    s.term = SimpleNamespace(with_order=lambda eta, k: dict(eta, k=k),
                             order_of=lambda eta: eta.get('k'))
    s.scored = []

    def cost(e):
        k = e['k']
        s.scored.append(k)
        return math.exp((crit_of(k) - 2 * k * math.log(n_eff)) / n_eff)
    s.cost = cost
    # the sum of squares as given (no speed bands to weigh: test_workbench_bands has them)
    s._likelihood_sse = lambda eta: cost
    return s


@settings(max_examples=300, deadline=None)
@given(st.integers(1, 8), st.lists(st.integers(0, 400), min_size=1, max_size=29, unique=True))
def test_order_search_takes_the_best_criterion_of_every_count(lo, crits):
    """The structural order is the count with the least criterion, however it varies.

    A knot count's criterion is not unimodal (joint100: odd counts 5 / 9 / 13 at BIC
    +7.4 / +0.1 / 0 with the even ones between 17–57 above): no count is skipped.
    """
    hi = lo + len(crits) - 1
    s = _order_search(lambda k: 2.0 * crits[k - lo])
    got = s._order({'k': lo}, lo, hi)['k']
    assert got == lo + int(np.argmin(crits))


@pytest.mark.parametrize('n', [1, 2, 7, 97, 1000, 4097, 65537, 199999])
def test_fast_lengths_are_scipys(n):
    from scipy.fft import next_fast_len as ref
    assert next_fast_len(n) == ref(n)


def _problem(rng: np.random.Generator, p: int, collinear: bool):
    n = p + int(rng.integers(1, 40))
    X = rng.normal(size=(n, p)) * rng.lognormal(0.0, 1.5, size=p)
    if collinear and p > 1:
        X[:, -1] = X[:, 0] + 1e-4 * rng.normal(size=n)
    y = rng.normal(size=n) * 3.0
    G = np.zeros((p + 1, p + 1))
    Z = np.column_stack([X, y])
    G[:] = Z.T @ Z
    return X, y, G


def _box(p: int, seed: int, collinear: bool):
    """Return a column-scaled, ridged box problem: As, b, d, lo, hi (the workbench's form)."""
    rng = np.random.default_rng(seed)
    _, _, G = _problem(rng, p, collinear)
    lo = np.where(rng.random(p) < 0.6, 0.0, -np.inf)
    hi = np.where(rng.random(p) < 0.2, rng.random(p), np.inf)
    lo = np.minimum(lo, hi)
    A, b = G[:p, :p], G[:p, p]
    d = np.sqrt(np.diag(A))
    return A / np.outer(d, d) + 1e-10 * np.eye(p), b, d, lo, hi


@settings(max_examples=120, deadline=None)
@given(p=st.integers(1, 20), seed=st.integers(0, 2 ** 16), collinear=st.booleans())
def test_box_qp_is_bounded_least_squares(p, seed, collinear):
    As, b, d, lo, hi = _box(p, seed, collinear)
    x = box_qp(As, b / d, lo * d, hi * d) / d
    tol = 1e-12 * np.maximum(np.abs(x), 1.0)
    assert np.all(x >= lo - tol) and np.all(x <= hi + tol)
    # scipy's BVLS on the same (column-scaled, ridged) problem, through its Cholesky
    # factor: ‖Rθ − R⁻ᵀb‖² = θᵀAθ − 2bᵀθ + const
    R = np.linalg.cholesky(As).T
    ref = lsq_linear(R, np.linalg.solve(R.T, b / d), bounds=(lo * d, hi * d), method='bvls',
                     tol=1e-12).x / d
    q = lambda t: float(0.5 * (t * d) @ As @ (t * d) - (b / d) @ (t * d))  # noqa: E731
    # to rounding: what a solve on this system can resolve
    tol = max(1e-10, 1e-14 * np.linalg.cond(As))
    assert q(x) <= q(ref) + tol * max(1.0, abs(q(ref)))


@settings(max_examples=120, deadline=None)
@given(p=st.integers(1, 16), seed=st.integers(0, 2 ** 16), zero=st.booleans())
def test_the_compiled_solve_is_least_squares(p, seed, zero):
    """θ and SSE of an augmented Gram: numpy's least squares on the design it comes from."""
    rng = np.random.default_rng(seed)
    X = rng.normal(size=(60, p)) * 10.0 ** rng.uniform(-3, 3, size=p)
    if zero:
        X[:, 0] = 0.0                     # a column all zero on these rows: the ridge
    y = X @ rng.normal(size=p) + rng.normal(size=60)
    Z = np.column_stack([X, y])
    th, sse = solve_gram(Z.T @ Z)
    keep = slice(1, None) if zero else slice(None)
    ref = np.linalg.lstsq(X[:, keep], y, rcond=None)[0]
    np.testing.assert_allclose(X[:, keep] @ th[keep], X[:, keep] @ ref, rtol=1e-8,
                               atol=1e-8 * float(np.abs(y).max()))
    assert abs(sse - float(np.sum((y - X @ th) ** 2))) <= 1e-8 * float(y @ y)
    if zero:
        assert th[0] == 0.0


@settings(max_examples=120, deadline=None)
@given(p=st.integers(2, 10), m=st.integers(1, 3), seed=st.integers(0, 2 ** 16))
def test_linear_constraints_are_held_at_slsqps_minimum(p, m, seed):
    rng = np.random.default_rng(seed)
    X, y, G = _problem(rng, p, False)
    lo = np.where(rng.random(p) < 0.5, 0.0, -np.inf)
    hi = np.full(p, np.inf)
    C = np.zeros((m, p))
    for r in range(m):     # the terms' own kind: fc ± dfc/2 ≥ 0, fc + dfc_j ≥ 0
        i, j = rng.choice(p, 2, replace=False)
        C[r, i], C[r, j] = 1.0, rng.choice([-0.5, 0.5, 1.0])
    th, sse = solve_gram(G, Bounds(lo, hi, C, np.zeros(m)))
    scale = max(1.0, float(np.max(np.abs(th))))
    assert np.all(C @ th >= -1e-9 * scale) and np.all(th >= lo)
    _assert_kkt(X, y, th, np.vstack([C, np.eye(p)[lo == 0.0]]),
                np.zeros(m + int(np.sum(lo == 0.0))))
    f = lambda t: 0.5 * float(np.sum((y - X @ t) ** 2))  # noqa: E731
    ref = minimize(f, np.zeros(p), jac=lambda t: -(X.T @ (y - X @ t)), method='SLSQP',
                   bounds=list(zip(lo, hi)), constraints=[{'type': 'ineq',
                                                           'fun': lambda t: C @ t}],
                   options={'ftol': 1e-15, 'maxiter': 500}).x
    # SLSQP may end a hair outside a constraint (1e-8), which a multiplier of a few
    # hundred turns into a lower objective than the constrained minimum's: its
    # objective counts only with that violation priced in (seed 260: 3.4e-6)
    assert f(th) <= f(ref) + 1e-8 * max(1.0, float(y @ y)) + _violation_price(X, y, th, C, ref)


def _multipliers(X, y, th, C, c):
    """Return the active rows of ``C·θ ≥ c`` at ``th`` and their KKT multipliers."""
    g = X.T @ (X @ th - y)
    scale = max(1.0, float(np.max(np.abs(th))))
    act = np.abs(C @ th - c) <= 1e-9 * scale * np.linalg.norm(C, axis=1)
    if not np.any(act):
        return act, np.zeros(0), g
    # non-negative: at a degenerate vertex (more active rows than coefficients) the
    # multipliers are not unique, and the certificate needs one set that is ≥ 0
    lam = nnls(C[act].T, g, maxiter=1000)[0]
    return act, lam, g


def _assert_kkt(X, y, th, C, c):
    """Assert the optimality certificate of a convex QP: stationary with multipliers ≥ 0.

    The gradient left over once the active rows' non-negative multipliers are taken
    out is what a Newton step could still gain: ``½ rᵀ(XᵀX)⁻¹r``, at most 1e-10 of the
    objective (SLSQP's fallback ends within ~1e-7 of stationarity, 1e-15 of the value).
    """
    act, lam, g = _multipliers(X, y, th, C, c)
    rest = g - (C[act].T @ lam if np.any(act) else 0.0)
    gain = 0.5 * float(rest @ np.linalg.solve(X.T @ X, rest))
    f = 0.5 * float(np.sum((y - X @ th) ** 2))
    assert gain <= 1e-10 * max(1.0, f), (gain, f)


def _violation_price(X, y, th, C, ref):
    _, lam, _ = _multipliers(X, y, th, C, np.zeros(len(C)))
    viol = np.maximum(-(C @ ref), 0.0)
    return float(np.max(np.abs(lam), initial=0.0) * viol.sum())


@settings(max_examples=60, deadline=None)
@given(p=st.integers(1, 12), seed=st.integers(0, 2 ** 16), collinear=st.booleans())
def test_box_qps_fallback_finds_the_same_minimum(p, seed, collinear):
    """An active set that does not settle hands over to BVLS on the Gram's factor.

    No run has reached it; forced here (no active-set step allowed), it must land on
    the active-set method's minimum.
    """
    As, b, d, lo, hi = _box(p, seed, collinear)
    bs = b / d
    x = box_qp(As, bs, lo * d, hi * d)
    y = box_qp(As, bs, lo * d, hi * d, iterations=0)
    assert np.all(y >= lo * d) and np.all(y <= hi * d)
    q = lambda t: float(0.5 * t @ As @ t - bs @ t)  # noqa: E731
    tol = max(1e-10, 1e-14 * np.linalg.cond(As))
    assert abs(q(y) - q(x)) <= tol * max(1.0, abs(q(x)))


@settings(max_examples=60, deadline=None)
@given(p=st.integers(2, 8), seed=st.integers(0, 2 ** 16))
def test_a_constraint_that_excludes_zero_is_held_by_the_fallback(p, seed):
    """``θᵢ + θⱼ ≥ 1``: no feasible start at 0, so the active-set method hands over to SLSQP.

    The terms' own constraints all hold at 0 and no run has reached this path; it must
    still return the constrained minimum (checked against SLSQP run on the design).
    """
    rng = np.random.default_rng(seed)
    X, y, G = _problem(rng, p, False)
    i, j = rng.choice(p, 2, replace=False)
    C = np.zeros((1, p))
    C[0, i] = C[0, j] = 1.0
    # a bound ≥ the unconstrained optimum's, so that the constraint binds
    t0, _ = solve_gram(G)
    need = float(C[0] @ t0) + 1.0 + float(rng.random())
    lo, hi = np.full(p, -np.inf), np.full(p, np.inf)
    th, _ = solve_gram(G, Bounds(lo, hi, C, np.array([need])))
    scale = max(1.0, float(np.max(np.abs(th))))
    assert float(C[0] @ th) >= need - 1e-8 * scale
    # the constraint binds, and θ is the minimum on it (KKT: the convex problem's
    # certificate, independent of any solver)
    _assert_kkt(X, y, th, C, np.array([need]))
    assert abs(float(C[0] @ th) - need) <= 1e-8 * scale


@settings(max_examples=30, deadline=None)
@given(p=st.integers(1, 12), k=st.integers(1, 9), seed=st.integers(0, 2**31 - 1),
       collinear=st.booleans())
def test_stacked_grams_solve_as_each_one_alone(p, k, seed, collinear):
    """Many unbounded Grams at once: bit for bit what each one solved alone gives."""
    rng = np.random.default_rng(seed)
    Z = rng.normal(size=(40 * k, p + 1)) * 10.0 ** rng.uniform(-3, 3, size=p + 1)
    if collinear and p > 1:
        Z[:, 1] = 2.0 * Z[:, 0]
    Gs = np.stack([Z[40 * i:40 * (i + 1)].T @ Z[40 * i:40 * (i + 1)] for i in range(k)])
    th = solve_grams(Gs)
    assert th.shape == (k, p)
    for g, t in zip(Gs, th):
        assert np.array_equal(t, solve_gram(g)[0])


def test_a_singular_gram_in_a_stack_is_solved_alone():
    """A Gram whose design has a zero column: the ridge solves it, alone as in the stack."""
    Z = np.random.default_rng(3).normal(size=(60, 4))
    Z[:30, 2] = 0.0
    Gs = np.stack([Z[:30].T @ Z[:30], Z[30:].T @ Z[30:]])
    th = solve_grams(Gs)
    for g, t in zip(Gs, th):
        assert np.array_equal(t, solve_gram(g)[0])
    assert np.all(np.isfinite(th))
