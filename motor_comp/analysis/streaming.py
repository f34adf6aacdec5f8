"""Streaming analysis: the run metrics of an MCAP file in memory independent of its length.

:func:`stream_metrics` gives the same :class:`~motor_comp.analysis.metrics.RunMetrics`
as ``compute_metrics(read_run(path))`` (the array path, kept as the reference), to
round-off (1e-12 relative), without ever holding a decoded series:

1. **Decode and spill.**  The reader of :mod:`motor_comp.logs.mcap_io` decodes the file
   chunk by chunk as usual, but appends the decoded columns to temporary files
   (:class:`_SpillColumn`) instead of growing arrays in memory.
2. **Scan.**  One pass per signal applies the reader's policies (present bits, NaN/Inf
   dropped with the same warnings, first/last stamp for the common start and for the
   end of a damaged file).  Stamps out of order or duplicated need a global sort: such
   files (rare: recorders write in order) are read by the array path instead.
3. **Align** (:meth:`RunStream.blocks`): the measurement stamps are read in blocks of
   :data:`BLOCK` samples; every other signal is sampled and held onto them by a cursor
   that keeps only the samples between two block ends.
4. **Metrics** (:func:`metrics_of_stream`): running sums (midpoint-rule weights need the
   neighbouring stamps: one sample of look-ahead), reversals and quadrant-glitch
   windows carried across block borders, point-to-point moves as a state machine, the
   median step by a radix selection over the stamps, and the chattering (whole-record
   spectrum above a cut-off) by a Bluestein DFT of the spilled voltage whose FFTs run
   out of core (four-step, files on disk) with exactly reduced chirp phases — fixed-size
   buffers, whatever the length.

What still grows with the length is the result itself: one :class:`Glitch` and one
:class:`Segment` per reversal (about 0.3 kB each).
"""
from __future__ import annotations

import dataclasses
import math
import os
import shutil
import tempfile
from array import array
from collections.abc import Sequence
from pathlib import Path
from typing import Any, Callable, Collection, Iterator, Mapping

import numpy as np

from motor_comp.analysis.glitches import Glitch
from motor_comp.analysis.metrics import Move, RunMetrics, Segment
from motor_comp.errors import InputFileError, ParameterError, check_positive
from motor_comp.logs import cdr
from motor_comp.logs import mcap_io as M
from motor_comp.logs.bags import Bag
from motor_comp.logs.progress import Progress, warn
from motor_comp.logs.run import Run
from motor_comp.logs.topics import RunTopics

#: samples per block of the streaming passes (fixed: memory does not depend on length)
BLOCK = 1 << 16
#: longest row of the out-of-core FFT of the chattering spectrum [complex values]
FFT_ROW = 1 << 16


# ============================================================================ spilling

class _SpillColumn:
    """A column of decoded values appended to a file (same semantics as ``_Column``)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.n = 0
        self.dtype: np.dtype | None = None
        self._f: Any = None

    def append(self, values: np.ndarray | int) -> None:
        if isinstance(values, int):
            if self.dtype is not None:
                self._write(np.full(values, np.nan, self.dtype))
            self.n += values
            return
        if self.dtype is None:
            self.dtype = values.dtype
            self._f = open(self.path, 'wb')
            for k in range(0, self.n, BLOCK):      # absent values before the first data
                self._write(np.full(min(BLOCK, self.n - k), np.nan, self.dtype))
        self._write(np.ascontiguousarray(values, self.dtype))
        self.n += values.size

    def _write(self, a: np.ndarray) -> None:
        self._f.write(a.tobytes())

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def read(self, start: int, count: int) -> np.ndarray:
        """Values ``start … start+count−1`` (NaN for a column that never had data)."""
        count = max(0, min(count, self.n - start))
        if self.dtype is None:
            return np.full(count, np.nan)
        with open(self.path, 'rb') as f:
            f.seek(start * self.dtype.itemsize)
            return np.fromfile(f, self.dtype, count)


@dataclasses.dataclass
class _SpillTopic(M._Topic):
    """A reader topic whose columns go to files in ``spill``."""

    spill: str = ''

    def add(self, **arrays: np.ndarray | int) -> None:
        """Append a chunk's arrays to the column files."""
        for k, v in arrays.items():
            col = self.columns.get(k)
            if col is None:
                safe = self.topic.strip('/').replace('/', '_')
                col = _SpillColumn(Path(self.spill) / f'{safe}.{k}')
                self.columns[k] = col       # type: ignore[assignment]
            col.append(v)

    def column(self, key: str) -> _SpillColumn | None:
        """Return the spilled column ``key`` (None if never added)."""
        return self.columns.get(key)  # type: ignore[return-value]


class _SpillReader(M._Reader):
    """The MCAP reader with topics that spill their columns to ``spill``."""

    def __init__(self, *args: Any, spill: str, **kw: Any) -> None:
        super().__init__(*args, **kw)
        self.spill = spill

    def add_channel(self, cid: int, topic: str, *args: Any) -> None:
        new = topic not in self.topics
        super().add_channel(cid, topic, *args)
        tp = self.topics.get(topic)
        if new and tp is not None and not isinstance(tp, _SpillTopic):
            self.topics[topic] = _SpillTopic(tp.topic, tp.kind, drop=tp.drop, joint=tp.joint,
                                             strict=tp.strict, spill=self.spill)


# ============================================================================ signals

