"""The one processing of every workbench command: smoothing, derivatives, sample selection.

``compare``, ``diagnose``, ``fit`` and ``monitor_node`` all see a run through this
module, so the same model and run give the same force NRMSE in every command
(DESIGN.md §6).  The inverse model ``S·F_in = M·S·ẍ + Σ_k S·F_k`` is formed with one
zero-phase smoother ``S`` applied alike to the drive force and to every effect's
pointwise force (so the pass band's shape cancels), and the acceleration is the
3-point second difference of ``S·x`` (``../shared/IDENTIFICATION.md`` §2).

Why this processing and not the Savitzky–Golay one the first ``compare`` used: on data
the project did not generate (the independent generator of ``test/workbench``), with
the *true* model, the force residual it leaves is what the processing itself adds, and
this one leaves less — measured by ``python bench/processing_choice.py --seeds 3``
(2026-11-26, 3b12908): on the 117 runs of the 39 suite cases × seeds 1–3 (20 s each) the
median NRMSE is 0.127 % against the Savitzky–Golay processing's 4.54 %, a median ratio of
0.031 (10–90 %: 0.006–0.130), lower in 117 of 117 runs; with the Savitzky–Golay
residual taken on this processing's rows (the filters alone) the median ratio is 0.071.
Three choices make the difference:

* ``S`` is a normalised Blackman window of ``W`` samples (:func:`smoother_length`,
  twice the derivative window): sidelobes below −58 dB, so the second difference of
  ``S·x`` stays quiet where a Savitzky–Golay filter leaks;
* the acceleration is the second difference of ``S·x``: the motion's acceleration
  averaged with the hat kernel over ``t ± dt`` — for a held command exactly what
  :meth:`Kinematics.input_at` gives the drive force — so both sides see the same
  kernel at every frequency; the velocity is the same hat average of ``ẋ``;
* samples are the sliding ones away from stops (:func:`fit_rows_mask`), every
  ``W/8``-th (the smoother correlates neighbours anyway), never within a window of a
  record's ends.

Pointwise laws (the sign of the velocity at a reversal, a Stribeck curve, the GMS
elements) need the velocity *at* a sample, not averaged over the smoother: they use a
short Savitzky–Golay derivative (:func:`point_velocity`) and a short smoothing of the
position (:func:`gms_position`).
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
from numba import njit


from motor_comp.physics import aot
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.savgol import correlate1d, savgol_coeffs
from motor_comp.workbench.turns import REVERSAL_HALF

_COEFFS: dict = {}


def _coeffs(window: int, polyorder: int, deriv: int = 0) -> np.ndarray:
    key = (window, polyorder, deriv)
    c = _COEFFS.get(key)
    if c is None:
        c = savgol_coeffs(window, polyorder, deriv=deriv)
        _COEFFS[key] = c
    return c


def kernel(W: int) -> np.ndarray:
    """Return the smoother ``S``: a normalised Blackman window of ``W`` samples."""
    key = ('blackman', W)
    b = _COEFFS.get(key)
    if b is None:
        b = np.blackman(W + 2)[1:-1]
        b = b / b.sum()
        _COEFFS[key] = b
    return b


def smoother_length(kin: Kinematics, scale: float = 1.0) -> int:
    """Return the length of ``S`` [samples]: twice the derivative window, times ``scale``."""
    W = 2 * (kin.window // 2) * 2 + 1
    if scale != 1.0:
        W = 2 * max(1, int(round(scale * (W // 2)))) + 1
    return W


def smooth_full(y: np.ndarray, W: int) -> np.ndarray:
    """Return ``S(y)`` at every sample (mirror padding at the ends)."""
    return correlate1d(np.asarray(y, dtype=float), kernel(W), mode='mirror', axis=0)


def smooth_at(y: np.ndarray, rows: np.ndarray, W: int) -> np.ndarray:
    """Return ``S(y)`` at ``rows`` only (1-D or 2-D ``y``, time along the first axis).

    The same sums as a full-rate correlation followed by the row selection, at a
    fraction of the work; the rows are never within a smoother half-width of the ends.
    """
    y = np.asarray(y, dtype=float)
    if y.ndim == 1:
        return smooth_columns_at(y.reshape(-1, 1), rows, W)[0]
    return smooth_columns_at(y, rows, W).T


def smooth_columns_at(y: np.ndarray, rows: np.ndarray, W: int) -> np.ndarray:
    """Return ``S(y)`` at ``rows`` column by column: shape ``(columns, rows)``.

    :func:`smooth_at` without its final transpose: each column's values contiguous, as
    the design takes them (a Fortran-ordered ``y`` is read without a copy).
    """
    y = np.asarray(y, dtype=float)
    h = W // 2
    if len(rows) and (rows[0] < h or rows[-1] + h >= y.shape[0]):
        raise ValueError('rows within a smoother half-width of the record ends')
    return _smooth_rows_entry(np.ascontiguousarray(y.T), rows, kernel(W))


def smooth_local_at(index: np.ndarray, value: np.ndarray, size: int, rows: np.ndarray,
                    W: int) -> np.ndarray:
    """Return ``S(L)`` at ``rows`` of a sample-local basis ``L``: shape ``(rows, size)``.

    ``L`` has ``size`` functions; sample ``i`` touches ``index[i]`` with ``value[i]``
    (:class:`~motor_comp.physics.effects.identification.LocalBasis`).  The same sums as
    :func:`smooth_columns_at` of the dense ``L`` (each row's over the taps in order),
    at the cost of the functions each sample touches instead of all of them.
    """
    h = W // 2
    if len(rows) and (rows[0] < h or rows[-1] + h >= index.shape[0]):
        raise ValueError('rows within a smoother half-width of the record ends')
    return _smooth_local_entry(np.ascontiguousarray(index, dtype=np.int64),
                               np.ascontiguousarray(value, dtype=float), int(size), rows,
                               kernel(W))


@aot.ahead(aot.array(2, 'int64'), aot.F8_2D, aot.I8, aot.I8_1D, aot.F8_1D)
@njit(cache=True)
def _smooth_local(index, value, size, rows, b):
    # hand-written for the same reason as _smooth_rows (the rows are a sparse subset),
    # and because no library smooths a basis given by its nonzeros: row by row, the taps
    # in order, each sample's few functions
    nr, W, m = rows.shape[0], b.shape[0], index.shape[1]
    h = W // 2
    out = np.zeros((nr, size))
    for q in range(nr):
        r0 = rows[q] - h
        for j in range(W):
            bj = b[j]
            s = r0 + j
            for k in range(m):
                out[q, index[s, k]] += bj * value[s, k]
    return out


#: rows summed side by side in one pass of the taps (a tile of the output that stays in
#: the processor's first-level cache)
_TILE = 256


@aot.ahead(aot.F8_2D, aot.I8_1D, aot.F8_1D)
@njit(cache=True)
def _smooth_rows(y, rows, b):
    # hand-written: scipy/numpy filter every sample; the rows are a sparse subset (every
    # W/8-th sample).  Each row's sum runs over the taps in order, the same sum on every
    # machine (a fast-math reduction is reassociated by the compiler, differently for
    # each vector width).  A stretch of equally spaced rows (spacing s) is summed tap by
    # tap into a tile of rows: sample r + j - h of row r is element (r - r0)/s + j//s of
    # the stretch's phase j % s, so the samples of one tap for consecutive rows are
    # consecutive once the stretch is split into its s phases, and the tile's sums
    # advance together in vector registers, each still over the taps in order (than
    # eight strided sums side by side: 1.6x faster compiled for a generic x86-64, 2.4x
    # with the host's vector width under the JIT)
    nc, nr, W = y.shape[0], rows.shape[0], b.shape[0]
    n = y.shape[1]
    h = W // 2
    out = np.empty((nc, nr))
    acc = np.empty(_TILE)
    buf = np.empty(0)
    i = 0
    while i < nr:
        s, e = 0, i + 1
        if i + 1 < nr:
            s, e = rows[i + 1] - rows[i], i + 2
            while e < nr and rows[e] - rows[e - 1] == s:
                e += 1
        m = e - i
        if s <= 0 or s > W or m < 8:
            for q in range(i, e):
                r0 = rows[q] - h
                for c in range(nc):
                    yc = y[c]
                    a = 0.0
                    for j in range(W):
                        a += b[j] * yc[r0 + j]
                    out[c, q] = a
            i = e
            continue
        nm = m + (W - 1) // s
        if buf.shape[0] < s * nm:
            buf = np.empty(s * nm)
        base = rows[i] - h
        for c in range(nc):
            yc = y[c]
            for t in range(s):
                for k in range(nm):
                    idx = base + t + k * s
                    buf[t * nm + k] = yc[idx] if idx < n else 0.0
            for k0 in range(0, m, _TILE):
                mt = min(_TILE, m - k0)
                acc[:mt] = 0.0
                for j in range(W):
                    bj = b[j]
                    o = (j % s) * nm + j // s + k0
                    src = buf[o:o + mt]
                    for k in range(mt):
                        acc[k] += bj * src[k]
                out[c, i + k0:i + k0 + mt] = acc[:mt]
        i = e
    return out


def stencil(xs: np.ndarray, rows: np.ndarray, dt: float, which: str) -> np.ndarray:
    """Return the velocity or acceleration of the smoothed position ``xs`` at ``rows``.

    The 3-point second difference of a trajectory is its acceleration averaged with the
    hat kernel over ``t_k ± dt`` — for a zero-order-hold force exactly ``(a_{k−1} +
    a_k)/2``, the triangle-weighted command :meth:`Kinematics.input_at` gives — so the
    acceleration and the drive force see the same kernel at every frequency.  The
    velocity (back-EMF, viscous columns) is the same hat average of ``ẋ``: the step
    integrals by the 4-point midpoint rule; the central difference alone is a box
    average, ``dt²/12·v̈`` more than the hat sees, which with a back-EMF damping ``k``
    reads as a dead time ``k·dt²/(12·M)`` (15 µs on the project's PMLM at 1 kHz).
    """
    x, r = xs, rows
    if which == 'velocity':
        return ((x[r + 1] - x[r - 1]) / (2 * dt)
                - (x[r + 2] - 2 * x[r + 1] + 2 * x[r - 1] - x[r - 2]) / (24 * dt))
    return (x[r + 1] - 2 * x[r] + x[r - 1]) / (dt * dt)


def stencil_gain(w: np.ndarray, vdt: np.ndarray) -> np.ndarray:
    """Return the gain the acceleration stencil applies to ``sin(w·x)``, shape ``(n, len(w))``.

    The second difference of the position averages the acceleration with a triangle of
    ±1 sample, so a force that varies with position is seen averaged over that
    triangle too: at a locally constant speed ``v`` a spatial harmonic ``sin(w·x)`` is
    seen as ``sinc²(w·v·dt/2π)·sin(w·x)`` (a pointwise column left a ripple amplitude
    0.1–0.7 % short on a 500 Hz sweep).  ``vdt`` is ``v·dt`` at the rows.
    """
    w = np.atleast_1d(np.asarray(w, dtype=float))
    return np.sinc(np.outer(vdt, w) / (2 * math.pi)) ** 2


def short_window(kin: Kinematics, scale: float = 1.0) -> int:
    """Return the Savitzky–Golay window of the pointwise laws: a third of the derivative's.

    ``scale`` lengthens it (the processing spread of the standard errors).
    """
    return max(5, int(kin.window * scale / 3) | 1)


def point_velocity(kin: Kinematics, x: np.ndarray) -> np.ndarray:
    """Return the pointwise velocity for the nonlinear laws (sign, Stribeck, GMS direction).

    A short Savitzky–Golay derivative (a third of the derivative window, order 2): the
    sign of the velocity decides the friction direction at every reversal, and a long
    window moves the sign change — the 21-sample derivative shifted the Coulomb
    switching enough to bias a dead time by +1.2 ms on the project's closed loop.
    """
    return correlate1d(np.asarray(x, dtype=float), _coeffs(short_window(kin), 2, 1),
                       mode='mirror') / kin.dt


def gms_position(kin: Kinematics, x: np.ndarray, scale: float = 1.0) -> np.ndarray:
    """Return the position the GMS elements are driven by: a short Savitzky–Golay smoothing.

    The elements' break-away distances are micrometres; the derivative window's
    smoothing rounds each reversal over that scale, so a freed shortest element came
    out stiffer than the truth (+32 % on the project's own 1 kHz run).  The short
    window keeps the reversal's shape and still averages the encoder noise; ``scale``
    lengthens it (the processing spread).
    """
    return correlate1d(np.asarray(x, dtype=float), _coeffs(short_window(kin, scale), 2, 0),
                       mode='mirror')


def point_position(kin: Kinematics, x: np.ndarray) -> np.ndarray:
    """Return the pointwise (derivative-window Savitzky–Golay) position of ``x``."""
    return correlate1d(np.asarray(x, dtype=float), _coeffs(kin.window, kin.polyorder, 0),
                       mode='mirror')


def sliding_threshold(kin: Kinematics, v: np.ndarray | None = None) -> float:
    """Return the speed above which ``kin``'s axis slides [m/s or rad/s].

    Five times the noise of the Savitzky–Golay velocity, estimated from the position
    noise (or the encoder quantum when the noise is below it) and the filter's own
    noise gain; never below 0.2 % of the peak speed of ``v`` (default ``kin.v``).
    """
    coeff_noise = np.sqrt(np.sum(savgol_coeffs(kin.window, kin.polyorder, deriv=1) ** 2))
    sigma_x = max(kin.noise_std(), kin.quantum() / np.sqrt(12.0))
    v = kin.v if v is None else v
    return max(5.0 * sigma_x * coeff_noise / kin.dt, 2e-3 * float(np.max(np.abs(v))))


def sliding_mask(kin: Kinematics, position: np.ndarray | None = None) -> np.ndarray:
    """Select the samples where the axis slides: |ẋ| above 5× its estimation noise.

    The velocity noise of the Savitzky–Golay derivative is estimated from the position
    noise (or the encoder quantum when the noise is below it) and the filter's own
    noise gain, so the threshold adapts to the sensor and the sample rate; never
    below 0.2 % of the peak speed (the sign of a near-stopped axis is arbitrary).
    ``position`` is another position signal on the run's grid (a motor motion across
    a gap); default the measured one.
    """
    v = kin.v if position is None else correlate1d(
        np.asarray(position, dtype=float), _coeffs(kin.window, kin.polyorder, 1),
        mode='mirror') / kin.dt
    m = np.abs(v) > sliding_threshold(kin, v)
    # the filter's transient at both ends of the record is not trusted
    m[:kin.window] = False
    m[-kin.window:] = False
    return m


def held_ends(kin: Kinematics, moving: np.ndarray) -> np.ndarray:
    """Return ``moving`` with the record's untrusted ends set to the nearest trusted sample.

    :func:`sliding_mask` distrusts the filter's transient at both ends; for telling a
    rest from motion an end is what the axis was doing just inside it (an end taken
    as a rest put the drive force of the record's last 21 samples into the friction,
    a 54 N residual on a run that ended sliding).
    """
    m = np.array(moving, dtype=bool)
    w = kin.window
    if len(m) > 2 * w:
        m[:w] = m[w]
        m[-w:] = m[-w - 1]
    return m


def rest_runs(moving: np.ndarray, min_stop: int = 3) -> np.ndarray:
    """Return the samples of runs of at least ``min_stop`` samples not ``moving``."""
    still = ~np.asarray(moving, dtype=bool)
    d = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    out = np.zeros(len(still), dtype=bool)
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
        if b - a >= min_stop:
            out[a:b] = True
    return out


def touches(kin: Kinematics) -> np.ndarray:
    """Return the samples where the axis may have stopped or turned back unseen: *touches*.

    Two kinds, both events the turn model cannot place
    (:func:`~motor_comp.workbench.turns.reversal_shares` keeps the sign of the velocity
    there, as if the axis slid on):

    * flips of the sign of the pointwise velocity (:func:`point_velocity`) closer than
      the turn model's half-width, after which the motion goes on the way it came;
    * a stroke braked to a near stop: the speed falls below what it lost over the
      last sample (by more than 5× the pointwise velocity's noise), with no flip
      within the half-width — before the next sample the axis may have stopped, or
      bounced back for part of it.

    Which one happened is not in the samples, so the friction there is as unknown as
    a stop's (:func:`fit_rows_mask` treats a touch as one).  Measured on the
    independent generator's sweeps braking at 24 m/s² (current drive, 500 Hz and
    1 kHz, seeds 1–4): the *true* model left 0.34–1.9 % force NRMSE with these rows
    in and 0.15–0.29 % without them; on the 500 Hz runs −2.6 to −4.0 N (times the
    direction) on the rows within 5 samples of a touch, and that bias alone halved a
    load friction's ``mu``.  The samples returned span each event (at least three).
    """
    half = max(3, int(round(REVERSAL_HALF * kin.window)))
    # the signal whose sign the turn model reads (not the derivative window's, which
    # smooths a one-sample overshoot away)
    v = point_velocity(kin, kin.position)
    idx = np.flatnonzero(v != 0.0)
    s = np.sign(v[idx])
    f = np.flatnonzero(s[1:] != s[:-1])
    out = np.zeros(len(v), dtype=bool)
    i = 0
    while i < len(f):
        # flips closer than ``half`` are one event, grouped as the turn model does
        j = i
        while j + 1 < len(f) and idx[f[j + 1]] - idx[f[j] + 1] < half:
            j += 1
        a, b = idx[f[i]], idx[f[j] + 1]     # last sample before, first after the event
        if s[f[i]] == s[f[j] + 1] and b - a <= 2 * half:
            c = (a + b) // 2
            out[min(a + 1, c - 1):max(b, c + 2)] = True
        i = j + 1
    # a near stop with no flip: the speed fell below what it lost over the last sample
    # (by more than 5× the pointwise velocity's noise), so the axis may have stopped or
    # bounced back before the next sample; a flip within ``half`` is a turn, the turn
    # model's to place.  Only braking into it: the speed *jumping* out of a near stop
    # is a gap's engagement or a break-away, which their own models place (counted as
    # touches too, they cost 3 of the suite's 312 fits their backlash)
    sp = np.abs(v)
    noise = 5.0 * max(kin.noise_std(), kin.quantum() / np.sqrt(12.0)) * float(
        np.sqrt(np.sum(_coeffs(short_window(kin), 2, 1) ** 2))) / kin.dt
    k = np.arange(1, len(v) - 1)
    lost = sp[k - 1] - sp[k]
    near = (sp[k] < lost) & (lost > noise)
    flip = np.zeros(len(v) + 1, dtype=np.int64)
    flip[idx[f] + 1] = 1                     # a sign change just before these samples
    cum = np.cumsum(flip)
    lo, hi = np.clip(k - half, 0, len(v)), np.clip(k + half + 1, 0, len(v))
    near &= cum[hi] - cum[lo + 1] == 0
    c = k[near]
    out[c - 1] = out[c] = out[c + 1] = True
    return out


def fit_rows_mask(kin: Kinematics, *, min_stop: int = 3, half: int | None = None) \
        -> np.ndarray:
    """Return the sliding samples whose smoothing window does not reach into a stop.

    A stopped (stuck) axis carries whatever friction balances the drive, so no
    sliding law explains it (``../shared/IDENTIFICATION.md`` §2); with a smoothing
    window every sample within half a window of a stop mixes that force in.  Stops
    are runs of at least ``min_stop`` samples below the sliding threshold, and the
    :func:`touches` (stops the samples do not resolve); a plain zero crossing of the
    velocity at a reversal (one or two samples) is kept, since pre-sliding and backlash
    live there.
    """
    m = sliding_mask(kin)
    still = ~m | touches(kin)
    d = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    half = kin.window // 2 if half is None else int(half)
    out = m.copy()
    for a, b in zip(starts, stops):
        if b - a >= min_stop:
            out[max(a - half, 0):b + half] = False
    return out


@dataclasses.dataclass(frozen=True)
class Processing:
    """The processing choices of one identification (see the module docstring).

    Parameters
    ----------
    smoother_scale : float
        Length of ``S`` relative to :func:`smoother_length` (the processing term of
        the standard errors refits with 2).
    decimate : bool
        Keep every ``W/8``-th fitted sample (the fits and every reported figure), or
        every one (the residual figures).
    gms_scale : float
        Length of the pre-sliding elements' position smoothing relative to
        :func:`short_window` (the processing term of the standard errors refits with 2:
        that smoothing rounds each reversal, and the GMS stiffness feels it).
    turns : bool
        Fit the sliding samples right up to each stop (the transitions out of and into
        a rest, where pre-sliding acts; the rest itself is out of the force balance),
        for a model with a term whose evidence is there; False (every other model)
        keeps a smoother half-width away from every stop: there the turn model's
        misfit of a stick would bias the sliding terms (measured on the independent
        suite: 97.8 % of 312 fits pass with the gap, 89.7 % without it).
    """

    smoother_scale: float = 1.0
    decimate: bool = True
    turns: bool = False
    gms_scale: float = 1.0

    def step(self, W: int) -> int:
        """Return the decimation step [samples] for a smoother of ``W`` samples."""
        return max(1, W // 8) if self.decimate else 1

    def window(self, kin: Kinematics) -> int:
        """Return the smoother length ``W`` [samples] for ``kin``."""
        return smoother_length(kin, self.smoother_scale)

    def stop_margin(self, W: int) -> int:
        """Return how far [samples] the fitted rows stay from a stop (see ``turns``)."""
        return 0 if self.turns else W // 2

    def rows(self, kin: Kinematics, W: int) -> np.ndarray:
        """Return the fitted samples of ``kin``: sliding, away from the record's ends."""
        if self.turns:
            # right up to each stop and through each touch: the turn's own models (the
            # stuck share, the pre-sliding elements and the gap driven by the measured
            # path) judge them — leaving touches out of these rows as well lifted a
            # pre-sliding model over Coulomb + viscous on 2 of 15 load-friction runs
            mask = sliding_mask(kin)
        else:
            mask = fit_rows_mask(kin, half=self.stop_margin(W), min_stop=3)
        mask[:W // 2 + 2] = False
        mask[len(kin) - W // 2 - 2:] = False
        return mask


__all__ = ['Processing', 'fit_rows_mask', 'gms_position', 'held_ends', 'kernel', 'point_position',
           'point_velocity', 'short_window', 'sliding_mask', 'sliding_threshold', 'smooth_at',
           'smooth_columns_at', 'smooth_full', 'smooth_local_at', 'smoother_length', 'stencil',
           'stencil_gain', 'touches']


# Python calls the kernels above through their entries: compiled ahead of time where
# built (see motor_comp.physics.aot), else the JIT
_smooth_rows_entry = aot.entry(_smooth_rows)
_smooth_local_entry = aot.entry(_smooth_local)
