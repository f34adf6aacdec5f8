"""Generalized Maxwell-Slip pre-sliding friction (GMS; Lampaert, Al-Bender, Swevers 2003).

N elementary blocks, element ``i`` a spring ``k_i`` [N/m] of deflection ``z_i = F_i/k_i``
with a slip limit ``α_i·|s(v)|`` (Lampaert et al. 2003 eq. 5–7; Chiew et al. eq. 3–5;
DESIGN.md §3):

* sticking:  ``dF_i/dt = k_i·v``  until ``F_i`` reaches ``α_i·s(v)`` (signed: in the
  direction of motion; an element loaded against the motion unloads elastically);
* slipping:  ``dF_i/dt = sgn(v)·C·(α_i − F_i/s(v))`` until the velocity reverses, with
  the *constant attraction* ``C`` [N/s].  Since ``sgn(s) = sgn(v)`` this is
  ``(C/|s(v)|)·(α_i·s(v) − F_i)``: a relaxation towards ``α_i·s(v)`` whose rate
  ``C/|s(v)|`` [1/s] follows the Stribeck curve (slower near break-away, where |s| is
  largest).  At constant ``v`` it integrates exactly over a step ``dt`` as
  ``F_i ← α_i·s − (α_i·s − F_i)·e^{−C·dt/|s(v)|}``.

``s(v) = sgn(v)·[fc + (fs − fc)·e^{−|v/vs|^δ}]`` is the *signed* Stribeck curve (the
unsigned form is unstable for v < 0).  Total friction (Lampaert eq. 8)
``F = Σ (F_i + σ_i·ż_i) + σ_2·v``: ``σ_i`` [N·s/m] is the element micro-damping, which
damps the pre-sliding resonance ``sqrt(Σk_i/M)`` of the axis, and ``ż_i`` the element's
deflection rate (``v`` while it sticks, ``Ḟ_i/k_i`` while it slips; over a step the laws
here use ``ΔF_i/(k_i·dt)``).  Near rest every element sticks and the axis is the
oscillator ``M·ẍ + (Σσ_i + d)·ẋ + Σk_i·x = f`` (``d``: drive damping + ``fv``), so
``ζ = (Σσ_i + d)/(2·sqrt(Σk_i·M))`` (:meth:`Presliding.damping_ratio`).  The default
ball-screw (``config/ballscrew.yaml``: M = 25 kg, Σk_i = 1.23e7 N/m, σ_i = k_i·1.4 ms,
d = 250 N·s/m) rings at 701 rad/s with ζ = 0.50; without σ_i it was ζ = 0.0071.
``σ_2·v`` is the model's ``viscous`` effect, so it is not repeated here.  When the model
has presliding, the sliding friction (coulomb + stribeck) is carried by the elements,
never added a second time.

Units: F_i, s(v) [N]; k_i [N/m]; C [N/s]; σ_i [N·s/m]; on a rotary axis read N·m, rad.
Model files from before the published law carried a slip *rate* ``c`` [1/s]
(``dF_i/dt = c·(α_i·s − F_i)``); :func:`upgrade_legacy_params` converts it with
``C = c·fc``, which keeps the relaxation rate at sliding speeds (|s| = fc) unchanged.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Callable, Mapping

import numpy as np
from numba import njit

from motor_comp.errors import ParameterError, check_nonnegative, check_positive
from motor_comp.physics import aot
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.identification import Column, Context, Evidence, Param, \
    Summary, Term
from motor_comp.physics.effects.stribeck import stribeck_curve

#: largest number of Maxwell-slip elements the compiled kernels carry
MAX_ELEMENTS = 8


@njit(cache=True)
def gms_update(forces, slip, alpha, k, sigma, C, dx, v, s_v, dt):
    """Advance every element by one step, in place; return the GMS friction force [N].

    Parameters
    ----------
    forces : ndarray
        Element spring forces ``F_i = k_i·z_i`` [N] (updated).
    slip : ndarray
        Element phase: 0 sticking, ±1 slipping in that direction (updated).
    alpha, k, sigma : ndarray
        Normalised slip limits [-], stiffnesses [N/m], micro-damping [N·s/m].
    C : float
        Constant attraction of the slip phase [N/s] (Lampaert 2003).
    dx : float
        Displacement during the step [m].
    v : float
        Velocity at the end of the step [m/s].
    s_v : float
        Signed Stribeck curve at ``v`` [N].
    dt : float
        Step [s], > 0.

    Returns
    -------
    float
        ``Σ (F_i + σ_i·ż_i)`` [N] with ``ż_i = ΔF_i/(k_i·dt)`` over the step.
    """
    return gms_step(forces, 0, slip, 0, alpha, 0, k, 0, sigma, 0, alpha.shape[0], C, dt,
                    dx, v, s_v)


@njit(cache=True, error_model='numpy')
def gms_step(forces, i_f, slip, i_s, alpha, i_a, k, i_k, sigma, i_g, n, C, dt, dx, v, s_v):
    """Apply the element law of :func:`gms_update` to packed vectors with offsets.

    ``F_i = forces[i_f + i]``, phase ``slip[i_s + i]``, ``α_i = alpha[i_a + i]``,
    ``k_i = k[i_k + i]``, ``σ_i = sigma[i_g + i]``, ``i < n``; ``C`` [N/s] the attraction,
    ``dt`` [s] the step (``dt = 0``: no relaxation and no micro-damping term).  The
    plant kernel and the friction feedforward call this with
    their parameter and state vectors and offsets (no array views in their inner loops);
    :func:`gms_update` with the element arrays themselves.  Returns the friction
    ``Σ (F_i + σ_i·ΔF_i/(k_i·dt))`` [N].
    """
    total = 0.0
    sv = np.sign(v)
    decay = -1.0                  # e^{−C·dt/|s|}, computed once if an element slips
    inv_dt = 1.0 / dt if dt > 0.0 else 0.0   # a zero-length step has no deflection rate
    for i in range(n):
        f_old = forces[i_f + i]
        if slip[i_s + i] != 0.0 and sv != slip[i_s + i]:
            slip[i_s + i] = 0.0  # velocity reversal (or rest): the element sticks again
        if slip[i_s + i] == 0.0:
            f = f_old + k[i_k + i] * dx
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
            if decay < 0.0:
                # the published slip law: relaxation rate C/|s(v)| [1/s]
                decay = np.exp(-C * dt / abs(s_v)) if s_v != 0.0 else 0.0
            target = alpha[i_a + i] * s_v
            forces[i_f + i] = target - (target - f_old) * decay
        f_new = forces[i_f + i]
        total += f_new + sigma[i_g + i] * (f_new - f_old) / k[i_k + i] * inv_dt
    return total


@njit(cache=True, inline='always', error_model='numpy')
def gms_slip_rate(f, alpha, C, s_v):
    """Spring-force rate ``dF_i/dt`` [N/s] of a slipping element (Lampaert 2003).

    ``sgn(v)·C·(α_i − F_i/s(v)) = (C/|s|)·(α_i·s − F_i)`` with the signed ``s_v`` [N];
    0 when ``s_v = 0`` (no friction level: the element carries nothing).
    """
    if s_v == 0.0:
        return 0.0
    return C / abs(s_v) * (alpha * s_v - f)


@njit(cache=True)
def gms_trajectory(x, alpha, k, sigma, C, fc, fs, vs, delta, dt):
    """GMS friction [N] along a sampled displacement ``x`` [m] at step ``dt`` [s].

    ``s(v)`` is evaluated at each step's mean velocity ``Δx/dt``; the elements start
    relaxed at the first sample.  (:func:`gms_trajectory_shifted` with no shift: the
    same numbers, ``fc + 0.0`` is ``fc``.)
    """
    return gms_trajectory_shifted(x, np.zeros(x.shape[0]), alpha, k, sigma, C, fc, fs, vs,
                                  delta, dt)


@njit(cache=True)
def gms_trajectory_shifted(x, shift, alpha, k, sigma, C, fc, fs, vs, delta, dt):
    """GMS friction [N] along ``x`` [m] with the dry-friction level raised by ``shift`` [N].

    As :func:`gms_trajectory`, with the Stribeck curve of step ``j`` (ending at sample
    ``j``) ``s(v) = sgn(v)·[fc + shift[j] + (fs − fc)·e^{−|v/vs|^δ}]``: the load- and
    position-dependent friction (``mu·|F_in| + dfc(x)`` at the step's end, as the plant
    kernel evaluates it) raise the level every element relaxes towards.
    """
    n = x.shape[0]
    out = np.zeros(n)
    forces = np.zeros(alpha.shape[0])
    slip = np.zeros(alpha.shape[0])
    for j in range(1, n):
        dx = x[j] - x[j - 1]
        v = dx / dt
        s_v = stribeck_curve(v, fc + shift[j], fs + shift[j], vs, delta)
        out[j] = gms_update(forces, slip, alpha, k, sigma, C, dx, v, s_v, dt)
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
    C : float
        Constant attraction of the slip phase [N/s], > 0 (Lampaert 2003): an element
        relaxes towards ``α_i·s(v)`` at the rate ``C/|s(v)|`` [1/s].
    sigma : tuple of float
        Element micro-damping ``σ_i`` [N·s/m], each >= 0, one per element; empty (the
        default) means none.  :meth:`damping_ratio` gives the ζ it lends the pre-sliding
        resonance of an axis, :meth:`with_damping_ratio` the σ_i for a wanted ζ.
    """

    name = 'presliding'
    title = 'pre-sliding hysteresis (GMS)'
    alpha: tuple = (0.45, 0.30, 0.15, 0.10)
    k: tuple = (8e6, 3e6, 1e6, 3e5)
    C: float = 12000.0
    sigma: tuple = ()

    def __post_init__(self) -> None:
        try:
            alpha = tuple(float(a) for a in self.alpha)
            k = tuple(float(s) for s in self.k)
            sigma = tuple(float(s) for s in self.sigma)
        except (TypeError, ValueError):
            raise ParameterError('presliding.alpha, presliding.k and presliding.sigma must '
                                 'be lists of numbers') from None
        if not 1 <= len(alpha) <= MAX_ELEMENTS:
            raise ParameterError(
                f'presliding.alpha must have 1..{MAX_ELEMENTS} elements, got {len(alpha)}')
        if len(k) != len(alpha):
            raise ParameterError(
                f'presliding.k has {len(k)} elements but alpha has {len(alpha)}')
        if not sigma:
            sigma = (0.0,) * len(alpha)
        if len(sigma) != len(alpha):
            raise ParameterError(
                f'presliding.sigma has {len(sigma)} elements but alpha has {len(alpha)}')
        for i, a in enumerate(alpha):
            check_positive(f'presliding.alpha[{i}] [-]', a)
        for i, s in enumerate(k):
            check_positive(f'presliding.k[{i}] [N/m]', s)
        for i, s in enumerate(sigma):
            check_nonnegative(f'presliding.sigma[{i}] [N·s/m]', s)
        if abs(sum(alpha) - 1.0) > 1e-6:
            raise ParameterError(f'presliding.alpha must sum to 1, got {sum(alpha):.6g}')
        object.__setattr__(self, 'alpha', alpha)
        object.__setattr__(self, 'k', k)
        object.__setattr__(self, 'sigma', sigma)
        object.__setattr__(self, 'C', check_positive('presliding.C [N/s]', self.C))

    @classmethod
    def from_params(cls, params: Mapping[str, Any] | None) -> 'Presliding':
        """Build from model-file parameters; the pre-published key ``c`` is refused here.

        Model and plant files are converted first by :func:`upgrade_legacy_params`, which
        knows the model's ``fc``; an effect built on its own cannot convert ``c``.
        """
        if params is not None and 'c' in params:
            raise ParameterError(LEGACY_C_MESSAGE)
        return super().from_params(params)  # type: ignore[return-value]

    @property
    def stiffness(self) -> float:
        """Pre-sliding stiffness at a reversal, Σ k_i [N/m]."""
        return float(sum(self.k))

    def damping_ratio(self, mass: float, other_damping: float = 0.0) -> float:
        """ζ of the pre-sliding resonance of an axis of ``mass`` [kg] with all elements stuck.

        Near rest every element sticks, so the axis is ``M·ẍ + (Σσ_i + d)·ẋ + Σk_i·x = f``
        with ``d = other_damping`` [N·s/m] (the drive's ``damping`` plus ``viscous.fv``):
        ``ω_n = sqrt(Σk_i/M)``, ``ζ = (Σσ_i + d)/(2·sqrt(Σk_i·M))``.
        """
        mass = check_positive('mass [kg]', mass)
        return (sum(self.sigma) + other_damping) / (2.0 * math.sqrt(self.stiffness * mass))

    def with_damping_ratio(self, zeta: float, mass: float,
                           other_damping: float = 0.0) -> 'Presliding':
        """Copy with ``σ_i ∝ k_i`` such that :meth:`damping_ratio` is ``zeta``.

        Stiffness-proportional damping (``σ_i = k_i·T``, one time constant T for all
        elements) damps each element's share of the resonance alike.
        """
        need = 2.0 * check_positive('zeta', zeta) * math.sqrt(self.stiffness * mass) \
            - other_damping
        if need < 0.0:
            raise ParameterError(f'the axis damping alone gives zeta > {zeta:g}')
        t = need / self.stiffness
        return dataclasses.replace(self, sigma=tuple(s * t for s in self.k))

    def force_along(self, x: np.ndarray, dt: float, *, fc: float, fs: float | None = None,
                    vs: float = 1e-3, delta: float = 1.0,
                    shift: np.ndarray | None = None) -> np.ndarray:
        """GMS friction ``Σ(F_i + σ_i·ż_i)`` [N] along samples ``x`` [m] spaced ``dt`` [s].

        The element state starts relaxed at the first sample; ``fc``/``fs``/``vs``/``delta``
        define the Stribeck curve (``fs`` defaults to ``fc``: no Stribeck effect).
        ``shift`` [N], one value per sample, raises the curve's level there (load- and
        position-dependent friction, :func:`gms_trajectory_shifted`).
        """
        fs = fc if fs is None else fs
        x = np.ascontiguousarray(x, dtype=float)
        args = (np.array(self.alpha), np.array(self.k), np.array(self.sigma), self.C,
                float(fc), float(fs), float(vs), float(delta), float(dt))
        if shift is None:
            return gms_trajectory(x, *args)
        shift = np.ascontiguousarray(np.broadcast_to(np.asarray(shift, dtype=float), x.shape))
        return gms_trajectory_shifted(x, shift, *args)


