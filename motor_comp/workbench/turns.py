"""The turn model: where, between samples, the axis reverses and how long it sticks.

The acceleration at sample ``k`` (second difference of the position) is the motion's
acceleration averaged with a hat kernel over ``t_k ± dt``, so the friction it balances
is the friction averaged with that kernel.  At a turn the Coulomb force switches at the
*instant* the velocity changes sign, and where the axis sticks for a while it is not
``±fc`` at all but whatever balances the drive.  The sign of a short derivative
switches at a whole sample, late or early by up to a sample (and in the middle of a
stick); the Coulomb force then trades with the acceleration's lag — a spurious dead
time and, through the back-EMF (``k·τ`` of force per unit acceleration), a mass 25 %
low on the project's own chirp.  So each turn is fitted on the raw position
(:func:`reversal_shares`), and the sign-based friction columns are the shares of each
sample's kernel spent sliding forward, backward and stuck.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from motor_comp.physics import aot

#: half-width of the local position fit at a reversal, as a share of the derivative window
#: (8 samples of a 21-sample window: about the time the drive takes to turn the axis)
REVERSAL_HALF = 0.4
#: least travel [position resolutions] of both sides of a turn within the local fit
MIN_TURN = 5.0
#: shortest stop at a turn resolved from the position [samples]
MIN_STICK = 1.0


def reversal_shares(x: np.ndarray, v: np.ndarray, half: int, eps: float = 0.0, *,
                    spread: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the shares of each sample spent sliding forward, backward and stuck.

    Each turn (a change of the sign of ``v``; flips closer than ``half`` samples are
    one turn) is fitted on the raw position over ``±half`` samples: an arc into a stop
    at ``ta``, the position held until ``tb``, an arc out (quadratic and cubic terms on
    each side: the acceleration jumps by ``2·fc/M`` at a turn without sticking and
    starts from 0 after a stick).  A stop shorter than ``MIN_STICK`` samples is not
    resolved and the two arcs meet (``ta = tb``).  Flips that are not a clear turn keep
    the sign of ``v``: spread over more than ``half`` samples (an axis at rest), back
    the same way, or a turn whose two sides do not both move ``MIN_TURN`` position
    resolutions away within the fit (too slow to locate).

    Parameters
    ----------
    x : ndarray
        Position [m or rad] at every sample.
    v : ndarray
        Pointwise velocity [m/s or rad/s] (its sign; exact zeros count as stopped).
    half : int
        Half-width of the local fit [samples], >= 3.
    eps : float
        Position resolution [m or rad]: the encoder quantum or the noise, the larger.
    spread : bool
        Spread the switch over the hat kernel (a held command: the model is the
        step-averaged force balance).  False for a sampled input, whose model is read
        at the sample instants: the switch is then the direction at each instant.

    Returns
    -------
    fwd, bwd, stuck : ndarray
        Share (0–1) of the kernel at each sample spent sliding forward, backward, and
        stuck at a fitted turn; away from turns ``v > 0``, ``v < 0`` and 0.
        ``fwd − bwd`` is the Coulomb column; on the stuck share the friction is the
        drive force.
    """
    s = np.sign(v)
    fwd, bwd = (s > 0).astype(float), (s < 0).astype(float)
    stuck = np.zeros(len(s))
    nz = np.flatnonzero(s)
    if len(nz) < 2:
        return fwd, bwd, stuck
    sn = s[nz]
    flips = np.flatnonzero(sn[:-1] != sn[1:])
    _fit_turns_entry(np.ascontiguousarray(x, dtype=float), nz, sn, flips, int(half),
                     MIN_TURN * float(eps), bool(spread), float(MIN_STICK), fwd, bwd, stuck)
    return fwd, bwd, stuck


@njit(cache=True)
def _hat_before(d):
    # area of the unit hat kernel on [−1, 1] left of d [samples]
    d = min(max(d, -1.0), 1.0)
    return 0.5 * (1.0 + d) ** 2 if d <= 0.0 else 1.0 - 0.5 * (1.0 - d) ** 2


@aot.ahead(aot.F8_1D, aot.I8_1D, aot.F8_1D, aot.I8_1D, aot.I8, aot.F8, aot.BOOL, aot.F8,
           *(aot.F8_1D,) * 3)