@dataclasses.dataclass
class _Signal:
    """One signal as spilled columns: stamps [ns], values, optional present bits."""

    name: str
    topic: str
    field: str
    stamp: _SpillColumn
    value: _SpillColumn
    present: _SpillColumn | None = None
    bit: int = 0
    offset: int = 0               # added to the stamps [ns] (voltage clock shift)
    count: int = 0                # samples kept after cleaning
    first: int = 0
    last: int = 0

    def raw_blocks(self) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """Blocks of (stamp [ns] int64, value) after the present mask and NaN filter."""
        n = self.stamp.n
        for k in range(0, n, BLOCK):
            ts = self.stamp.read(k, BLOCK).astype(np.int64)
            vs = self.value.read(k, BLOCK).astype(float)
            if self.present is not None:
                m = (self.present.read(k, BLOCK).astype(np.uint8) & self.bit) != 0
                if not m.all():
                    ts, vs = ts[m], vs[m]
            fin = np.isfinite(vs)
            if not fin.all():
                ts, vs = ts[fin], vs[fin]
            if self.offset:
                ts = ts + self.offset
            if ts.size:
                yield ts, vs

    def scan(self, path: Path, unusable: dict[str, str]) -> bool:
        """Apply the reader's cleaning policy; False if stamps need sorting (not streamable).

        Sets ``count``, ``first`` and ``last``; warns about dropped NaN/Inf samples or
        records the signal as unusable (all non-finite), like ``mcap_io._clean``.
        """
        total = bad = kept = 0
        last = None
        ordered = True
        n = self.stamp.n
        for k in range(0, n, BLOCK):
            vs = self.value.read(k, BLOCK).astype(float)
            ts = self.stamp.read(k, BLOCK).astype(np.int64)
            if self.present is not None:
                m = (self.present.read(k, BLOCK).astype(np.uint8) & self.bit) != 0
                ts, vs = ts[m], vs[m]
            total += ts.size
            fin = np.isfinite(vs)
            bad += int(ts.size - np.count_nonzero(fin))
            ts = ts[fin]
            if ts.size:
                if last is not None and ts[0] <= last or np.any(np.diff(ts) <= 0):
                    ordered = False
                if kept == 0:
                    self.first = int(ts[0]) + self.offset
                last = int(ts[-1])
                kept += ts.size
        self.count = kept
        if last is not None:
            self.last = last + self.offset
        if total == 0:
            return True
        if bad == total:
            unusable[self.name] = f'all {bad} {self.topic} {self.field} samples are NaN/Inf'
            self.count = 0
            return True
        if bad:
            warn(f'{path.name}: {self.topic} {self.field}: dropped {bad} non-finite '
                 '(NaN/Inf) samples')
        return ordered


class _Hold:
    """Sample and hold of one signal onto increasing measurement stamps, block by block."""

    def __init__(self, sig: _Signal) -> None:
        self.src = sig.raw_blocks()
        self.ts = np.empty(0, np.int64)
        self.vs = np.empty(0)
        self.done = False

    def at(self, t: np.ndarray) -> np.ndarray:
        """Return the latest value stamped at or before each of ``t`` (increasing)."""
        while not self.done and (self.ts.size == 0 or self.ts[-1] <= t[-1]):
            nxt = next(self.src, None)
            if nxt is None:
                self.done = True
            else:
                self.ts = np.concatenate((self.ts, nxt[0]))
                self.vs = np.concatenate((self.vs, nxt[1]))
        i = np.searchsorted(self.ts, t, side='right') - 1
        out = self.vs[i]
        keep = int(i[-1])
        self.ts, self.vs = self.ts[keep:], self.vs[keep:]
        return out


