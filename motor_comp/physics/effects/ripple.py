"""Force ripple / cogging, periodic in position (Tan 2002 eq. 9 is the first harmonic).

``F = Σ_h [a_h·sin(h·ωx) + b_h·cos(h·ωx)]``, ``ω = 2π/period``.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from motor_comp.errors import ParameterError, check_finite, check_positive
from motor_comp.physics.effects.base import Effect

#: largest number of harmonics the compiled kernels carry
MAX_HARMONICS = 16


@njit(cache=True, inline='always', error_model='numpy')
def ripple_sum(x, period, a, ia, b, ib, nh):
    """Ripple force [N] at ``x`` [m] with ``a_h = a[ia + h]``, ``b_h = b[ib + h]``, h < nh.

    The law of the effect, shared by :func:`ripple_force` and the plant kernel (which
    passes its packed parameter vector with offsets instead of slicing views off it in
    the hot loop).  Harmonics h ≥ 2 come from the angle-addition recurrence
    ``sin((h+1)θ) = sin hθ·cos θ + cos hθ·sin θ`` (and the cosine alike) on one sin/cos
    pair: exact identities, rounding error growing like h·eps of the amplitude, instead
    of a sin and a cos per harmonic; odd/even symmetry in ``x`` is kept bit for bit.
    A single pure sine harmonic needs no cosine at all (exact special case).
    """
    th = 2.0 * np.pi / period * x
    if nh == 1 and b[ib] == 0.0:
        # one pure sine harmonic (Tan eq. 9 with B1 = 0, the PMLM default): the cosine
        # term is exactly 0, and sin alone is cheaper than the sin/cos pair
        return a[ia] * np.sin(th)
    s1 = np.sin(th)
    c1 = np.cos(th)
    f = a[ia] * s1 + b[ib] * c1
    s = s1
    c = c1
    for h in range(1, nh):
        s, c = s * c1 + c * s1, c * c1 - s * s1
        f = f + a[ia + h] * s + b[ib + h] * c
    return f


@njit(cache=True, error_model='numpy')
def ripple_force(x, period, a, b):
    """Ripple force [N] at position ``x`` [m]; ``a``, ``b`` are sin/cos amplitudes [N]."""
    return ripple_sum(x, period, a, 0, b, 0, a.shape[0])


@dataclasses.dataclass(frozen=True)
class Ripple(Effect):
    """Position-periodic force ripple (cogging, detent force).

    Parameters
    ----------
    period : float
        Spatial period of the first harmonic [m], > 0 (magnet pitch, screw lead, ...).
    harmonics : tuple of (a_h, b_h)
        Sine and cosine amplitudes [N] of harmonics h = 1, 2, ...
    """

    name = 'ripple'
    title = 'force ripple'
    period: float = 0.02
    harmonics: tuple = ((0.0, 0.0),)

    def __post_init__(self) -> None:
        object.__setattr__(self, 'period', check_positive('ripple.period [m]', self.period))
        try:
            hs = tuple((check_finite(f'ripple.harmonics[{i}][0] [N]', h[0]),
                        check_finite(f'ripple.harmonics[{i}][1] [N]', h[1]))
                       for i, h in enumerate(self.harmonics))
        except (TypeError, IndexError):
            raise ParameterError('ripple.harmonics must be a list of [a_h, b_h] pairs') from None
        if not 1 <= len(hs) <= MAX_HARMONICS:
            raise ParameterError(
                f'ripple.harmonics must have 1..{MAX_HARMONICS} pairs, got {len(hs)}')
        object.__setattr__(self, 'harmonics', hs)

    @property
    def a(self) -> np.ndarray:
        """Sine amplitudes [N]."""
        return np.array([h[0] for h in self.harmonics])

    @property
    def b(self) -> np.ndarray:
        """Cosine amplitudes [N]."""
        return np.array([h[1] for h in self.harmonics])

    @property
    def amplitudes(self) -> np.ndarray:
        """Amplitude of each harmonic, sqrt(a_h² + b_h²) [N]."""
        return np.hypot(self.a, self.b)

    def force(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Ripple force [N] at positions ``x`` [m]."""
        return ripple_force(np.asarray(x, dtype=float), self.period, self.a, self.b)

    def regressors(self, x: np.ndarray, v: np.ndarray | None = None) -> np.ndarray:
        """Columns ``[sin ωx, cos ωx, sin 2ωx, cos 2ωx, ...]`` for the current period."""
        x = np.asarray(x, dtype=float)
        w = 2.0 * np.pi / self.period
        cols = []
        for h in range(1, len(self.harmonics) + 1):
            cols += [np.sin(h * w * x), np.cos(h * w * x)]
        return np.stack(cols, axis=1)