@njit(cache=True)
def _fit_turns(x, nz, sn, flips, half, min_travel, spread, min_stick, fwd, bwd, stuck):
    # the turn loop of reversal_shares (compiled: it runs at every backlash trial)
    n = x.shape[0]
    i = 0
    while i < flips.shape[0]:
        j = i
        # flips of a slow, noisy turn: one turn (or none) between them
        while j + 1 < flips.shape[0] and nz[flips[j + 1]] - nz[flips[j] + 1] < half:
            j += 1
        a, b = nz[flips[i]], nz[flips[j] + 1]
        s0, s1 = sn[flips[i]], sn[flips[j] + 1]
        i = j + 1
        lo, hi = a - half, b + half + 1
        if s0 == s1 or b - a > half or lo < 0 or hi > n:
            continue                # a touch, an axis at rest, or at the record ends
        # a turn: both ends of the fit clearly behind the turning point (a maximum of the
        # position after forward motion, a minimum after backward motion)
        xm = np.mean(x[a:b + 1])
        if min(s0 * (xm - x[lo]), s0 * (xm - x[hi - 1])) <= min_travel:
            continue
        y = x[lo:hi] - np.mean(x[lo:hi])
        y = y / max(np.max(np.abs(y)), 1e-300)
        # searched from a sample before the last old-sign sample to one after the first
        # new-sign one: the short derivative's sign change is off by up to a sample
        # where the two sides' accelerations differ
        t_lo, t_hi = a - 1.0 - lo, b + 1.0 - lo
        ta, tb = _span_search(y, t_lo, t_hi, float(half), True)
        if tb - ta < min_stick:
            # shorter than the resolved stop: two arcs that meet fit the turn as well
            # (the plateau only absorbs the arcs' misfit)
            ta, tb = _span_search(y, t_lo, t_hi, float(half), False)
        for k in range(lo, hi):
            if spread:
                before = _hat_before(ta + lo - k)
                after = 1.0 - _hat_before(tb + lo - k)
            else:
                before = 1.0 if k < ta + lo else 0.0
                after = 1.0 if k > tb + lo else 0.0
            if s0 > 0:
                fwd[k], bwd[k] = before, after
            else:
                fwd[k], bwd[k] = after, before
            stuck[k] = 1.0 - before - after


@njit(cache=True)
def _arc_stats(y, t, half, left):
    # the arc columns (d², d³) of one side are 0 on the other side and on the plateau,
    # so the 5-column normal equations split into two 2×2 blocks coupled only through
    # the level: each side reduces to three numbers (sᵀG⁻¹s, sᵀG⁻¹b, bᵀG⁻¹b)
    g11 = g12 = g22 = s1 = s2 = b1 = b2 = 0.0
    for j in range(y.shape[0]):
        d = (j - t) / half
        if (left and d >= 0.0) or (not left and d <= 0.0):
            continue
        c1, c2 = d * d, d * d * d
        g11 += c1 * c1
        g12 += c1 * c2
        g22 += c2 * c2
        s1 += c1
        s2 += c2
        b1 += c1 * y[j]
        b2 += c2 * y[j]
    g11 += 1e-12 * (1.0 + g11)      # a side with one sample or none: its arc is 0
    g22 += 1e-12 * (1.0 + g22)
    det = g11 * g22 - g12 * g12
    i11, i12, i22 = g22 / det, -g12 / det, g11 / det
    q = s1 * (i11 * s1 + i12 * s2) + s2 * (i12 * s1 + i22 * s2)
    p = s1 * (i11 * b1 + i12 * b2) + s2 * (i12 * b1 + i22 * b2)
    w = b1 * (i11 * b1 + i12 * b2) + b2 * (i12 * b1 + i22 * b2)
    return q, p, w


@njit(cache=True)
def _span_search(y, t_lo, t_hi, half, stick):
    n = y.shape[0]
    sy = 0.0
    yy = 0.0
    for j in range(n):
        sy += y[j]
        yy += y[j] * y[j]
    best_a, best_b = t_lo, t_lo
    lo_a, hi_a, lo_b, hi_b = t_lo, t_hi, t_lo, t_hi
    for step in (0.25, 0.05, 0.0125):
        na = int(np.floor((hi_a - lo_a) / step + 1e-9)) + 1
        nb = int(np.floor((hi_b - lo_b) / step + 1e-9)) + 1
        L = np.empty((na, 3))
        for i in range(na):
            L[i, 0], L[i, 1], L[i, 2] = _arc_stats(y, lo_a + i * step, half, True)
        R = np.empty((nb, 3))
        for k in range(nb):
            R[k, 0], R[k, 1], R[k, 2] = _arc_stats(y, lo_b + k * step, half, False)
        best = np.inf
        for i in range(na):
            ta = lo_a + i * step
            for k in range(nb):
                tb = lo_b + k * step
                if tb < ta - 1e-9 or (not stick and abs(tb - ta) > 1e-9):
                    continue
                c0 = (sy - L[i, 1] - R[k, 1]) / (n - L[i, 0] - R[k, 0])
                e = yy - c0 * sy - (L[i, 2] - c0 * L[i, 1]) - (R[k, 2] - c0 * R[k, 1])
                if e < best:
                    best, best_a, best_b = e, ta, tb
        # the next grid spans one step of this one each way, inside the search range
        lo_a, hi_a = max(best_a - step, t_lo), min(best_a + step, t_hi)
        lo_b, hi_b = max(best_b - step, t_lo), min(best_b + step, t_hi)
        if not stick:
            lo_b, hi_b = lo_a, hi_a
    return best_a, max(best_b, best_a)


__all__ = ['MIN_STICK', 'MIN_TURN', 'REVERSAL_HALF', 'reversal_shares']


# Python calls the kernels above through their entries: compiled ahead of time where
# built (see motor_comp.physics.aot), else the JIT
_fit_turns_entry = aot.entry(_fit_turns)
