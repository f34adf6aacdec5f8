"""Parameter sweeps: a grid of closed-loop simulations run in parallel, locally or on Dask.

A sweep is a base scenario (plant, controller, feedforward, duration, settings — see
:mod:`motor_comp.control.scenario`) and a grid ``{name: [v1, v2, …]}``; every point of
the Cartesian product is one :class:`~motor_comp.control.scenario.Scenario`.  Points are
independent; they are grouped into *batches* (many short simulations per task, so task
overhead does not dominate) and the batches run on

* a local :class:`concurrent.futures.ProcessPoolExecutor` (default), or any
  ``concurrent.futures``-style executor (``submit(fn, *args)`` → future);
* a Dask cluster: a ``distributed.Client`` (see :func:`dask_client` and
  ``docs/sweep.md``).

Results stream back as batches finish (:func:`iter_sweep`); at most ``max_pending``
batches are submitted and unfinished at any time (backpressure: a 100 000-point grid
never holds 100 000 futures).  A point that raises is returned as a :class:`PointResult`
with its ``error`` set; the others complete.  On Dask, a batch whose worker dies is
recomputed by the scheduler on another worker, and each point is yielded exactly once
(the batch's results arrive once, through its future).

The worker function :func:`run_batch` is a plain module-level function taking plain data
(settings dicts and a picklable metrics callable), so it pickles to remote workers; each
worker needs ``motor_comp`` installed.
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
import itertools
import math
import os
import time
import uuid
from typing import Any, Callable, Iterable, Iterator, Mapping, Sequence

import numpy as np

from motor_comp.control.scenario import Scenario
from motor_comp.control.simulator import SimResult
from motor_comp.errors import MotorCompError, ParameterError

#: metrics callable: SimResult → {name: number}
Metrics = Callable[[SimResult], Mapping[str, Any]]


def basic_metrics(result: SimResult) -> dict[str, float]:
    """RMS and max tracking error [m] (the CLI passes the full analysis metrics instead)."""
    e = result.error
    return {'rms_error': float(np.sqrt(np.mean(e * e))),
            'max_error': float(np.max(np.abs(e)))}


def _check_grid(grid: Mapping[str, Sequence[Any]]) -> None:
    for n in grid:
        if not isinstance(grid[n], (list, tuple)) or not grid[n]:
            raise ParameterError(f'grid {n}: needs a non-empty list of values')


def grid_size(grid: Mapping[str, Sequence[Any]]) -> int:
    """Return the number of points of the grid (product of the value counts)."""
    _check_grid(grid)
    return math.prod(len(v) for v in grid.values())


def iter_grid(base: Mapping[str, Any], grid: Mapping[str, Sequence[Any]]
              ) -> Iterator[dict[str, Any]]:
    """Every combination of the grid values on top of ``base``, lazily (last name fastest)."""
    _check_grid(grid)
    names = list(grid)
    for combo in itertools.product(*(grid[n] for n in names)):
        p = dict(base)
        p.update(zip(names, combo))
        yield p


def expand_grid(base: Mapping[str, Any], grid: Mapping[str, Sequence[Any]]) -> list[dict]:
    """Every combination of the grid values on top of ``base`` (last name varies fastest)."""
    return list(iter_grid(base, grid))


@dataclasses.dataclass(frozen=True)
class PointResult:
    """One grid point: its settings, metrics and the time it took.

    Attributes
    ----------
    point : Mapping
        The settings of the point.
    metrics : Mapping
        Metric name → value (empty if the point failed).
    wall_s : float
        Wall time of the simulation and metrics [s].
    error : str or None
        ``"<ExceptionType>: <message>"`` if the point raised, else None.
    index : int
        Position of the point in the grid (0-based).
    """

    point: Mapping[str, Any]
    metrics: Mapping[str, Any]
    wall_s: float
    error: str | None = None
    index: int = 0

    @property
    def ok(self) -> bool:
        """True if the point ran without error."""
        return self.error is None


def _label(point: Mapping[str, Any]) -> str:
    return ', '.join(f'{k}={v}' for k, v in point.items())


def run_point(point: Mapping[str, Any], metrics: Metrics = basic_metrics, *,
              index: int = 0) -> PointResult:
    """Simulate one grid point; an exception becomes the result's ``error``."""
    t0 = time.perf_counter()
    try:
        result, _ = Scenario.from_mapping(point).run()
        values = dict(metrics(result))
    except Exception as exc:  # noqa: BLE001 - reported per point; the sweep goes on
        return PointResult(point=dict(point), metrics={}, wall_s=time.perf_counter() - t0,
                           error=f'{type(exc).__name__}: {exc}', index=index)
    return PointResult(point=dict(point), metrics=values, wall_s=time.perf_counter() - t0,
                       index=index)


