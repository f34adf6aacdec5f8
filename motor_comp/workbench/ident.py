"""Joint inverse-dynamic-model identification (IDIM-LS) with variable projection.

``F_in(u(t − τ)) = M·ẍ + Σ_g Φ_g(x, ẋ; η_g)·θ_g`` (``../shared/IDENTIFICATION.md`` §1;
Gautier & Janot's IDIM-LS for robot joints and EMPS-class axes): every effect is a
*group of named columns* of one regressor matrix (PySINDy-style libraries that
compose), and every coefficient that enters linearly — mass/inertia, ``fc``, ``fv``,
``fs − fc``, ripple harmonics, offset, spring, asymmetry, gravity ``mgl·cos q0`` and
``−mgl·sin q0`` — is re-estimated *together* each time the effect set changes.
Nonlinear parameters ``η`` (ripple period and harmonic count, Stribeck ``vs``/``δ``,
delay ``τ``, backlash width, GMS distance scale and ``c``) are searched by
variable projection (Golub & Pereyra 1973): at each trial ``η`` the linear part is
re-solved, so the search is over 1–2 numbers, never over everything.

Validation (§4): the sliding samples are cut into many short blocks (0.25–2 s) assigned
to folds round-robin, so every fold covers every regime of a time-ordered experiment
(a slow→fast sweep included); training excludes one filter half-width next to each
held-out block (hv-block CV, Racine 2000).  Per-block Gram matrices make a held-out
score a few small solves; data-driven choices (period, harmonic count, Stribeck basin,
delay, GMS distance scale, gap width) are made inside each fold from its training blocks.

Uncertainty (§5): residuals are coloured, so ``σ²(ΦᵀΦ)⁻¹`` is too small; the
covariance is a delete-one-stretch jackknife over a few contiguous stretches of each run
(regimes of a time-ordered experiment, so regime-to-regime disagreement of a model that
does not quite fit counts too), with the nonlinear parameters (backlash width included)
entering through their Gauss–Newton (linearised) columns; derived parameters (``x0``,
``fs``, ``mgl``/``q0``, …) by the delta method.  Correlations near ±1, from the
block sandwich, name the pairs this run cannot separate (§6).
"""
from __future__ import annotations

import dataclasses
import math
import weakref
from typing import Any, Callable, Sequence

import numpy as np
from scipy.optimize import minimize, minimize_scalar
from numba import njit
from scipy.signal import savgol_coeffs

from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import make_effect
from motor_comp.physics.effects.presliding import gms_step, gms_trajectory
from motor_comp.physics.effects.stribeck import stribeck_curve, stribeck_shape
from motor_comp.workbench.derivatives import InputHold, Kinematics
from motor_comp.workbench.residual import motor_position, sliding_mask

#: the moving mass/inertia: always a column (unless the run does not excite it)
MASS = 'mass'
#: candidates the selection may add (vocabulary order); gravity only on rotary axes
LINEAR = ('coulomb', 'viscous', 'offset', 'spring', 'asymmetry', 'gravity')
NONLINEAR = ('stribeck', 'presliding', 'ripple', 'delay', 'backlash')
ORDER = ('coulomb', 'viscous', 'stribeck', 'presliding', 'ripple', 'offset', 'spring',
         'asymmetry', 'delay', 'backlash', 'gravity')
#: least share of the sliding samples in the minority direction for the runs to count as
#: moving both ways: below it the backward samples are jitter of a one-way run, not a
#: second direction of sliding (a Coulomb force does not flip on them)
MIN_DIRECTION_SHARE = 0.05
#: the largest number of ripple harmonics
MAX_HARMONICS = 6
#: widest backlash gap searched [m or rad]
MAX_BACKLASH = 0.01
#: pre-sliding distances of the GMS element columns, relative to the searched scale
#: ``d0``: the element distribution (how much of the friction level each distance
#: carries) is then linear and fitted jointly, so the element count and split are
#: estimated, not assumed (unused distances get no weight)
GMS_DISTANCES = (0.3, 1.0, 3.0)
#: most GMS elements the structural search grows to (``_grow_gms``)
GMS_MAX_ELEMENTS = 4
#: contiguous stretches of the record the standard errors are jackknifed over (see
#: ``_sandwich``): each a regime of a time-ordered experiment, still 7 degrees of freedom
SE_CLUSTERS = 8


