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
from scipy.ndimage import correlate1d

_CACHE: dict = {}


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
