"""The minimisers the nonlinear searches use: Brent's, Nelder–Mead's, Levenberg–Marquardt's.

Written here rather than called from ``scipy.optimize`` (``minimize_scalar(method=
'bounded')``, ``minimize(method='Nelder-Mead')`` and ``least_squares`` implement the
same methods, and the tests compare against them): importing ``scipy.optimize`` pulls
in ``scipy.linalg``, ``scipy.sparse``, ``scipy.special`` and ``scipy.spatial`` and cost
about 0.15 s of CPU in every ``fit`` and ``diagnose``, half the 0.33 s a whole
``diagnose`` of a 20 s run may take by the speed goal of issue 22.  Only what the
workbench asks of them is provided: a bounded scalar search to an absolute tolerance,
a simplex search from a given simplex to absolute tolerances on the points and the
costs (also stopped where the costs agree to a resolution the caller gives: scipy's
iterates until then), and a damped Gauss–Newton search of a few bounded coordinates on
a residual vector (the variable-projection residual of :mod:`.varpro`: Golub & Pereyra's
own method) to absolute tolerances on the step and the fall of the cost.

References: R. P. Brent, *Algorithms for Minimization without Derivatives* (1973), ch. 5;
G. E. Forsythe, M. A. Malcolm, C. B. Moler, *Computer Methods for Mathematical
Computations* (1977), procedure ``fmin``; J. A. Nelder, R. Mead, "A simplex method for
function minimization", Comput. J. 7 (1965) 308–313, with the coefficients and the
ordering rules of J. C. Lagarias et al., SIAM J. Optim. 9 (1998) 112–147; K. Levenberg,
Q. Appl. Math. 2 (1944) 164–168; D. W. Marquardt, J. SIAM 11 (1963) 431–441 (the
scaling by diag JᵀJ).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Callable

import numpy as np

#: the golden section's smaller share, (3 − √5)/2
_GOLDEN = 0.5 * (3.0 - math.sqrt(5.0))
#: √ of the double-precision machine epsilon: the relative resolution of a minimum
_SQRT_EPS = math.sqrt(2.2e-16)
#: damped steps tried per Levenberg–Marquardt iteration before it stops (λ × 10 each)
_MAX_REJECTIONS = 8


@dataclasses.dataclass(frozen=True)
class Minimum:
    """Where a search ended: the point, its cost and how many costs it evaluated."""

    x: np.ndarray | float
    fun: float
    nfev: int


def _away(value: float, step: float) -> float:
    """Return ``step`` with the sign of ``value`` (+ for 0), as Fortran's ``SIGN``."""
    return step if value >= 0.0 else -step


def brent_bounded(f: Callable[[float], float], lo: float, hi: float, *, xatol: float = 1e-5,
                  maxfev: int = 500) -> Minimum:
    """Return the minimum of ``f`` on ``[lo, hi]`` by Brent's method, to ``xatol``.

    Golden sections and successive parabolic interpolation; the tolerance grows by
    √ε·|x|.  The first point is the golden section of the interval from ``lo``; a
    parabolic step is taken when it falls inside the interval and shrinks the step
    before last by half, else a golden-section step; no point is evaluated closer than
    the tolerance to another or to the ends.
    """
    a, b = float(lo), float(hi)
    x = w = v = a + _GOLDEN * (b - a)
    fx = fw = fv = float(f(x))
    nfev = 1
    d = e = 0.0
    while nfev < maxfev:
        xm = 0.5 * (a + b)
        tol1 = _SQRT_EPS * abs(x) + xatol / 3.0
        tol2 = 2.0 * tol1
        if abs(x - xm) <= tol2 - 0.5 * (b - a):
            break
        golden = True
        if abs(e) > tol1:
            # the parabola through (v, fv), (w, fw), (x, fx): its vertex at x + p/q
            r = (x - w) * (fx - fv)
            q = (x - v) * (fx - fw)
            p = (x - v) * q - (x - w) * r
            q = 2.0 * (q - r)
            if q > 0.0:
                p = -p
            q = abs(q)
            r, e = e, d
            if abs(p) < abs(0.5 * q * r) and q * (a - x) < p < q * (b - x):
                d = p / q
                u = x + d
                if u - a < tol2 or b - u < tol2:
                    d = _away(xm - x, tol1)
                golden = False
        if golden:
            e = (a - x) if x >= xm else (b - x)
            d = _GOLDEN * e
        u = x + _away(d, max(abs(d), tol1))
        fu = float(f(u))
        nfev += 1
        if fu <= fx:
            if u >= x:
                a = x
            else:
                b = x
            v, fv, w, fw, x, fx = w, fw, x, fx, u, fu
        else:
            if u < x:
                a = u
            else:
                b = u
            if fu <= fw or w == x:
                v, fv, w, fw = w, fw, u, fu
            elif fu <= fv or v == x or v == w:
                v, fv = u, fu
    return Minimum(x, fx, nfev)