#: the one-line message for the pre-published slip-rate key in a stand-alone effect
LEGACY_C_MESSAGE = ("presliding: 'c' [1/s] (old slip rate) was replaced by 'C' [N/s], "
                    "Lampaert's constant attraction (rate C/|s(v)|); use C = c·fc")


def upgrade_legacy_params(effects: Mapping[str, Any]) -> tuple[dict[str, Any], str | None]:
    """Convert a pre-published ``presliding.c`` [1/s] in a model file's ``effects`` mapping.

    The old slip law relaxed at the constant rate ``c``; the published one at
    ``C/|s(v)|``.  ``C = c·fc`` (``fc`` from the file's ``coulomb``) keeps the rate at
    sliding speeds, where ``|s(v)| = fc``, and makes it slower near break-away as
    published.  Returns the (possibly) converted mapping and a one-line note for the
    user, or None when nothing was converted.  Raises :class:`ParameterError` when ``c``
    cannot be converted (no ``coulomb.fc``, or both ``c`` and ``C`` given).
    """
    gms = effects.get('presliding') if isinstance(effects, Mapping) else None
    if not isinstance(gms, Mapping) or 'c' not in gms:
        return dict(effects) if isinstance(effects, Mapping) else effects, None
    if 'C' in gms:
        raise ParameterError("presliding: give either 'C' [N/s] or the old 'c' [1/s], "
                             "not both")
    coulomb = effects.get('coulomb')
    fc = coulomb.get('fc') if isinstance(coulomb, Mapping) else None
    try:
        fc = float(fc)
        c = float(gms['c'])
    except (TypeError, ValueError):
        raise ParameterError(LEGACY_C_MESSAGE + ' (no coulomb.fc in this file to convert '
                             'with)') from None
    if not fc > 0.0:
        raise ParameterError(LEGACY_C_MESSAGE + ' (coulomb.fc must be > 0 to convert)')
    new = {key: val for key, val in gms.items() if key != 'c'}
    new['C'] = c * fc
    out = dict(effects)
    out['presliding'] = new
    note = (f"presliding.c = {c:g} 1/s is the old slip rate; read as C = c·fc = "
            f"{c * fc:g} N/s (Lampaert's constant attraction, rate C/|s(v)|); write "
            f"'C: {c * fc:g}' in the file to silence this")
    return out, note