def fit_rows_mask(kin: Kinematics, *, min_stop: int = 3, half: int | None = None) \
        -> np.ndarray:
    """Sliding samples whose smoothing window does not reach into a stop.

    A stopped (stuck) axis carries whatever friction balances the drive, so no
    sliding law explains it (``../shared/IDENTIFICATION.md`` §2); with a smoothing
    window every sample within half a window of a stop mixes that force in.  Stops
    are runs of at least ``min_stop`` samples below the sliding threshold; a plain
    zero crossing of the velocity at a reversal (one or two samples) is kept, since
    pre-sliding and backlash live there (the workbench uses half a smoother length as
    ``min_stop``: a gap crossing or a short stick at a reversal stays in).
    """
    m = sliding_mask(kin)
    still = ~m
    d = np.diff(np.concatenate([[0], still.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(d == 1), np.flatnonzero(d == -1)
    half = kin.window // 2 if half is None else int(half)
    out = m.copy()
    for a, b in zip(starts, stops):
        if b - a >= min_stop:
            out[max(a - half, 0):b + half] = False
    return out


# ------------------------------------------------------------------------------------
# data: one or several runs, decimated sliding rows, hv-blocks
# ------------------------------------------------------------------------------------
@dataclasses.dataclass
class _RunPart:
    kin: Kinematics
    rows: np.ndarray            # indices into the run's full-rate arrays
    W: int                      # smoother length [samples] (odd)
    xs: np.ndarray              # S(motor position) at full rate (linear columns)
    x: np.ndarray               # pointwise motor position / velocity for the nonlinear
    v: np.ndarray               # laws (backlash changes them)
    xg: np.ndarray | None = None    # position for the GMS elements (see _gms_position)


#: memory for cached smoothed columns of one fit [bytes]
COLUMN_CACHE_BYTES = 256 * 2**20


class Data:
    """One identification experiment: the sliding samples of one or more runs.

    Parameters
    ----------
    kins : sequence of Kinematics
        The runs (one experiment, one model).
    model : AxisModel
        Supplies the drive constants (``input_gain``, ``back_emf``, ``damping``).
    folds : int
        Number of folds the blocks are dealt to (round-robin).
    block_s : float, optional
        Block length [s]; default from the record length (0.25–2 s).
    smoother_scale : float
        Length of the smoother ``S`` relative to :func:`smoother_length` (the
        processing-sensitivity term of the standard errors refits with 2).
    masks : sequence of ndarray of bool, optional
        The sliding samples of each run (``Data.masks`` of another experiment on the
        same time grid), instead of finding them in ``kins``: the measurement term of
        the standard errors refits the same samples of re-measured positions.
    """

    def __init__(self, kins: Sequence[Kinematics], model: AxisModel, *, folds: int = 5,
                 block_s: float | None = None, smoother_scale: float = 1.0,
                 masks: Sequence[np.ndarray] | None = None) -> None:
        if folds < 2:
            raise ParameterError(f'folds must be >= 2, got {folds}')
        self.kins = list(kins)
        self.model = model
        self.folds = int(folds)
        self.smoother_scale = float(smoother_scale)
        self.parts: list[_RunPart] = []
        #: the sliding samples of each run (full rate, before decimation)
        self.masks: list[np.ndarray] = []
        total = sum(k.duration for k in self.kins)
        if block_s is None:
            block_s = float(np.clip(total / (10.0 * folds), 0.25, 2.0))
        run_id, blk, t_rows, head_tail = [], [], [], []
        nblk = 0
        n_full = 0.0
        for i, kin in enumerate(self.kins):
            W = smoother_length(kin)
            if smoother_scale != 1.0:
                W = 2 * max(1, int(round(smoother_scale * (W // 2)))) + 1
            if masks is None:
                mask = fit_rows_mask(kin, half=W // 2, min_stop=3)
                mask[:W // 2 + 2] = False
                mask[len(kin) - W // 2 - 2:] = False
            else:
                mask = np.asarray(masks[i], dtype=bool)
            self.masks.append(mask)
            step = max(1, W // 8)
            keep = np.zeros(len(kin), dtype=bool)
            keep[::step] = True
            rows = np.flatnonzero(mask & keep)
            xs = _smooth_full(kin.position, W)
            vp = _point_velocity(kin, kin.position)
            self.parts.append(_RunPart(kin, rows, W, xs, kin.x, vp,
                                       _gms_position(kin, kin.position)))
            # independent samples: Σb² of the normalised kernel per sample
            n_full += len(rows) * step * float(np.sum(_kernel(W) ** 2))
            t = kin.t[rows] - kin.t[0]
            b = np.floor(t / block_s).astype(int)
            # position of each row inside its block, for the hv gap
            half = 0.5 * W * kin.dt
            b_lo = b * block_s
            b_hi = (b + 1) * block_s
            ht = np.where(t - b_lo < half, 0, np.where(b_hi - t <= half, 2, 1))
            blk.append(b + nblk)
            nblk += int(b.max()) + 1 if len(b) else 0
            run_id.append(np.full(len(rows), i))
            t_rows.append(t)
            head_tail.append(ht)
        self.run_id = np.concatenate(run_id)
        block = np.concatenate(blk)
        ht = np.concatenate(head_tail)
        if len(block) == 0:
            raise ParameterError('no sliding samples in the run(s): the axis does not move')
        # renumber the non-empty blocks in time order; deal them to folds round-robin
        _, block = np.unique(block, return_inverse=True)
        self.block = block
        self.n_blocks = int(block.max()) + 1
        self.block_fold = np.arange(self.n_blocks) % self.folds
        self.fold = self.block_fold[block]
        # parts: (block, head/core/tail); rows are in time order so parts are contiguous
        part_key = block * 3 + ht
        change = np.flatnonzero(np.diff(part_key)) + 1
        self.starts = np.concatenate([[0], change])
        self.part_block = block[self.starts]
        self.part_pos = ht[self.starts]
        self.n = len(block)
        self._train_parts = []
        for f in range(self.folds):
            tr = self.block_fold[self.part_block] != f
            prev_f = np.roll(self.block_fold, 1)[self.part_block]
            next_f = np.roll(self.block_fold, -1)[self.part_block]
            # hv gap: a training block's edge next to a held-out block is left out
            tr &= ~((self.part_pos == 0) & (prev_f == f) & (self.part_block > 0))
            tr &= ~((self.part_pos == 2) & (next_f == f)
                    & (self.part_block < self.n_blocks - 1))
            self._train_parts.append(tr)
        self._test_parts = [self.block_fold[self.part_block] == f for f in range(self.folds)]
        self.n_eff = max(n_full, 2.0)
        v = np.concatenate([np.asarray(p.v)[p.rows] for p in self.parts])
        n_pos, n_neg = int(np.count_nonzero(v > 0)), int(np.count_nonzero(v < 0))
        #: share of the sliding samples in the less frequent direction (0–0.5)
        self.minority_share = min(n_pos, n_neg) / max(n_pos + n_neg, 1)
        #: +1/−1 when the runs slide one way only (``MIN_DIRECTION_SHARE``), else 0
        self.direction = (0 if self.minority_share >= MIN_DIRECTION_SHARE
                          else (1 if n_pos >= n_neg else -1))
        self.window = max(p.W for p in self.parts)
        self.tau0 = 0.0
        self.width0 = 0.0
        #: which motion the parts hold: 0 the measured one; a new number each time a
        #: backlash gap is reconstructed (the motion then depends on the gap, the model
        #: and the delay), so cached columns never outlive the motion they came from
        self.motion = 0
        self._motions = 0
        self._cache: dict = {}
        #: cached smoothed columns: a fitting run's searches reuse ~1500 of them (delay,
        #: GMS, Stribeck trials across the rounds of --auto); clearing the cache at 400
        #: recomputed them 34 times in one fit.  Bounded by memory (COLUMN_CACHE_BYTES).
        self._cache_max = max(400, COLUMN_CACHE_BYTES // (8 * max(self.n, 1)))
        self._gram: dict = {}
        self._row_sets: dict = {}
        #: √weights of the rows (None: ordinary least squares), applied to every
        #: column and the target (:meth:`set_speed_weights`); ``weight_id`` keys the
        #: caches, a new number for each weighting
        self.sw: np.ndarray | None = None
        self.weight_id = 0
        self._weightings = 0
        self.speed_weights: tuple | None = None
        self._a = None
        starts = np.asarray(self.starts)
        self._part_bounds = list(zip(starts.tolist(), np.append(starts[1:], self.n).tolist()))

    # -- signals at the rows ------------------------------------------------------
    def vl(self) -> np.ndarray:
        """Velocity ``S(ẋ)`` at the rows: the exact derivative of the smoothed position.

        The smoothing ``S`` commutes with differentiation, so a difference quotient of
        ``S x`` is the velocity smoothed by the *same* filter as the force — unlike a
        Savitzky–Golay derivative filter, whose response differs from the smoother's
        and biases the linear coefficients (the mass most, and a delay with it).
        """
        return self.smooth_gather(None, ('vl',))

    def al(self) -> np.ndarray:
        """Acceleration ``S(ẍ)`` at the rows (second difference of the smoothed position)."""
        return self.smooth_gather(None, ('al',))

    def gather(self, fn: Callable[[_RunPart], np.ndarray]) -> np.ndarray:
        """Concatenate ``fn(run)[run.rows]`` over the runs (full-rate arrays)."""
        return np.concatenate([np.asarray(fn(p))[p.rows] for p in self.parts])

    def smooth_gather(self, fn: Callable[[_RunPart], np.ndarray],
                      key: tuple | None = None) -> np.ndarray:
        """Like :meth:`gather`, smoothing ``fn(run)`` with the run's filter.

        The zero-phase Savitzky–Golay smoothing is evaluated at the rows only (a dot
        product with the filter's coefficients over each row's window: the rows are
        decimated and never within a window of the record's ends).  With ``key`` the
        result is cached (per backlash width): the columns of the effects not being
        searched are computed once, not at every trial.
        """
        if key is not None:
            k = self.key(key)
            hit = self._cache.get(k)
            if hit is not None:
                return hit
        if key is not None and key[0] in ('vl', 'al'):
            out = np.concatenate([_stencil(p, key[0]) for p in self.parts])
        else:
            out = np.concatenate([_smooth_at(p, np.asarray(fn(p), dtype=float))
                                  for p in self.parts])
        if key is not None:
            if len(self._cache) > self._cache_max:
                self._cache.clear()
            self._cache[k] = out
        return out

    def smooth_gather_many(self, fn: Callable[[_RunPart], np.ndarray],
                           keys: Sequence[tuple]) -> None:
        """Cache the columns of ``fn(run)`` (2-D, one column per key), smoothed at the rows.

        For laws that give several columns in one pass (the GMS elements); nothing is
        computed when every key is cached already.
        """
        if all(self.key(k) in self._cache for k in keys):
            return
        out = np.concatenate([_smooth_at(p, np.asarray(fn(p), dtype=float))
                              for p in self.parts])
        if len(self._cache) > self._cache_max:
            self._cache.clear()
        for j, k in enumerate(keys):
            self._cache[self.key(k)] = np.ascontiguousarray(out[:, j])

    def smooth_harmonics(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``S(sin(w_h·x))`` and ``S(cos(w_h·x))`` at the rows, shape ``(n, len(w))``.

        ``w`` must be the harmonics ``h·w_1`` (h = 1, 2, …) of a spatial frequency
        [rad/m]: they come from one sine and cosine per sample by the angle-addition
        recurrence (a period search evaluates this thousands of times).
        """
        w = np.asarray(w, dtype=float)
        nh = len(w)
        out = []
        for p in self.parts:
            th = w[0] * np.asarray(p.x, dtype=float)
            s1, c1 = np.sin(th), np.cos(th)
            cols = np.empty((2 * nh, len(th)))
            cols[0], cols[nh] = s1, c1
            for h in range(1, nh):
                cols[h] = cols[h - 1] * c1 + cols[nh + h - 1] * s1
                cols[nh + h] = cols[nh + h - 1] * c1 - cols[h - 1] * s1
            out.append(_smooth_rows(cols, p.rows, _kernel(p.W)))
        both = np.concatenate(out)
        g = self.stencil_gain(w)
        return both[:, :nh] * g, both[:, nh:] * g

    def stencil_gain_cached(self, w: float) -> np.ndarray:
        """:meth:`stencil_gain` of one spatial frequency, cached with the columns."""
        k = self.key(('stencil_gain', float(w)))
        hit = self._cache.get(k)
        if hit is None:
            if len(self._cache) > self._cache_max:
                self._cache.clear()
            hit = self._cache[k] = np.ascontiguousarray(self.stencil_gain(w)[:, 0])
        return hit

    def stencil_gain(self, w: np.ndarray) -> np.ndarray:
        """Return the gain the acceleration stencil applies to ``sin(w·x)``, at the rows.

        The 3-point second difference of the position is the acceleration averaged
        with a triangle of ±1 sample (:func:`_stencil`), so a force that varies with
        position is seen averaged over that triangle too: at a locally constant speed
        ``v`` a spatial harmonic ``sin(w·x)`` is seen as ``sinc²(w·v·dt/2π)·sin(w·x)``.
        A pointwise column left the fitted ripple amplitude 0.1–0.7 % short on a 500 Hz
        sweep over a 7–30 mm period (and the mass took up the rest).  The factor is
        applied to the smoothed column at the row: it varies with the speed, slowly
        against the smoother's window.  Shape ``(n, len(w))``.
        """
        w = np.atleast_1d(np.asarray(w, dtype=float))
        vdt = self.gather(lambda p: np.asarray(p.v, dtype=float) * p.kin.dt)
        if len(w) == 1 or not np.allclose(w, w[0] * np.arange(1, len(w) + 1)):
            return np.sinc(np.outer(vdt, w) / (2 * math.pi)) ** 2
        # harmonics h·w₁: sin(h·θ) by the angle-addition recurrence (one sin, one cos)
        th = 0.5 * w[0] * vdt
        s1, c1 = np.sin(th), np.cos(th)
        out = np.empty((len(vdt), len(w)))
        sh, ch = s1, c1
        safe = np.where(th == 0.0, 1.0, th)
        for h in range(len(w)):
            if h:
                sh, ch = sh * c1 + ch * s1, ch * c1 - sh * s1
            out[:, h] = np.where(th == 0.0, 1.0, sh / ((h + 1) * safe)) ** 2
        return out

    def key(self, key: tuple) -> tuple:
        """Cache key of a column: its own key, the motion and the row weights."""
        return key + (self.width0, self.motion, self.weight_id)

    def set_speed_weights(self, weights: tuple[np.ndarray, np.ndarray] | None) -> None:
        """Weight each row by its speed band from now on; None: unweighted.

        ``weights`` is ``(edges, w)``: bands ``edges[i] ≤ |ẋ| < edges[i+1]`` [m/s or
        rad/s] with weight ``w[i]`` (> 0), the last band open-ended.  A rule, not a
        vector: a second processing of the same runs (:func:`processing_spread`) weights
        its own rows by it.
        """
        self.speed_weights = weights
        if weights is None:
            self.sw, self.weight_id = None, 0
            return
        edges, w = (np.asarray(a, dtype=float) for a in weights)
        if len(w) != len(edges) or not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise ParameterError('speed weights must be finite and positive, one per band')
        band = np.clip(np.searchsorted(edges, np.abs(self.vl()), side='right') - 1, 0,
                       len(w) - 1)
        self.sw = np.sqrt(w[band])
        self._weightings += 1
        self.weight_id = self._weightings

    # -- Gram entries, cached by column key ----------------------------------------
    def rows_id(self, rows: np.ndarray | None) -> int:
        """Return a small number naming a row subset (None: all rows) for the Gram cache."""
        if rows is None:
            return -1
        sig = np.packbits(rows).tobytes()
        rid = self._row_sets.get(sig)
        if rid is None:
            if len(self._row_sets) > 64:
                self._row_sets.clear()
                self._gram.clear()
            rid = self._row_sets[sig] = len(self._row_sets)
        return rid

    def gram(self, cols: Sequence[np.ndarray], keys: Sequence[tuple | None],
             rows: np.ndarray | None = None) -> np.ndarray:
        """``ZᵀZ`` of the columns ``cols`` over ``rows``, reusing cached entries.

        Variable projection re-solves the same design with one group of columns
        changed per trial: the products among the unchanged columns (named by
        ``keys``; None is never cached) are computed once, the trial columns' products
        with everything else at each trial — O(n·k·p) instead of O(n·p²) per trial.
        """
        q = len(cols)
        rid = self.rows_id(rows)
        G = np.empty((q, q))
        missing = []
        for i in range(q):
            ki = keys[i]
            if ki is None:
                missing.append(i)
                continue
            for j in range(i + 1):
                kj = keys[j]
                v = None if kj is None else self._gram.get((rid, ki, kj))
                if v is None:
                    missing.append(i)
                    break
                G[i, j] = G[j, i] = v
        if missing:
            Z = np.stack(cols, axis=1)
            if rows is not None:
                Z = Z[rows]
            M = Z[:, missing].T @ Z
            if len(self._gram) > 200_000:
                self._gram.clear()
            for a, i in enumerate(missing):
                G[i, :] = M[a]
                G[:, i] = M[a]
                ki = keys[i]
                if ki is None:
                    continue
                for j in range(q):
                    kj = keys[j]
                    if kj is not None:
                        self._gram[(rid, ki, kj)] = self._gram[(rid, kj, ki)] = M[a, j]
        return G

    def y(self, tau: float) -> np.ndarray:
        """Smoothed drive force at the rows with input delay ``tau`` [s] (moving part)."""
        m = self.model
        k = m.input_gain * m.back_emf + m.damping
        # the exact delayed command (held or sampled) smoothed at the rows: shifting the
        # smoothed signal instead would low-pass the smoother's leakage differently
        g = m.input_gain
        w = self.smooth_gather(lambda p: g * p.kin.input_at(float(tau)), ('u', float(tau)))
        return w - k * self.vl() if k else w

    def f_in_scale(self) -> float:
        """``Σ(F_in − mean)²`` over the rows (the NRMSE denominator)."""
        y = self.y(self.tau0)
        return float(np.sum((y - y.mean()) ** 2))

    def set_backlash(self, width: float, model: AxisModel) -> None:
        """Replace the motion by the motor position reconstructed across a gap."""
        self.width0 = float(width)
        if width <= 0:
            self.motion = 0
        else:
            self._motions += 1
            self.motion = self._motions
        for p in self.parts:
            if width <= 0:
                p.x, p.v = p.kin.x, _point_velocity(p.kin, p.kin.position)
                p.xs = _smooth_full(p.kin.position, p.W)
                p.xg = _gms_position(p.kin, p.kin.position)
                continue
            # the flight sees the logged command delayed by the current τ at the
            # integrator's sub-step (a whole-sample shift moved it by up to dt/2)
            xm = motor_position(p.kin, width, model.without('backlash', 'delay'), p.kin.u,
                                tau=self.tau0)
            p.x = _derivatives(p.kin, xm)[0]
            p.v = _point_velocity(p.kin, xm)
            p.xs = _smooth_full(xm, p.W)
            p.xg = _gms_position(p.kin, xm)

    # -- Gram matrices per part ---------------------------------------------------
    def part_grams(self, Z: np.ndarray, W: np.ndarray | None = None) -> np.ndarray:
        """Per-part ``Zᵀ W`` (``W`` defaults to ``Z``): shape (parts, q, r)."""
        W = Z if W is None else W
        # one small product per part: the n×q×r outer-product temporary of an einsum
        # followed by reduceat cost ~10× more at 60 000 rows
        out = np.empty((len(self._part_bounds), Z.shape[1], W.shape[1]))
        for i, (a, b) in enumerate(self._part_bounds):
            np.matmul(Z[a:b].T, W[a:b], out=out[i])
        return out

    def train(self, P: np.ndarray, f: int) -> np.ndarray:
        """Sum of the training parts of fold ``f``."""
        return P[self._train_parts[f]].sum(axis=0)

    def test(self, P: np.ndarray, f: int) -> np.ndarray:
        """Sum of the held-out parts of fold ``f``."""
        return P[self._test_parts[f]].sum(axis=0)

    def train_rows(self, f: int) -> np.ndarray:
        """Boolean row mask of fold ``f``'s training samples."""
        part_of_row = np.repeat(np.arange(len(self.starts)),
                                np.diff(np.append(self.starts, self.n)))
        return self._train_parts[f][part_of_row]


def _coeffs(window: int, polyorder: int, deriv: int = 0) -> np.ndarray:
    key = (window, polyorder, deriv)
    c = _COEFFS.get(key)
    if c is None:
        c = savgol_coeffs(window, polyorder, deriv=deriv, use='dot')
        _COEFFS[key] = c
    return c


_COEFFS: dict = {}


def _kernel(W: int) -> np.ndarray:
    """Return the smoother ``S``: a normalised Blackman window of ``W`` samples.

    Only its stop band matters (the same ``S`` is applied to the drive force and to
    every column, so the pass band's shape cancels): the Blackman window's sidelobes
    are below −58 dB, so the second difference of ``S x`` — which multiplies the
    position noise by ω² — stays quiet, where a Savitzky–Golay smoother leaks.
    """
    key = ('blackman', W)
    b = _COEFFS.get(key)
    if b is None:
        b = np.blackman(W + 2)[1:-1]
        b = b / b.sum()
        _COEFFS[key] = b
    return b


def smoother_length(kin: Kinematics) -> int:
    """Length of ``S`` [samples]: twice the derivative window (the same time scale)."""
    return 2 * (kin.window // 2) * 2 + 1


def _smooth_full(y: np.ndarray, W: int) -> np.ndarray:
    from scipy.ndimage import correlate1d
    return correlate1d(np.asarray(y, dtype=float), _kernel(W), mode='mirror')


def _smooth_at(p: _RunPart, y: np.ndarray) -> np.ndarray:
    """``S(y)`` at the rows (1-D or 2-D ``y``, time along the first axis).

    Only at the rows (every ``W/8``-th sliding sample, never within a window of the
    record's ends): the same sums as a full-rate ``scipy.ndimage.correlate1d``
    followed by the row selection, at a fraction of the work.
    """
    y = np.asarray(y, dtype=float)
    b = _kernel(p.W)
    h = p.W // 2
    if len(p.rows) and (p.rows[0] < h or p.rows[-1] + h >= y.shape[0]):
        raise ValueError('rows within a smoother half-width of the record ends')
    if y.ndim == 1:
        return _smooth_rows(np.ascontiguousarray(y).reshape(1, -1), p.rows, b)[:, 0]
    return _smooth_rows(np.ascontiguousarray(y.T), p.rows, b)


@njit(cache=True, fastmath=True)
def _smooth_rows(y: np.ndarray, rows: np.ndarray, b: np.ndarray) -> np.ndarray:
    # hand-written: scipy/numpy filter every sample; the rows are a sparse subset.
    # Column by column, each a contiguous dot product (y is time-major per column).
    h = b.shape[0] // 2
    out = np.empty((rows.shape[0], y.shape[0]))
    for c in range(y.shape[0]):
        yc = y[c]
        for i in range(rows.shape[0]):
            r0 = rows[i] - h
            acc = 0.0
            for j in range(b.shape[0]):
                acc += b[j] * yc[r0 + j]
            out[i, c] = acc
    return out


def _stencil(p: _RunPart, which: str) -> np.ndarray:
    """Velocity and acceleration of the smoothed position at the rows, under one kernel.

    The 3-point second difference of a trajectory is its acceleration averaged with
    the hat kernel over ``t_k ± dt`` — for a zero-order-hold force exactly
    ``(a_{k−1} + a_k)/2``, the triangle-weighted command :meth:`Kinematics.input_at`
    gives — so the acceleration and the drive force see the same kernel at every
    frequency, not only in the smoother's pass band (a Savitzky–Golay filter leaks
    above it).  The velocity (back-EMF, viscous columns) is the same hat average of
    ``ẋ``, not the central difference.
    """
    x, r, dt = p.xs, p.rows, p.kin.dt
    if which == 'vl':
        # the velocity under the same hat kernel: ∫hat·ẋ = (∫ x over the step after −
        # the step before)/dt², the step integrals by the 4-point midpoint rule.  The
        # central difference alone is a box average over ±dt, dt²/12·v̈ more than the
        # hat sees: with a back-EMF damping k that reads as a dead time k·dt²/(12·M)
        # (15 µs at k = 816 N·s/m, M = 4.7 kg, 1 kHz — the delay fits' bias)
        return ((x[r + 1] - x[r - 1]) / (2 * dt)
                - (x[r + 2] - 2 * x[r + 1] + 2 * x[r - 1] - x[r - 2]) / (24 * dt))
    return (x[r + 1] - 2 * x[r] + x[r - 1]) / (dt * dt)


def _gms_position(kin: Kinematics, x: np.ndarray) -> np.ndarray:
    """Position the GMS elements are driven by: a short Savitzky–Golay smoothing.

    The elements' break-away distances are micrometres; the derivative window's
    smoothing rounds each reversal over that scale, so a freed shortest element came
    out stiffer than the truth (+32 % on the project's own 1 kHz run).  The short
    window of :func:`_point_velocity` keeps the reversal's shape and still averages
    the encoder noise.
    """
    from scipy.ndimage import correlate1d
    return correlate1d(np.asarray(x, dtype=float), _coeffs(_short_window(kin), 2, 0),
                       mode='mirror')


def _short_window(kin: Kinematics) -> int:
    """Savitzky–Golay window of the pointwise laws: a third of the derivative's."""
    return max(5, (kin.window // 3) | 1)


def _point_velocity(kin: Kinematics, x: np.ndarray) -> np.ndarray:
    """Pointwise velocity for the nonlinear laws (sign, Stribeck, GMS direction).

    A short Savitzky–Golay derivative (a third of the derivative window, order 2): the
    sign of the velocity decides the friction direction at every reversal, and a long
    window moves the sign change — measured on the project's closed loop, the 21-sample
    derivative shifted the Coulomb switching enough to bias a dead time by +1.2 ms.
    """
    from scipy.ndimage import correlate1d
    w = _short_window(kin)
    x = np.asarray(x, dtype=float)
    v = correlate1d(x, _coeffs(w, 2, 1), mode='mirror') / kin.dt
    # remember the raw position: the reversal instants are located on it (a backlash
    # gap's reconstructed motor position is not kept anywhere else unsmoothed)
    key = id(v)
    _SOURCES[key] = (weakref.ref(v, lambda _, k=key: _SOURCES.pop(k, None)), x)
    return v


#: raw position of each live pointwise velocity, by the velocity array's id
_SOURCES: dict[int, tuple[weakref.ref, np.ndarray]] = {}


def _derivatives(kin: Kinematics, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pointwise (Savitzky–Golay) position and velocity of another position signal."""
    from scipy.ndimage import correlate1d
    w, o = kin.window, kin.polyorder
    return (correlate1d(x, _coeffs(w, o, 0), mode='mirror'),
            correlate1d(x, _coeffs(w, o, 1), mode='mirror') / kin.dt)


# ------------------------------------------------------------------------------------
# least squares on an augmented Gram [X y]ᵀ[X y]
# ------------------------------------------------------------------------------------
def solve_gram(G: np.ndarray) -> tuple[np.ndarray, float]:
    """θ and SSE from an augmented Gram ``[X y]ᵀ[X y]`` (tiny ridge, column-scaled)."""
    p = G.shape[0] - 1
    if p == 0:
        return np.zeros(0), float(G[0, 0])
    A = G[:p, :p]
    b = G[:p, p]
    d = np.sqrt(np.maximum(np.diag(A), 1e-300))
    As = A / np.outer(d, d)
    try:
        th = np.linalg.solve(As + 1e-10 * np.eye(p), b / d) / d
    except np.linalg.LinAlgError:
        th = np.linalg.lstsq(As, b / d, rcond=None)[0] / d
    sse = float(G[p, p] - 2.0 * th @ b + th @ A @ th)
    return th, max(sse, 0.0)


def _sse_with(G: np.ndarray, th: np.ndarray) -> float:
    p = len(th)
    return max(float(G[p, p] - 2.0 * th @ G[:p, p] + th @ G[:p, :p] @ th), 0.0)


# ------------------------------------------------------------------------------------
# groups of columns
# ------------------------------------------------------------------------------------
@dataclasses.dataclass
class Spec:
    """An effect set with its nonlinear parameters: what a design is built from.

    Parameters
    ----------
    names : tuple of str
        Effects present (vocabulary names).
    eta : dict
        Nonlinear parameters per effect: ripple ``(period, H)``, stribeck ``(vs, δ)``,
        presliding ``(distances, c, Stribeck ratio)``, delay ``τ``, backlash width.
    mass_free : bool
        Whether the mass is a column (else fixed at ``mass``).
    mass : float
        The fixed mass when not free [kg or kg·m²].
    """

    names: tuple
    eta: dict
    mass_free: bool = True
    mass: float = 1.0

    def with_(self, name: str, eta: Any = None) -> 'Spec':
        """Return a copy with ``name`` added (and its nonlinear parameters)."""
        e = dict(self.eta)
        if eta is not None:
            e[name] = eta
        names = tuple(n for n in ORDER if n in set(self.names) | {name})
        return Spec(names, e, self.mass_free, self.mass)

    def without(self, name: str) -> 'Spec':
        """Return a copy without ``name``."""
        e = {k: v for k, v in self.eta.items() if k != name}
        return Spec(tuple(n for n in self.names if n != name), e, self.mass_free, self.mass)


#: half-width of the local position fit at a reversal, as a share of the derivative window
#: (8 samples of a 21-sample window: about the time the drive takes to turn the axis)
REVERSAL_HALF = 0.4
#: least travel [position resolutions] of both sides of a turn within the local fit
MIN_TURN = 5.0
#: stuck samples at a turn carry the drive force as friction (:func:`target`)
STUCK_FORCE = True
#: shortest stop at a turn resolved from the position [samples]
MIN_STICK = 1.0


def _direction_shares(p: _RunPart) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Share of each sample's acceleration kernel spent sliding forward, backward, stuck.

    The sign-based friction columns (Coulomb, Stribeck, asymmetry) are these shares, not
    the sign of an estimated velocity, and the stuck share carries the drive force into
    the friction (see :func:`reversal_shares` and :func:`target`).  Cached on the part
    for as long as its motion (``p.v``) is the same object.
    """
    hit = getattr(p, '_shares', None)
    if hit is not None and hit[0] is p.v:
        return hit[1]
    # the reversal instant comes from the raw position the velocity was derived from
    # (the reconstructed motor position with a backlash gap)
    src = _SOURCES.get(id(p.v))
    raw = src[1] if src is not None and src[0]() is p.v else \
        (p.kin.position if p.x is p.kin.x else p.x)
    half = max(3, int(round(REVERSAL_HALF * p.kin.window)))
    eps = getattr(p, '_eps', None)
    if eps is None:             # the sensor's resolution: once per run
        eps = max(p.kin.quantum(), p.kin.noise_std())
        p._eps = eps    # type: ignore[attr-defined]
    out = reversal_shares(np.asarray(raw, dtype=float), np.asarray(p.v, dtype=float),
                          half, eps, spread=p.kin.hold is not InputHold.SAMPLE)
    p._shares = (p.v, out)    # type: ignore[attr-defined]
    return out


def _signed_share(p: _RunPart) -> np.ndarray:
    """Coulomb column before smoothing: forward minus backward share (``sgn ẋ``)."""
    fwd, bwd, _ = _direction_shares(p)
    return fwd - bwd


def _moving_share(p: _RunPart, sticks: bool) -> np.ndarray:
    """Share of the kernel spent sliding either way (``abs(sgn ẋ)``).

    With ``sticks`` (:func:`target` leaves the stuck samples out) a constant force's
    column is 0 on them too, so at a turn an offset and a Coulomb asymmetry stay the
    same column, as they are physically (both shift the break-away band alike;
    ``../shared/IDENTIFICATION.md`` §1); without, a stop at a turn counts as sliding.
    """
    fwd, bwd, stuck = _direction_shares(p)
    return fwd + bwd if sticks else fwd + bwd + stuck


def reversal_shares(x: np.ndarray, v: np.ndarray, half: int, eps: float = 0.0, *,
                    spread: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Shares of each sample spent sliding forward, backward and stuck, at sub-sample turns.

    The acceleration at sample ``k`` (second difference) is the motion's acceleration
    averaged with a hat kernel over ``t_k ± dt``, so the friction it balances is the
    friction averaged with that kernel.  At a turn the Coulomb force switches at the
    *instant* the velocity changes sign, and where the axis sticks for a while it is
    not ``±fc`` at all but whatever balances the drive.  The sign of a short
    derivative switches at a whole sample, late or early by up to a sample (and in the
    middle of a stick); the Coulomb force then trades with the acceleration's lag — a
    spurious dead time and, through the back-EMF (``k·τ`` of force per unit
    acceleration), a mass 25 % low on the project's own chirp.  Here each turn (a
    change of the sign of ``v``; flips closer than ``half`` samples are one turn) is
    fitted on the raw position over ``±half`` samples: an arc into a stop at ``ta``,
    the position held until ``tb``, an arc out (quadratic and cubic terms on each side:
    the acceleration jumps by ``2·fc/M`` at a turn without sticking and starts from 0
    after a stick).  A stop shorter than ``MIN_STICK`` samples is not resolved and the
    two arcs meet (``ta = tb``).  Flips that are not a clear turn keep the sign of
    ``v``: spread over more than ``half`` samples (an axis at rest, whose rows the fit
    leaves out anyway), back the same way, or a turn whose two sides do not both move
    ``MIN_TURN`` position resolutions away within the fit (too slow to locate).

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
        drive force (:func:`target`).
    """
    s = np.sign(v)
    fwd, bwd = (s > 0).astype(float), (s < 0).astype(float)
    stuck = np.zeros(len(s))
    nz = np.flatnonzero(s)
    if len(nz) < 2:
        return fwd, bwd, stuck
    sn = s[nz]
    flips = np.flatnonzero(sn[:-1] != sn[1:])
    _fit_turns(np.ascontiguousarray(x, dtype=float), nz, sn, flips, int(half),
               MIN_TURN * float(eps), bool(spread), float(MIN_STICK), fwd, bwd, stuck)
    return fwd, bwd, stuck


@njit(cache=True)
def _hat_before(d):
    # area of the unit hat kernel on [−1, 1] left of d [samples]
    d = min(max(d, -1.0), 1.0)
    return 0.5 * (1.0 + d) ** 2 if d <= 0.0 else 1.0 - 0.5 * (1.0 - d) ** 2


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


def gms_columns(p: _RunPart, dists: Sequence[float], c: float, ratio: float, vs: float,
                delta: float) -> np.ndarray:
    """:func:`gms_column` for several distances in one pass (shape ``(n, len(dists))``).

    The elements share the displacement, the Stribeck curve and the slip decay of each
    step, so one pass of the physics' own element law (``gms_step``) gives every
    column; with ``σ = 0`` each element's force after the step is its column.
    """
    inv_d = np.array([1.0 / d for d in dists])
    return _gms_unit_columns(np.ascontiguousarray(p.xg), inv_d, float(c), 1.0 + ratio,
                             float(vs), float(delta), p.kin.dt)


@njit(cache=True)
def _gms_unit_columns(x, inv_d, C, fs, vs, delta, dt):
    n, m = x.shape[0], inv_d.shape[0]
    out = np.zeros((n, m))
    forces = np.zeros(m)
    slip = np.zeros(m)
    alpha = np.ones(m)
    sigma = np.zeros(m)
    for j in range(1, n):
        dx = x[j] - x[j - 1]
        v = dx / dt
        s_v = stribeck_curve(v, 1.0, fs, vs, delta)
        gms_step(forces, 0, slip, 0, alpha, 0, inv_d, 0, sigma, 0, m, C, dt, dx, v, s_v)
        for e in range(m):
            out[j, e] = forces[e]
    return out


def gms_column(p: _RunPart, d: float, c: float, ratio: float, vs: float,
               delta: float) -> np.ndarray:
    """Force of one Maxwell-slip element per newton of its slip limit along a run.

    An element of slip limit ``β·s(v)/fc`` and stiffness ``β/d`` (pre-sliding distance
    ``d`` [m]) gives exactly ``β`` times this column: with the distances held, the
    GMS force ``Σ β_j·g_j`` is linear in the element levels ``β_j`` (Lampaert 2003;
    Chiew eq. 3–5), their sum is the Coulomb level ``fc``, ``α_j = β_j/fc``,
    ``k_j = β_j/d_j``.  The published slip law's attraction ``C = c·fc`` keeps the
    unit-level column homogeneous.
    """
    return gms_trajectory(np.ascontiguousarray(p.xg), np.ones(1), np.array([1.0 / d]),
                          np.zeros(1), float(c), 1.0, 1.0 + ratio, float(vs), float(delta),
                          p.kin.dt)


def columns(D: Data, spec: Spec) -> tuple[np.ndarray, list[tuple[str, str]]]:
    """Regressor matrix of ``spec`` at the rows and its column labels (group, name)."""
    cols, labels, _ = keyed_columns(D, spec)
    X = np.stack(cols, axis=1) if cols else np.zeros((D.n, 0))
    return X, labels


def keyed_columns(D: Data, spec: Spec) \
        -> tuple[list[np.ndarray], list[tuple[str, str]], list[tuple]]:
    """Columns of ``spec`` at the rows, their labels and their cache keys.

    The keys name what a column is computed from (see :meth:`Data.gram`).
    """
    cols: list[np.ndarray] = []
    labels: list[tuple[str, str]] = []
    keys: list[tuple] = []
    names = set(spec.names)
    last: dict = {}

    def sg(fn: Callable[[_RunPart], np.ndarray], key: tuple) -> np.ndarray:
        last['key'] = D.key(key)
        return D.smooth_gather(fn, key)

    def add(group: str, label: str, c: np.ndarray, key: tuple | None = None) -> None:
        c = np.asarray(c, dtype=float)
        cols.append(c if D.sw is None else c * D.sw)
        labels.append((group, label))
        keys.append(key if key is not None else last.pop('key'))

    if spec.mass_free:
        add(MASS, 'mass', D.al(), D.key(('al',)))
    gms = 'presliding' in names
    st = spec.eta.get('stribeck')
    if 'coulomb' in names:
        if gms:
            dists, c, ratio = spec.eta['presliding']
            vs, dl = st if (st is not None and 'stribeck' in names) else (1e-3, 1.0)
            ratio = ratio if 'stribeck' in names else 0.0
            D.smooth_gather_many(lambda p: gms_columns(p, dists, c, ratio, vs, dl),
                                 [('gms', d, c, ratio, vs, dl) for d in dists])
            for j, d in enumerate(dists):
                add('presliding', f'b{j}', sg(
                    lambda p, d=d: gms_column(p, d, c, ratio, vs, dl),
                    ('gms', d, c, ratio, vs, dl)))
        elif D.direction:
            # one-way runs: the friction opposes the one direction of sliding throughout
            add('coulomb', 'fc', np.full(D.n, float(D.direction)),
                ('direction', D.direction))
        else:
            add('coulomb', 'fc', sg(lambda p: _signed_share(p), ('sgn_shares',)))
    if 'viscous' in names:
        add('viscous', 'fv', D.vl(), D.key(('vl',)))
    if 'stribeck' in names and not gms:
        vs, dl = st
        add('stribeck', 'dfs', sg(
            lambda p: stribeck_shape(p.v / vs, dl) * _signed_share(p),
            ('stribeck_shares', vs, dl)))
    if 'ripple' in names:
        period, nh = spec.eta['ripple']
        for h in range(1, int(nh) + 1):
            w = 2 * math.pi * h / period
            g = D.stencil_gain_cached(w)
            add('ripple', f'a{h}', sg(lambda p, w=w: np.sin(w * p.x), ('sin', w)) * g,
                D.key(('sin_stencil', w)))
            add('ripple', f'b{h}', sg(lambda p, w=w: np.cos(w * p.x), ('cos', w)) * g,
                D.key(('cos_stencil', w)))
    const_owner = None
    sticks = _sticks(D, spec)
    if sticks and ('offset' in names or 'spring' in names):
        # the samples stuck at a turn are left out of the force balance (see target):
        # of a constant force too, which an offset and a Coulomb asymmetry share
        ones = sg(lambda p: 1.0 - _direction_shares(p)[2], ('not_stuck',))
        ones_key = last.pop('key')
    else:
        ones, ones_key = np.ones(D.n), ('ones',)
    if 'offset' in names:
        add('offset', 'f0', ones, ones_key)
        const_owner = 'offset'
    if 'spring' in names:
        add('spring', 'k', D.gather(lambda p: p.xs), D.key(('xs',)))
        if const_owner is None:
            add('spring', 'c', ones, ones_key)
            const_owner = 'spring'
    if 'asymmetry' in names:
        if const_owner is None:
            add('asymmetry', 'dfc', sg(lambda p: 0.5 * _moving_share(p, sticks),
                                       ('moving_share', sticks)))
        add('asymmetry', 'dfv', sg(lambda p: 0.5 * np.abs(p.v), ('abs_v',)))
    if 'gravity' in names:
        add('gravity', 'A', sg(lambda p: np.sin(p.x), ('sinq',)))
        add('gravity', 'B', sg(lambda p: np.cos(p.x), ('cosq',)))
    return cols, labels, keys


def target(D: Data, spec: Spec) -> np.ndarray:
    """Return the left-hand side: drive force (delayed), minus ``M·ẍ`` if M is fixed.

    With dry friction (and no pre-sliding model, which describes sticking itself), the
    drive force of the samples where the axis sticks at a turn is taken out: a stuck
    axis's friction is exactly that force (it neither accelerates nor moves), not
    ``±fc``, so the Coulomb model predicts it and the sign columns are 0 there
    (:func:`reversal_shares`).
    """
    tau = spec.eta.get('delay', 0.0) if 'delay' in spec.names else 0.0
    y = D.y(tau)
    if _sticks(D, spec):
        g = D.model.input_gain
        y = y - D.smooth_gather(
            lambda p: g * _direction_shares(p)[2] * p.kin.input_at(float(tau)),
            ('stuck_u', float(tau)))
    if not spec.mass_free:
        y = y - spec.mass * D.al()
    return y if D.sw is None else y * D.sw


def target_key(D: Data, spec: Spec) -> tuple:
    """Cache key of :func:`target` (delay, fixed mass, and the motion)."""
    tau = spec.eta.get('delay', 0.0) if 'delay' in spec.names else 0.0
    return D.key(('target', float(tau), spec.mass_free, 0.0 if spec.mass_free
                  else float(spec.mass), _sticks(D, spec)))


def _sticks(D: Data, spec: Spec) -> bool:
    """Whether :func:`target` carries the stuck samples' drive force into the friction."""
    names = spec.names
    return (STUCK_FORCE and 'coulomb' in names and 'presliding' not in names
            and not D.direction)


# ------------------------------------------------------------------------------------
# cross-validated score of a fixed design, and of a candidate with in-fold η
# ------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Score:
    """Held-out result of one design."""

    sse_cv: float
    sse_fit: float
    n_params: int
    fold_theta: tuple


def cv_design(D: Data, X: np.ndarray, y: np.ndarray) -> Score:
    """Held-out SSE of the joint least squares of ``y`` on ``X`` over the folds."""
    Z = np.column_stack([X, y])
    P = D.part_grams(Z)
    total = 0.0
    ths = []
    for f in range(D.folds):
        th, _ = solve_gram(D.train(P, f))
        total += _sse_with(D.test(P, f), th)
        ths.append(th)
    _, sse = solve_gram(P.sum(axis=0))
    return Score(total, sse, X.shape[1], tuple(ths))


def solve_spec(D: Data, spec: Spec) -> np.ndarray:
    """Linear parameters of ``spec`` by least squares on all rows (``D``'s weights)."""
    X, _ = columns(D, spec)
    Z = np.column_stack([X, target(D, spec)])
    return solve_gram(Z.T @ Z)[0]


def cv_unweighted(D: Data, spec: Spec) -> float:
    """Held-out SSE [N²], unweighted, of fold fits made with ``D``'s row weights.

    The weighted fit is the estimator; its score is in the force units every other
    score is in (each fold's parameters from its weighted training rows, scored on
    its held-out rows without the weights).
    """
    X, _ = columns(D, spec)
    Zw = np.column_stack([X, target(D, spec)])
    Pw = D.part_grams(Zw)
    P = Pw if D.sw is None else D.part_grams(Zw / D.sw[:, None])
    total = 0.0
    for f in range(D.folds):
        th, _ = solve_gram(D.train(Pw, f))
        total += _sse_with(D.test(P, f), th)
    return float(total)


def cv_choices(D: Data, designs: Sequence[tuple[np.ndarray, np.ndarray]]) -> float:
    """Held-out SSE when each fold picks, from its training blocks, the best design.

    ``designs`` are ``(X, y)`` for each trial of a nonlinear parameter (a grid); the
    choice is made per fold on its training SSE, so the held-out score is honest.
    """
    Ps = [D.part_grams(np.column_stack([X, y])) for X, y in designs]
    total = 0.0
    for f in range(D.folds):
        best = None
        for P in Ps:
            th, sse = solve_gram(D.train(P, f))
            if best is None or sse < best[0]:
                best = (sse, th, P)
        total += _sse_with(D.test(best[2], f), best[1])
    return total


# ------------------------------------------------------------------------------------
# nonlinear searches (variable projection)
# ------------------------------------------------------------------------------------
def _vp_sse(D: Data, spec: Spec, rows: np.ndarray | None = None) -> float:
    cols, _, keys = keyed_columns(D, spec)
    G = D.gram(cols + [target(D, spec)], keys + [target_key(D, spec)], rows)
    return solve_gram(G)[1]


def spatial_profile_spectrum(x: np.ndarray, r: np.ndarray) \
        -> tuple[np.ndarray, np.ndarray, float, float]:
    """Amplitude spectrum of ``r`` against position (binned means, Hann, padded FFT)."""
    from motor_comp.workbench.candidates import spatial_spectrum
    s = spatial_spectrum(x, r)
    return s.frequency, s.amplitude, s.bin_width, s.span


def ripple_basin(D: Data, spec: Spec, rows: np.ndarray) -> tuple[float, int]:
    """Ripple period and harmonic count from the spectrum of the residual on ``rows``."""
    X, _ = columns(D, spec)
    y = target(D, spec)
    Z = np.column_stack([X[rows], y[rows]])
    th, _ = solve_gram(Z.T @ Z)
    r = y - X @ th
    x = D.gather(lambda p: p.x)
    freq, amp, width, span = spatial_profile_spectrum(x[rows], r[rows])
    v = np.abs(D.gather(lambda p: p.v))[rows]
    dt = D.kins[0].dt
    min_p = max(8 * width, 4.0 * dt * float(np.percentile(v, 90)))
    max_p = span / 3.0
    ok = (freq >= 1.0 / max_p) & (freq <= 1.0 / min_p) if max_p > min_p else freq < 0
    if not np.any(ok):
        return max(max_p, 1e-6), 1
    i = np.flatnonzero(ok)[np.argmax(amp[ok])]
    p0 = 1.0 / float(freq[i])
    df = 1.0 / span

    def amp_at(fq: float) -> float:
        m = np.abs(freq - fq) <= df
        return float(np.max(amp[m])) if np.any(m) else 0.0
    a1 = amp_at(1.0 / p0)
    floor = float(np.median(amp))
    nh = 1
    for h in range(2, MAX_HARMONICS + 1):
        if h / p0 > 1.0 / min_p:
            break
        ah = amp_at(h / p0)
        if ah > 0.15 * a1 and ah > 4 * floor:
            nh = h
    return p0, nh


def fit_ripple(D: Data, spec: Spec, rows: np.ndarray) -> tuple[float, int]:
    """Ripple period and harmonic count of ``spec`` + ripple, from ``rows`` only.

    The basin from the spatial spectrum of the current residual, the period by
    variable projection, then the harmonic count by BIC (``n_eff·ln SSE + 2H·ln n_eff``
    over the rows' independent samples) with every linear parameter re-solved, and
    the period refined once more for that count.
    """
    return fit_ripple_folds(D, spec, [rows])[0]


def fit_ripple_folds(D: Data, spec: Spec,
                     rows_list: Sequence[np.ndarray]) -> list[tuple[float, int]]:
    """:func:`fit_ripple` on each row set of ``rows_list`` (e.g. the training folds).

    Every choice is made on each row set's own samples; only the trial periods are
    shared: one evaluation of the smoothed harmonics (most of the cost) gives the
    SSE of every row set at that period (see :func:`refine_periods`).
    """
    base = spec.without('ripple')
    basins = [ripple_basin(D, base, rows) for rows in rows_list]
    periods = refine_periods(D, base, basins, rows_list)
    nhs = [_bic_harmonics(D, base, period, rows) for period, rows in zip(periods, rows_list)]
    redo = [i for i, (nh, (_, nh0)) in enumerate(zip(nhs, basins)) if nh != nh0]
    if redo:
        again = refine_periods(D, base, [(periods[i], nhs[i]) for i in redo],
                               [rows_list[i] for i in redo])
        for i, period in zip(redo, again):
            periods[i] = period
    return list(zip(periods, nhs))


def _bic_harmonics(D: Data, base: Spec, period: float, rows: np.ndarray) -> int:
    """Harmonic count by BIC at ``period`` on ``rows`` (every linear parameter re-solved).

    At most 4 samples per spatial period at the median speed of the rows.
    """
    v = np.abs(D.gather(lambda p: p.v))[rows]
    min_p = max(4.0 * D.kins[0].dt * float(np.percentile(v, 50)), 1e-12)
    Xf, _ = columns(D, base)
    y = target(D, base)
    Xf, y = Xf[rows], y[rows]
    n_eff = max(D.n_eff * np.count_nonzero(rows) / D.n, 2.0)
    top = max(1, min(MAX_HARMONICS, int(math.floor(period / min_p))))
    # one evaluation for all counts: harmonic h's columns do not depend on the others
    S, C = D.smooth_harmonics(2 * math.pi * np.arange(1, top + 1) / period)
    S, C = S[rows], C[rows]
    best = None
    for h in range(1, top + 1):
        Z = np.column_stack([Xf, S[:, :h], C[:, :h], y])
        sse = solve_gram(Z.T @ Z)[1]
        bic = n_eff * math.log(max(sse, 1e-300)) + 2 * h * math.log(n_eff)
        if best is None or bic < best[0]:
            best = (bic, h)
    return best[1]


def refine_period(D: Data, spec: Spec, p0: float, nh: int, rows: np.ndarray) -> float:
    """Local variable-projection search of the ripple period around ``p0``.

    The trial columns are smoothed like every other column: at the speeds of a fast
    sweep the ripple's time frequency reaches the smoother's stop band, so an
    unsmoothed search would weigh those samples differently from the final fit.
    """
    return refine_periods(D, spec, [(p0, nh)], [rows])[0]


def refine_periods(D: Data, spec: Spec, starts: Sequence[tuple[float, int]],
                   rows_list: Sequence[np.ndarray]) -> list[float]:
    """:func:`refine_period` for several row sets, ``starts`` = (p0, nh) of each.

    Row sets with the same harmonic count and nearby basins share their trial
    periods: a bounded Brent search on the sum of their SSEs finds the common well,
    then each set's own minimum is polished by parabolic steps through the shared
    evaluations until each is within the search tolerance of an evaluated period,
    and each set gets its own best evaluated period.  A lone row set is a plain
    bounded Brent search on its own SSE.
    """
    base = spec.without('ripple')
    Xf, _ = columns(D, base)
    y = target(D, base)
    x = D.gather(lambda p: p.x)
    out = [0.0] * len(rows_list)
    groups: list[list[int]] = []
    for i in sorted(range(len(starts)), key=lambda i: (starts[i][1], starts[i][0])):
        p0, nh = starts[i]
        span = float(np.ptp(x[rows_list[i]])) or 1.0
        g = groups[-1] if groups else None
        if (g is not None and starts[g[0]][1] == nh
                and abs(p0 - starts[g[0]][0]) <= 0.25 * 1.5 * p0 * p0 / span):
            g.append(i)
        else:
            groups.append([i])
    for g in groups:
        periods = _refine_group(D, Xf, y, x, [starts[i][0] for i in g], starts[g[0]][1],
                                [rows_list[i] for i in g])
        for i, period in zip(g, periods):
            out[i] = period
    return out


def _refine_group(D: Data, Xf: np.ndarray, y: np.ndarray, x: np.ndarray,
                  p0s: Sequence[float], nh: int,
                  rows_list: Sequence[np.ndarray]) -> list[float]:
    p0 = float(np.median(p0s))
    span = min(float(np.ptp(x[rows])) or 1.0 for rows in rows_list)
    dp = 1.5 * p0 * p0 / span
    lo = max(min(p0s) - dp, 0.5 * p0)
    hi = max(p0s) + dp
    xtol = 1e-6 * p0
    seen: dict[float, np.ndarray] = {}

    def sse(period: float) -> np.ndarray:
        hit = seen.get(period)
        if hit is None:
            w = 2 * math.pi * np.arange(1, nh + 1) / period
            S, C = D.smooth_harmonics(w)
            Z = np.column_stack([Xf, S, C, y])
            hit = seen[period] = np.array([solve_gram(Z[r].T @ Z[r])[1]
                                           for r in rows_list])
        return hit
    opt = minimize_scalar(lambda t: float(sse(float(t)).sum()), bounds=(lo, hi),
                          method='bounded', options={'xatol': xtol})
    if len(rows_list) == 1:
        return [float(opt.x)]
    for _ in range(6):
        pts = np.array(sorted(seen))
        vals = np.array([seen[t] for t in pts])
        want = []
        for k in range(len(rows_list)):
            j = int(np.argmin(vals[:, k]))
            if 0 < j < len(pts) - 1:
                a, b, c = pts[j - 1:j + 2]
                fa, fb, fc = vals[j - 1:j + 2, k]
                den = (b - a) * (fb - fc) - (b - c) * (fb - fa)
                t = b if den == 0 else b - 0.5 * ((b - a) ** 2 * (fb - fc)
                                                  - (b - c) ** 2 * (fb - fa)) / den
                t = float(np.clip(t, a, c))
            else:   # the minimum at an end of what was tried: step outwards
                t = float(pts[j] + (-1 if j == 0 else 1) * max(xtol, 0.1 * dp))
                t = float(np.clip(t, lo, hi))
            if np.min(np.abs(pts - t)) > xtol:
                want.append(t)
        if not want:
            break
        for t in sorted(want):
            if min(abs(t - u) for u in seen) > xtol:
                sse(t)
    pts = np.array(sorted(seen))
    vals = np.array([seen[t] for t in pts])
    return [float(pts[int(np.argmin(vals[:, k]))]) for k in range(len(rows_list))]


def stribeck_grid(D: Data, rows: np.ndarray | None = None) -> list[tuple[float, float]]:
    """Trial ``(vs, δ)``: vs inside the observed speeds, below 10 % of the high ones.

    A larger vs would stretch the hump over the whole speed range, where it copies a
    (negative) viscous term instead of describing low-speed friction.
    """
    v = np.abs(D.gather(lambda p: p.v))
    v = v if rows is None else v[rows]
    lo = max(float(np.percentile(v, 1)), 1e-7)
    hi = max(0.1 * float(np.percentile(v, 95)), 2 * lo)
    return [(float(vs), d) for d in (0.5, 1.0, 2.0)
            for vs in np.exp(np.linspace(np.log(lo), np.log(hi), 8))]


def delay_grid(D: Data, max_tau: float = 0.03) -> np.ndarray:
    """Trial delays [s]: 0 … min(30 ms, 10 % of the record) in half samples."""
    dt = D.kins[0].dt
    hi = min(max_tau, 0.1 * min(k.duration for k in D.kins))
    return np.arange(0.0, hi + 1e-12, max(0.5 * dt, hi / 60.0))


def backlash_grid(D: Data) -> np.ndarray:
    """Trial gap widths: from ten times the position noise to 5 % of the travel (log-spaced)."""
    kin = D.kins[0]
    # ten noise σ, not a few counts: a gap search that starts at 5 counts (10 µm on
    # a 2 µm encoder) sat on a coarser grid and missed a 39 µm gap of the independent
    # suite (backlash seed 4); a gap too small to tell from stiction does not pay
    lo = max(1e-7, 10.0 * kin.noise_std())
    hi = min(MAX_BACKLASH, 0.05 * float(np.ptp(kin.x)))
    hi = min(max(hi, 4 * lo), MAX_BACKLASH)
    lo = min(lo, 0.25 * hi)
    return np.logspace(np.log10(lo), np.log10(hi), 8)


def gms_grid(D: Data) -> list[tuple[float, float]]:
    """Return trial ``(d0, c)``: GMS distance scale and slip rate.

    The scale from 3 encoder counts (a pre-sliding displacement below the encoder's
    resolution is not observable: a GMS that stiff only mimics a stick or a gap) to
    1 % of the travel, c 300 … 3000 1/s.
    """
    lo = gms_min_scale(D)
    hi = max(0.01 * float(np.ptp(D.kins[0].x)), 100 * lo)
    return [(float(d), float(c)) for d in np.logspace(np.log10(lo), np.log10(hi), 6)
            for c in (300.0, 3000.0)]


def gms_min_scale(D: Data) -> float:
    """Return the smallest GMS distance scale searched [m]: 3 encoder counts (or noise)."""
    kin = D.kins[0]
    return max(3.0 * kin.quantum(), 3.0 * kin.noise_std(), 1e-9)


def gms_eta(d0: float, c: float, ratio: float) -> tuple:
    """Return the presliding spec entry: element distances, slip rate, Stribeck ratio."""
    return (tuple(d0 * f for f in GMS_DISTANCES), float(c), float(ratio))


def _eta_trials(D: Data, spec: Spec, name: str, model: AxisModel) -> list:
    """Grid of the nonlinear parameters of ``name`` (for the in-fold choice)."""
    if name == 'stribeck':
        return stribeck_grid(D)
    if name == 'delay':
        return list(delay_grid(D))
    if name == 'backlash':
        return list(backlash_grid(D))
    if name == 'presliding':
        ratio = _stribeck_ratio(D, spec.without(name))
        return [gms_eta(d, c, ratio) for d, c in gms_grid(D)]
    raise KeyError(name)


def _stribeck_ratio(D: Data, spec: Spec) -> float:
    if 'stribeck' not in spec.names:
        return 0.0
    X, lab = columns(D, spec)
    y = target(D, spec)
    th, _ = solve_gram(np.column_stack([X, y]).T @ np.column_stack([X, y]))
    d = dict(zip(lab, th))
    fc = max(float(d.get(('coulomb', 'fc'), 1.0)), 1e-6)
    return max(float(d.get(('stribeck', 'dfs'), 0.0)), 0.0) / fc


def sync(D: Data, spec: Spec, model: AxisModel) -> None:
    """Put the data in the state ``spec`` assumes (delay for the NRMSE, backlash gap)."""
    w = float(spec.eta.get('backlash', 0.0)) if 'backlash' in spec.names else 0.0
    if w != D.width0:
        D.set_backlash(w, model)
    D.tau0 = float(spec.eta.get('delay', 0.0)) if 'delay' in spec.names else 0.0


def _design_for(D: Data, spec: Spec, model: AxisModel) -> tuple[np.ndarray, np.ndarray]:
    if 'backlash' in spec.names and abs(D.width0 - spec.eta['backlash']) > 0:
        D.set_backlash(spec.eta['backlash'], model)
    X, _ = columns(D, spec)
    return X, target(D, spec)


def best_eta(D: Data, spec: Spec, name: str, model: AxisModel,
             rows: np.ndarray | None = None, *, stop_above: float = math.inf,
             refine: bool = True) -> Any:
    """Nonlinear parameters of ``name`` in ``spec`` fitted on ``rows`` (all by default).

    A grid, then a local search from its best point.  When even the grid's best SSE is
    above ``stop_above`` (a screened candidate that cannot pay), the grid point is
    returned without the local search: it is most of the cost, and on a fitting run
    most candidates are absent effects scored round after round.  ``refine=False``
    leaves out the GMS element growth and distance polish (:func:`refine_gms`), which
    a screened candidate gets only once it passes the screen.
    """
    rows = np.ones(D.n, dtype=bool) if rows is None else rows
    sync(D, spec.without(name), model)
    if name == 'ripple':
        return fit_ripple(D, spec, rows)
    trials = _eta_trials(D, spec, name, model)
    costs = []
    for eta in trials:
        s = spec.with_(name, eta)
        if name == 'backlash':
            D.set_backlash(eta, model)
        costs.append(_vp_sse(D, s, rows))
    i = int(np.argmin(costs))
    eta = trials[i]
    if costs[i] > stop_above:
        return eta
    if name == 'stribeck':
        vs_hi = max(t[0] for t in trials)

        def cost(q: np.ndarray) -> float:
            vs = float(np.exp(np.clip(q[0], -16, np.log(vs_hi))))
            dl = float(np.clip(q[1], 0.3, 5.0))
            return _vp_sse(D, spec.with_(name, (vs, dl)), rows)
        opt = minimize(cost, np.array([np.log(eta[0]), eta[1]]), method='Nelder-Mead',
                       options={'xatol': 1e-3, 'fatol': 1e-9 * costs[i], 'maxiter': 50})
        eta = (float(np.exp(np.clip(opt.x[0], -16, np.log(vs_hi)))),
               float(np.clip(opt.x[1], 0.3, 5.0)))
    elif name == 'delay':
        lo, hi = trials[max(i - 1, 0)], trials[min(i + 1, len(trials) - 1)]
        if hi > lo:
            opt = minimize_scalar(lambda t: _vp_sse(D, spec.with_(name, float(t)), rows),
                                  bounds=(lo, hi), method='bounded',
                                  options={'xatol': 1e-3 * D.kins[0].dt})
            eta = float(opt.x)
    elif name == 'backlash':
        lo, hi = trials[max(i - 1, 0)], trials[min(i + 1, len(trials) - 1)]

        def bcost(lw: float) -> float:
            D.set_backlash(float(np.exp(lw)), model)
            return _vp_sse(D, spec.with_(name, float(np.exp(lw))), rows)
        opt = minimize_scalar(bcost, bounds=(np.log(lo), np.log(hi)), method='bounded',
                              options={'xatol': 0.01})
        eta = float(np.exp(opt.x))
        D.set_backlash(eta, model)
    elif name == 'presliding':
        dists, c0, ratio = eta
        d0 = dists[1] / GMS_DISTANCES[1]

        lo_d = np.log(gms_min_scale(D))

        def gcost(q: np.ndarray) -> float:
            d = float(np.exp(np.clip(q[0], lo_d, np.log(1.0))))
            c = float(np.exp(np.clip(q[1], 0.0, np.log(1e6))))
            return _vp_sse(D, spec.with_(name, gms_eta(d, c, ratio)), rows)
        opt = minimize(gcost, np.log([d0, c0]), method='Nelder-Mead',
                       options={'xatol': 2e-2, 'fatol': 1e-6 * costs[i], 'maxiter': 30})
        eta = gms_eta(float(np.exp(np.clip(opt.x[0], lo_d, 0.0))),
                      float(np.exp(np.clip(opt.x[1], 0.0, np.log(1e6)))), ratio)
        eta = _free_gms(D, spec, _prune_gms(D, spec, eta, rows), rows, costs[i])
        if refine:
            eta = refine_gms(D, spec, eta, rows, costs[i])
    return eta


def refine_gms(D: Data, spec: Spec, eta: tuple, rows: np.ndarray, scale: float) -> tuple:
    """Grow a stiffer GMS element where it pays, then polish every distance."""
    return _polish_gms(D, spec, _grow_gms(D, spec, eta, rows, scale), rows)


def _polish_gms(D: Data, spec: Spec, eta: tuple, rows: np.ndarray) -> tuple:
    """Refine each GMS element's distance, one at a time: a scan, then Brent to 0.01 %.

    The searches before stop at about 1 % (Nelder–Mead on the logarithms), and in a
    local minimum where one element's distance is off by a factor: the residual of a
    pre-sliding curve is steep and rugged in its distances.  On the independent
    generator a single element's distance 2.4 % long left twice the true model's
    force NRMSE (presliding seed 1), and a three-element curve whose stiffest element
    sat at 8.6 µm for 30 µm left 16× the true distances' SSE (seed 7).  Each distance
    is scanned over 0.22–4.5× (13 points, the others fixed, the levels re-solved
    inside: variable projection), then refined around the best point; two passes.
    """
    dists, c, ratio = eta
    d = list(dists)
    lo_d = float(np.log(gms_min_scale(D)))

    def sse_of(ds: list) -> float:
        return _vp_sse(D, spec.with_('presliding', (tuple(sorted(ds)), c, ratio)), rows)
    best = sse_of(d)
    steps = np.linspace(-1.5, 1.5, 13)
    h = float(steps[1] - steps[0])
    for _ in range(2):
        improved = False
        for j in range(len(d)):
            def cost(q: float, j: int = j) -> float:
                trial = list(d)
                trial[j] = float(np.exp(q))
                return sse_of(trial)
            q0 = float(np.log(d[j]))
            grid = [q for q in q0 + steps if lo_d <= q <= 0.0]
            vals = [cost(q) for q in grid]
            qb = grid[int(np.argmin(vals))] if grid else q0
            opt = minimize_scalar(cost, bounds=(max(qb - h, lo_d), min(qb + h, 0.0)),
                                  method='bounded', options={'xatol': 1e-4})
            cand = [(float(opt.fun), float(opt.x))]
            if grid:
                cand.append((float(min(vals)), qb))
            f, q = min(cand)
            if f < best * (1.0 - 1e-9):
                best, d[j], improved = f, float(np.exp(q)), True
        d = sorted(d)
        if not improved:
            break
    return (tuple(d), c, ratio)


def _grow_gms(D: Data, spec: Spec, eta: tuple, rows: np.ndarray, scale: float) -> tuple:
    """Try a stiffer GMS element than any found; keep it when it pays (BIC).

    The free search moves the distances it has but never adds one: from the family's
    fit it can settle with two elements where the curve has three, the two stiffest
    merged into one of medium distance (independent generator, coverage seeds 2 and
    13: Σk 33 % low, the three-element curve's SSE 5× lower).  A new element at a third
    of the shortest distance, the distances then searched freely again and pruned, is
    accepted when the BIC (two parameters: its distance and level) improves; repeated
    while it does, up to :data:`GMS_MAX_ELEMENTS`.
    """
    n_eff = max(D.n_eff * np.count_nonzero(rows) / D.n, 2.0)
    sse = _vp_sse(D, spec.with_('presliding', eta), rows)
    lo = gms_min_scale(D)
    while len(eta[0]) < GMS_MAX_ELEMENTS and min(eta[0]) / 3.0 >= lo:
        dists, c, ratio = eta
        trial = _free_gms(D, spec, ((min(dists) / 3.0,) + tuple(dists), c, ratio), rows,
                          scale)
        s1 = _vp_sse(D, spec.with_('presliding', trial), rows)
        k = len(trial[0]) - len(dists)
        # an element the search pushes to the resolution floor is no pre-sliding the
        # run resolves: a stick (two such at 3 counts made Σk 2.3× the truth)
        if k <= 0 or min(trial[0]) <= 1.05 * lo or n_eff * math.log(
                max(s1, 1e-300) / max(sse, 1e-300)) + 2 * k * math.log(n_eff) >= 0:
            break
        eta, sse = trial, s1
    return eta


def _free_gms(D: Data, spec: Spec, eta: tuple, rows: np.ndarray, scale: float) -> tuple:
    """Free each GMS element's pre-sliding distance, starting from the family's fit.

    The family (distances ``d0·GMS_DISTANCES``, levels by least squares, elements with
    a negative level pruned) finds the scale and the element count; the distances are
    then searched freely, one dimension each (Nelder–Mead on their logarithms, the
    levels re-solved inside: variable projection), so a virgin curve whose break-away
    points are not in the family's fixed ratios is still described (an independent
    generator's two close elements, or three at ratios 1 : 3.9 : 8.3).  The slip rate is
    searched with them when a Stribeck curve makes it matter (with a constant friction
    level a slipping element sits at its limit and ``c`` has no effect).  Elements
    that end with a negative level are pruned again.
    """
    dists, c, ratio = eta
    m = len(dists)
    lo_d = np.log(gms_min_scale(D))
    free_c = ratio > 0.0

    def unpack(q: np.ndarray) -> tuple:
        d = tuple(sorted(float(np.exp(np.clip(v, lo_d, 0.0))) for v in q[:m]))
        cc = float(np.exp(np.clip(q[m], 0.0, np.log(1e6)))) if free_c else c
        return (d, cc, ratio)

    def cost(q: np.ndarray) -> float:
        return _vp_sse(D, spec.with_('presliding', unpack(q)), rows)
    q0 = np.log(np.asarray(dists, dtype=float))
    if free_c:
        q0 = np.append(q0, np.log(c))
    f0 = cost(q0)
    opt = minimize(cost, q0, method='Nelder-Mead',
                   options={'xatol': 1e-2, 'fatol': 1e-6 * scale, 'maxiter': 60 * len(q0)})
    if not opt.fun < f0:
        return eta
    return _bic_gms(D, spec, _prune_gms(D, spec, unpack(opt.x), rows), rows)


def _bic_gms(D: Data, spec: Spec, eta: tuple, rows: np.ndarray) -> tuple:
    """Drop GMS elements that do not pay for their distance and level (BIC, repeated).

    A free distance can run to a tiny element at the encoder's resolution whose level
    is a sliver of the friction: it changes the fit by less than its two parameters are
    worth, but its stiffness ``β/d`` would dominate the reported ``Σk``.
    """
    dists, c, ratio = eta
    n_eff = max(D.n_eff * np.count_nonzero(rows) / D.n, 2.0)
    sse = _vp_sse(D, spec.with_('presliding', eta), rows)
    while len(dists) > 1:
        best = None
        for j in range(len(dists)):
            d = tuple(x for i, x in enumerate(dists) if i != j)
            s1 = _vp_sse(D, spec.with_('presliding', (d, c, ratio)), rows)
            dbic = n_eff * math.log(max(s1, 1e-300) / max(sse, 1e-300)) - 2 * math.log(n_eff)
            if best is None or dbic < best[0]:
                best = (dbic, d, s1)
        if best[0] >= 0:
            break
        _, dists, sse = best
    return (tuple(dists), c, ratio)


def _prune_gms(D: Data, spec: Spec, eta: tuple, rows: np.ndarray) -> tuple:
    """Drop GMS elements whose fitted level is not positive (active set, repeated).

    An element with a negative slip limit is no physical friction: left in, pairs of
    elements of opposite sign can mimic other reversal transients (a backlash gap).
    """
    dists, c, ratio = eta
    while len(dists) > 1:
        s1 = spec.with_('presliding', (dists, c, ratio))
        X, labels = columns(D, s1)
        y = target(D, s1)
        Z = np.column_stack([X[rows], y[rows]])
        th, _ = solve_gram(Z.T @ Z)
        beta = [t for (g, n), t in zip(labels, th) if g == 'presliding']
        worst = int(np.argmin(beta))
        if beta[worst] > 0:
            break
        dists = tuple(d for j, d in enumerate(dists) if j != worst)
    return (tuple(dists), c, ratio)


def cv_candidate(D: Data, spec: Spec, name: str, model: AxisModel, *,
                 screen: float = 0.0) -> tuple[float, Any]:
    """Held-out SSE of ``spec`` + ``name`` with its nonlinear parameters chosen in-fold.

    Returns the SSE and the all-data choice of the nonlinear parameters (None for a
    linear effect).  With ``screen`` > 0, a nonlinear candidate whose all-data
    (in-sample) gain is below ``screen`` is scored with its nonlinear parameters held
    at the all-data choice instead (it cannot pay on held-out data anyway, and the
    in-fold searches are the expensive part).
    """
    sync(D, spec, model)
    if name in LINEAR:
        s = spec.with_(name)
        X, _ = columns(D, s)
        return cv_design(D, X, target(D, s)).sse_cv, None
    sse0 = _vp_sse(D, spec) if screen > 0 else math.inf
    if name == 'ripple':
        eta_all = best_eta(D, spec.with_('ripple', (1.0, 1)), 'ripple', model)
    else:
        trials = _eta_trials(D, spec, name, model)
        # a grid optimum below half the screen's gain skips the local search
        eta_all = best_eta(D, spec.with_(name, trials[0]), name, model,
                           stop_above=sse0 * (1.0 - 0.5 * screen), refine=screen <= 0)
    if screen > 0:
        s1 = spec.with_(name, eta_all)
        X1, _ = _design_for(D, s1, model)
        sse1 = _vp_sse(D, s1)
        sync(D, spec, model)
        if sse0 <= 0 or 1.0 - sse1 / sse0 < screen:
            X, y = _design_for(D, s1, model)
            out = cv_design(D, X, y).sse_cv
            sync(D, spec, model)
            return out, eta_all
        if name == 'presliding':
            # past the screen: the element structure and distances in full
            sync(D, spec, model)
            eta_all = refine_gms(D, spec, eta_all, np.ones(D.n, dtype=bool), sse1)
    if name == 'ripple':
        total = 0.0
        chosen = fit_ripple_folds(D, spec, [D.train_rows(f) for f in range(D.folds)])
        for f, (period, nh) in enumerate(chosen):
            s = spec.with_('ripple', (period, nh))
            X, _ = columns(D, s)
            y = target(D, s)
            P = D.part_grams(np.column_stack([X, y]))
            th, _ = solve_gram(D.train(P, f))
            total += _sse_with(D.test(P, f), th)
        return total, eta_all
    # refine the grid near the all-data optimum so the in-fold choice is not grid-bound
    if name == 'delay':
        dt = D.kins[0].dt
        near = np.clip(eta_all + dt * np.linspace(-2, 2, 17), 0.0, None)
        trials = sorted(set(trials) | set(near))
    elif name == 'stribeck':
        vs, dl = eta_all
        trials = trials + [(vs * f, d) for f in (0.7, 1.0, 1.4) for d in (dl * 0.8, dl,
                                                                          dl * 1.25)]
    elif name == 'backlash':
        trials = list(trials) + [eta_all * f for f in (0.8, 0.9, 1.0, 1.1, 1.25)]
    elif name == 'presliding':
        dists, c, ratio = eta_all
        trials = [(tuple(d * f for d in dists), c * g, ratio) for f, g in
                  ((1.0, 1.0), (0.6, 1.0), (1.6, 1.0), (1.0, 0.5), (1.0, 2.0))]
    designs = []
    for eta in trials:
        s = spec.with_(name, eta)
        designs.append(_design_for(D, s, model))
    sse = cv_choices(D, designs)
    sync(D, spec, model)
    return sse, eta_all


# ------------------------------------------------------------------------------------
# the fit of a spec: parameters, covariance, decoded effects
# ------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class Estimate:
    """A spec fitted on all rows, with its held-out score and uncertainties.

    Parameters
    ----------
    spec : Spec
        Effects and nonlinear parameters.
    model : AxisModel
        The fitted model (model-file form).
    scalars : dict[str, dict[str, float]]
        Flat physical parameters per effect (and ``mass``).
    se : dict[str, dict[str, float]]
        Their standard errors (stretch jackknife + delta method).
    at_bound : dict[str, list[str]]
        Parameters held at a physical bound (``fc ≥ 0`` …).
    correlations : list of (str, str, float)
        Strongly correlated parameter pairs ``(group.name, group.name, ρ)``.
    sse_cv, sse_fit : float
        Held-out and in-sample sums of squared residuals [N²].
    n_params : int
        Fitted parameters (linear and nonlinear).
    nrmse_cv : float
        Held-out force NRMSE.
    """

    spec: Spec
    model: AxisModel
    scalars: dict
    se: dict
    at_bound: dict
    correlations: list
    sse_cv: float
    sse_fit: float
    n_params: int
    nrmse_cv: float


def n_params(spec: Spec) -> int:
    """Fitted parameters of ``spec`` (linear columns + free nonlinear ones)."""
    k = int(spec.mass_free)
    per = {'coulomb': 1, 'viscous': 1, 'stribeck': 3, 'presliding': 2, 'offset': 1,
           'spring': 2, 'asymmetry': 2, 'delay': 1, 'backlash': 1, 'gravity': 2}
    for n in spec.names:
        if n == 'ripple':
            k += 1 + 2 * int(spec.eta['ripple'][1])
        elif n == 'presliding':
            m = len(spec.eta['presliding'][0])
            k += m + 1 + m - 1   # element distances, c, element levels − fc
        else:
            k += per[n]
    return k


def _nl_params(spec: Spec) -> list[tuple[str, str, float, Callable[[Spec, float], Spec]]]:
    """Free nonlinear parameters as (group, name, value, setter) for the Jacobian."""
    out = []
    if 'ripple' in spec.names:
        p, nh = spec.eta['ripple']
        out.append(('ripple', 'period', p, lambda s, v: s.with_('ripple', (v, nh))))
    if 'stribeck' in spec.names and 'presliding' not in spec.names:
        vs, dl = spec.eta['stribeck']
        out.append(('stribeck', 'vs', vs, lambda s, v: s.with_('stribeck', (v, dl))))
        out.append(('stribeck', 'delta', dl, lambda s, v: s.with_('stribeck', (vs, v))))
    if 'delay' in spec.names:
        out.append(('delay', 'tau', spec.eta['delay'],
                    lambda s, v: s.with_('delay', v)))
    if 'backlash' in spec.names:
        # the gap moves the reconstructed motor position every column is built from
        # (``estimate`` syncs the data to each trial spec)
        out.append(('backlash', 'width', spec.eta['backlash'],
                    lambda s, v: s.with_('backlash', v)))
    if 'presliding' in spec.names:
        dists, c, r = spec.eta['presliding']
        # each element's distance is searched freely (``_free_gms``), so each is a
        # parameter of the fit: a common scale alone would leave out how poorly the
        # stiffest (shortest) element is pinned down, and Σk is dominated by it
        for j in range(len(dists)):
            out.append(('presliding', f'd{j}', 1.0,
                        lambda s, v, j=j: s.with_('presliding', (tuple(
                            d * v if i == j else d for i, d in enumerate(dists)), c, r))))
        out.append(('presliding', 'c', c,
                    lambda s, v: s.with_('presliding', (dists, v, r))))
    return out


def _jacobian(D: Data, spec: Spec, model: AxisModel) \
        -> tuple[np.ndarray, np.ndarray, list, np.ndarray, np.ndarray, np.ndarray, float]:
    """θ, its labels, the Jacobian of all parameters, residual, X, y and SSE of a fit."""
    sync(D, spec, model)
    X, labels = columns(D, spec)
    y = target(D, spec)
    Z = np.column_stack([X, y])
    th, sse = solve_gram(Z.T @ Z)
    e = y - X @ th
    # Gauss–Newton columns of the nonlinear parameters (derivative of the fit)
    J = [X]
    jl = list(labels)
    for g, name, val, setter in _nl_params(spec):
        h = 1e-3 * abs(val) if val else 1e-6
        s1 = setter(spec, val + h)
        sync(D, s1, model)
        X1, _ = columns(D, s1)
        y1 = target(D, s1)
        # d(residual)/dη = d(y − Xθ)/dη; the Jacobian column is its negative
        J.append(((e - (y1 - X1 @ th)) / h)[:, None])
        jl.append((g, name))
    sync(D, spec, model)
    return th, jl, np.column_stack(J), e, X, y, sse


def estimate(D: Data, spec: Spec, model: AxisModel, *, cv: bool = True) -> Estimate:
    """Fit ``spec`` on all rows: θ, sandwich covariance, decoded model (see module doc)."""
    th, jl, Jm, e, X, y, sse = _jacobian(D, spec, model)
    sc = cv_design(D, X, y) if cv else None
    cov = _sandwich(D, Jm, e)
    phi = np.concatenate([th, [v for _, _, v, _ in _nl_params(spec)]])
    vals = {lab: float(v) for lab, v in zip(jl, phi)}
    idx = {lab: i for i, lab in enumerate(jl)}
    fitted, scalars, se, at_bound = decode(spec, model, vals, idx, cov)
    # correlations from the block sandwich: the jackknife's covariance has rank
    # ≤ stretches − 1, so with more parameters than that it would show spurious ±1 pairs
    corr = _correlations(_block_sandwich(D, Jm, e), jl)
    sse_cv = sc.sse_cv if sc is not None else float('nan')
    den = D.f_in_scale()
    nr = math.sqrt(sse_cv / den) if den > 0 and np.isfinite(sse_cv) else float('nan')
    return Estimate(spec=spec, model=fitted, scalars=scalars, se=se, at_bound=at_bound,
                    correlations=corr, sse_cv=sse_cv, sse_fit=sse, n_params=n_params(spec),
                    nrmse_cv=nr)


def _gauss_newton_point(D: Data, spec: Spec, model: AxisModel) -> tuple[dict, dict]:
    """Every parameter one Gauss–Newton step from (linear optimum, ``spec``'s η) on ``D``.

    The linear parameters are at their least-squares optimum already; the step moves
    the nonlinear ones (and, through their coupling, the linear ones) to where the
    data of ``D`` want them, without a new search.
    """
    th, jl, Jm, e, _, _, _ = _jacobian(D, spec, model)
    d = np.sqrt(np.maximum(np.sum(Jm * Jm, axis=0), 1e-300))
    step = np.linalg.lstsq(Jm / d, e, rcond=1e-10)[0] / d
    phi = np.concatenate([th, [v for _, _, v, _ in _nl_params(spec)]]) + step
    return ({lab: float(v) for lab, v in zip(jl, phi)},
            {lab: i for i, lab in enumerate(jl)})


def processing_spread(D: Data, spec: Spec, model: AxisModel) -> dict[str, dict[str, float]]:
    """How far each decoded parameter moves when the smoother is twice as long [SI].

    The columns are smoothed and the acceleration is a difference of the smoothed
    position: a choice of processing, not a property of the axis.  On nearly
    noise-free runs the jackknife standard errors fall below the bias this choice
    leaves (0.05–0.3 % on the independent generator's runs, moving with the smoother
    length: ``test_workbench_coverage``), so the fit reports
    ``√(SE² + spread²)``, the spread being ``|φ(2S) − φ(S)|`` with every parameter
    (nonlinear ones too) one Gauss–Newton step from the fit on each processing.
    """
    D2 = Data(D.kins, D.model, folds=D.folds, smoother_scale=2.0 * D.smoother_scale)
    D2.set_speed_weights(D.speed_weights)
    return _spread(D, D2, spec, model)


def measurement_spread(D: Data, spec: Spec, model: AxisModel, *,
                       seed: int = 0) -> dict[str, dict[str, float]]:
    """How far each decoded parameter moves when the position is measured again [SI].

    Every column is built from the measured position, so its error (encoder
    quantisation, noise) sits in the regressors as well as the target: an
    errors-in-variables bias that the jackknife, which resamples the residuals, does
    not see.  It matters where a parameter lives at the encoder's resolution — a GMS
    element whose break-away distance is a few counts carries most of ``Σk`` — and
    left ``Σk`` 0.2–1 % off with standard errors of 0.05–0.2 % on single-element
    runs (``test_workbench_coverage``).  Following SIMEX (Cook & Stefanski 1994: the
    bias grows with the error variance, so adding the same variance again shows it),
    the same sliding samples are refitted from positions with a second error of the
    measured size, ``σ = max(noise, quantum/√12)``, and the shift of each parameter,
    one Gauss–Newton step from the fit on each, is reported as a spread (a fixed
    ``seed`` keeps a fit reproducible).
    """
    rng = np.random.default_rng(seed)
    kins = []
    for kin in D.kins:
        sigma = max(kin.noise_std(), kin.quantum() / math.sqrt(12.0))
        pos = kin.position + rng.normal(0.0, sigma, len(kin.position)) if sigma > 0 \
            else kin.position
        k2 = dataclasses.replace(kin, position=pos)
        x, v, a = k2.derivatives(pos)
        kins.append(dataclasses.replace(k2, x=x, v=v, a=a))
    D2 = Data(kins, D.model, folds=D.folds, smoother_scale=D.smoother_scale,
              masks=D.masks)
    D2.set_speed_weights(D.speed_weights)
    return _spread(D, D2, spec, model)


def gap_profile_se(D: Data, spec: Spec, model: AxisModel, *, level: float = 4.0) -> float:
    """Return the backlash width's standard error from its profile-likelihood interval [m].

    The force residual bounds the gap sharply from below (a flight that ends before
    the load moves leaves it stuck under a driving force) but only weakly from above:
    while the load rests its samples are not fitted, so a wider gap changes little
    but the transient after the load is taken along.  On the independent generator the
    SSE rose 7 % one per cent below the truth and 0.4 % three per cent above it, and
    the fit sat 1–4 % wide with a jackknife SE of 0.3–1 % (``test_workbench_coverage``:
    22–25 of 30 covered).  The interval is where the SSE, every linear parameter
    re-solved (variable projection), stays within ``1 + level/n_eff`` of the fit's
    (Venzon & Moolgavkar 1988; ``level`` 4 ≈ the χ²₁ 95 % point, the noise variance
    ``SSE/n_eff``), found by doubling steps and bisection on each side; its half-width
    is two standard errors.  Returns NaN without a gap.
    """
    if 'backlash' not in spec.names:
        return float('nan')
    w = float(spec.eta['backlash'])

    def sse(v: float) -> float:
        s1 = spec.with_('backlash', v)
        sync(D, s1, model)
        return _vp_sse(D, s1)
    thr = sse(w) * (1.0 + level / max(D.n_eff, 2.0))

    def edge(sign: float) -> float:
        inside, outside, step = w, None, 0.005
        while step <= 0.64:
            v = w * (1.0 + sign * step)
            if sse(v) > thr:
                outside = v
                break
            inside, step = v, 2.0 * step
        if outside is None:
            return abs(inside - w)
        for _ in range(4):
            mid = 0.5 * (inside + outside)
            if sse(mid) > thr:
                outside = mid
            else:
                inside = mid
        return abs(inside - w)
    try:
        half = edge(-1.0) + edge(1.0)
    finally:
        sync(D, spec, model)
    return 0.25 * half


def _spread(D: Data, D2: Data, spec: Spec, model: AxisModel) -> dict[str, dict[str, float]]:
    """``|φ(D2) − φ(D)|`` per decoded parameter, each one Gauss–Newton step from ``spec``."""
    out: dict[str, dict[str, float]] = {}
    try:
        v1, idx = _gauss_newton_point(D, spec, model)
        v2, _ = _gauss_newton_point(D2, spec, model)
    except (np.linalg.LinAlgError, ValueError):
        sync(D, spec, model)
        return out
    nan_cov = np.full((len(idx), len(idx)), np.nan)
    _, s1, _, _ = decode(spec, model, v1, idx, nan_cov)
    _, s2, _, _ = decode(spec, model, v2, idx, nan_cov)
    sync(D, spec, model)
    for g, d in s1.items():
        for k, a in d.items():
            b = s2.get(g, {}).get(k)
            if b is not None and np.isfinite(a) and np.isfinite(b):
                out.setdefault(g, {})[k] = abs(float(b) - float(a))
    return out


def _sandwich(D: Data, J: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Delete-a-stretch jackknife covariance of the (Gauss–Newton) fit [CR3].

    Each run is cut into ``SE_CLUSTERS`` contiguous stretches of validation blocks;
    the covariance is the jackknife spread of the one-step estimates with one stretch
    left out, ``(G−1)/G·Σ_g (δ_g − δ̄)(δ_g − δ̄)ᵀ``, ``δ_g = (JᵀJ − J_gᵀJ_g)⁻¹J_gᵀe_g``.
    Two reasons over the cluster-robust sandwich with many short blocks: a stretch of a
    time-ordered experiment is a regime (one speed of a sweep, one band of a chirp), so
    a parameter that the regimes disagree on — a model that does not quite fit — gets
    that disagreement as its uncertainty, not only the noise; and with few, unequally
    informative clusters (the slow stretches carry Coulomb, the fast ones viscous) the
    plain sandwich is biased low where the jackknife is not (MacKinnon, Nielsen & Webb
    2023, "CV3").  Measured on the independent generator (``test_workbench_coverage``):
    see that module's docstring.
    """
    p = J.shape[1]
    # stretches within each run: a run of a multi-run experiment is often one regime
    # (one torque level, one direction); leaving a whole run out would measure what
    # the others cannot identify without it, not how well the model fits
    cl = np.zeros(len(e), dtype=int)
    G = 0
    for i in np.unique(D.run_id):
        m = D.run_id == i
        b = D.block[m]
        b0, nb = int(b.min()), int(b.max() - b.min()) + 1
        g = min(SE_CLUSTERS, nb)
        cl[m] = G + ((b - b0) * g) // nb
        G += g
    if G < 2 or len(e) <= p:
        return np.full((p, p), np.nan)
    A = J.T @ J
    deltas = np.zeros((G, p))
    for c in range(G):
        m = cl == c
        Jc = J[m]
        Ac = A - Jc.T @ Jc
        d = np.sqrt(np.maximum(np.diag(Ac), 1e-300))
        try:
            Ai = np.linalg.pinv(Ac / np.outer(d, d), rcond=1e-12) / np.outer(d, d)
        except np.linalg.LinAlgError:
            return np.full((p, p), np.nan)
        deltas[c] = Ai @ (Jc.T @ e[m])
    deltas -= deltas.mean(axis=0)
    return (G - 1) / G * deltas.T @ deltas


def _block_sandwich(D: Data, J: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Cluster-robust sandwich with the validation blocks as clusters (CR1).

    Used for the correlations only (full rank as long as there are more blocks than
    parameters); the standard errors come from :func:`_sandwich`.
    """
    G = J.T @ J
    d = np.sqrt(np.maximum(np.diag(G), 1e-300))
    try:
        Ginv = np.linalg.pinv(G / np.outer(d, d), rcond=1e-12) / np.outer(d, d)
    except np.linalg.LinAlgError:
        return np.full(G.shape, np.nan)
    nb = int(D.block.max()) + 1
    S = np.zeros((nb, J.shape[1]))
    np.add.at(S, D.block, J * e[:, None])
    c = nb / max(nb - 1, 1) * (len(e) - 1) / max(len(e) - J.shape[1], 1)
    return c * Ginv @ (S.T @ S) @ Ginv


def _correlations(cov: np.ndarray, labels: list) -> list[tuple[str, str, float]]:
    sd = np.sqrt(np.maximum(np.diag(cov), 0.0))
    out = []
    for i in range(len(labels)):
        for j in range(i + 1, len(labels)):
            if labels[i][0] == labels[j][0] or sd[i] == 0 or sd[j] == 0:
                continue
            rho = float(cov[i, j] / (sd[i] * sd[j]))
            if abs(rho) >= 0.97:
                out.append((f'{labels[i][0]}.{labels[i][1]}',
                            f'{labels[j][0]}.{labels[j][1]}', rho))
    return out


def _delta_se(fn: Callable[[dict], float], vals: dict, idx: dict, cov: np.ndarray) -> float:
    """Return the standard error of ``fn(vals)`` by the delta method."""
    base = fn(vals)
    g = np.zeros(cov.shape[0])
    for lab, i in idx.items():
        h = 1e-6 * max(abs(vals[lab]), 1e-12)
        v2 = dict(vals)
        v2[lab] = vals[lab] + h
        g[i] = (fn(v2) - base) / h
    var = float(g @ cov @ g)
    return math.sqrt(var) if var > 0 and np.isfinite(var) else float('nan')


def decode(spec: Spec, model: AxisModel, vals: dict, idx: dict, cov: np.ndarray) \
        -> tuple[AxisModel, dict, dict, dict]:
    """Physical effects from the estimated columns (model-file form) and their SEs."""
    names = set(spec.names)
    scalars: dict[str, dict[str, float]] = {}
    fns: dict[str, dict[str, Callable[[dict], float]]] = {}
    at_bound: dict[str, list[str]] = {}

    def g(v: dict, group: str, name: str, default: float = 0.0) -> float:
        return float(v.get((group, name), default))

    fns[MASS] = {'mass': (lambda v: g(v, MASS, 'mass', spec.mass))}
    gms = 'presliding' in names and 'coulomb' in names
    if gms:
        dists = spec.eta['presliding'][0]
        nd = len(dists)

        def fc_of(v: dict) -> float:
            return sum(g(v, 'presliding', f'b{j}') for j in range(nd))
        fns['coulomb'] = {'fc': fc_of}
    elif 'coulomb' in names:
        fns['coulomb'] = {'fc': lambda v: g(v, 'coulomb', 'fc')}
    if 'viscous' in names:
        fns['viscous'] = {'fv': lambda v: g(v, 'viscous', 'fv')}
    if 'stribeck' in names:
        if gms:
            r = spec.eta['presliding'][2]
            fns['stribeck'] = {'fs': lambda v: fc_of(v) * (1 + r)}
        else:
            fns['stribeck'] = {'fs': lambda v: g(v, 'coulomb', 'fc') + g(v, 'stribeck', 'dfs'),
                               'vs': lambda v: g(v, 'stribeck', 'vs'),
                               'delta': lambda v: g(v, 'stribeck', 'delta')}
    if gms:
        fns['presliding'] = {
            'stiffness': lambda v: sum(max(g(v, 'presliding', f'b{j}'), 0.0) / (
                dists[j] * g(v, 'presliding', f'd{j}', 1.0)) for j in range(nd)),
            'c': lambda v: g(v, 'presliding', 'c'),
            'elements': lambda v: float(sum(g(v, 'presliding', f'b{j}') > 0
                                            for j in range(nd)))}
    if 'ripple' in names:
        nh = int(spec.eta['ripple'][1])
        d = {'period': lambda v: g(v, 'ripple', 'period')}
        for h in range(1, nh + 1):
            d[f'amplitude_{h}'] = (lambda v, h=h: math.hypot(g(v, 'ripple', f'a{h}'),
                                                             g(v, 'ripple', f'b{h}')))
        fns['ripple'] = d
    if 'offset' in names:
        fns['offset'] = {'f0': lambda v: g(v, 'offset', 'f0')}
    if 'spring' in names:
        if ('spring', 'c') in vals:
            fns['spring'] = {'k': lambda v: g(v, 'spring', 'k'),
                             'x0': lambda v: (-g(v, 'spring', 'c') / g(v, 'spring', 'k')
                                              if g(v, 'spring', 'k') else 0.0)}
        else:
            fns['spring'] = {'k': lambda v: g(v, 'spring', 'k')}
    if 'asymmetry' in names:
        fns['asymmetry'] = {'dfc': lambda v: g(v, 'asymmetry', 'dfc'),
                            'dfv': lambda v: g(v, 'asymmetry', 'dfv')}
    if 'gravity' in names:
        fns['gravity'] = {'mgl': lambda v: math.hypot(g(v, 'gravity', 'A'),
                                                      g(v, 'gravity', 'B')),
                          'q0': lambda v: math.atan2(-g(v, 'gravity', 'B'),
                                                     g(v, 'gravity', 'A'))}
    if 'delay' in names:
        fns['delay'] = {'tau': lambda v: g(v, 'delay', 'tau', spec.eta['delay'])}
    if 'backlash' in names:
        fns['backlash'] = {'width': lambda v: g(v, 'backlash', 'width',
                                                spec.eta['backlash'])}
    se: dict[str, dict[str, float]] = {}
    for grp, d in fns.items():
        scalars[grp] = {}
        se[grp] = {}
        for k, fn in d.items():
            scalars[grp][k] = float(fn(vals))
            se[grp][k] = _delta_se(fn, vals, idx, cov) if idx else float('nan')
    # -- to effects (physical bounds applied and reported) ---------------------------
    mass = scalars[MASS]['mass']
    if spec.mass_free and not mass > 0:
        at_bound.setdefault(MASS, []).append('mass')
        mass = model.mass
    out = model.without(*model.names).replace(mass=float(mass))
    effects = []

    def nonnegative(effect: str, key: str) -> float:
        # a friction level below 0 is no friction: held at its bound, and said so
        v = scalars[effect][key]
        if v < 0:
            at_bound.setdefault(effect, []).append(key)
            v = 0.0
        effects.append(make_effect(effect, {key: v}))
        return v

    fc = nonnegative('coulomb', 'fc') if 'coulomb' in names else 0.0
    if 'viscous' in names:
        nonnegative('viscous', 'fv')
    if 'stribeck' in names:
        s = scalars['stribeck']
        fs = max(s['fs'], fc)
        if s['fs'] < fc:
            at_bound.setdefault('stribeck', []).append('fs')
        vs, dl = spec.eta['stribeck'] if 'stribeck' in spec.eta else (1e-3, 1.0)
        effects.append(make_effect('stribeck', {'fs': fs, 'vs': vs, 'delta': dl}))
    if gms:
        dists, c, _ = spec.eta['presliding']
        beta = [max(g(vals, 'presliding', f'b{j}'), 0.0) for j in range(len(dists))]
        keep = [j for j in range(len(dists)) if beta[j] > 1e-9 * max(sum(beta), 1e-300)]
        if not keep:
            keep = [int(np.argmax(beta))]
            beta[keep[0]] = max(fc, 1e-9)
        tot = sum(beta[j] for j in keep)
        effects.append(make_effect('presliding', {
            'alpha': [beta[j] / tot for j in keep],
            'k': [max(beta[j], 1e-12) / dists[j] for j in keep],
            'C': c * max(fc, 1e-9)}))
    if 'ripple' in names:
        period, nh = spec.eta['ripple']
        harm = [[g(vals, 'ripple', f'a{h}'), g(vals, 'ripple', f'b{h}')]
                for h in range(1, int(nh) + 1)]
        effects.append(make_effect('ripple', {'period': period, 'harmonics': harm}))
    if 'offset' in names:
        f0 = scalars['offset']['f0']
        effects.append(make_effect('offset', {'f0': f0}))
    if 'spring' in names:
        k = scalars['spring']['k']
        x0 = scalars['spring'].get('x0', 0.0)
        x0 = float(np.clip(x0, -1e3, 1e3)) if np.isfinite(x0) else 0.0
        effects.append(make_effect('spring', {'k': k, 'x0': x0}))
    if 'asymmetry' in names:
        a = scalars['asymmetry']
        effects.append(make_effect('asymmetry', {'dfc': a['dfc'], 'dfv': a['dfv']}))
    if 'delay' in names:
        effects.append(make_effect('delay', {'tau': max(scalars['delay']['tau'], 0.0)}))
    if 'backlash' in names:
        effects.append(make_effect('backlash', {'width': scalars['backlash']['width']}))
    if 'gravity' in names:
        gr = scalars['gravity']
        effects.append(make_effect('gravity', {'mgl': gr['mgl'], 'q0': gr['q0']}))
    for e in effects:
        out = out.with_effect(e)
    if not spec.mass_free:
        scalars[MASS] = {'mass': float(spec.mass)}
        se[MASS] = {'mass': float('nan')}
    return out, scalars, se, at_bound


def spec_of(model: AxisModel) -> Spec:
    """Return the spec of an existing model (its nonlinear parameters as given)."""
    eta: dict[str, Any] = {}
    names = []
    for e in model.effects:
        n = e.name
        names.append(n)
        if n == 'ripple':
            eta[n] = (e.period, len(e.harmonics))
        elif n == 'stribeck':
            eta[n] = (e.vs, e.delta)
        elif n == 'delay':
            eta[n] = e.tau
        elif n == 'backlash':
            eta[n] = e.width
        elif n == 'presliding':
            fc = max(model.fc, 1e-6)
            ratio = (model.stribeck_curve_params()[1] - fc) / fc
            dists = tuple(a * fc / k for a, k in zip(e.alpha, e.k))
            eta[n] = (dists, e.C / fc, ratio)
    return Spec(tuple(n for n in ORDER if n in names), eta, True, model.mass)


def theta_of(model: AxisModel, labels: Sequence[tuple[str, str]]) -> np.ndarray:
    """Return the coefficients a model gives the columns ``labels`` of its own spec."""
    out = []
    for g, n in labels:
        e = model.get(g) if g != MASS else None
        if g == MASS:
            v = model.mass
        elif g == 'coulomb':
            v = model.fc
        elif g == 'presliding':
            v = model.get('presliding').alpha[int(n[1:])] * model.fc
        elif g == 'viscous':
            v = model.fv
        elif g == 'stribeck':
            v = e.fs - model.fc
        elif g == 'ripple':
            h = int(n[1:]) - 1
            v = e.harmonics[h][0 if n[0] == 'a' else 1] if h < len(e.harmonics) else 0.0
        elif g == 'offset':
            v = e.f0
        elif g == 'spring':
            v = e.k if n == 'k' else -e.k * e.x0
        elif g == 'asymmetry':
            v = e.dfc if n == 'dfc' else e.dfv
        elif g == 'gravity':
            v = e.mgl * math.cos(e.q0) if n == 'A' else -e.mgl * math.sin(e.q0)
        else:
            v = 0.0
        out.append(float(v))
    # a constant shared by offset and spring: the spring's part goes to the offset
    if model.has('offset') and model.has('spring'):
        sp = model.get('spring')
        for i, (g, n) in enumerate(labels):
            if (g, n) == ('offset', 'f0'):
                out[i] -= sp.k * sp.x0
    return np.array(out)


def given_sse(D: Data, model: AxisModel) -> float:
    """Sum of squared force residuals of ``model`` as given, on the rows (no fitting)."""
    spec = spec_of(model)
    sync(D, spec, model)
    X, labels = columns(D, spec)
    r = target(D, spec) - X @ theta_of(model, labels)
    return float(r @ r)
