"""One identification experiment as an immutable dataset, and its views.

A :class:`Dataset` is one or several runs (one experiment, one model), processed once
(:mod:`.processing`): the fitted samples of each run, cut into short blocks dealt to
validation folds round-robin, so every fold covers every regime of a time-ordered
experiment (a slow→fast sweep included); training leaves out one smoother half-width
next to each held-out block (hv-block cross-validation, Racine 2000;
``../shared/IDENTIFICATION.md`` §4).  Nothing in it changes after construction.

What depends on a model — the motor motion reconstructed across a backlash gap (it
follows the model's own dynamics), the drive force delayed by a dead time, rows
weighted by speed band — is a :class:`View`, ``dataset.at(width=, tau=, model=,
weights=)``.  Views are cheap and immutable; the smoothed columns, motions and Gram
entries they compute are cached on the dataset under keys naming everything they
depend on, so a search that returns to a view finds its columns again and no caller
ever re-synchronises anything.
"""
from __future__ import annotations

import hashlib
import json
import math
from typing import Any, Sequence

import numpy as np

from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import EffectKind
from motor_comp.physics.effects.identification import Column, Signal, Summary
from motor_comp.workbench import processing as proc
from motor_comp.workbench.bands import SpeedWeights
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.motion import motor_position
from motor_comp.workbench.parts import Motion, PathView, RunPart

#: least share of the sliding samples in the minority direction for the runs to count as
#: moving both ways: below it the backward samples are jitter of a one-way run
MIN_DIRECTION_SHARE = 0.05
#: memory for cached smoothed columns of one dataset [bytes]
COLUMN_CACHE_BYTES = 256 * 2**20


def forces_only(model: AxisModel) -> AxisModel:
    """Return ``model`` without its input and output effects (the flight across a gap).

    The gap's own motion is being reconstructed and the delayed command is applied by
    the flight itself, so only the forces stay.
    """
    return model.without(*[e.name for e in model.effects if e.kind is not EffectKind.FORCE])


def model_signature(model: AxisModel | None) -> str:
    """Return a short key of a model's parameters (what a reconstructed motion depends on)."""
    if model is None:
        return ''
    text = json.dumps(model.to_dict(), sort_keys=True, default=str)
    return hashlib.blake2b(text.encode(), digest_size=8).hexdigest()