def run_batch(batch: Sequence[tuple[int, Mapping[str, Any]]],
              metrics: Metrics = basic_metrics) -> list[PointResult]:
    """Simulate a batch of ``(index, point)`` pairs one after the other (one task)."""
    return [run_point(p, metrics, index=i) for i, p in batch]


def validate_points(points: Iterable[Mapping[str, Any]]) -> None:
    """Build every scenario once in the caller, so a bad value fails before any work."""
    for p in points:
        try:
            Scenario.from_mapping(p).build()
        except ParameterError as exc:
            raise ParameterError(f'sweep point ({_label(p)}): {exc}') from None


def validate_grid(base: Mapping[str, Any], grid: Mapping[str, Sequence[Any]]) -> None:
    """Check every grid value once, on top of ``base`` and the first value of the others.

    ``sum(len(values))`` scenario builds instead of one per point, so a bad value of a
    100 000-point grid is reported at once; a failure that only a combination of values
    provokes is reported per point by the sweep.
    """
    _check_grid(grid)
    first = {n: v[0] for n, v in grid.items()}
    seen: set[tuple[str, str]] = set()
    for n, values in grid.items():
        for v in values:
            if (n, repr(v)) in seen:
                continue
            seen.add((n, repr(v)))
            validate_points([{**base, **first, n: v}])


def default_batch_size(total: int, workers: int) -> int:
    """Points per task: about 8 tasks per worker (load balance), at most 64 points."""
    return max(1, min(64, math.ceil(total / (8 * max(1, workers)))))


def _is_dask(executor: Any) -> bool:
    return type(executor).__module__.startswith('distributed') and \
        hasattr(executor, 'scheduler_info')


def _batches(points: Iterable[Mapping[str, Any]], size: int
             ) -> Iterator[list[tuple[int, dict[str, Any]]]]:
    it = enumerate(dict(p) for p in points)
    while True:
        chunk = list(itertools.islice(it, size))
        if not chunk:
            return
        yield chunk


class _Window:
    """Submit batches keeping at most ``limit`` unfinished; yield finished futures."""

    def __init__(self, executor: Any, metrics: Metrics, limit: int) -> None:
        self.executor = executor
        self.metrics = metrics
        self.limit = max(1, limit)
        self.dask = _is_dask(executor)
        self.tag = uuid.uuid4().hex[:12]
        self.batch_of: dict[Any, list[tuple[int, dict[str, Any]]]] = {}
        self.peak = 0                       # most futures alive at once (tests, bench)
        if self.dask:
            import distributed
            self._ac = distributed.as_completed()

    def submit(self, batch: list[tuple[int, dict[str, Any]]]) -> None:
        if self.dask:
            # own key: identical batches of two sweeps must not share a result; no
            # retries needed for lost workers (the scheduler recomputes those tasks)
            f = self.executor.submit(run_batch, batch, self.metrics, pure=False,
                                     key=f'motor-comp-sweep-{self.tag}-{batch[0][0]}')
            self._ac.add(f)
        else:
            f = self.executor.submit(run_batch, batch, self.metrics)
        self.batch_of[f] = batch
        self.peak = max(self.peak, len(self.batch_of))

    def __len__(self) -> int:
        return len(self.batch_of)

    def next_done(self) -> tuple[Any, list[tuple[int, dict[str, Any]]]]:
        if self.dask:
            f = next(self._ac)
        else:
            done, _ = concurrent.futures.wait(list(self.batch_of),
                                              return_when=concurrent.futures.FIRST_COMPLETED)
            f = next(iter(done))
        return f, self.batch_of.pop(f)


