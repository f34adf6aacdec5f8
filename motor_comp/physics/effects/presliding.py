"""Generalized Maxwell-Slip pre-sliding friction (GMS; Lampaert, Al-Bender, Swevers 2003).

N elementary blocks, each a spring ``k_i`` [N/m] with a slip limit ``α_i·|s(v)|``
(Chiew et al. eq. 3–5, DESIGN.md §3):

* sticking:  ``dF_i/dt = k_i·v``            until ``F_i`` reaches ``α_i·s(v)`` (signed:
  in the direction of motion; an element loaded against the motion unloads elastically);
* slipping:  ``dF_i/dt = c·(α_i·s(v) − F_i)`` until the velocity reverses.

``s(v)`` is the *signed* Stribeck curve (the unsigned form is unstable for v < 0).
The slip law is written in rate form with ``c`` [1/s]; it equals Lampaert's
``sgn(v)·C·(α_i − F_i/s(v))`` with ``C = c·|s(v)|``, and integrates exactly over a
step as ``F_i ← α_i s − (α_i s − F_i)·e^{−c·dt}``.  Total GMS force
``F = Σ F_i + σ·v``; ``σ·v`` is the model's ``viscous`` effect, so it is not repeated
here.  When the model has presliding, the sliding friction (coulomb + stribeck) is
carried by the elements, never added a second time.
"""
from __future__ import annotations

import dataclasses

import numpy as np
from numba import njit

from motor_comp.errors import ParameterError, check_positive
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.stribeck import stribeck_curve

#: largest number of Maxwell-slip elements the compiled kernels carry
MAX_ELEMENTS = 8


@njit(cache=True)
def gms_update(forces, slip, alpha, k, c, dx, v, s_v, dt):
    """Advance every element by one step, in place; return the summed element force [N].

    Parameters
    ----------
    forces : ndarray
        Element forces ``F_i`` [N] (updated).
    slip : ndarray
        Element phase: 0 sticking, ±1 slipping in that direction (updated).
    alpha, k : ndarray
        Normalised slip limits [-] and stiffnesses [N/m].
    c : float
        Slip attraction rate [1/s].
    dx : float
        Displacement during the step [m].
    v : float
        Velocity at the end of the step [m/s].
    s_v : float
        Signed Stribeck curve at ``v`` [N].
    dt : float
        Step [s].
    """
    return gms_step(forces, 0, slip, 0, alpha, 0, k, 0, alpha.shape[0], np.exp(-c * dt),
                    dx, v, s_v)


@njit(cache=True)
def gms_step(forces, i_f, slip, i_s, alpha, i_a, k, i_k, n, decay, dx, v, s_v):
    """Apply the element law of :func:`gms_update` to packed vectors with offsets.

    ``F_i = forces[i_f + i]``, phase ``slip[i_s + i]``, ``α_i = alpha[i_a + i]``,
    ``k_i = k[i_k + i]``; ``decay = e^{−c·dt}`` of the slip phase.  The plant kernel calls
    this with its parameter and state vectors and offsets (no array views in its inner
    loop, and the exponential hoisted out of the step loop); :func:`gms_update` with
    the element arrays themselves.  Returns the summed element force [N].
    """
    total = 0.0
    sv = np.sign(v)
    for i in range(n):
        if slip[i_s + i] != 0.0 and sv != slip[i_s + i]:
            slip[i_s + i] = 0.0  # velocity reversal (or rest): the element sticks again
        if slip[i_s + i] == 0.0:
            f = forces[i_f + i] + k[i_k + i] * dx
            lim = alpha[i_a + i] * abs(s_v)
            # slip starts when F_i reaches α_i·s(v) in the direction of motion (Chiew
            # eq. 3–4).  An element still loaded against the motion (after a reversal
            # into a lower |s(v)|) keeps unloading elastically: clamping it to α_i|s(v)|
            # would make the force jump by up to α_i·(fs − fc) on a nanometre step.
            # (at rest, sv = 0, nothing slips; with no friction level, s = 0, an element
            # moving carries no force instead of acting as an unlimited spring)
            if sv != 0.0 and abs(f) >= lim and np.sign(f) == sv:
                f = np.sign(f) * lim
                slip[i_s + i] = sv
            forces[i_f + i] = f
        else:
            target = alpha[i_a + i] * s_v
            forces[i_f + i] = target - (target - forces[i_f + i]) * decay
        total += forces[i_f + i]
    return total