class Dataset:
    """One identification experiment: the fitted samples of one or more runs.

    Parameters
    ----------
    kins : sequence of Kinematics
        The runs (one experiment, one model).
    model : AxisModel
        Supplies the drive constants (``input_gain``, ``back_emf``, ``damping``).
    folds : int
        Number of folds the blocks are dealt to (round-robin).
    processing : Processing
        The processing choices (smoother length).
    block_s : float, optional
        Block length [s]; default from the record length (0.25–2 s).
    masks : sequence of ndarray of bool, optional
        The fitted samples of each run (another dataset's ``masks`` on the same time
        grid), instead of selecting them here.
    """

    def __init__(self, kins: Sequence[Kinematics], model: AxisModel, *, folds: int = 5,
                 processing: proc.Processing = proc.Processing(),
                 block_s: float | None = None,
                 masks: Sequence[np.ndarray] | None = None) -> None:
        if folds < 2:
            raise ParameterError(f'folds must be >= 2, got {folds}')
        self.kins = list(kins)
        self.model = model
        self.folds = int(folds)
        self.processing = processing
        self.parts: list[RunPart] = []
        self.masks: list[np.ndarray] = []
        total = sum(k.duration for k in self.kins)
        if block_s is None:
            block_s = float(np.clip(total / (10.0 * folds), 0.25, 2.0))
        run_id, blk, head_tail = [], [], []
        nblk = 0
        n_full = 0.0
        for i, kin in enumerate(self.kins):
            W = processing.window(kin)
            mask = processing.rows(kin, W) if masks is None else np.asarray(masks[i], bool)
            self.masks.append(mask)
            step = processing.step(W)
            keep = np.zeros(len(kin), dtype=bool)
            keep[::step] = True
            rows = np.flatnonzero(mask & keep)
            self.parts.append(RunPart(kin, rows, W, processing.gms_scale))
            # independent samples: Σb² of the normalised kernel per sample
            n_full += len(rows) * step * float(np.sum(proc.kernel(W) ** 2))
            t = kin.t[rows] - kin.t[0]
            b = np.floor(t / block_s).astype(int)
            half = 0.5 * W * kin.dt
            b_lo, b_hi = b * block_s, (b + 1) * block_s
            head_tail.append(np.where(t - b_lo < half, 0, np.where(b_hi - t <= half, 2, 1)))
            blk.append(b + nblk)
            nblk += int(b.max()) + 1 if len(b) else 0
            run_id.append(np.full(len(rows), i))
        self.run_id = np.concatenate(run_id)
        block = np.concatenate(blk)
        ht = np.concatenate(head_tail)
        if len(block) == 0:
            raise ParameterError('no sliding samples in the run(s): the axis does not move')
        _, block = np.unique(block, return_inverse=True)
        self.block = block
        self.n_blocks = int(block.max()) + 1
        self.block_fold = np.arange(self.n_blocks) % self.folds
        self.fold = self.block_fold[block]
        part_key = block * 3 + ht
        change = np.flatnonzero(np.diff(part_key)) + 1
        self.starts = np.concatenate([[0], change])
        part_block = block[self.starts]
        part_pos = ht[self.starts]
        self.n = len(block)
        self._train_parts, self._test_parts = [], []
        prev_f = np.roll(self.block_fold, 1)[part_block]
        next_f = np.roll(self.block_fold, -1)[part_block]
        for f in range(self.folds):
            tr = self.block_fold[part_block] != f
            # hv gap: a training block's edge next to a held-out block is left out
            tr &= ~((part_pos == 0) & (prev_f == f) & (part_block > 0))
            tr &= ~((part_pos == 2) & (next_f == f) & (part_block < self.n_blocks - 1))
            self._train_parts.append(tr)
            self._test_parts.append(self.block_fold[part_block] == f)
        self.n_eff = max(n_full, 2.0)
        ends = np.append(self.starts[1:], self.n)
        self._part_bounds = list(zip(self.starts.tolist(), ends.tolist()))
        self._fold_w = (np.array(self._train_parts, dtype=float),
                        np.array(self._test_parts, dtype=float))
        self._cache: dict = {}
        self._cache_max = max(400, COLUMN_CACHE_BYTES // (8 * max(self.n, 1)))
        self._gram: dict = {}
        self._key_ids: dict = {}
        self._row_sets: dict = {}
        self._motions: dict = {}
        self._views: dict = {}
        base = self.at()
        v = np.concatenate([np.asarray(m.v)[p.rows] for p, m in
                            zip(self.parts, base.motions)])
        n_pos, n_neg = int(np.count_nonzero(v > 0)), int(np.count_nonzero(v < 0))
        #: share of the fitted samples in the less frequent direction (0–0.5)
        self.minority_share = min(n_pos, n_neg) / max(n_pos + n_neg, 1)
        #: +1/−1 when the runs slide one way only, else 0
        self.direction = (0 if self.minority_share >= MIN_DIRECTION_SHARE
                          else (1 if n_pos >= n_neg else -1))
        self.window = max(p.W for p in self.parts)
        y0 = base.y()
        #: NRMSE denominator: Σ(F_in − mean)² over the rows, without delay (one per run set)
        self.den = float(np.sum((y0 - y0.mean()) ** 2))
        self.summary = self._summary(base)

    # -- structure ------------------------------------------------------------------
    def _summary(self, base: 'View') -> Summary:
        speed = np.abs(base.gather(lambda p, m: m.v))
        acc = np.abs(base.signal(Signal.ACCELERATION))
        x = base.gather(lambda p, m: m.x)
        kin = self.kins[0]
        n_rev = int(sum(np.count_nonzero(np.diff(np.sign(p.kin.v[p.rows])) != 0)
                        for p in self.parts))
        pct = (1, 10, 50, 90, 95)
        v = base.gather(lambda p, m: m.v)
        fwd, bwd = x[v > 0], x[v < 0]
        shared: tuple = ()
        if len(fwd) > 1 and len(bwd) > 1:
            lo = max(np.percentile(fwd, 1), np.percentile(bwd, 1))
            hi = min(np.percentile(fwd, 99), np.percentile(bwd, 99))
            shared = (float(lo), float(hi)) if hi > lo else ()
        return Summary(shared_span=shared, dt=max(k.dt for k in self.kins),
                       duration=min(k.duration for k in self.kins), quantum=kin.quantum(),
                       noise=kin.noise_std(), span=(float(x.min()), float(x.max())),
                       speeds=dict(zip(pct, (float(q) for q in np.percentile(speed, pct)))),
                       accel90=float(np.percentile(acc, 90)), reversals=n_rev,
                       direction=int(self.direction),
                       rotary=bool(self.model.units.rotary))

    def at(self, *, width: float = 0.0, tau: float = 0.0, model: AxisModel | None = None,
           weights: SpeedWeights | None = None) -> 'View':
        """Return the view of the data with a backlash ``width`` [m], a delay ``tau`` [s].

        ``model`` is the model whose dynamics carry the motor across the gap (only
        used with ``width > 0``); ``weights`` weight the rows by speed band.
        """
        width, tau = float(width), float(tau)
        mkey: tuple = (0,) if width <= 0 else (
            'gap', width, tau, model_signature(forces_only(model)
                                               if model is not None else None))
        key = (mkey, tau, weights)
        v = self._views.get(key)
        if v is None:
            if len(self._views) > 256:
                self._views.clear()
            v = self._views[key] = View(self, width, tau, model, weights, mkey)
        return v

    def motions(self, width: float, tau: float, model: AxisModel | None,
                mkey: tuple) -> list[Motion]:
        """Return each run's motion (measured, or the motor's across a gap), cached."""
        hit = self._motions.get(mkey)
        if hit is not None:
            return hit
        out = []
        for p in self.parts:
            if width <= 0:
                out.append(Motion(p, p.kin.position, True))
                continue
            # the flight sees the logged command delayed by τ at the integrator's sub-step
            base = forces_only(model or self.model)
            xm = motor_position(p.kin, width, base, p.kin.u, tau=tau)
            out.append(Motion(p, xm, False))
        if len(self._motions) > 64:
            self._motions.clear()
        self._motions[mkey] = out
        return out

    # -- folds ------------------------------------------------------------------------
    def part_grams(self, Z: np.ndarray) -> np.ndarray:
        """Return the per-part ``ZᵀZ``: shape (parts, q, q)."""
        out = np.empty((len(self._part_bounds), Z.shape[1], Z.shape[1]))
        for i, (a, b) in enumerate(self._part_bounds):
            np.matmul(Z[a:b].T, Z[a:b], out=out[i])
        return out

    def part_grams_of(self, cols: Sequence[np.ndarray], keys: Sequence[tuple | None]) \
            -> np.ndarray:
        """Return :meth:`part_grams` of ``cols``, reusing cached entries by column key.

        What :meth:`gram` does for all rows, per part: a held-out score of trials that
        change one group of columns (a delay's drive force, a fold's choices among 77
        of them) computes the new columns' products alone.  Each product is summed per
        part in one pass over the rows (``np.add.reduceat`` at the part starts).
        """
        def products(Z: np.ndarray, missing: list[int]) -> list:
            # (q, parts) per missing column: its products with every column, per part
            return [np.add.reduceat(Z * Z[i], self.starts, axis=1) for i in missing]
        return self._products(cols, keys, 'parts', (len(self._part_bounds),), products)

    def fold_grams(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Return each fold's training and held-out Grams from per-part ones ``P``.

        Shapes (folds, q, q): the sums of the parts in :attr:`train_parts` and
        :attr:`test_parts`, all folds in one product each (a fold choosing among 77
        trials summed its parts 4 × 77 times).
        """
        k, q = P.shape[0], P.shape[1]
        flat = P.reshape(k, q * q)
        f = self.folds
        return (self._fold_w[0] @ flat).reshape(f, q, q), \
            (self._fold_w[1] @ flat).reshape(f, q, q)

    @property
    def train_parts(self) -> list[np.ndarray]:
        """Part masks of each fold's training set."""
        return self._train_parts

    @property
    def test_parts(self) -> list[np.ndarray]:
        """Part masks of each fold's held-out set."""
        return self._test_parts

    def train_rows(self, f: int) -> np.ndarray:
        """Return the boolean row mask of fold ``f``'s training samples."""
        part_of_row = np.repeat(np.arange(len(self.starts)),
                                np.diff(np.append(self.starts, self.n)))
        return self._train_parts[f][part_of_row]

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

    def cached(self, key: tuple, make: Any) -> np.ndarray:
        """Return the cached array under ``key``, computing it with ``make()`` once."""
        hit = self._cache.get(key)
        if hit is None:
            if len(self._cache) > self._cache_max:
                self._cache.clear()
            hit = self._cache[key] = make()
        return hit

    def gram(self, cols: Sequence[np.ndarray], keys: Sequence[tuple | None],
             rows: np.ndarray | None = None) -> np.ndarray:
        """Return ``ZᵀZ`` of ``cols`` over ``rows``, reusing cached entries by column key.

        Variable projection re-solves the same design with one group of columns
        changed per trial: the products among the unchanged columns are computed once,
        the trial columns' products at each trial (O(n·k·p) instead of O(n·p²)).
        """
        rid = self.rows_id(rows)

        def products(Z: np.ndarray, missing: list[int]) -> list:
            if rows is not None:
                Z = Z[:, rows]
            return list(Z[missing] @ Z.T)
        return self._products(cols, keys, rid, (), products)

    def _products(self, cols: Sequence[np.ndarray], keys: Sequence[tuple | None], tag: Any,
                  lead: tuple, products: Any) -> np.ndarray:
        """Return the products of ``cols`` (shape ``lead + (q, q)``), cached by column key.

        Entry ``[..., i, j]`` is cached under ``(tag, key_i, key_j)`` (``tag`` names the
        rows they are summed over); ``products(Z, missing)`` returns, for each column
        index in ``missing``, its products with every column (``Z`` the columns as rows
        of one array), shape ``(q,) + lead``.
        """
        q = len(cols)
        # each key named once by a small number: the pairs' lookups then hash three
        # integers, not two nested key tuples (most of this method's time, q² of them)
        ids = self._key_ids
        if len(ids) > 100_000:
            ids.clear()
            self._gram.clear()
        ks = [None if k is None else ids.setdefault(k, len(ids)) for k in keys]
        cache = self._gram
        # filled as (q, q) + lead: a pair's entry is out[i, j] (plain indexing, the
        # loop's cost), returned as lead + (q, q)
        out = np.empty((q, q) + lead)
        missing: list[int] = []
        for i in range(q):
            ki = ks[i]
            if ki is None:
                missing.append(i)
                continue
            for j in range(i + 1):
                if j in missing:
                    # the pair comes with column j's products: a trial's new column
                    # does not make every later column's products computed again
                    continue
                kj = ks[j]
                v = cache.get((tag, ki, kj))
                if v is None:
                    missing.append(i)
                    break
                out[i, j] = out[j, i] = v
        if missing:
            # the columns as rows of one array (each a contiguous copy; a stack along
            # axis 1 transposed them element by element)
            rows_of = products(np.array(cols), missing)
            if len(cache) > 200_000:
                cache.clear()
            for i, M in zip(missing, rows_of):
                out[i] = M
                out[:, i] = M
                ki = ks[i]
                if ki is None:
                    continue
                for kj, v in zip(ks, M.tolist() if not lead else M):
                    if kj is not None:
                        cache[(tag, ki, kj)] = cache[(tag, kj, ki)] = v
        return np.ascontiguousarray(np.moveaxis(out, (0, 1), (-2, -1))) if lead else out


class View:
    """The dataset seen with a backlash gap, a dead time and row weights (immutable).

    Built by :meth:`Dataset.at`; every array it returns is at the dataset's rows.
    """

    def __init__(self, data: Dataset, width: float, tau: float, model: AxisModel | None,
                 weights: SpeedWeights | None, mkey: tuple) -> None:
        self.data = data
        self.width = width
        self.tau = tau
        self.model = model
        self.weights = weights
        self.mkey = mkey
        self.wkey = (weights.edges, weights.w) if weights is not None else None
        self._motions: list[Motion] | None = None
        self._sw: np.ndarray | None = None

    @property
    def motions(self) -> list[Motion]:
        """Each run's motion in this view."""
        if self._motions is None:
            self._motions = self.data.motions(self.width, self.tau, self.model, self.mkey)
        return self._motions

    def paths(self) -> list[PathView]:
        """Return each run's :class:`PathView` (the signals a term's columns use)."""
        m = self.data.model
        k = m.input_gain * m.back_emf + m.damping
        tau = self.tau

        def f_in(motion: Motion) -> np.ndarray:
            return m.input_gain * motion.part.kin.input_at(tau) - k * motion.v
        return [PathView(mo, f_in, self.data.direction) for mo in self.motions]

    def gather(self, fn: Any) -> np.ndarray:
        """Concatenate ``fn(part, motion)[rows]`` over the runs (full-rate arrays)."""
        return np.concatenate([np.asarray(fn(p, mo))[p.rows]
                               for p, mo in zip(self.data.parts, self.motions)])

    def key(self, key: tuple, *, uses_input: bool = False) -> tuple:
        """Return the cache key of a column in this view."""
        return key + (self.mkey, self.tau if uses_input else None, self.wkey)

    @property
    def sw(self) -> np.ndarray | None:
        """Return the √weight of each row (None: unweighted)."""
        if self.weights is None:
            return None
        if self._sw is None:
            vl = self.data.at(width=self.width, tau=self.tau, model=self.model)\
                .signal(Signal.VELOCITY)
            self._sw = np.sqrt(self.weights.at(vl))
        return self._sw

    def _weigh(self, a: np.ndarray) -> np.ndarray:
        sw = self.sw
        return a if sw is None else a * sw

    def signal(self, sig: Signal) -> np.ndarray:
        """Return the velocity or acceleration of the smoothed position at the rows."""
        which = sig.value
        return self.data.cached(self.key(('signal', which)), lambda: self._weigh(
            np.concatenate([proc.stencil(mo.smoothed, p.rows, p.kin.dt, which)
                            for p, mo in zip(self.data.parts, self.motions)])))

    def smooth_input(self, factor: Any, key: tuple) -> np.ndarray:
        """Return ``S(factor(part, motion)·u(t − τ))`` at the rows (unweighted), cached.

        ``S`` is linear and time-invariant and the delayed input a weighted sum of
        whole-sample shifts (:meth:`Kinematics.input_lags`): each shift is smoothed once
        and cached, and a trial delay sums two or three of them (a delay search smoothed
        the whole input at each of its ~80 trials).
        """
        def make() -> np.ndarray:
            out = []
            for i, (p, mo) in enumerate(zip(self.data.parts, self.motions)):
                def lag(s: int) -> np.ndarray:
                    return self.data.cached(self.key(key + ('lag', i, s)), lambda: proc.smooth_at(
                        factor(p, mo) * p.kin.input_shifted(s), p.rows, p.W))
                out.append(sum(w * lag(s) for s, w in p.kin.input_lags(self.tau)))
            return np.concatenate(out)
        return self.data.cached(self.key(key, uses_input=True), make)

    def ckey(self, col: Column, rests: bool) -> tuple:
        """Return the cache key of a term's column in this view."""
        if col.signal is not None:
            return self.key(('signal', col.signal.value))
        return self.key(col.key + (('rest',) if rests else ()), uses_input=col.uses_input)

    def columns(self, cols: Sequence[Column], *, rests: bool = False) -> list[np.ndarray]:
        """Return terms' columns at the rows: smoothed, stencil-averaged, weighted.

        With ``rests`` each pointwise column is 0 where the axis is at rest (its
        friction balances every force there, so no force law is seen).  Columns of one
        block (``width > 1``, one function giving several columns in one pass) are
        computed together and each cached under its own key.
        """
        out: list[np.ndarray | None] = []
        todo: dict[int, list[tuple[int, Column]]] = {}
        for i, col in enumerate(cols):
            if col.signal is not None:
                out.append(self.signal(col.signal))
                continue
            hit = self.data._cache.get(self.ckey(col, rests))
            out.append(hit)
            if hit is None:
                todo.setdefault(id(col.fn), []).append((i, col))
        if todo:
            paths = self.paths()
            for group in todo.values():
                col0 = group[0][1]
                # only a block's missing columns are weighted and smoothed (a ripple's
                # order search adds one harmonic to a block whose others are cached);
                # each column's sums are its own, so the values are the same
                pick = [col.index for _, col in group]
                parts = []
                for p, path in zip(self.data.parts, paths):
                    keep = 1.0 - path.rest if rests else None
                    if col0.local is not None:
                        # smoothed on its local basis and mapped (the smoother is linear)
                        lb = col0.local(path)
                        val = lb.value if keep is None else lb.value * keep[:, None]
                        sl = proc.smooth_local_at(lb.index, val, lb.mix.shape[0], p.rows, p.W)
                        parts.append(np.ascontiguousarray((sl @ lb.mix[:, pick]).T))
                        continue
                    a = np.asarray(col0.fn(path), dtype=float)
                    if a.ndim == 1:
                        parts.append(proc.smooth_at(a if keep is None else a * keep,
                                                    p.rows, p.W))
                        continue
                    # a block's columns transposed, picked and weighted in one pass: each
                    # column's samples contiguous, as the smoother reads them and the
                    # design takes them
                    at = a.T if pick == list(range(a.shape[1])) else a.T[pick]
                    at = np.ascontiguousarray(at) if keep is None else \
                        np.multiply(at, keep, order='C')
                    parts.append(proc.smooth_columns_at(at.T, p.rows, p.W))
                raw = np.concatenate(parts, axis=-1)
                for k, (i, col) in enumerate(group):
                    a = raw[k] if raw.ndim == 2 else raw
                    out[i] = self.data.cached(self.ckey(col, rests),
                                              lambda a=a, col=col: self._finish(col, a))
        return out  # type: ignore[return-value]

    def _finish(self, col: Column, a: np.ndarray) -> np.ndarray:
        if col.frequency:
            a = a * self.stencil_gain(col.frequency)
        return self._weigh(np.ascontiguousarray(a))

    def stencil_gain(self, w: float) -> np.ndarray:
        """Return the stencil's gain on a position-periodic force of frequency ``w``."""
        def make() -> np.ndarray:
            vdt = self.gather(lambda p, mo: mo.v * p.kin.dt)
            return np.ascontiguousarray(proc.stencil_gain(w, vdt)[:, 0])
        return self.data.cached(('stencil_gain', float(w), self.mkey), make)

    def y(self, *, rests: bool = False) -> np.ndarray:
        """Return the smoothed drive force at the rows (unweighted) with this view's delay.

        With ``rests`` the drive force of the samples at rest is left out (the friction
        balances it there).
        """
        m = self.data.model
        k = m.input_gain * m.back_emf + m.damping
        g = m.input_gain
        if rests:
            w = self.smooth_input(lambda p, mo: g * (1.0 - mo.shares[3]), ('u', 'moving'))
        else:
            w = self.smooth_input(lambda p, mo: g, ('u',))
        if not k:
            return w
        vl = self.data.at(width=self.width, tau=self.tau, model=self.model)\
            .signal(Signal.VELOCITY)
        return w - k * vl

    def stuck_force(self) -> np.ndarray:
        """Return the smoothed drive force of the samples stuck at a turn (unweighted)."""
        g = self.data.model.input_gain
        return self.smooth_input(lambda p, mo: g * mo.shares[2], ('stuck_u',))

    def nrmse(self, sse: float) -> float:
        """Return the force NRMSE of a sum of squared residuals over the rows."""
        den = self.data.den
        return math.sqrt(sse / den) if den > 0 else float('inf')


__all__ = ['COLUMN_CACHE_BYTES', 'Dataset', 'MIN_DIRECTION_SHARE', 'Motion', 'PathView',
           'RunPart', 'View', 'model_signature']
