"""Force ripple / cogging, periodic in position (Tan 2002 eq. 9 is the first harmonic).

``F = Σ_h [a_h·sin(h·ωx) + b_h·cos(h·ωx)]``, ``ω = 2π/period``.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.errors import ParameterError, check_finite, check_positive
from motor_comp.physics import aot
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.identification import Column, Context, Param, Shape, Summary, Term

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


@aot.ahead(aot.F8, aot.F8_1D, aot.I8)
@njit(cache=True)
def harmonic_columns(w, x, nh):
    """Return ``sin(h·w·x)``, ``cos(h·w·x)`` for ``h = 1…nh`` side by side, ``(n, 2·nh)``.

    The identification columns of every harmonic in one pass: the fundamental by the
    libm (the same product and calls as ``np.sin(w * x)``, ``np.cos(w * x)``), the
    harmonics by the angle-addition recurrence
    ``sin((h+1)z) = sin(hz)·cos z + cos(hz)·sin z`` (and the cosine's).  A period
    search evaluates all harmonics at each trial: two libm calls per harmonic and
    sample were most of a ripple's scoring (0.7 of 2.2 s on HSM150's four runs).  The
    recurrence's rounding grows by about an ulp per harmonic (≤ 1e-14 at six; tested),
    far below any force the columns are fitted to.
    """
    n = x.shape[0]
    # column by column in memory (returned transposed, Fortran-ordered): the smoothing
    # reads each column whole, without a transposed copy
    out = np.empty((2 * nh, n))
    for i in range(n):
        z = w * x[i]
        s1 = np.sin(z)
        c1 = np.cos(z)
        s, c = s1, c1
        out[0, i] = s
        out[1, i] = c
        for h in range(1, nh):
            s, c = s * c1 + c * s1, c * c1 - s * s1
            out[2 * h, i] = s
            out[2 * h + 1, i] = c
    return out.T


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
    position_dependent = True
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


@dataclasses.dataclass(frozen=True)
class SpatialSpectrum:
    """Amplitude spectrum of a force against position.

    Parameters
    ----------
    frequency : ndarray
        Spatial frequency [cycles/m] (or cycles/rad for a rotary axis).
    amplitude : ndarray
        Amplitude [N] of the sinusoid at each frequency.
    bin_width : float
        Position grid step [m].
    span : float
        Position range covered [m].
    """

    frequency: np.ndarray
    amplitude: np.ndarray
    bin_width: float
    span: float

    def peak_period(self, *, min_period: float, max_period: float) -> float:
        """Return the period [m] of the largest peak within the allowed range."""
        f = self.frequency
        ok = (f >= 1.0 / max_period) & (f <= 1.0 / min_period)
        if not np.any(ok):
            return float('nan')
        i = np.flatnonzero(ok)[np.argmax(self.amplitude[ok])]
        return 1.0 / float(f[i])

    def amplitude_at(self, freq: float) -> float:
        """Return the largest amplitude [N] within one resolution bin of ``freq``."""
        df = 1.0 / self.span
        m = np.abs(self.frequency - freq) <= df
        return float(np.max(self.amplitude[m])) if np.any(m) else 0.0


def spatial_spectrum(x: np.ndarray, r: np.ndarray, *, n_bins: int | None = None) \
        -> SpatialSpectrum:
    """Return the spectrum of ``r`` against position ``x`` (binned means, padded FFT).

    The axis travels the same positions many times at different speeds; averaging the
    residual in position bins keeps what is periodic in position and averages out what
    is not, and a uniform position grid makes the FFT applicable (the samples
    themselves are uniform in time, not in position).
    """
    x = np.asarray(x, dtype=float)
    lo, hi = float(np.min(x)), float(np.max(x))
    span = hi - lo
    if n_bins is None:
        n_bins = int(np.clip(len(x) // 8, 64, 8192))
    width = span / n_bins if span > 0 else 1.0
    idx = np.clip(((x - lo) / width).astype(int), 0, n_bins - 1)
    counts = np.bincount(idx, minlength=n_bins)
    sums = np.bincount(idx, weights=r, minlength=n_bins)
    filled = counts > 0
    centers = lo + (np.arange(n_bins) + 0.5) * width
    prof = np.interp(centers, centers[filled], sums[filled] / counts[filled])
    prof = prof - np.polyval(np.polyfit(centers, prof, 1), centers)
    nfft = 1 << int(math.ceil(math.log2(4 * n_bins)))
    win = np.hanning(n_bins)
    spec = np.fft.rfft(prof * win, nfft)
    # amplitude of a sinusoid: 2|X|/Σw for a Hann window
    amp = 2.0 * np.abs(spec) / np.sum(win)
    freq = np.fft.rfftfreq(nfft, width)
    return SpatialSpectrum(frequency=freq, amplitude=amp, bin_width=width, span=span)


#: the largest number of harmonics identified
MAX_FIT_HARMONICS = 6


#: least periods over the travel for a ripple: two tell a periodic force from a shape
#: along the travel (validated on stretches not fitted, ``RippleTerm.repeats_every``)
PERIODS_SEEN = 2.0


class RippleTerm(Term):
    """Identification of force ripple: harmonics on ``sin/cos(h·2πx/period)``.

    The period starts at the largest peak of the residual's spatial spectrum between
    eight position bins (or four samples per period at the high speeds) and half the
    travel (two periods seen) — on a rotary axis at most one revolution: a force that is
    a function of the angle repeats every turn, so a longer period is no ripple of this
    axis (only of a shaft geared faster than the one measured, which the model does not
    hold) — and is refined by variable projection within
    ``±1.5·p²/span`` (the spectrum's resolution); the harmonic count (the term's order,
    1–6, at least four samples per period at the median speed) by an information
    criterion.  It pays only if it predicts stretches of the travel it was not fitted
    on (:meth:`repeats_every`).  Each column is position-periodic: the workbench averages
    it over the acceleration stencil's kernel.
    """

    name = 'ripple'
    #: in a residual's scan: a force that varies along the travel, either way of motion
    shape = Shape('position', odd=False)
    effect = Ripple
    params = ('period',)
    force_scaled = (('ripple', 'amplitude_1'),)

    def _min_period(self, s: Summary, n_bins: float = 8192.0) -> float:
        return max(8.0 * s.travel / n_bins, 4.0 * s.dt * float(s.speeds[90]), 1e-12)

    @staticmethod
    def _max_period(travel: float, rotary: bool) -> float:
        # two periods seen; on a rotary axis one revolution at most [rad]
        return min(travel / PERIODS_SEEN, 2.0 * math.pi) if rotary else travel / PERIODS_SEEN

    def space(self, s: Summary, ctx: Context) -> tuple[Param, ...]:
        """Return ``period`` [m] (no grid: the start comes from the spectrum).

        Up to half the travel: two periods seen tell a sinusoid from a shape along the
        travel; on a rotary axis up to one revolution [rad].
        """
        hi = max(self._max_period(s.travel, s.rotary), 2.0 * self._min_period(s))
        return (Param('period', self._min_period(s), hi, resolved=True),)

    def bracket(self, value: float, s: Summary) -> tuple[float, float]:
        """Return the local search interval around a period: the spectrum's resolution."""
        dp = 1.5 * value * value / max(s.travel, 1e-12)
        return max(value - dp, 0.5 * value), value + dp

    def fold_steps(self, value: float, s: Summary) -> tuple[float, ...]:
        """Return the periods tried inside each validation fold around the all-data one."""
        dp = 1.5 * value * value / max(s.travel, 1e-12)
        return tuple(value + k * dp for k in (-0.5, -0.25, 0.0, 0.25, 0.5))

    def aliases(self, s: Summary) -> list[dict]:
        """Return ripples longer than the travel: over it they are a spring or an offset."""
        return [{'period': k * max(s.travel, 1e-9), 'harmonics': 1} for k in (1.5, 3, 6, 12)]

    def orders(self, s: Summary, eta: Mapping) -> tuple[int, int]:
        """Return the harmonic counts allowed at the period (four samples per period)."""
        min_p = max(4.0 * s.dt * float(s.speeds[50]), 1e-12)
        return 1, max(1, min(MAX_FIT_HARMONICS, int(math.floor(float(eta['period']) / min_p))))

    def order_of(self, eta: Mapping) -> int:
        """Return the harmonic count."""
        return int(eta.get('harmonics', 1))

    def with_order(self, eta: Mapping, order: int) -> dict:
        """Return ``eta`` with ``order`` harmonics."""
        return dict(eta, harmonics=int(order))

    def repeats_every(self, eta: Mapping) -> float:
        """Return the period: each period of the travel must be predicted from the others.

        Over two or three periods, harmonics of a long period would draw any shape along
        the travel (a bump the library lacks) and its copy a period away; a periodic
        force fitted without one period still sees every phase on the others, a bump's
        copy is where nothing is (the generator's bumps: 23 % and 52 % of what the
        harmonics explained where fitted; its ripples 95–100 %).
        """
        return float(eta['period'])

    def initial(self, s: Summary, ctx: Context, profile: Any) -> list[dict]:
        """Return the spectrum's largest peak and its visible harmonics as the start."""
        x, r = profile
        spec = spatial_spectrum(x, r)
        min_p = max(8 * spec.bin_width, 4.0 * s.dt * float(s.speeds[90]))
        max_p = self._max_period(spec.span, s.rotary)
        f, amp = spec.frequency, spec.amplitude
        ok = (f >= 1.0 / max_p) & (f <= 1.0 / min_p) if max_p > min_p else f < 0
        if not np.any(ok):
            return [{'period': max(max_p, 1e-6), 'harmonics': 1}]
        i = np.flatnonzero(ok)[np.argmax(amp[ok])]
        p0 = 1.0 / float(f[i])
        a1 = spec.amplitude_at(1.0 / p0)
        floor = float(np.median(amp))
        nh = 1
        for h in range(2, MAX_FIT_HARMONICS + 1):
            if h / p0 > 1.0 / min_p:
                break
            ah = spec.amplitude_at(h / p0)
            if ah > 0.15 * a1 and ah > 4 * floor:
                nh = h
        return [{'period': p0, 'harmonics': nh}]

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return ``a_h``/``b_h`` on ``sin``/``cos(h·ω·x)``, h = 1…harmonics."""
        period, nh = float(eta['period']), int(eta.get('harmonics', 1))
        w1 = 2 * math.pi / period

        # one block for every harmonic, in one compiled pass; a harmonic's value does
        # not depend on how many are computed, so its key is (period, h)
        def block(p: Any) -> np.ndarray:
            return harmonic_columns_entry(w1, np.ascontiguousarray(p.x, dtype=float), nh)
        cols = []
        for h in range(1, nh + 1):
            w = 2 * math.pi * h / period
            cols.append(Column(f'a{h}', ('sin', period, h), block, frequency=w,
                               width=2 * nh, index=2 * h - 2))
            cols.append(Column(f'b{h}', ('cos', period, h), block, frequency=w,
                               width=2 * nh, index=2 * h - 1))
        return cols

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted ripple."""
        nh = int(eta.get('harmonics', 1))
        harm = [[float(values.get((self.name, f'a{h}'), 0.0)),
                 float(values.get((self.name, f'b{h}'), 0.0))] for h in range(1, nh + 1)]
        return [Ripple(period=float(eta['period']), harmonics=harm)]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return the harmonics' coefficients and ``(period, harmonics)``."""
        e = model.get(self.name)
        coef = {}
        for h, (a, b) in enumerate(e.harmonics, start=1):
            coef[f'a{h}'], coef[f'b{h}'] = a, b
        return coef, {'period': e.period, 'harmonics': len(e.harmonics)}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``period`` [m] and each harmonic's amplitude [N]."""
        out = {('ripple', 'period'):
               lambda v: float(v.get(('ripple', 'period'), eta['period']))}
        for h in range(1, int(eta.get('harmonics', 1)) + 1):
            out[('ripple', f'amplitude_{h}')] = (
                lambda v, h=h: math.hypot(float(v.get(('ripple', f'a{h}'), 0.0)),
                                          float(v.get(('ripple', f'b{h}'), 0.0))))
        return out


TERM = RippleTerm()


# Python calls the kernels above through their entries: compiled ahead of time where
# built (see motor_comp.physics.aot), else the JIT
harmonic_columns_entry = aot.entry(harmonic_columns)