@njit(cache=True)
def gms_trajectory(x, alpha, k, c, fc, fs, vs, delta, dt):
    """GMS element force [N] along a sampled displacement ``x`` [m] at step ``dt`` [s]."""
    n = x.shape[0]
    out = np.zeros(n)
    forces = np.zeros(alpha.shape[0])
    slip = np.zeros(alpha.shape[0])
    for j in range(1, n):
        dx = x[j] - x[j - 1]
        v = dx / dt
        s_v = stribeck_curve(v, fc, fs, vs, delta)
        out[j] = gms_update(forces, slip, alpha, k, c, dx, v, s_v, dt)
    return out


@dataclasses.dataclass(frozen=True)
class Presliding(Effect):
    """GMS pre-sliding hysteresis with N Maxwell-slip elements (Chiew uses N = 4).

    Parameters
    ----------
    alpha : tuple of float
        Normalised element slip limits [-], each > 0, summing to 1.
    k : tuple of float
        Element stiffnesses [N/m], each > 0; the pre-sliding stiffness at a reversal is Σk.
    c : float
        Slip attraction rate [1/s] (Chiew: C = 1/Vs), > 0.
    """

    name = 'presliding'
    title = 'pre-sliding hysteresis (GMS)'
    alpha: tuple = (0.45, 0.30, 0.15, 0.10)
    k: tuple = (8e6, 3e6, 1e6, 3e5)
    c: float = 1000.0

    def __post_init__(self) -> None:
        try:
            alpha = tuple(float(a) for a in self.alpha)
            k = tuple(float(s) for s in self.k)
        except (TypeError, ValueError):
            raise ParameterError('presliding.alpha and presliding.k must be lists of numbers') \
                from None
        if not 1 <= len(alpha) <= MAX_ELEMENTS:
            raise ParameterError(
                f'presliding.alpha must have 1..{MAX_ELEMENTS} elements, got {len(alpha)}')
        if len(k) != len(alpha):
            raise ParameterError(
                f'presliding.k has {len(k)} elements but alpha has {len(alpha)}')
        for i, a in enumerate(alpha):
            check_positive(f'presliding.alpha[{i}] [-]', a)
        for i, s in enumerate(k):
            check_positive(f'presliding.k[{i}] [N/m]', s)
        if abs(sum(alpha) - 1.0) > 1e-6:
            raise ParameterError(f'presliding.alpha must sum to 1, got {sum(alpha):.6g}')
        object.__setattr__(self, 'alpha', alpha)
        object.__setattr__(self, 'k', k)
        object.__setattr__(self, 'c', check_positive('presliding.c [1/s]', self.c))

    @property
    def stiffness(self) -> float:
        """Pre-sliding stiffness at a reversal, Σ k_i [N/m]."""
        return float(sum(self.k))

    def force_along(self, x: np.ndarray, dt: float, *, fc: float, fs: float | None = None,
                    vs: float = 1e-3, delta: float = 1.0) -> np.ndarray:
        """Element force [N] along displacement samples ``x`` [m] spaced ``dt`` [s].

        The element state starts relaxed at the first sample; ``fc``/``fs``/``vs``/``delta``
        define the Stribeck curve (``fs`` defaults to ``fc``: no Stribeck effect).
        """
        fs = fc if fs is None else fs
        return gms_trajectory(np.ascontiguousarray(x, dtype=float),
                              np.array(self.alpha), np.array(self.k), self.c,
                              float(fc), float(fs), float(vs), float(delta), float(dt))