@dataclasses.dataclass
class RunStream:
    """A run on disk: its aligned signals are read block by block (see the module doc).

    Attributes
    ----------
    name : str
        File stem.
    metadata : Mapping
        As :attr:`Run.metadata`.
    samples : int
        Number of aligned samples.
    signals : tuple of str
        Signals present besides ``t`` and ``position``.
    """

    name: str
    metadata: Mapping[str, Any]
    samples: int
    signals: tuple[str, ...]
    _position: _Signal
    _others: dict[str, _Signal]
    _skip: int
    _spill: str

    def __len__(self) -> int:
        return self.samples

    def has(self, signal: str) -> bool:
        """Return True if ``signal`` is present."""
        return signal in ('t', 'position') or signal in self.signals

    def blocks(self, *, only_t: bool = False) -> Iterator[dict[str, np.ndarray]]:
        """Blocks of aligned arrays: ``t`` [s], ``position`` and the present signals."""
        holds = {} if only_t else {f: _Hold(s) for f, s in self._others.items()}
        lo, hi = self._skip, self._skip + self.samples
        g = 0
        for ts, pos in self._position.raw_blocks():
            a, z = max(lo - g, 0), min(hi - g, ts.size)
            g += ts.size
            if z <= a:
                if g >= hi:
                    return
                continue
            ts, pos = ts[a:z], pos[a:z]
            out = {'t': ts / 1e9, 'position': pos}
            for f, h in holds.items():
                out[f] = h.at(ts)
            yield out

    def close(self) -> None:
        """Delete the spill files."""
        shutil.rmtree(self._spill, ignore_errors=True)

    def __enter__(self) -> RunStream:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def to_run(self) -> Run:
        """Materialise the whole run (tests; defeats the purpose on long files)."""
        parts = list(self.blocks())
        arrays = {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        return Run(metadata=dict(self.metadata), name=self.name, **arrays)


def open_stream(path: str | os.PathLike, *, progress: bool = False, namespace: str = 'axis',
                signals: Collection[str] | None = None,
                require: Collection[str] | Mapping[str, str] = (),
                spill_dir: str | None = None, topics: RunTopics | None = None
                ) -> RunStream | Run:
    """Open a run for streaming; same checks, warnings and errors as ``read_run``.

    Any bag ``read_run`` reads (an MCAP file, a rosbag2 directory of either storage) and
    the same ``topics`` selection.

    Returns a :class:`RunStream` (close it, or use it as a context manager, to delete
    its spill files), or a :class:`Run` read by ``read_run`` when the file's stamps are
    out of order or duplicated (they need a global sort).
    """
    bag, size, names, wanted, topics = M._prepare(path, namespace, signals, require, topics)
    spill = tempfile.mkdtemp(prefix='motor_comp_stream_', dir=spill_dir)
    try:
        stream = _open(bag, size, names, wanted, spill, progress=progress, topics=topics,
                       require=require)
    except BaseException:
        shutil.rmtree(spill, ignore_errors=True)
        raise
    if stream is None:
        shutil.rmtree(spill, ignore_errors=True)
        return M.read_run(path, progress=progress, signals=signals, require=require,
                          topics=topics)
    return stream


def _open(bag: Bag, size: int, names: dict[str, str | None], wanted: dict[str, M.Want],
          spill: str, *, progress: bool, topics: RunTopics,
          require: Collection[str] | Mapping[str, str]) -> RunStream | None:
    path = bag.path
    prog = Progress(bag.path.name, size, enabled=progress)
    reader = _SpillReader(bag.files[0], wanted, prog, spill=spill)
    try:
        damage = M._read(bag, reader)
    finally:
        prog.finish()
        for tp in reader.topics.values():
            for col in tp.columns.values():
                col.close()   # type: ignore[attr-defined]
    js = M.joint_states_of(path, reader, names, damage, topics)
    assert isinstance(js, _SpillTopic)
    unusable: dict[str, str] = {}
    sigs: dict[str, _Signal] = {}
    for field, bit in (('position', cdr.HAS_POSITION), ('velocity', cdr.HAS_VELOCITY),
                       ('effort', cdr.HAS_EFFORT)):
        if field not in js.drop and js.column(field) is not None:
            sigs[field] = _Signal(field, js.topic, field, js.column('stamp'),
                                  js.column(field), js.column('present'), bit)
    ref = reader.topics.get(names['reference'])
    if ref is not None and ref.count():
        assert isinstance(ref, _SpillTopic)
        for field, key, bit in (('reference', 'position', cdr.HAS_POSITION),
                                ('reference_velocity', 'velocity', cdr.HAS_VELOCITY)):
            if key not in ref.drop and ref.column(key) is not None:
                sigs[field] = _Signal(field, ref.topic, key, ref.column('stamp'),
                                      ref.column(key), ref.column('present'), bit)
    volt = reader.topics.get(names['voltage'] or '')
    if topics.effort_input:
        if 'effort' in sigs:
            e = sigs['effort']
            sigs['voltage'] = _Signal('voltage', e.topic, 'effort', e.stamp, e.value,
                                      e.present, e.bit)
    elif volt is not None and volt.count() and volt.kind == 'joint':
        assert isinstance(volt, _SpillTopic)
        if volt.column('effort') is not None:
            sigs['voltage'] = _Signal('voltage', volt.topic, 'effort', volt.column('stamp'),
                                      volt.column('effort'), volt.column('present'),
                                      cdr.HAS_EFFORT)
    elif volt is not None and volt.count():
        assert isinstance(volt, _SpillTopic)
        offset = -int(np.median(np.concatenate(js.log_minus_stamp)))
        sigs['voltage'] = _Signal('voltage', volt.topic, 'value', volt.column('stamp'),
                                  volt.column('value'),
                                  offset=offset if abs(offset) > 1_000_000_000 else 0)
    for s in sigs.values():
        if not s.scan(path, unusable):
            return None                       # out of order: the array path sorts
    pos = sigs.pop('position', None)
    if pos is None or pos.count == 0:
        why = unusable.get('position', f'{js.topic} carries no position samples')
        raise InputFileError(f'{path}: missing position: {why}')
    present = {f: s for f, s in sigs.items() if s.count > 0}
    start = max((s.first for s in present.values()), default=pos.first)
    first = _count_below(pos, start)          # mcap_io._assemble, by counting
    if first >= pos.count:
        late = max(present, key=lambda f: present[f].first)
        raise InputFileError(f'{path}: {late} starts after the last measurement '
                             '(topics do not overlap in time)')
    stop = pos.count
    if damage is not None and present:
        end = min(s.last for s in present.values())
        stop = max(_count_below(pos, end + 1), first + 1)
    samples = stop - first
    meta: dict[str, Any] = {}
    for name, rec in reader.metadata.items():
        for k, v in rec.items():
            meta[k if name == M.METADATA_NAME else f'{name}/{k}'] = v
    stream = RunStream(name=bag.name, metadata=meta, samples=samples,
                       signals=tuple(present), _position=pos, _others=present, _skip=first,
                       _spill=spill)
    for field in require:
        if not stream.has(field):
            hint = require.get(field, '') if isinstance(require, Mapping) else ''
            raise InputFileError(M._absent(path, reader, names, field, unusable, damage,
                                           hint=hint, topics=topics))
    for field, why in unusable.items():
        warn(f'{path.name}: {why}; {field} treated as absent')
    if damage is not None:
        t0 = tn = 0.0
        for b in stream.blocks(only_t=True):
            t0 = float(b['t'][0]) if tn == 0.0 else t0
            tn = float(b['t'][-1])
        warn(f'{path.name}: {"unfinished" if "footer" in damage.reason else "damaged"} '
             f'file, reading stopped at byte {damage.offset} of {size} ({damage.reason}); '
             f'recovered {reader.messages} messages, {samples} samples, {t0:.6g}–{tn:.6g} s')
    return stream


def _count_below(sig: _Signal, stamp: int) -> int:
    """Count the cleaned samples of ``sig`` stamped before ``stamp`` [ns]."""
    n = 0
    for ts, _ in sig.raw_blocks():
        if ts[-1] < stamp:
            n += ts.size
            continue
        return n + int(np.searchsorted(ts, stamp, side='left'))
    return n


# ============================================================================ metrics

class Records(Sequence):
    """A read-only sequence of :class:`Glitch` or :class:`Segment` kept as float columns.

    One reversal per second of a 10 h run is 36 000 glitches and strokes: as columns
    they take 32 bytes each instead of a few hundred as objects.  Items are built on
    access; equality is element-wise, so it compares equal to the tuple of objects.
    """

    def __init__(self, make: Callable[..., Any], columns: Sequence[np.ndarray]) -> None:
        self._make = make
        self._cols = [np.asarray(c) for c in columns]

    def __len__(self) -> int:
        return int(self._cols[0].size)

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        n = len(self)
        i = int(i) + (n if int(i) < 0 else 0)
        if not 0 <= i < n:
            raise IndexError('record index out of range')
        return self._make(*(c[i].item() for c in self._cols))

    def __eq__(self, other: object) -> bool:
        return (isinstance(other, Sequence) and len(self) == len(other)
                and all(a == b for a, b in zip(self, other)))

    __hash__ = None        # type: ignore[assignment]

    def __repr__(self) -> str:
        return f'Records({len(self)} × {getattr(self._make, "__name__", "record")})'


def _glitch(t: float, magnitude: float, t_peak: float, direction: int) -> Glitch:
    return Glitch(t=t, magnitude=magnitude, t_peak=t_peak, direction=int(direction))


def _segment(t_start: float, t_end: float, rms_error: float, max_error: float) -> Segment:
    return Segment(t_start=t_start, t_end=t_end, rms_error=rms_error, max_error=max_error)


def _select(stream: RunStream, ranks: tuple[int, ...]) -> list[float]:
    """Return the ``ranks``-th smallest steps ``diff(t)`` (0-based), by radix selection.

    Steps of increasing times are positive floats, whose IEEE bit patterns sort like
    the values: 4 passes over the stamps, 16 bits each, count the candidates.
    """
    out = []
    for rank in ranks:
        prefix, shift, r = 0, 64, rank
        while shift > 0:
            shift -= 16
            counts = np.zeros(1 << 16, np.int64)
            for d in _steps(stream):  # noqa: B007
                bits = d.view(np.int64)
                if shift < 48:
                    bits = bits[(bits >> (shift + 16)) == prefix]
                counts += np.bincount(((bits >> shift) & 0xFFFF).astype(np.int64),
                                      minlength=1 << 16)
            cum = np.cumsum(counts)
            digit = int(np.searchsorted(cum, r, side='right'))
            r -= int(cum[digit - 1]) if digit else 0
            prefix = (prefix << 16) | digit
        out.append(float(np.array([prefix], np.int64).view(np.float64)[0]))
    return out


def _steps(stream: RunStream) -> Iterator[np.ndarray]:
    """``np.diff(t)`` block by block."""
    prev = None
    for b in stream.blocks(only_t=True):
        t = b['t']
        if prev is not None:
            t = np.concatenate(([prev], t))
        prev = b['t'][-1]
        if t.size > 1:
            yield np.diff(t)


def _median_step(stream: RunStream) -> float:
    n = stream.samples - 1
    if n % 2:
        return _select(stream, (n // 2,))[0]
    a, b = _select(stream, (n // 2 - 1, n // 2))
    return float(np.mean(np.array([a, b])))


class _Sums:
    """Weighted running sums of one signal: Σw, Σw·x, Σw·x², max |x|."""

    def __init__(self) -> None:
        self.w = self.wx = self.wxx = 0.0
        self.max = -math.inf

    def add(self, x: np.ndarray, w: np.ndarray) -> None:
        if x.size:
            self.w += float(np.sum(w))
            self.wx += float(np.sum(w * x))
            self.wxx += float(np.sum(w * x * x))
            self.max = max(self.max, float(np.max(np.abs(x))))

    def rms(self) -> float:
        return math.sqrt(self.wxx / self.w)


@dataclasses.dataclass
class _Window:
    t: float
    end: float
    direction: int
    mag: float = -1.0
    t_peak: float = 0.0


@dataclasses.dataclass
class _Dwell:
    """A point-to-point move whose reference has come to rest (DESIGN.md §6)."""

    t_start: float
    t_end: float
    target: float
    dist: float
    band: float
    e: int
    over: float = -math.inf
    last_out: int = -1
    t_after: float = math.nan
    need_after: bool = False
    t_last: float = math.nan


def stream_metrics(path: str | os.PathLike, *, glitch_window: float = 0.2,
                   settle_tolerance: float = 0.02, settle_band: float | None = None,
                   min_dwell: float = 0.01, chatter_cutoff: float = 100.0,
                   zero_tol: float = 1e-6, progress: bool = False, namespace: str = 'axis',
                   spill_dir: str | None = None, topics: RunTopics | None = None
                   ) -> RunMetrics:
    """Metrics of an MCAP run, streamed (see the module docstring).

    Same parameters, result and errors as
    ``compute_metrics(read_run(path, signals=…, require={'reference': …}), …)``.
    """
    from motor_comp.analysis.metrics import compute_metrics
    check_positive('glitch_window', glitch_window)     # before reading, not after
    check_positive('chatter_cutoff', chatter_cutoff)
    src = open_stream(path, progress=progress, namespace=namespace,
                      signals=('reference', 'reference_velocity', 'voltage'),
                      require={'reference': 'the tracking error is reference − position'},
                      spill_dir=spill_dir, topics=topics)
    kw = dict(glitch_window=glitch_window, settle_tolerance=settle_tolerance,
              settle_band=settle_band, min_dwell=min_dwell, chatter_cutoff=chatter_cutoff,
              zero_tol=zero_tol)
    if isinstance(src, Run):
        return compute_metrics(src, **kw)
    with src:
        return metrics_of_stream(src, **kw)


def metrics_of_stream(stream: RunStream, *, glitch_window: float = 0.2,
                      settle_tolerance: float = 0.02, settle_band: float | None = None,
                      min_dwell: float = 0.01, chatter_cutoff: float = 100.0,
                      zero_tol: float = 1e-6) -> RunMetrics:
    """:func:`~motor_comp.analysis.metrics.compute_metrics` of a :class:`RunStream`."""
    window = check_positive('glitch_window', glitch_window)
    check_positive('chatter_cutoff', chatter_cutoff)
    if not 0 < settle_tolerance < 1:
        raise ParameterError(f'settle_tolerance must be in (0, 1), got {settle_tolerance}')
    if not stream.has('reference'):
        raise InputFileError(f'{stream.name}: missing reference')
    n = stream.samples
    if n < 2:
        raise InputFileError(f'{stream.name}: only {n} sample(s); need at least 2')
    logged_v = stream.has('reference_velocity')
    has_u = stream.has('voltage')

    # pass 1: finiteness, max |v_ref|, step extremes, t range
    vmax = 0.0
    dmin, dmax = math.inf, -math.inf
    t_first = t_last = math.nan
    u_finite = True
    for b, v in _with_velocity(stream, logged_v):
        t = b['t']
        e = b['reference'] - b['position']
        if not (np.all(np.isfinite(e)) and np.all(np.isfinite(t))):
            raise InputFileError(f'{stream.name}: error or time has NaN/Inf samples')
        if has_u and not np.all(np.isfinite(b['voltage'])):
            u_finite = False
        if v.size:
            vmax = max(vmax, float(np.max(np.abs(v))))
        if math.isnan(t_first):
            t_first = float(t[0])
        else:
            d0 = float(t[0]) - t_last
            dmin, dmax = min(dmin, d0), max(dmax, d0)
        if t.size > 1:
            d = np.diff(t)
            dmin, dmax = min(dmin, float(d.min())), max(dmax, float(d.max()))
        t_last = float(t[-1])
    if not np.isfinite(vmax):
        vmax = 0.0                    # reversals(): no reversal with a non-finite max
    thr = zero_tol * vmax
    has_u = has_u and u_finite

    # pass 2: sums, reversals, glitches, segments, moves, voltage spill
    tot, tot_u = _Sums(), _Sums()
    seg = _Sums()
    seg_t0 = t_first
    segs = [array('d') for _ in range(5)]       # t_start, edge, rms, max, count
    glitches = [array('d'), array('d'), array('d'), array('b')]
    open_w: list[_Window] = []
    carry: dict[str, float] | None = None        # sample g0−1 (not yet accumulated)
    t_before = math.nan                           # t of sample g0−2
    last_nz_i, last_nz_s = -1, 0.0
    g0 = 0
    moves: list[Move] = []
    mv = _MoveState(zero_thr=thr, vmax=vmax, settle_tolerance=settle_tolerance,
                    settle_band=settle_band, min_dwell=min_dwell, moves=moves)
    chat_spill = _ChatterSpill(stream, has_u)
    for b, v in _with_velocity(stream, logged_v):
        t, x, r = b['t'], b['position'], b['reference']
        e = r - x
        u = b['voltage'] if has_u else None
        m = t.size
        final = g0 + m == n
        # --- reversals (reference.reversals, carried across blocks)
        s = np.where(np.abs(v) > thr, np.sign(v), 0.0) if vmax > 0 else np.zeros(m)
        nz = np.flatnonzero(s)
        found_t: list[float] = []
        found_k: list[int] = []
        if nz.size:
            gi = np.concatenate(([last_nz_i], g0 + nz)) if last_nz_i >= 0 else g0 + nz
            sg = np.concatenate(([last_nz_s], s[nz])) if last_nz_i >= 0 else s[nz]
            ch = np.flatnonzero(sg[1:] != sg[:-1])
            for c in ch:
                k, prev = int(gi[c + 1]), int(gi[c])
                j = k - 1
                tk, vk = float(t[k - g0]), float(v[k - g0])
                if j >= g0:
                    tj, vj = float(t[j - g0]), float(v[j - g0])
                else:
                    tj, vj = carry['t'], carry['v']          # type: ignore[index]
                frac = (np.float64(vj) / (np.float64(vj) - np.float64(vk))
                        if j == prev else 0.0)
                tr = float(np.float64(tj) + frac * (np.float64(tk) - np.float64(tj)))
                found_t.append(tr)
                found_k.append(int(sg[c + 1]))
            last_nz_i, last_nz_s = int(g0 + nz[-1]), float(s[nz[-1]])
        # extended arrays: the carried sample g0−1, then this block
        if carry is not None:
            te = np.concatenate(([carry['t']], t))
            ee = np.concatenate(([carry['e']], e))
            ue = np.concatenate(([carry['u']], u)) if u is not None else None
            base = g0 - 1
        else:
            te, ee, ue, base = t, e, u, g0
        # --- glitch windows: every window scans the extended samples in [tr, tr + W]
        for tr, d in zip(found_t, found_k):
            open_w.append(_Window(tr, tr + window, d))
        still = []
        for w in open_w:
            a = int(np.searchsorted(te, w.t, side='left'))
            z = int(np.searchsorted(te, w.end, side='right'))
            if z > a:
                i = a + int(np.argmax(np.abs(ee[a:z])))
                mag = float(abs(ee[i]))
                if mag > w.mag:
                    w.mag, w.t_peak = mag, float(te[i])
            if final or w.end >= te[-1]:
                if not final:
                    still.append(w)
                    continue
            if w.mag >= 0:
                for col, value in zip(glitches, (w.t, w.mag, w.t_peak, w.direction)):
                    col.append(value)
        open_w = still
        # --- weights (midpoint rule) of the samples accumulated now: the carried one
        #     and this block but its last (whose right neighbour is in the next block)
        upto = te.size if final else te.size - 1
        if upto > 0:
            # w_i = (d_{i−1} + d_i)/2, w_0 = d_0/2, w_{n−1} = d_{n−2}/2 (metrics._weights)
            dd = np.diff(np.concatenate(([t_before if base > 0 else math.nan], te)))
            dprev = dd[:upto]
            dnext = np.concatenate((dd[1:upto + 1], [math.nan] * (upto + 1 - dd.size)))
            wts = (dprev + dnext) / 2
            if base == 0:
                wts[0] = dnext[0] / 2
            if final:
                wts[-1] = dprev[-1] / 2
            xe = ee[:upto]
            tot.add(xe, wts)
            if ue is not None:
                tot_u.add(ue[:upto], wts)
            # --- segments: boundaries at searchsorted(t, tr, 'left') of each reversal
            bounds = [int(np.searchsorted(te, tr, side='left')) for tr in found_t]
            edges_t = list(found_t)
            a = 0
            for bnd, et in zip(bounds, edges_t):
                bnd = min(bnd, upto)
                seg.add(xe[a:bnd], wts[a:bnd])
                for col, value in zip(segs, (seg_t0, et, *_seg_close(seg))):
                    col.append(value)
                seg = _Sums()
                seg_t0 = et
                a = bnd
            seg.add(xe[a:upto], wts[a:upto])
            t_before = float(te[upto - 1])
        if final:
            for col, value in zip(segs, (seg_t0, float(te[-1]) + 1e-12, *_seg_close(seg))):
                col.append(value)
        # --- moves (no look-ahead needed)
        mv.feed(t, x, r, v, g0, final)
        # --- chattering input
        chat_spill.feed(t, u, final)
        if not final:
            carry = {'t': float(t[-1]), 'e': float(e[-1]), 'v': float(v[-1]),
                     'u': float(u[-1]) if u is not None else 0.0}
        g0 += m

    keep = np.frombuffer(segs[4], float) > 0
    t0s, edge, srms, smax = (np.frombuffer(c, float)[keep] for c in segs[:4])
    segments = Records(_segment, (t0s, np.minimum(edge, t_last), srms, smax))
    found = Records(_glitch, [np.frombuffer(c, float) for c in glitches[:3]]
                    + [np.frombuffer(glitches[3], np.int8)])
    mags = found._cols[1]
    if has_u:
        rms_u = tot_u.rms()
        chat = chat_spill.chattering(chatter_cutoff, dmin, dmax)
        ratio = (chat / rms_u) if (chat is not None and rms_u > 0) else None
        umax: float | None = tot_u.max
    else:
        rms_u = umax = chat = ratio = None
    chat_spill.close()
    return RunMetrics(
        name=stream.name, samples=n, duration=float(t_last - t_first),
        rms_error=tot.rms(), max_error=tot.max, mean_error=tot.wx / tot.w,
        glitch_window=window, glitches=found,     # type: ignore[arg-type]
        max_glitch=float(mags.max()) if mags.size else None,
        mean_glitch=float(mags.mean()) if mags.size else None,
        segments=segments, moves=tuple(moves),   # type: ignore[arg-type]
        rms_voltage=rms_u, max_voltage=umax, chattering=chat, chattering_ratio=ratio,
        chatter_cutoff=float(chatter_cutoff))


def _seg_close(s: _Sums) -> tuple[float, float, int]:
    if s.w <= 0:
        return math.nan, math.nan, 0
    return s.rms(), s.max, 1


def _with_velocity(stream: RunStream, logged: bool
                   ) -> Iterator[tuple[dict[str, np.ndarray], np.ndarray]]:
    """Blocks with the reference velocity: logged, or ``np.gradient(reference, t)``."""
    if logged:
        for b in stream.blocks():
            yield b, b['reference_velocity']
        return
    # np.gradient (edge_order 1) needs one neighbour each side: one block of delay
    prev: dict[str, np.ndarray] | None = None
    tail: tuple[float, float] | None = None      # (t, r) of the sample before prev
    for b in stream.blocks():
        if prev is not None:
            yield prev, _gradient(prev, tail, (float(b['t'][0]), float(b['reference'][0])))
            tail = (float(prev['t'][-1]), float(prev['reference'][-1]))
        prev = b
    if prev is not None:
        yield prev, _gradient(prev, tail, None)


def _gradient(b: dict[str, np.ndarray], before: tuple[float, float] | None,
              after: tuple[float, float] | None) -> np.ndarray:
    t, r = b['t'], b['reference']
    tt = np.concatenate(([before[0]] if before else [], t, [after[0]] if after else []))
    rr = np.concatenate(([before[1]] if before else [], r, [after[1]] if after else []))
    if tt.size < 2:
        return np.zeros_like(t)
    g = np.gradient(rr, tt)
    return g[(1 if before else 0):(g.size - 1 if after else g.size)]


class _MoveState:
    """Point-to-point moves (``metrics._moves``) from blocks, as a state machine."""

    def __init__(self, *, zero_thr: float, vmax: float, settle_tolerance: float,
                 settle_band: float | None, min_dwell: float, moves: list[Move]) -> None:
        self.thr = zero_thr
        self.tol = settle_tolerance
        self.band = settle_band
        self.min_dwell = min_dwell
        self.moves = moves
        self.prev_moving: bool | None = None
        self.prev_r = math.nan
        self.start: tuple[int, float, float] | None = None    # (s, t_s, origin)
        self.dwell: _Dwell | None = None
        self.active = vmax > 0             # metrics._moves: no moves without motion

    def feed(self, t: np.ndarray, x: np.ndarray, r: np.ndarray, v: np.ndarray, g0: int,
             final: bool) -> None:
        if not self.active:
            return
        moving = np.abs(v) > self.thr
        prev = moving[0] if self.prev_moving is None else self.prev_moving
        change = np.flatnonzero(np.concatenate(([prev], moving[:-1])) != moving)
        if self.prev_moving is None and moving[0]:
            self._start(0, t, r, 0, g0)
        a = 0
        for c in change:
            c = int(c)
            self._dwell_scan(t, x, a, c, g0)
            a = c
            if moving[c]:                          # a start: closes the dwell
                self._finish()
                self._start(c, t, r, c, g0)
            elif self.start is not None:           # an end: first resting sample
                s, ts, origin = self.start
                self.start = None
                target = float(r[c])
                dist = target - origin
                if dist != 0.0:
                    band = self.band if self.band is not None else self.tol * abs(dist)
                    self.dwell = _Dwell(t_start=ts, t_end=float(t[c]), target=target,
                                        dist=dist, band=float(band), e=g0 + c)
        self._dwell_scan(t, x, a, t.size, g0)
        self.prev_moving = bool(moving[-1])
        self.prev_r = float(r[-1])
        if final:
            self._finish()

    def _start(self, c: int, t: np.ndarray, r: np.ndarray, _i: int, g0: int) -> None:
        g = g0 + c
        origin = float(r[c - 1]) if c > 0 else (self.prev_r if g > 0 else float(r[c]))
        self.start = (g, float(t[c]), origin)

    def _dwell_scan(self, t: np.ndarray, x: np.ndarray, a: int, z: int, g0: int) -> None:
        d = self.dwell
        if d is None or z <= a:
            return
        if d.need_after:
            d.t_after, d.need_after = float(t[a]), False
        dev = x[a:z] - d.target
        d.over = max(d.over, float(np.max(dev * np.sign(d.dist))))
        out = np.flatnonzero(np.abs(dev) > d.band)
        if out.size:
            i = int(out[-1])
            d.last_out = g0 + a + i
            if a + i + 1 < z:
                d.t_after = float(t[a + i + 1])
            else:
                d.need_after = True
        d.t_last = float(t[z - 1])
        d.stop = g0 + z                           # type: ignore[attr-defined]

    def _finish(self) -> None:
        d, self.dwell = self.dwell, None
        if d is None:
            return
        if d.t_last - d.t_end < self.min_dwell:
            return
        over = max(0.0, d.over)
        if d.last_out < 0:
            ts: float | None = 0.0
        elif d.last_out == d.stop - 1:             # type: ignore[attr-defined]
            ts = None
        else:
            ts = float(d.t_after - d.t_end)
        self.moves.append(Move(t_start=d.t_start, t_end=d.t_end, distance=d.dist,
                               overshoot=over, overshoot_ratio=over / abs(d.dist),
                               settling_time=ts, band=d.band))


class _ChatterSpill:
    """The voltage for the chattering spectrum, spilled to a file (uniform or raw)."""

    def __init__(self, stream: RunStream, enabled: bool) -> None:
        self.stream = stream
        self.enabled = enabled
        self.path = Path(stream._spill) / 'voltage.f8'
        self._f = open(self.path, 'wb') if enabled else None
        self.n = 0

    def feed(self, t: np.ndarray, u: np.ndarray | None, final: bool) -> None:
        if self._f is not None and u is not None:
            self._f.write(np.ascontiguousarray(u, float).tobytes())
            self.n += u.size

    def close(self) -> None:
        if self._f is not None:
            self._f.close()
            self._f = None

    def chattering(self, cutoff: float, dmin: float, dmax: float) -> float | None:
        """``metrics.chattering`` of the spilled voltage."""
        self.close()
        if self.n < 4:
            return None
        dt = _median_step(self.stream)
        if not dt > 0 or cutoff >= 0.5 / dt:
            return None
        src = self.path
        if dmax > 1.01 * dmin:
            src = self._resample(dt)
        return _blocked_chatter(src, cutoff, dt)

    def _resample(self, dt: float) -> Path:
        """``np.interp`` of the voltage onto ``t0 + dt·k`` (irregular stamps), spilled."""
        out = Path(self.stream._spill) / 'voltage_uniform.f8'
        t0 = t_end = math.nan
        for b in self.stream.blocks(only_t=True):
            t0 = float(b['t'][0]) if math.isnan(t0) else t0
            t_end = float(b['t'][-1])
        count = int((t_end - t0) / dt) + 1
        k = 0
        tt = uu = np.empty(0)
        with open(out, 'wb') as f, open(self.path, 'rb') as fu:
            for b in self.stream.blocks(only_t=True):
                t = b['t']
                u = np.fromfile(fu, float, t.size)
                # the previous sample brackets the first grid points of this block
                tt, uu = np.concatenate((tt[-1:], t)), np.concatenate((uu[-1:], u))
                k = self._emit(f, tt, uu, t0, dt, k, count, float(t[-1]))
            self._emit(f, tt, uu, t0, dt, k, count, math.inf)   # past the end: last value
        return out

    @staticmethod
    def _emit(f: Any, tt: np.ndarray, uu: np.ndarray, t0: float, dt: float, k: int,
              count: int, upto: float) -> int:
        while k < count:
            g = t0 + dt * np.arange(k, min(count, k + BLOCK))
            g = g[g <= upto]
            if not g.size:
                break
            f.write(np.interp(g, tt, uu).tobytes())
            k += g.size
        return k


def _blocked_chatter(path: Path, cutoff: float, dt: float) -> float:
    """RMS above ``cutoff`` of the samples in ``path`` (``metrics.chattering``, out of core).

    ``chat = sqrt(Σ_{f_k ≥ cutoff} c_k |Y_k|²) / N`` with ``Y`` the DFT of ``u − mean(u)``
    and ``c_k`` the one-sided weights.  Bluestein: ``Y_k = conj(w_k)·(a ⊛ h)_k`` with
    ``w_j = e^{iπj²/N}``, ``a_j = y_j·conj(w_j)``, ``h_d = w_d`` — so
    ``|Y_k| = |(a ⊛ h)_k|`` — and the convolution is done with FFTs of a power-of-two
    length ``M ≥ N + N/2`` that live in files (:func:`_ooc_fft`).  Chirp phases are
    reduced modulo 2N in integers, so the round-off is that of an FFT, as in numpy's.
    """
    n = path.stat().st_size // 8
    total = 0.0
    with open(path, 'rb') as f:
        for _ in range(0, n, BLOCK):
            total += math.fsum(np.fromfile(f, float, BLOCK))
    mean = total / n
    # bins: rfftfreq(n, dt) = k·val; the high band starts at the first k with k·val ≥ cutoff
    val = 1.0 / (n * dt)
    nb = n // 2 + 1
    k_hi = min(nb, max(0, int(cutoff / val) - 2))
    while k_hi < nb and not (k_hi * val >= cutoff):
        k_hi += 1
    if k_hi >= nb:
        return 0.0
    big = 1 << int(math.ceil(math.log2(n + nb)))
    two_n = 2 * n
    a_path, h_path = path.with_suffix('.a'), path.with_suffix('.h')
    with open(path, 'rb') as f, open(a_path, 'wb') as fa:
        for j0 in range(0, big, BLOCK):
            j = np.arange(j0, min(big, j0 + BLOCK), dtype=np.int64)
            y = np.fromfile(f, float, BLOCK) if j0 < n else np.empty(0)
            a = np.zeros(j.size, complex)
            a[:y.size] = (y - mean) * np.exp(-1j * np.pi * ((j[:y.size] ** 2) % two_n) / n)
            fa.write(a.tobytes())
    with open(h_path, 'wb') as fh:
        for i0 in range(0, big, BLOCK):
            i = np.arange(i0, min(big, i0 + BLOCK), dtype=np.int64)
            d = np.where(i < nb, i, i - big)           # lags −(n−1) … nb−1, circularly
            used = (i < nb) | (i >= big - (n - 1))
            h = np.where(used, np.exp(1j * np.pi * ((d * d) % two_n) / n), 0.0)
            fh.write(h.astype(complex).tobytes())
    _ooc_fft(a_path, big, inverse=False)
    _ooc_fft(h_path, big, inverse=False)
    with open(a_path, 'r+b') as fa, open(h_path, 'rb') as fh:
        for i0 in range(0, big, BLOCK):
            x = np.fromfile(fh, complex, BLOCK)
            fa.seek(i0 * 16)
            prod = np.fromfile(fa, complex, x.size) * x
            fa.seek(i0 * 16)
            fa.write(prod.tobytes())
    h_path.unlink()
    _ooc_fft(a_path, big, inverse=True)              # unnormalised: divide by M below
    energy = 0.0
    with open(a_path, 'rb') as fa:
        fa.seek(k_hi * 16)
        for k0 in range(k_hi, nb, BLOCK):
            z = np.fromfile(fa, complex, min(BLOCK, nb - k0))
            k = k0 + np.arange(z.size)
            c = np.where((k == 0) | ((n % 2 == 0) & (k == n // 2)), 1.0, 2.0)
            energy += math.fsum(c * (z.real ** 2 + z.imag ** 2))
    a_path.unlink()
    return float(np.sqrt(energy) / big / n)


def _ooc_fft(path: Path, size: int, *, inverse: bool) -> None:
    """In-place FFT of ``size`` (a power of two) complex128 values in ``path`` (four-step).

    The file is a ``M1 × M2`` row-major matrix (``M2`` ≤ :data:`FFT_ROW`).  Forward:
    FFTs down the columns in panels, twiddles ``e^{−2πi n2 k1/M}``, FFTs along the
    rows: the file then holds ``X[k1 + M1·k2]`` at row ``k1``, column ``k2``
    (transposed order).  ``inverse=True`` takes that order back to natural order with
    the conjugate steps in reverse, unnormalised.  Working set: one panel or one row.
    """
    m2 = min(size, FFT_ROW)
    m1 = size // m2
    width = max(1, FFT_ROW // m1)                       # columns per panel
    sign = 1.0 if inverse else -1.0
    fd = os.open(path, os.O_RDWR)
    try:
        def rows() -> None:
            for r in range(m1):
                x = np.frombuffer(os.pread(fd, m2 * 16, r * m2 * 16), complex)
                if inverse:
                    x = np.fft.ifft(x, norm='forward')
                    x = x * np.exp(sign * 2j * np.pi * ((np.arange(m2) * r) % size) / size)
                else:
                    x = np.fft.fft(x)
                os.pwrite(fd, x.tobytes(), r * m2 * 16)

        def columns() -> None:
            if m1 == 1:
                return
            k1 = np.arange(m1, dtype=np.int64)[:, None]
            for c0 in range(0, m2, width):
                w = min(width, m2 - c0)
                panel = np.empty((m1, w), complex)
                for r in range(m1):
                    panel[r] = np.frombuffer(os.pread(fd, w * 16, (r * m2 + c0) * 16), complex)
                if inverse:
                    panel = np.fft.ifft(panel, axis=0, norm='forward')
                else:
                    panel = np.fft.fft(panel, axis=0)
                    n2 = np.arange(c0, c0 + w, dtype=np.int64)[None, :]
                    panel *= np.exp(sign * 2j * np.pi * ((k1 * n2) % size) / size)
                for r in range(m1):
                    os.pwrite(fd, panel[r].tobytes(), (r * m2 + c0) * 16)

        if inverse:
            rows()
            columns()
        else:
            columns()
            rows()
    finally:
        os.close(fd)