@njit(cache=True)
def gms_unit_columns(x, inv_d, C, fs, vs, delta, dt, tdamp):
    """Force of unit-level Maxwell-slip elements along ``x`` [m], one column per element.

    An element of slip limit ``β·s(v)/fc`` and stiffness ``β/d`` (pre-sliding distance
    ``d`` [m]) gives exactly ``β`` times its column (``inv_d`` = ``1/d``), so with the
    distances held the GMS force ``Σ β_j·g_j`` is linear in the element levels ``β_j``
    (Lampaert 2003; Chiew eq. 3–5): their sum is the Coulomb level ``fc``,
    ``α_j = β_j/fc``, ``k_j = β_j/d_j``.  ``fs`` is the break-away level per unit
    Coulomb level (``1 + (fs − fc)/fc``) and ``C`` the attraction per unit level
    (``C/fc``).  ``tdamp`` [s] is each element's micro-damping time constant
    ``σ_j/k_j``: the element's damping force ``σ_j·ż_j = σ_j·ΔF_j/(k_j·dt)`` is then
    ``tdamp_j·ΔF_j/dt``, linear in the level too (Lampaert eq. 8).  The elements share
    the displacement, the Stribeck curve and the slip decay of each step, so one pass of
    the element law :func:`gms_step` gives every column.
    """
    return gms_unit_columns_sv(x, gms_unit_curve(x, fs, vs, delta, dt), inv_d, C, dt, tdamp)


