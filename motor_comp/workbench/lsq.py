"""Least squares on augmented Gram matrices, with the terms' bounds inside the estimator.

Every fit of the workbench is ``min ‖y − Xθ‖²`` over some rows; the rows enter only
through ``[X y]ᵀ[X y]`` (per validation part, summed per fold), so a held-out score is a
few small solves.  Bounds a term declares on its coefficients (``fc ≥ 0``, ``fs ≥ fc``,
GMS element levels ≥ 0) and linear constraints (``fc ± dfc/2 ≥ 0``) are enforced in the
solve itself — bounded-variable least squares (Stark & Parker 1995, ``scipy.optimize.
lsq_linear``) on the Cholesky factor of the Gram, or SLSQP when a general linear
constraint is active — never clipped after scoring: what is scored is what is reported.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Sequence

import numpy as np
from scipy.optimize import lsq_linear, minimize


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


def _bounded(A: np.ndarray, b: np.ndarray, bounds: Bounds) -> np.ndarray:
    """Solve the normal equations under bounds (and linear constraints)."""
    p = len(b)
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    As = A / np.outer(d, d) + 1e-10 * np.eye(p)
    bs = b / d
    lo, hi = bounds.lo * d, bounds.hi * d
    if not len(bounds.b):
        # ‖Rθ − R⁻ᵀb‖² = θᵀAθ − 2bᵀθ + const: the box-constrained LS on the factor
        try:
            R = np.linalg.cholesky(As).T
        except np.linalg.LinAlgError:
            w, V = np.linalg.eigh(As)
            R = (V * np.sqrt(np.maximum(w, 1e-14))).T
        rhs = np.linalg.solve(R.T, bs)
        res = lsq_linear(R, rhs, bounds=(lo, hi), method='bvls', tol=1e-12)
        return res.x / d
    Ac = bounds.A / d
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


__all__ = ['Bounds', 'Score', 'bic', 'cv_grams', 'solve_gram', 'sse_with']
