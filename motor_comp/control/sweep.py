"""Parameter sweeps: a grid of closed-loop simulations run in parallel.

A sweep is a base scenario (plant, controller, feedforward, duration, settings — see
:mod:`motor_comp.control.scenario`) and a grid ``{name: [v1, v2, …]}``; every point of
the Cartesian product is one :class:`~motor_comp.control.scenario.Scenario`.  Points are
independent, so they are farmed out to any :class:`concurrent.futures.Executor`-like
object — only ``executor.submit(fn, arg)`` and ``future.result()`` are used:

* locally (default): :class:`concurrent.futures.ProcessPoolExecutor` over the machine's
  cores;
* on a Dask cluster: ``distributed.Client(address).get_executor()`` (or the ``Client``
  itself, whose ``submit`` has the same shape);
* on a Ray cluster: Ray's ``concurrent.futures`` executor
  (``ray.util.concurrent.futures.RayExecutor``, Ray >= 2.4), or any wrapper that turns
  ``ray.remote`` calls into futures.

The worker function :func:`run_point` is a plain module-level function taking plain
data (a dict of settings and a metrics callable), so it pickles to remote workers;
each worker needs ``motor_comp`` installed.  See ``docs/sweep.md``.
"""
from __future__ import annotations

import concurrent.futures
import dataclasses
import itertools
import math
import os
import time
from typing import Any, Callable, Iterable, Mapping, Sequence

import numpy as np

from motor_comp.control.scenario import Scenario
from motor_comp.control.simulator import SimResult
from motor_comp.errors import ParameterError

#: metrics callable: SimResult → {name: number}
Metrics = Callable[[SimResult], Mapping[str, Any]]


def basic_metrics(result: SimResult) -> dict[str, float]:
    """RMS and max tracking error [m] (the CLI passes the full analysis metrics instead)."""
    e = result.error
    return {'rms_error': float(np.sqrt(np.mean(e * e))),
            'max_error': float(np.max(np.abs(e)))}


def expand_grid(base: Mapping[str, Any], grid: Mapping[str, Sequence[Any]]) -> list[dict]:
    """Every combination of the grid values on top of ``base`` (last name varies fastest)."""
    names = list(grid)
    for n in names:
        if not isinstance(grid[n], (list, tuple)) or not grid[n]:
            raise ParameterError(f'grid {n}: needs a non-empty list of values')
    points = []
    for combo in itertools.product(*(grid[n] for n in names)):
        p = dict(base)
        p.update(zip(names, combo))
        points.append(p)
    return points


@dataclasses.dataclass(frozen=True)
class PointResult:
    """One grid point: its settings, metrics and the time it took."""

    point: Mapping[str, Any]
    metrics: Mapping[str, Any]
    wall_s: float


def run_point(point: Mapping[str, Any], metrics: Metrics = basic_metrics) -> PointResult:
    """Simulate one grid point (runs in a worker process)."""
    t0 = time.perf_counter()
    result, _ = Scenario.from_mapping(point).run()
    return PointResult(point=dict(point), metrics=dict(metrics(result)),
                       wall_s=time.perf_counter() - t0)


def validate_points(points: Iterable[Mapping[str, Any]]) -> None:
    """Build every scenario once in the caller, so a bad value fails before any work."""
    for p in points:
        try:
            Scenario.from_mapping(p).build()
        except ParameterError as exc:
            label = ', '.join(f'{k}={v}' for k, v in p.items())
            raise ParameterError(f'sweep point ({label}): {exc}') from None


def run_sweep(points: Sequence[Mapping[str, Any]], *, executor: Any | None = None,
              max_workers: int | None = None, metrics: Metrics = basic_metrics,
              progress: Callable[[int, int], None] | None = None) -> list[PointResult]:
    """Run every point, in parallel, and return the results in the order of ``points``.

    Parameters
    ----------
    executor : Executor-like, optional
        Anything with ``submit(fn, *args)`` returning futures with ``result()``.
        Default: a local ``ProcessPoolExecutor`` with ``max_workers`` processes
        (default: all cores, at most the number of points).
    metrics : callable
        ``SimResult → {name: number}``; must be picklable (module-level function).
    progress : callable, optional
        Called with (done, total) as points finish.
    """
    points = [dict(p) for p in points]
    if not points:
        return []
    validate_points(points)
    own = executor is None
    if own:
        n = max_workers or os.cpu_count() or 1
        executor = concurrent.futures.ProcessPoolExecutor(max_workers=min(n, len(points)))
    try:
        futures = [executor.submit(run_point, p, metrics) for p in points]
        results: list[PointResult | None] = [None] * len(points)
        index = {id(f): i for i, f in enumerate(futures)}
        done = 0
        pending: Iterable[Any] = futures   # foreign futures (a Dask Client's): in order
        if all(isinstance(f, concurrent.futures.Future) for f in futures):
            pending = concurrent.futures.as_completed(futures)
        for f in pending:
            results[index[id(f)]] = f.result()
            done += 1
            if progress is not None:
                progress(done, len(points))
        return [r for r in results if r is not None]
    finally:
        if own:
            executor.shutdown()


def table(results: Sequence[PointResult], *,
          keys: Sequence[str]) -> tuple[list[str], list[list[Any]]]:
    """Header and rows: the varied settings, then the metrics ``keys`` and wall time."""
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