def _failed_batch(batch: Sequence[tuple[int, Mapping[str, Any]]], exc: BaseException
                  ) -> list[PointResult]:
    why = f'{type(exc).__name__}: {exc}'.strip().rstrip(':')
    return [PointResult(point=dict(p), metrics={}, wall_s=0.0, error=f'task failed ({why})',
                        index=i) for i, p in batch]


@dataclasses.dataclass
class SweepStats:
    """Counters of a running sweep (mutable: updated as tasks finish)."""

    tasks: int = 0
    peak_pending: int = 0


def iter_sweep(points: Iterable[Mapping[str, Any]], *, executor: Any,
               metrics: Metrics = basic_metrics, batch_size: int = 1,
               max_pending: int = 8, stats: SweepStats | None = None
               ) -> Iterator[PointResult]:
    """Yield the result of every point as its batch finishes (completion order).

    Parameters
    ----------
    points : iterable of mappings
        Consumed lazily: only ``max_pending`` batches are materialised at a time.
    executor : Executor-like or ``distributed.Client``
        ``submit(fn, *args)`` returning futures with ``result()``.
    metrics : callable
        ``SimResult → {name: number}``; must be picklable (module-level or a class
        instance).
    batch_size : int
        Points per task.
    max_pending : int
        Most batches submitted and not yet finished at once (backpressure).
    stats : SweepStats, optional
        Filled in as tasks finish (task count, most futures alive at once).
    """
    if batch_size < 1 or max_pending < 1:
        raise ParameterError('batch_size and max_pending must be >= 1')
    window = _Window(executor, metrics, max_pending)
    source = _batches(points, batch_size)
    exhausted = False
    while True:
        while not exhausted and len(window) < window.limit:
            batch = next(source, None)
            if batch is None:
                exhausted = True
            else:
                window.submit(batch)
        if not len(window):
            return
        f, batch = window.next_done()
        try:
            results = f.result()
        except Exception as exc:  # noqa: BLE001 - the task itself failed: report its points
            results = _failed_batch(batch, exc)
        finally:
            if window.dask:
                f.release()
        if stats is not None:
            stats.tasks += 1
            stats.peak_pending = max(stats.peak_pending, window.peak)
        yield from results


def run_sweep(points: Iterable[Mapping[str, Any]], *, executor: Any | None = None,
              max_workers: int | None = None, metrics: Metrics = basic_metrics,
              progress: Callable[[int, int], None] | None = None,
              batch_size: int | None = None, max_pending: int | None = None,
              validate: bool = True, stats: SweepStats | None = None
              ) -> list[PointResult]:
    """Run every point, in parallel, and return the results in the order of ``points``.

    Parameters
    ----------
    points : iterable of mappings
        Grid points (see :func:`expand_grid`).
    executor : Executor-like or ``distributed.Client``, optional
        Default: a local ``ProcessPoolExecutor`` with ``max_workers`` processes
        (default: all cores, at most the number of batches).
    max_workers : int, optional
        Local processes, or the worker count used to size batches for ``executor``.
    metrics : callable
        ``SimResult → {name: number}``; must be picklable (module-level function).
    progress : callable, optional
        Called with (done, total) as points finish.
    batch_size : int, optional
        Points per task (default :func:`default_batch_size`).
    max_pending : int, optional
        Most unfinished tasks at once (default 2 per worker + 2).
    validate : bool
        Build every scenario first, so a bad value fails before any work.
    stats : SweepStats, optional
        Filled in as tasks finish.

    Returns
    -------
    list of PointResult
        One per point, in grid order; failed points have ``error`` set.
    """
    points = [dict(p) for p in points]
    if not points:
        return []
    if validate:
        validate_points(points)
    workers = max_workers or _workers_of(executor) or os.cpu_count() or 1
    size = batch_size or default_batch_size(len(points), workers)
    own = executor is None
    if own:
        executor = concurrent.futures.ProcessPoolExecutor(
            max_workers=min(workers, math.ceil(len(points) / size)))
    results: list[PointResult | None] = [None] * len(points)
    try:
        done = 0
        for r in iter_sweep(points, executor=executor, metrics=metrics, batch_size=size,
                            max_pending=max_pending or 2 * workers + 2, stats=stats):
            results[r.index] = r
            done += 1
            if progress is not None:
                progress(done, len(points))
    finally:
        if own:
            executor.shutdown()
    return [r for r in results if r is not None]


