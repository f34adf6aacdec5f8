"""Savitzky–Golay coefficients and filter (centred least-squares polynomial, zero phase).

Written here rather than imported from ``scipy.signal`` (whose ``savgol_coeffs`` and
``savgol_filter`` compute the same numbers, and which the tests compare against): importing
``scipy.signal`` pulls in ``scipy.stats`` and costs about 0.45 s of CPU in every command
that reads a run — more than a whole ``diagnose`` of a 20 s run, against the speed goal
of issue 22.  Only the two modes the workbench uses are provided: ``'mirror'`` and
``'interp'`` (the polynomial fitted to the first and last window gives the end values).

Reference: A. Savitzky, M. J. E. Golay, "Smoothing and differentiation of data by
simplified least squares procedures", Anal. Chem. 36 (1964) 1627–1639.
"""
from __future__ import annotations

import math

import numpy as np
from numba import njit

from motor_comp.physics import aot

_CACHE: dict = {}

#: the float64 machine epsilon (C's ``DBL_EPSILON``)
_EPS = float(np.finfo(float).eps)


def correlate1d(x: np.ndarray, weights: np.ndarray, *, axis: int = 0,
                mode: str = 'mirror') -> np.ndarray:
    """Correlate ``x`` with ``weights`` along ``axis``: ``scipy.ndimage.correlate1d``'s sums.

    Written here because importing ``scipy.ndimage`` (with the ``scipy.special`` it
    loads) cost every command that reads a run 0.07 s of CPU beyond what numba's first
    call loads of scipy anyway.  The sums are ndimage's, term for term (bit for bit,
    tested): an odd kernel whose taps mirror within the machine epsilon (a smoother) adds
    each pair of samples before weighting them, outermost pair first, one that mirrors
    with opposite signs (a derivative) their difference; any other kernel runs its taps
    last-first.  A rounding off in the last bit moved samples across the sliding
    threshold and flipped three marginal backlash decisions of the independent suite.

    Parameters
    ----------
    x : numpy.ndarray
        Samples, any shape (float64).
    weights : numpy.ndarray
        Kernel of odd or even length, centred at ``len // 2`` (origin 0).
    axis : int
        Axis of the samples.
    mode : {'mirror', 'constant'}
        Extension beyond the ends: reflected about the end samples (``d c b | a b c d |
        c b a``) or zeros.
    """
    if mode not in ('mirror', 'constant'):
        raise ValueError(f"correlate1d mode must be 'mirror' or 'constant', got {mode!r}")
    x = np.asarray(x, dtype=float)
    w = np.ascontiguousarray(weights, dtype=float)
    n = len(w)
    size1 = n // 2
    symmetric = 0
    if n % 2:
        symmetric = 1
        for i in range(1, size1 + 1):
            if abs(w[size1 + i] - w[size1 - i]) > _EPS:
                symmetric = 0
                break
        if not symmetric:
            symmetric = -1
            for i in range(1, size1 + 1):
                if abs(w[size1 + i] + w[size1 - i]) > _EPS:
                    symmetric = 0
                    break
    moved = np.moveaxis(x, axis, -1)
    lines = np.ascontiguousarray(moved).reshape(-1, moved.shape[-1])
    out = _correlate_lines_entry(lines, w, mode == 'mirror', symmetric)
    return np.ascontiguousarray(np.moveaxis(out.reshape(moved.shape), -1, axis))


@njit(cache=True)
def _mirror_index(k, L):
    # the sample at index k of a line of L reflected about its end samples, repeatedly
    if L == 1:
        return 0
    p = 2 * (L - 1)
    k = k % p
    return k if k < L else p - k


@aot.ahead(aot.F8_2D, aot.F8_1D, aot.BOOL, aot.I8)
@njit(cache=True)
def _correlate_lines(lines, w, mirror, symmetric):
    # ndimage's NI_Correlate1D on each line: the same extension and, for every output,
    # the same sum in the same order (taken tap by tap across the line, which the
    # compiler vectorises without reordering any one sum)
    nl, L = lines.shape
    n = w.shape[0]
    size1 = n // 2
    size2 = n - size1 - 1
    out = np.empty((nl, L))
    buf = np.empty(L + size1 + size2)
    for li in range(nl):
        line = lines[li]
        for k in range(-size1, L + size2):
            if 0 <= k < L:
                buf[k + size1] = line[k]
            elif mirror:
                buf[k + size1] = line[_mirror_index(k, L)]
            else:
                buf[k + size1] = 0.0
        o = out[li]
        if symmetric != 0:
            w0 = w[size1]
            for ll in range(L):
                o[ll] = buf[ll + size1] * w0
            for jj in range(-size1, 0):
                wj = w[size1 + jj]
                lo = size1 + jj
                hi = size1 - jj
                if symmetric > 0:
                    for ll in range(L):
                        o[ll] += (buf[ll + lo] + buf[ll + hi]) * wj
                else:
                    for ll in range(L):
                        o[ll] += (buf[ll + lo] - buf[ll + hi]) * wj
        else:
            wl = w[size1 + size2]
            for ll in range(L):
                o[ll] = buf[ll + size1 + size2] * wl
            for jj in range(-size1, size2):
                wj = w[size1 + jj]
                lo = size1 + jj
                for ll in range(L):
                    o[ll] += buf[ll + lo] * wj
    return out