@aot.ahead(aot.F8_1D, *(aot.F8,) * 4)
@njit(cache=True)
def gms_unit_curve(x, fs, vs, delta, dt):
    """Stribeck curve per unit Coulomb level at each step's velocity along ``x`` [-].

    ``out[j]`` is ``s(v_j)`` with ``v_j = (x_j − x_{j−1})/dt``: what every element of
    :func:`gms_unit_columns` sees at step ``j`` (computed once for all of them).
    """
    n = x.shape[0]
    out = np.zeros(n)
    flat = fs == 1.0          # no Stribeck rise: s(v) = sgn(v), no exponential per step
    for j in range(1, n):
        v = (x[j] - x[j - 1]) / dt
        out[j] = np.sign(v) if flat else stribeck_curve(v, 1.0, fs, vs, delta)
    return out


@njit(cache=True)
def gms_unit_columns_sv(x, curve, inv_d, C, dt, tdamp):
    """:func:`gms_unit_columns` with the unit Stribeck curve of each step given."""
    n, m = x.shape[0], inv_d.shape[0]
    out = np.zeros((n, m))
    forces = np.zeros(m)
    slip = np.zeros(m)
    alpha = np.ones(m)
    sigma = np.zeros(m)
    prev = np.zeros(m)
    for j in range(1, n):
        dx = x[j] - x[j - 1]
        v = dx / dt
        s_v = curve[j]
        for e in range(m):
            prev[e] = forces[e]           # the force before the step, for the damping
        gms_step(forces, 0, slip, 0, alpha, 0, inv_d, 0, sigma, 0, m, C, dt, dx, v, s_v)
        for e in range(m):
            out[j, e] = forces[e] + tdamp[e] * (forces[e] - prev[e]) / dt
    return out


