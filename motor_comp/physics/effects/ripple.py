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


@njit(cache=True)
def ripple_force(x, period, a, b):
    """Ripple force [N] at position ``x`` [m]; ``a``, ``b`` are sin/cos amplitudes [N]."""
    w = 2.0 * np.pi / period
    f = 0.0 * x
    for h in range(a.shape[0]):
        f = f + a[h] * np.sin((h + 1) * w * x) + b[h] * np.cos((h + 1) * w * x)
    return f


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