def _workers_of(executor: Any) -> int | None:
    """Worker count of a Dask client or a local pool (None if unknown)."""
    if executor is None:
        return None
    if _is_dask(executor):
        try:
            return max(1, len(executor.scheduler_info().get('workers', {})))
        except Exception:  # noqa: BLE001 - only used to size batches
            return None
    return getattr(executor, '_max_workers', None)


class SchedulerError(MotorCompError):
    """The Dask scheduler cannot be used (``distributed`` missing, unreachable, bad spec)."""


def dask_client(spec: str, *, timeout: float = 30.0) -> Any:
    """Connect to ``tcp://HOST:PORT`` (any Dask address) or start ``local:N``; return a Client.

    ``local:N`` starts a :class:`distributed.LocalCluster` of N single-threaded worker
    processes listening on loopback only (``127.0.0.1``), without dashboard; it is closed
    with the client (``client.close()`` then ``client.cluster.close()``, or use
    :func:`close_client`).

    Raises
    ------
    SchedulerError
        ``distributed`` is not installed, the spec is malformed or the scheduler does
        not answer within ``timeout`` [s].
    """
    try:
        import distributed
    except ImportError:
        raise SchedulerError("--scheduler needs Dask's 'distributed' package: "
                             "pip install 'motor_comp[cluster]' "
                             "(or pip install distributed)") from None
    import logging
    spec = spec.strip()
    if spec.startswith('local'):
        _, sep, n = spec.partition(':')
        try:
            workers = int(n) if sep else (os.cpu_count() or 1)
        except ValueError:
            workers = 0
        if workers < 1 or workers > 256:
            raise SchedulerError(f'--scheduler {spec!r}: expected local:N with N in 1..256')
        cluster = distributed.LocalCluster(
            n_workers=workers, threads_per_worker=1, processes=True, host='127.0.0.1',
            dashboard_address=None, silence_logs=logging.ERROR)
        return distributed.Client(cluster, timeout=timeout)
    if '://' not in spec and ':' not in spec:
        raise SchedulerError(f'--scheduler {spec!r}: expected tcp://HOST:PORT or local:N')
    try:
        return distributed.Client(spec, timeout=timeout)
    except (OSError, TimeoutError, ValueError) as exc:
        why = str(exc).splitlines()[0] if str(exc) else type(exc).__name__
        raise SchedulerError(f'--scheduler {spec}: cannot connect to the Dask scheduler '
                             f'({why})') from None


def close_client(client: Any) -> None:
    """Close a client from :func:`dask_client`, and its LocalCluster if it started one."""
    cluster = getattr(client, 'cluster', None)
    client.close()
    if cluster is not None:
        cluster.close()


def table(results: Sequence[PointResult], *,
          keys: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    """Header and rows of the points that ran: varied settings, metrics ``keys``, wall time."""
    results = [r for r in results if r.ok]
    if not results:
        return [], []
    varied = [k for k in results[0].point
              if len({repr(r.point.get(k)) for r in results}) > 1]
    header = varied + list(keys) + ['wall_s']
    rows = []
    for r in results:
        rows.append([r.point.get(k) for k in varied] +
                    [r.metrics.get(k, math.nan) for k in keys] + [r.wall_s])
    return header, rows