@aot.ahead(aot.F8_1D, aot.F8_1D, *(aot.F8,) * 4, aot.F8_1D)
@njit(cache=True)
def gms_unit_column(x, curve, inv_d, C, dt, tdamp, decay):
    """One column of :func:`gms_unit_columns_sv`: the element of ``1/d = inv_d`` alone.

    The workbench computes its columns one element at a time (a search moves one
    distance); the general kernel's per-element loops and unused friction sum cost it
    two thirds of its time on one element.  The same element law as :func:`gms_step`,
    operation for operation, so the column is bit for bit the general kernel's.
    ``decay`` (one per step, negative where not yet known) holds the slip decay
    ``e^{−C·dt/|s|}`` of each step: it depends on the curve and ``C`` only, not on the
    element, so the elements and distances a search tries share it (filled here where
    an element first slips; the exponential was half of the column's cost).
    """
    n = x.shape[0]
    out = np.zeros(n)
    f = 0.0
    slip = 0.0
    for j in range(1, n):
        dx = x[j] - x[j - 1]
        v = dx / dt
        s_v = curve[j]
        sv = np.sign(v)
        f_old = f
        if slip != 0.0 and sv != slip:
            slip = 0.0            # velocity reversal (or rest): the element sticks again
        if slip == 0.0:
            f = f_old + inv_d * dx
            lim = abs(s_v)
            if sv != 0.0 and abs(f) >= lim and np.sign(f) == sv:
                f = np.sign(f) * lim
                slip = sv
        else:
            e = decay[j]
            if e < 0.0:
                e = np.exp(-C * dt / abs(s_v)) if s_v != 0.0 else 0.0
                decay[j] = e
            f = s_v - (s_v - f_old) * e
        out[j] = f + tdamp * (f - f_old) / dt
    return out