def _check(window: int, polyorder: int, deriv: int) -> None:
    if window < 1 or window % 2 == 0:
        raise ValueError(f'Savitzky-Golay window must be a positive odd number, got {window}')
    if not 0 <= polyorder < window:
        raise ValueError(f'Savitzky-Golay polyorder must be in [0, window), got {polyorder}')
    if deriv < 0:
        raise ValueError(f'Savitzky-Golay derivative order must be >= 0, got {deriv}')


def _fit_matrix(window: int, polyorder: int) -> np.ndarray:
    """Pseudo-inverse ``(p + 1, W)`` of the Vandermonde matrix at offsets −h…h (cached)."""
    key = ('pinv', window, polyorder)
    p = _CACHE.get(key)
    if p is None:
        half = window // 2
        x = np.arange(-half, half + 1, dtype=float)
        p = np.linalg.pinv(np.vander(x, polyorder + 1, increasing=True))
        _CACHE[key] = p
    return p


def savgol_coeffs(window: int, polyorder: int, *, deriv: int = 0,
                  delta: float = 1.0) -> np.ndarray:
    """Weights that, dotted with a window of samples, give the ``deriv``-th derivative.

    Parameters
    ----------
    window : int
        Odd number of samples.
    polyorder : int
        Degree of the fitted polynomial, ``< window``.
    deriv : int
        Derivative order (0: the smoothed value).
    delta : float
        Sample spacing (the derivative's unit is per ``delta**deriv``).

    Returns
    -------
    numpy.ndarray
        ``window`` weights in sample order (scipy's ``use='dot'``).
    """
    _check(window, polyorder, deriv)
    if deriv > polyorder:
        return np.zeros(window)
    c = _fit_matrix(window, polyorder)[deriv] * math.factorial(deriv)
    return c / delta ** deriv


def savgol_filter(y: np.ndarray, window: int, polyorder: int, *, deriv: int = 0,
                  delta: float = 1.0, axis: int = 0, mode: str = 'interp') -> np.ndarray:
    """Savitzky–Golay filter of ``y`` along ``axis`` (scipy's ``savgol_filter`` semantics).

    Parameters
    ----------
    y : numpy.ndarray
        Samples (any unit).
    window, polyorder, deriv, delta
        As in :func:`savgol_coeffs`.
    axis : int
        Axis of the samples.
    mode : {'interp', 'mirror'}
        End treatment: the polynomial of the first/last full window (``'interp'``,
        needs ``len ≥ window``) or reflection about the end samples (``'mirror'``).

    Returns
    -------
    numpy.ndarray
        Filtered values, same shape as ``y``.
    """
    y = np.asarray(y, dtype=float)
    coeffs = savgol_coeffs(window, polyorder, deriv=deriv, delta=delta)
    if mode == 'mirror':
        return correlate1d(y, coeffs, axis=axis, mode='mirror')
    if mode != 'interp':
        raise ValueError(f"Savitzky-Golay mode must be 'interp' or 'mirror', got {mode!r}")
    n = y.shape[axis]
    if n < window:
        raise ValueError(f'Savitzky-Golay interp mode needs at least {window} samples, got {n}')
    out = correlate1d(y, coeffs, axis=axis, mode='constant')
    ym = np.moveaxis(y, axis, 0)
    om = np.moveaxis(out, axis, 0)
    half = window // 2
    if half == 0:
        return out
    fitm = _fit_matrix(window, polyorder)
    # the ends: evaluate the polynomial (or its derivative) fitted to the first and last
    # full window at the offsets of the samples it covers
    offs = np.arange(-half, half + 1, dtype=float)
    k = np.arange(polyorder + 1)
    scale = np.array([0.0 if j < deriv else math.factorial(j) / math.factorial(j - deriv)
                      for j in k]) / delta ** deriv
    powers = np.where(k >= deriv, k - deriv, 0)
    basis = np.where(k >= deriv, offs[:, None] ** powers[None, :], 0.0) * scale
    ends = basis @ fitm            # (window, window): values at each offset from samples
    head = np.tensordot(ends[:half], ym[:window], axes=(1, 0))
    tail = np.tensordot(ends[half + 1:], ym[n - window:], axes=(1, 0))
    om[:half] = head
    om[n - half:] = tail
    return out


# Python calls the kernels above through their entries: compiled ahead of time where
# built (see motor_comp.physics.aot), else the JIT
_correlate_lines_entry = aot.entry(_correlate_lines)