def nelder_mead(f: Callable[[np.ndarray], float], simplex: np.ndarray, *,
                xatol: float = 1e-4, fatol: float = 1e-4, maxiter: int = 200,
                resolution: float = 0.0) -> Minimum:
    """Return the minimum of ``f`` found by the Nelder–Mead simplex from ``simplex``.

    ``simplex`` holds ``n + 1`` points of ``n`` coordinates.  Reflection 1, expansion 2,
    contraction ½, shrink ½; the search stops when every vertex is within ``xatol`` of
    the best in each coordinate and every cost within ``fatol`` of the best, when every
    cost is within ``resolution`` > 0 of the best (the vertices are then the same to
    the caller, however far apart), or after ``maxiter`` iterations.
    """
    sim = np.array(simplex, dtype=float)
    n = sim.shape[1]
    fsim = np.array([float(f(p)) for p in sim])
    nfev = n + 1
    order = np.argsort(fsim)
    sim, fsim = sim[order], fsim[order]
    for _ in range(1, maxiter):
        spread = np.max(np.abs(fsim[0] - fsim[1:]))
        if (resolution > 0.0 and spread <= resolution) or \
                (np.max(np.abs(sim[1:] - sim[0])) <= xatol and spread <= fatol):
            break
        centre = np.add.reduce(sim[:-1], 0) / n
        worst = sim[-1]
        xr = 2.0 * centre - worst                 # reflection
        fr = float(f(xr))
        nfev += 1
        shrink = False
        if fr < fsim[0]:
            xe = 3.0 * centre - 2.0 * worst       # expansion
            fe = float(f(xe))
            nfev += 1
            sim[-1], fsim[-1] = (xe, fe) if fe < fr else (xr, fr)
        elif fr < fsim[-2]:
            sim[-1], fsim[-1] = xr, fr
        elif fr < fsim[-1]:
            xc = 1.5 * centre - 0.5 * worst       # contraction outside
            fc = float(f(xc))
            nfev += 1
            if fc <= fr:
                sim[-1], fsim[-1] = xc, fc
            else:
                shrink = True
        else:
            xc = 0.5 * centre + 0.5 * worst       # contraction inside
            fc = float(f(xc))
            nfev += 1
            if fc < fsim[-1]:
                sim[-1], fsim[-1] = xc, fc
            else:
                shrink = True
        if shrink:
            for j in range(1, n + 1):
                sim[j] = sim[0] + 0.5 * (sim[j] - sim[0])
                fsim[j] = float(f(sim[j]))
            nfev += n
        order = np.argsort(fsim)
        sim, fsim = sim[order], fsim[order]
    return Minimum(sim[0], float(fsim[0]), nfev)


def levenberg_marquardt(residual: Callable[[np.ndarray], np.ndarray], x0: np.ndarray, *,
                        lo: np.ndarray, hi: np.ndarray, step: np.ndarray, xatol: float,
                        fatol: float, maxiter: int = 30) -> Minimum:
    """Return the least ``‖r(x)‖²`` found by Levenberg–Marquardt from ``x0`` inside the box.

    Each iteration takes the Jacobian of ``residual`` by forward differences of
    ``step`` (backwards where the forward point would leave ``[lo, hi]``) and solves
    ``(JᵀJ + λ·diag JᵀJ) δ = −Jᵀr`` (Marquardt's scaling); λ falls tenfold after a step
    that lowers the cost and rises tenfold after one that does not (at most
    :data:`_MAX_REJECTIONS` in a row).  A coordinate on a bound whose gradient points
    out of the box is held there, the others step and are clipped to it.  Stops after
    an accepted step that moves every coordinate by at most ``xatol`` or lowers the
    cost by at most ``fatol``, when no damping lowers it, or after ``maxiter``
    Jacobians.  ``fun`` is ``‖r‖²`` at ``x``; ``nfev`` counts the residuals evaluated.
    """
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    x = np.clip(np.asarray(x0, dtype=float), lo, hi)
    r = np.asarray(residual(x), dtype=float)
    f = float(r @ r)
    nfev = 1
    lam = 1e-3
    n = x.size
    for _ in range(maxiter):
        J = np.empty((r.size, n))
        for i in range(n):
            h = step[i] if x[i] + step[i] <= hi[i] else -step[i]
            xi = x.copy()
            xi[i] += h
            J[:, i] = (np.asarray(residual(xi), dtype=float) - r) / h
            nfev += 1
        A, g = J.T @ J, J.T @ r
        free = ~(((x <= lo) & (g > 0.0)) | ((x >= hi) & (g < 0.0)))
        if not free.any():
            break
        Af, gf = A[np.ix_(free, free)], g[free]
        scale = np.diag(Af).copy()
        scale = np.maximum(scale, 1e-12 * max(float(scale.max()), 1e-300))
        accepted = False
        for _ in range(_MAX_REJECTIONS):
            try:
                dx = np.linalg.solve(Af + lam * np.diag(scale), -gf)
            except np.linalg.LinAlgError:
                lam *= 10.0
                continue
            xn = x.copy()
            xn[free] += dx
            xn = np.clip(xn, lo, hi)
            if np.array_equal(xn, x):
                break
            rn = np.asarray(residual(xn), dtype=float)
            fn = float(rn @ rn)
            nfev += 1
            if fn < f:
                accepted = True
                break
            lam *= 10.0
        if not accepted:
            break
        moved, fell = float(np.max(np.abs(xn - x))), f - fn
        x, r, f = xn, rn, fn
        lam = max(lam / 10.0, 1e-12)
        if moved <= xatol or fell <= fatol:
            break
    return Minimum(x, f, nfev)


def next_fast_len(n: int) -> int:
    """Return the least length ``≥ n`` with no prime factor above 11 (a fast FFT size).

    The lengths ``scipy.fft.next_fast_len`` gives for complex transforms (pocketfft's
    fast radices), so a spectrum's frequency grid is the same; here because that
    import alone cost ~0.02 s of CPU for one number.
    """
    n = max(int(n), 1)
    while True:
        m = n
        for p in (2, 3, 5, 7, 11):
            while m % p == 0:
                m //= p
        if m == 1:
            return n
        n += 1


__all__ = ['Minimum', 'brent_bounded', 'levenberg_marquardt', 'nelder_mead', 'next_fast_len']