#: slip-decay vectors kept per run motion (the last curves and attractions searched):
#: one is 8 bytes a sample, and a search moving one parameter returns to few of them
GMS_DECAYS_KEPT = 4


def _decays(p: Any, key: tuple, n: int) -> np.ndarray:
    """Return the slip decays of the motion ``p`` for ``key`` (unknown: −1), kept few."""
    kept = p.memo(('gms_decays',), dict)
    hit = kept.get(key)
    if hit is None:
        if len(kept) >= GMS_DECAYS_KEPT:
            del kept[next(iter(kept))]       # the oldest
        hit = kept[key] = np.full(n, -1.0)
    return hit


#: the element distances of the family the search starts from, relative to its scale
GMS_FAMILY = (0.3, 1.0, 3.0)
#: most elements the structure search grows to
GMS_MAX_ELEMENTS = 4


class PreslidingTerm(Term):
    """Identification of GMS pre-sliding: element levels on unit-element columns.

    With the element distances ``d_j`` (pre-sliding displacement to break-away) and the
    attraction held, the friction is linear in the element levels ``β_j ≥ 0`` (held
    inside the estimator: a negative slip limit is no friction), whose sum is the
    Coulomb level: the term carries the Coulomb (and Stribeck) columns.  The
    distances are a vector parameter whose length is the element count: the search
    starts from a family ``d0·(0.3, 1, 3)``, frees each distance, drops elements that
    do not pay and grows a stiffer one where it does (at most four).  Declared bounds:
    a distance is at least three encoder counts (or noise σ) — below the sensor's
    resolution a pre-sliding curve is not observable and only mimics a stick or a gap
    — and at most 1 m; and the longest element's curve must span samples: leaving a
    reversal at the run's acceleration the axis covers ``½·a·(2·dt)²`` in two samples,
    so a GMS whose longest distance is shorter is crossed within a sample or two and
    fits how a stick ends between samples, not a curve.  The attraction ``C`` is free
    only when a Stribeck curve makes it matter (with a constant level a slipping
    element sits at its limit).  Its evidence is around reversals and in the transitions
    out of a rest, where the elements are loaded again: its fits reach the stops.
    """

    name = 'presliding'
    effect = Presliding
    evidence = Evidence.TURNS | Evidence.STOPS
    requires = ('coulomb',)
    replaces = ('coulomb', 'stribeck')
    excludes = ('backlash',)
    models_sticking = True
    min_reversals = 4
    params = ('d', 'c')
    force_scaled = (('presliding', 'stiffness'),)
    #: Σk is set by the first encoder counts after each reversal: looser than a delay's
    #: or a gap's shape (0.19 relative SE on an independent run whose pre-sliding is half
    #: of what a Coulomb + ripple model leaves)

    def space(self, s: Summary, ctx: Context) -> tuple[Param, ...]:
        """Return the element distances ``d`` [m] and the attraction ``c`` [1/s]."""
        lo = max(3.0 * s.quantum, 3.0 * s.noise, 1e-9)
        hi = max(0.01 * s.travel, 100 * lo)
        grid = tuple(tuple(float(d0 * f) for f in GMS_FAMILY)
                     for d0 in np.logspace(np.log10(lo), np.log10(hi), 6))
        return (Param('d', lo, 1.0, grid=grid, log=True, vector=GMS_MAX_ELEMENTS,
                      steps=tuple(np.log((0.6, 1.0, 1.6)))),
                Param('c', 1.0, 1e6, grid=(300.0, 3000.0), log=True,
                      steps=tuple(np.log((0.5, 1.0, 2.0)))))

    def orders(self, s: Summary, eta: Mapping) -> tuple[int, int]:
        """Return 1 to :data:`GMS_MAX_ELEMENTS` elements."""
        return 1, GMS_MAX_ELEMENTS

    def order_of(self, eta: Mapping) -> int:
        """Return the element count."""
        return len(eta['d'])

    def grow(self, eta: Mapping) -> dict:
        """Return ``eta`` with a stiffer element at a third of the shortest distance."""
        d = tuple(eta['d'])
        return {k: v for k, v in dict(eta, d=(min(d) / 3.0,) + d).items() if k != 'tdamp'}

    def nonlinear(self, eta: Mapping) -> list:
        """Return the distances, and ``c`` when a Stribeck curve makes it matter."""
        out = [('d', j, float(v)) for j, v in enumerate(eta['d'])]
        if float(eta.get('ratio', 0.0)) > 0.0:
            out.append(('c', None, float(eta['c'])))
        return out

    def derive(self, eta: Mapping, base: Mapping) -> dict:
        """Set the Stribeck ratio ``(fs − fc)/fc`` from the fit without pre-sliding."""
        fc = max(float(base.get(('coulomb', 'fc'), 1.0)), 1e-6)
        dfs = max(float(base.get(('stribeck', 'dfs'), 0.0)), 0.0)
        return dict(eta, ratio=dfs / fc)

    def _shape(self, eta: Mapping, ctx: Context) -> tuple[float, float, float]:
        st = ctx.eta.get('stribeck') if 'stribeck' in ctx.present else None
        if st is None:
            return 0.0, 1e-3, 1.0
        return float(eta.get('ratio', 0.0)), float(st['vs']), float(st['delta'])

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return one unit-element column per distance (computed in one pass)."""
        dists = tuple(float(d) for d in eta['d'])
        c = float(eta['c'])
        ratio, vs, dl = self._shape(eta, ctx)
        inv = [1.0 / d for d in dists]
        tdamp = tuple(float(t) for t in eta.get('tdamp', ()))
        if len(tdamp) != len(dists):      # no damping, or a structure the search changed
            tdamp = (0.0,) * len(dists)

        # one block per element: the elements are independent given the path, so a
        # search that moves one distance recomputes one column, not all (the polish
        # of a 3-element GMS spent two thirds of its time on unchanged elements)
        def block_of(j: int) -> Callable[[Any], np.ndarray]:
            def block(p: Any) -> np.ndarray:
                xg = np.ascontiguousarray(p.xg)
                curve = p.memo(('gms_curve', ratio, vs, dl),
                               lambda: gms_unit_curve_entry(xg, 1.0 + ratio, vs, dl, p.dt))
                return gms_unit_column_entry(xg, curve, inv[j], c, p.dt, tdamp[j],
                                             _decays(p, (ratio, vs, dl, c), len(xg)))
            return block
        return [Column(f'b{j}', ('gms', d, c, ratio, vs, dl, t), block_of(j), lo=0.0)
                for j, (d, t) in enumerate(zip(dists, tdamp))]

    def admissible(self, values: Mapping, eta: Mapping, s: Summary) -> str | None:
        """Refuse a curve crossed within two samples at the run's acceleration."""
        need = 2.0 * s.accel90 * s.dt * s.dt
        if max(eta['d']) < need:
            return (f'the longest pre-sliding distance {max(eta["d"]):.3g} is crossed within '
                    f'two samples ({need:.3g} at the run\'s acceleration)')
        return None

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return Coulomb, pre-sliding (and Stribeck) effects of the element levels."""
        from motor_comp.physics.effects.coulomb import Coulomb
        from motor_comp.physics.effects.stribeck import Stribeck
        dists, c = eta['d'], float(eta['c'])
        beta = [max(float(values.get((self.name, f'b{j}'), 0.0)), 0.0)
                for j in range(len(dists))]
        keep = [j for j in range(len(dists)) if beta[j] > 1e-9 * max(sum(beta), 1e-300)]
        if not keep:
            keep = [int(np.argmax(beta))]
            beta[keep[0]] = 1e-9
        fc = sum(beta[j] for j in keep)
        tdamp = tuple(eta.get('tdamp', ()))
        if len(tdamp) != len(dists):
            tdamp = (0.0,) * len(dists)
        k = tuple(max(beta[j], 1e-12) / dists[j] for j in keep)
        sigma = tuple(kk * float(tdamp[j]) for kk, j in zip(k, keep))
        out: list[Effect] = [Coulomb(fc=fc), Presliding(
            alpha=tuple(beta[j] / fc for j in keep), k=k, C=c * max(fc, 1e-9),
            sigma=sigma if any(sigma) else ())]
        ratio, vs, dl = self._shape(eta, ctx)
        if 'stribeck' in ctx.present:
            out.append(Stribeck(fs=fc * (1.0 + ratio), vs=vs, delta=dl))
        return out

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return the element levels and ``(d, c, ratio)`` of the model's GMS."""
        e = model.get(self.name)
        fc = max(model.fc, 1e-6)
        ratio = (model.stribeck_curve_params()[1] - fc) / fc
        dists = tuple(a * fc / k for a, k in zip(e.alpha, e.k))
        eta = {'d': dists, 'c': e.C / fc, 'ratio': ratio}
        if any(e.sigma):
            eta['tdamp'] = tuple(s / k for s, k in zip(e.sigma, e.k))
        return {f'b{j}': a * model.fc for j, a in enumerate(e.alpha)}, eta

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report ``fc`` (Σβ), ``fs``, the stiffness Σk [N/m], ``c`` and the elements."""
        dists = tuple(eta['d'])
        nd = len(dists)
        ratio, _, _ = self._shape(eta, ctx)

        def b(v: Mapping, j: int) -> float:
            return float(v.get((self.name, f'b{j}'), 0.0))

        def fc(v: Mapping) -> float:
            return sum(b(v, j) for j in range(nd))
        out = {('coulomb', 'fc'): fc}
        if 'stribeck' in ctx.present:
            out[('stribeck', 'fs')] = lambda v: fc(v) * (1.0 + ratio)
        out[(self.name, 'stiffness')] = lambda v: sum(
            max(b(v, j), 0.0) / float(v.get((self.name, f'd{j}'), dists[j]))
            for j in range(nd))
        out[(self.name, 'c')] = lambda v: float(v.get((self.name, 'c'), eta['c']))
        # the structure's count, not a function of the levels: a count that jumps when
        # a level at its bound 0 is perturbed has no standard error (it printed ±3.5e19)
        out[(self.name, 'elements')] = lambda v: float(nd)
        return out


TERM = PreslidingTerm()


# Python calls the kernels above through their entries: compiled ahead of time where
# built (see motor_comp.physics.aot), else the JIT
gms_unit_curve_entry = aot.entry(gms_unit_curve)
gms_unit_column_entry = aot.entry(gms_unit_column)
