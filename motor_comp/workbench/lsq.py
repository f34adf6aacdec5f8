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
from typing import Sequence

import numpy as np


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
    (0.30 against 0.14 ms a call under the profiler; 13 % of the ball-screw run's
    ``fit --auto`` went to it).  If the active set has not settled after ``iterations``
    changes (default ``4p + 10``: cycling on a degenerate vertex), that BVLS solves it.
    """
    p = len(b)
    x = np.linalg.solve(A, b)
    at = np.zeros(p, dtype=np.int8)           # -1 at lo, +1 at hi, 0 free
    at[x <= lo] = -1
    at[x >= hi] = 1
    x = np.clip(x, lo, hi)
    for _ in range(4 * p + 10 if iterations is None else iterations):
        free = at == 0
        fixed = ~free
        target = x.copy()
        if np.any(free):
            rhs = b[free] - A[np.ix_(free, fixed)] @ x[fixed]
            target[free] = np.linalg.solve(A[np.ix_(free, free)], rhs)
        step = target - x
        # the longest step along which every free coefficient stays in the box
        alpha, block = 1.0, -1
        for i in np.flatnonzero(free & ((target < lo) | (target > hi))):
            bound = lo[i] if step[i] < 0 else hi[i]
            a = (bound - x[i]) / step[i] if step[i] != 0.0 else 0.0
            if a < alpha:
                alpha, block = a, i
        x = x + max(alpha, 0.0) * step
        if block >= 0:
            x[block] = lo[block] if step[block] < 0 else hi[block]
            at[block] = -1 if step[block] < 0 else 1
            continue
        g = A @ x - b                          # the multipliers of the active bounds
        wrong = np.where(at == -1, -g, np.where(at == 1, g, 0.0))
        j = int(np.argmax(wrong))
        if wrong[j] <= 1e-13 * max(float(np.abs(b).max()), 1e-300):
            break
        at[j] = 0
    else:
        # not settled (cycling on a degenerate vertex): scipy's BVLS on the factor
        from scipy.optimize import lsq_linear
        R = np.linalg.cholesky(A).T
        x = lsq_linear(R, np.linalg.solve(R.T, b), bounds=(lo, hi), method='bvls',
                       tol=1e-12).x
    return np.clip(x, lo, hi)


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


def solve_gram(G: np.ndarray, bounds: Bounds | None = None) -> tuple[np.ndarray, float]:
    """Return θ and the SSE from an augmented Gram ``[X y]ᵀ[X y]`` (bounds enforced).

    A tiny ridge on the column-scaled system keeps a rank-deficient design (a column
    that is all zero on these rows) solvable; a solution outside the bounds is
    re-solved with them.
    """
    p = G.shape[0] - 1
    if p == 0:
        return np.zeros(0), float(G[0, 0])
    A, b = G[:p, :p], G[:p, p]
    th = _unconstrained(A, b)
    if bounds is not None and bounds.active and not bounds.feasible(th):
        th = _bounded(A, b, bounds)
    return th, sse_with(G, th)


def solve_grams(Gs: np.ndarray) -> np.ndarray:
    """Return the unbounded θ of a stack of augmented Grams, shape ``(k, p)``.

    :func:`solve_gram` without bounds for many Grams at once: the same scaled,
    ridged normal equations, solved by one stacked LAPACK call (the same routine, the
    same numbers); a singular one is solved alone, as :func:`solve_gram` would.
    """
    Gs = np.asarray(Gs, dtype=float)
    p = Gs.shape[-1] - 1
    if p == 0:
        return np.zeros((Gs.shape[0], 0))
    A, b = Gs[:, :p, :p], Gs[:, :p, p]
    d = np.sqrt(np.maximum(np.diagonal(A, axis1=1, axis2=2), 1e-300))
    As = A / (d[:, :, None] * d[:, None, :])
    try:
        return np.linalg.solve(As + 1e-10 * np.eye(p), (b / d)[:, :, None])[:, :, 0] / d
    except np.linalg.LinAlgError:
        return np.stack([_unconstrained(a, v) for a, v in zip(A, b)])


@dataclasses.dataclass(frozen=True)
class Score:
    """Held-out result of one design."""

    sse_cv: float
    sse_fit: float
    n_params: int


def cv_grams(P: np.ndarray, train: Sequence[np.ndarray], test: Sequence[np.ndarray],
             bounds: Bounds | None = None) -> float:
    """Return the held-out SSE over folds from per-part Grams ``P`` and part masks."""
    total = 0.0
    for tr, te in zip(train, test):
        th, _ = solve_gram(P[tr].sum(axis=0), bounds)
        total += sse_with(P[te].sum(axis=0), th)
    return total


def bic(n_eff: float, sse0: float, sse1: float, dp: int) -> float:
    """Return the BIC change ``n_eff·ln(SSE₁/SSE₀) + Δp·ln n_eff`` (< 0: pays)."""
    return n_eff * math.log(max(sse1, 1e-300) / max(sse0, 1e-300)) + dp * math.log(n_eff)


__all__ = ['Bounds', 'Score', 'bic', 'box_qp', 'cv_grams', 'linear_qp', 'solve_gram',
           'solve_grams', 'sse_with']
