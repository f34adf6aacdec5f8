"""Least squares on augmented Gram matrices, with the terms' bounds inside the estimator.

Every fit of the workbench is ``min ‖y − Xθ‖²`` over some rows; the rows enter only
through ``[X y]ᵀ[X y]`` (per validation part, summed per fold), so a held-out score is a
few small solves.  Bounds a term declares on its coefficients (``fc ≥ 0``, ``fs ≥ fc``,
GMS element levels ≥ 0) and linear constraints (``fc ± dfc/2 ≥ 0``) are enforced in the
solve itself — active-set methods on the normal equations (:func:`box_qp` for bounds,
:func:`linear_qp` with general linear constraints) — never clipped after scoring: what is
scored is what is reported.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit

from motor_comp.physics import aot


@dataclasses.dataclass(frozen=True)
class Bounds:
    """Bounds and linear constraints on the coefficients of one design.

    Parameters
    ----------
    lo, hi : ndarray
        Bounds per coefficient (``±inf`` when free).
    A, b : ndarray
        Linear constraints ``A·θ ≥ b`` (``A`` of shape ``(m, p)``; ``m`` may be 0).
    """

    lo: np.ndarray
    hi: np.ndarray
    A: np.ndarray
    b: np.ndarray

    @classmethod
    def free(cls, p: int) -> 'Bounds':
        """Return no bounds for ``p`` coefficients."""
        return cls(np.full(p, -np.inf), np.full(p, np.inf), np.zeros((0, p)), np.zeros(0))

    @property
    def active(self) -> bool:
        """Whether anything is bounded at all."""
        return bool(np.any(np.isfinite(self.lo)) or np.any(np.isfinite(self.hi))
                    or len(self.b))

    def feasible(self, th: np.ndarray, tol: float = 0.0) -> bool:
        """Whether ``th`` satisfies every bound and constraint."""
        if np.any(th < self.lo - tol) or np.any(th > self.hi + tol):
            return False
        return not len(self.b) or bool(np.all(self.A @ th >= self.b - tol))

    def at_bound(self, th: np.ndarray) -> np.ndarray:
        """Return a mask of the coefficients sitting on a finite bound."""
        scale = np.maximum(np.abs(th), 1e-300)
        return ((np.isfinite(self.lo) & (th - self.lo <= 1e-9 * scale + 1e-300))
                | (np.isfinite(self.hi) & (self.hi - th <= 1e-9 * scale + 1e-300)))


def sse_with(G: np.ndarray, th: np.ndarray) -> float:
    """Return the SSE of coefficients ``th`` from an augmented Gram ``[X y]ᵀ[X y]``."""
    p = len(th)
    return max(float(G[p, p] - 2.0 * th @ G[:p, p] + th @ G[:p, :p] @ th), 0.0)


def _unconstrained(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    p = len(b)
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    As = A / np.outer(d, d)
    try:
        return np.linalg.solve(As + 1e-10 * np.eye(p), b / d) / d
    except np.linalg.LinAlgError:
        return np.linalg.lstsq(As, b / d, rcond=None)[0] / d


def box_qp(A: np.ndarray, b: np.ndarray, lo: np.ndarray, hi: np.ndarray, *,
           iterations: int | None = None) -> np.ndarray:
    """Return ``argmin ½θᵀAθ − bᵀθ`` subject to ``lo ≤ θ ≤ hi`` (``A`` positive definite).

    The primal active-set method (Nocedal & Wright, *Numerical Optimization*, 2nd ed.,
    algorithm 16.3) on the normal equations: from the unconstrained solution clipped to
    the box, solve with the active coefficients at their bounds; step towards that
    solution until a free coefficient meets a bound (it joins the active set), or,
    there, release the active coefficient whose multiplier has the wrong sign.  The
    problem is strictly convex, so this is the minimiser bounded-variable least squares
    (Stark & Parker 1995) finds on the Gram's factor.  Written here because the
    workbench holds the Gram, not the design: ``scipy.optimize.lsq_linear`` needs a
    factor of it, and the factor, its checks and its BVLS took twice as long as this
    in numpy (0.30 against 0.14 ms a call under the profiler; 13 % of the ball-screw
    run's ``fit --auto`` went to it); the iterations are compiled
    (:func:`_box_active`, the subsystems by Cholesky).  If the active set has not
    settled after ``iterations`` changes (default ``4p + 10``: cycling on a degenerate
    vertex), that BVLS solves it.
    """
    A = np.ascontiguousarray(A, dtype=float)
    x, settled = _box_active_entry(A, np.ascontiguousarray(b, dtype=float),
                                   np.ascontiguousarray(lo, dtype=float),
                                   np.ascontiguousarray(hi, dtype=float),
                                   4 * len(b) + 10 if iterations is None else int(iterations))
    if not settled:
        # not settled (cycling on a degenerate vertex): scipy's BVLS on the factor
        from scipy.optimize import lsq_linear
        R = np.linalg.cholesky(A).T
        x = lsq_linear(R, np.linalg.solve(R.T, b), bounds=(lo, hi), method='bvls',
                       tol=1e-12).x
    return np.clip(x, lo, hi)


@njit(cache=True, inline='always')
def _sub_solve(A, r, idx, m, out):
    # solve A[idx, idx]·y = r[:m] (the first m of idx) by Cholesky into out[:m]; False
    # when a pivot is not positive
    L = np.zeros((m, m))
    for j in range(m):
        a = A[idx[j], idx[j]]
        for k in range(j):
            a -= L[j, k] * L[j, k]
        if not a > 0.0:
            return False
        L[j, j] = np.sqrt(a)
        for i in range(j + 1, m):
            a = A[idx[i], idx[j]]
            for k in range(j):
                a -= L[i, k] * L[j, k]
            L[i, j] = a / L[j, j]
    for i in range(m):
        a = r[i]
        for k in range(i):
            a -= L[i, k] * out[k]
        out[i] = a / L[i, i]
    for i in range(m - 1, -1, -1):
        a = out[i]
        for k in range(i + 1, m):
            a -= L[k, i] * out[k]
        out[i] = a / L[i, i]
    return True


@aot.ahead(aot.F8_2D, aot.F8_1D, aot.F8_1D, aot.F8_1D, aot.I8)
@njit(cache=True)
def _box_active(A, b, lo, hi, iterations):
    # box_qp's active-set iterations, compiled: the systems are the same few unknowns as
    # solve_gram's and numpy's cost per call was most of each (~150 us a bounded solve);
    # returns (x, settled) — not settled after `iterations` changes, or a subsystem
    # that is not positive definite, leaves it to the caller
    p = b.shape[0]
    idx = np.arange(p)
    x = np.empty(p)
    if not _sub_solve(A, b, idx, p, x):
        return x, False
    at = np.zeros(p, np.int8)                 # -1 at lo, +1 at hi, 0 free
    for i in range(p):
        if x[i] >= hi[i]:
            at[i] = 1
        elif x[i] <= lo[i]:
            at[i] = -1
        x[i] = min(max(x[i], lo[i]), hi[i])
    target = np.empty(p)
    step = np.empty(p)
    rhs = np.empty(p)
    sol = np.empty(p)
    scale = 0.0
    for i in range(p):
        scale = max(scale, abs(b[i]))
    for _ in range(iterations):
        m = 0
        for i in range(p):
            target[i] = x[i]
            if at[i] == 0:
                idx[m] = i
                m += 1
        if m > 0:
            for a in range(m):
                i = idx[a]
                r = b[i]
                for k in range(p):
                    if at[k] != 0:
                        r -= A[i, k] * x[k]
                rhs[a] = r
            if not _sub_solve(A, rhs, idx, m, sol):
                return x, False
            for a in range(m):
                target[idx[a]] = sol[a]
        # the longest step along which every free coefficient stays in the box
        alpha, block = 1.0, -1
        for i in range(p):
            step[i] = target[i] - x[i]
        for i in range(p):
            if at[i] != 0 or not (target[i] < lo[i] or target[i] > hi[i]):
                continue
            bound = lo[i] if step[i] < 0 else hi[i]
            a = (bound - x[i]) / step[i] if step[i] != 0.0 else 0.0
            if a < alpha:
                alpha, block = a, i
        alpha = max(alpha, 0.0)
        for i in range(p):
            x[i] = x[i] + alpha * step[i]
        if block >= 0:
            x[block] = lo[block] if step[block] < 0 else hi[block]
            at[block] = -1 if step[block] < 0 else 1
            continue
        # the multipliers of the active bounds: the one of the wrong sign is released
        j, worst = 0, -np.inf
        for i in range(p):
            g = -b[i]
            for k in range(p):
                g += A[i, k] * x[k]
            w = -g if at[i] == -1 else (g if at[i] == 1 else 0.0)
            if w > worst:
                j, worst = i, w
        if worst <= 1e-13 * max(scale, 1e-300):
            return x, True
        at[j] = 0
    return x, False


def linear_qp(A: np.ndarray, b: np.ndarray, C: np.ndarray, d: np.ndarray,
              x0: np.ndarray) -> np.ndarray | None:
    """Return ``argmin ½θᵀAθ − bᵀθ`` subject to ``C·θ ≥ d`` from a feasible ``x0``.

    The primal active-set method of :func:`box_qp` with general constraints (Nocedal &
    Wright algorithm 16.3): each step solves the problem with the working constraints
    as equalities (its KKT system); a constraint the step meets joins them, one with a
    negative multiplier at the working problem's minimiser leaves.  None when it does
    not converge (a degenerate working set): the caller falls back to SLSQP.
    """
    m, p = C.shape
    x = np.array(x0, dtype=float)
    work: list[int] = []
    tol = 1e-12 * max(1.0, float(np.max(np.abs(b), initial=0.0)))
    for _ in range(10 * (m + p) + 20):
        g = A @ x - b
        k = len(work)
        K = np.zeros((p + k, p + k))
        K[:p, :p] = A
        if k:
            K[:p, p:] = -C[work].T
            K[p:, :p] = C[work]
        try:
            sol = np.linalg.solve(K, np.concatenate([-g, np.zeros(k)]))
        except np.linalg.LinAlgError:
            return None
        step, lam = sol[:p], sol[p:]
        if np.max(np.abs(step)) <= 1e-13 * max(1.0, float(np.max(np.abs(x)))):
            if k == 0 or lam.min() >= -tol:
                return x
            work.pop(int(np.argmin(lam)))
            continue
        cs = C @ step
        # a constraint the step runs along (0 up to rounding) does not block it: taken
        # in, it would make the working set dependent
        edge = -1e-12 * np.linalg.norm(step) * np.linalg.norm(C, axis=1)
        alpha, block = 1.0, -1
        for i in range(m):
            if i not in work and cs[i] < edge[i]:
                a = max((d[i] - C[i] @ x) / cs[i], 0.0)
                if a < alpha:
                    alpha, block = a, i
        x = x + alpha * step
        if block >= 0:
            work.append(block)
    return None


def _bounded(A: np.ndarray, b: np.ndarray, bounds: Bounds) -> np.ndarray:
    """Solve the normal equations under bounds (and linear constraints)."""
    p = len(b)
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    As = A / np.outer(d, d) + 1e-10 * np.eye(p)
    bs = b / d
    lo, hi = bounds.lo * d, bounds.hi * d
    if not len(bounds.b):
        return box_qp(As, bs, lo, hi) / d
    Ac = bounds.A / d
    # the bounds as rows of the constraints, from the feasible point nearest 0 (every
    # term's constraint holds at 0: a friction level ≥ 0)
    eye = np.eye(p)
    fin_lo, fin_hi = np.isfinite(lo), np.isfinite(hi)
    C = np.vstack([Ac, eye[fin_lo], -eye[fin_hi]])
    rhs = np.concatenate([bounds.b, lo[fin_lo], -hi[fin_hi]])
    x0 = np.clip(np.zeros(p), lo, hi)
    if np.all(C @ x0 >= rhs - 1e-12):
        x = linear_qp(As, bs, C, rhs, x0)
        if x is not None:
            return np.clip(x, lo, hi) / d
    # imported here: scipy.optimize costs every command ~0.15 s of CPU, and only a start
    # the active-set method cannot take needs it (see .optim)
    from scipy.optimize import minimize
    x0 = np.clip(np.linalg.solve(As, bs), lo, hi)
    res = minimize(lambda t: 0.5 * t @ As @ t - bs @ t, x0, jac=lambda t: As @ t - bs,
                   method='SLSQP', bounds=list(zip(lo, hi)),
                   constraints=[{'type': 'ineq', 'fun': lambda t: Ac @ t - bounds.b,
                                 'jac': lambda t: Ac}],
                   options={'ftol': 1e-14, 'maxiter': 200})
    return np.clip(res.x, lo, hi) / d


#: what :func:`_normal_solve` found: the scaled system was not positive definite (a
#: numpy solve decides), the solution meets every bound, or it does not
_NOT_FACTORED, _FEASIBLE, _INFEASIBLE = 0, 1, 2


@njit(cache=True, inline='always')
def _normal_solve(G, th):
    # θ of the augmented Gram's scaled, ridged normal equations (solve_gram's) into
    # `th` (_sub_solve: the scaled Gram has a unit diagonal, and with the ridge it is
    # positive definite); False when a pivot says otherwise (numpy decides).  Compiled
    # because the systems are tiny (2-8 unknowns in most of a search's thousands of
    # solves) and numpy's cost per call was most of each: 87 us a solve, 0.42 s of
    # the ball-screw run's fit.
    p = G.shape[0] - 1
    d = np.empty(p)
    for i in range(p):
        d[i] = np.sqrt(max(G[i, i], 1e-300))
    As = np.empty((p, p))
    bs = np.empty(p)
    for i in range(p):
        for j in range(p):
            As[i, j] = G[i, j] / (d[i] * d[j])
        As[i, i] += 1e-10
        bs[i] = G[i, p] / d[i]
    if not _sub_solve(As, bs, np.arange(p), p, th):
        return False
    for i in range(p):
        th[i] /= d[i]
    return True


@aot.ahead(aot.F8_2D, aot.F8_1D, aot.F8_1D, aot.F8_2D, aot.F8_1D)
@njit(cache=True)
def _solve_small(G, lo, hi, C, c):
    # solve_gram's unbounded solve in one compiled call: θ (_normal_solve), the SSE as
    # sse_with takes it, and whether θ meets the bounds and constraints
    p = G.shape[0] - 1
    th = np.zeros(p)
    if not _normal_solve(G, th):
        return th, 0.0, _NOT_FACTORED
    # the SSE as sse_with: G_yy − 2·θᵀG_xy + θᵀG_xx·θ, at least 0
    lin = 0.0
    quad = 0.0
    for i in range(p):
        lin += th[i] * G[i, p]
        row = 0.0
        for k in range(p):
            row += G[i, k] * th[k]
        quad += th[i] * row
    sse = max(G[p, p] - 2.0 * lin + quad, 0.0)
    state = _FEASIBLE
    for i in range(p):
        if th[i] < lo[i] or th[i] > hi[i]:
            state = _INFEASIBLE
    for r in range(C.shape[0]):
        a = 0.0
        for k in range(p):
            a += C[r, k] * th[k]
        if not a >= c[r]:
            state = _INFEASIBLE
    return th, sse, state


@aot.ahead(aot.array(3))
@njit(cache=True)
def _solve_stack(Gs):
    # _normal_solve of each Gram of a stack; a row of NaN where one was not factored
    k, p = Gs.shape[0], Gs.shape[1] - 1
    out = np.empty((k, p))
    th = np.zeros(p)
    for i in range(k):
        if _normal_solve(Gs[i], th):
            out[i] = th
        else:
            out[i] = np.nan
    return out


_FREE: dict = {}


def _free_of(p: int) -> Bounds:
    hit = _FREE.get(p)
    if hit is None:
        hit = _FREE[p] = Bounds.free(p)
    return hit


def solve_gram(G: np.ndarray, bounds: Bounds | None = None) -> tuple[np.ndarray, float]:
    """Return θ and the SSE from an augmented Gram ``[X y]ᵀ[X y]`` (bounds enforced).

    A tiny ridge on the column-scaled system keeps a rank-deficient design (a column
    that is all zero on these rows) solvable (compiled, :func:`_normal_solve`); a
    solution outside the bounds is re-solved with them.
    """
    p = G.shape[0] - 1
    if p == 0:
        return np.zeros(0), float(G[0, 0])
    b = bounds if bounds is not None else _free_of(p)
    th, sse, state = _solve_small_entry(np.ascontiguousarray(G, dtype=float), b.lo, b.hi,
                                        b.A, b.b)
    if state == _NOT_FACTORED:
        th = _unconstrained(G[:p, :p], G[:p, p])
        sse = sse_with(G, th)
        state = _FEASIBLE if b.feasible(th) else _INFEASIBLE
    if state == _INFEASIBLE and b.active:
        th = _bounded(G[:p, :p], G[:p, p], b)
        sse = sse_with(G, th)
    return th, float(sse)


def solve_grams(Gs: np.ndarray) -> np.ndarray:
    """Return the unbounded θ of a stack of augmented Grams, shape ``(k, p)``.

    :func:`solve_gram` without bounds for many Grams at once, in one compiled call:
    the same routine, the same numbers; one that is not factored is solved alone, as
    :func:`solve_gram` would.
    """
    Gs = np.ascontiguousarray(Gs, dtype=float)
    p = Gs.shape[-1] - 1
    if p == 0:
        return np.zeros((Gs.shape[0], 0))
    th = _solve_stack_entry(Gs)
    for i in np.flatnonzero(np.isnan(th[:, 0])):
        th[i] = solve_gram(Gs[i])[0]
    return th


@dataclasses.dataclass(frozen=True)
class Score:
    """Held-out result of one design."""

    sse_cv: float
    sse_fit: float
    n_params: int


def bic(n_eff: float, sse0: float, sse1: float, dp: int) -> float:
    """Return the BIC change ``n_eff·ln(SSE₁/SSE₀) + Δp·ln n_eff`` (< 0: pays)."""
    return n_eff * math.log(max(sse1, 1e-300) / max(sse0, 1e-300)) + dp * math.log(n_eff)


__all__ = ['Bounds', 'Score', 'bic', 'box_qp', 'linear_qp', 'solve_gram',
           'solve_grams', 'sse_with']


# Python calls the kernel above through its entry: compiled ahead of time where built
# (see motor_comp.physics.aot), else the JIT
_solve_small_entry = aot.entry(_solve_small)
_solve_stack_entry = aot.entry(_solve_stack)
_box_active_entry = aot.entry(_box_active)
