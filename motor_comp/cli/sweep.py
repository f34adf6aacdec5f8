"""``motor-comp sweep``: a grid of closed-loop simulations in parallel, one summary table.

``--grid name=v1,v2,…`` (repeatable; names as ``simulate --set`` plus ``controller``,
``feedforward``, ``plant``, ``seed``, ``duration``) or ``--grid-file GRID.yaml`` with
``{base: {name: value}, grid: {name: [values]}}``.  Points run on a local process pool
(``--workers``, default all cores) or on a Dask cluster (``--scheduler tcp://HOST:PORT``,
or the ``DASK_SCHEDULER_ADDRESS`` environment variable; ``--scheduler local:N`` starts
a loopback-only ``LocalCluster`` of N workers), grouped ``--batch`` points per task.
A progress line (done/total, points/s, ETA) goes to stderr.  Prints the table,
``--csv FILE`` writes it, ``--json`` prints ``{"points": [{settings…, metrics…}],
"grid": {…}, "failed": [{settings…, "error": …}]}``.  A point that raises is reported
on stderr by its settings and the error, the others complete, and the exit status is 1.
"""
from __future__ import annotations

import argparse
import concurrent.futures
import csv
import json
import math
import os
import sys
import time
from typing import Any, Mapping

from motor_comp.cli.common import add_json, check_output_file, jsonable, positive_float
from motor_comp.cli.simulate import add_scenario_arguments
from motor_comp.errors import InputFileError, ParameterError

METRIC_KEYS = ('rms_error', 'max_error', 'max_glitch', 'mean_glitch')


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``sweep`` subcommand."""
    p = subparsers.add_parser('sweep', help='grid of simulations in parallel',
                              description=__doc__.splitlines()[0])
    add_scenario_arguments(p, plant_required=False)
    p.add_argument('--grid', action='append', default=[], metavar='NAME=V1,V2,...',
                   help='a swept setting and its values (repeatable)')
    p.add_argument('--grid-file', metavar='GRID.yaml', help='base settings and grid in YAML')
    p.add_argument('--workers', type=int, default=None, help='processes (default: cores)')
    p.add_argument('--scheduler', metavar='ADDRESS', default=None,
                   help='run on a Dask cluster: tcp://HOST:PORT, or local:N to start N '
                        'local workers (default: $DASK_SCHEDULER_ADDRESS, else the local '
                        'process pool); needs motor_comp[cluster]')
    p.add_argument('--batch', type=int, default=None, metavar='N',
                   help='points per task (default: about 8 tasks per worker, at most 64)')
    p.add_argument('--progress', action='store_true',
                   help='progress line on stderr even when it is not a terminal')
    p.add_argument('--glitch-window', type=positive_float, default=0.2, metavar='S',
                   help='quadrant-glitch window W [s] (default 0.2)')
    p.add_argument('--csv', metavar='FILE', help='write the summary table as CSV')
    add_json(p)
    p.set_defaults(func=run)


def _grid_from_args(items: list[str]) -> dict[str, list[Any]]:
    from motor_comp.control.scenario import parse_value
    grid: dict[str, list[Any]] = {}
    for item in items:
        name, sep, values = item.partition('=')
        name = name.strip()
        if not sep or not name or not values.strip():
            raise ParameterError(f'--grid: expected name=v1,v2,..., got {item!r}')
        if name in grid:
            raise ParameterError(f'--grid: {name} given twice')
        grid[name] = [parse_value(v) for v in values.split(',') if v.strip()]
    return grid


def _grid_file(path: str) -> tuple[dict[str, Any], dict[str, list[Any]]]:
    import yaml
    try:
        with open(path, encoding='utf-8') as f:
            data = yaml.safe_load(f)
    except FileNotFoundError:
        raise InputFileError(f'{path}: no such grid file') from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(f'{path}: cannot read ({exc})') from None
    except yaml.YAMLError as exc:
        raise InputFileError(f'{path}: not valid YAML ({str(exc).splitlines()[0]})') from None
    if not isinstance(data, Mapping) or not isinstance(data.get('grid'), Mapping):
        raise InputFileError(f'{path}: expected a mapping with a "grid" mapping')
    base = data.get('base') or {}
    if not isinstance(base, Mapping):
        raise InputFileError(f'{path}: base must be a mapping')
    grid = {str(k): (list(v) if isinstance(v, (list, tuple)) else [v])
            for k, v in data['grid'].items()}
    return dict(base), grid


class AnalysisMetrics:
    """Picklable metrics callable: the analysis layer's DESIGN.md §6 metrics of a run."""

    def __init__(self, glitch_window: float) -> None:
        self.glitch_window = glitch_window

    def __call__(self, result: Any) -> dict[str, Any]:
        """Metrics of one simulated run."""
        from motor_comp.analysis.metrics import compute_metrics
        m = compute_metrics(result.to_run(), glitch_window=self.glitch_window).as_dict()
        return {k: m.get(k) for k in METRIC_KEYS + ('glitch_count',)}


class _ProgressLine:
    """Progress on stderr: done/total points, points/s, ETA (refreshed 4/s on a terminal)."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.total = total
        self.enabled = enabled
        self.t0 = time.monotonic()
        self.last = 0.0

    def __call__(self, done: int) -> None:
        if not self.enabled:
            return
        now = time.monotonic()
        if done < self.total and now - self.last < (0.25 if sys.stderr.isatty() else 2.0):
            return
        self.last = now
        dt = max(now - self.t0, 1e-9)
        rate = done / dt
        eta = (self.total - done) / rate if rate > 0 else math.inf
        line = f'sweep: {done}/{self.total} points, {rate:.1f} points/s, ETA {eta:.0f} s'
        if sys.stderr.isatty():     # one line rewritten in place
            print('\r' + line + ' ', end='\n' if done >= self.total else '',
                  file=sys.stderr, flush=True)
        else:                       # a log file: one line per update
            print(line, file=sys.stderr, flush=True)


def run(args: argparse.Namespace) -> int:
    """Run the sweep; return the exit status."""
    from motor_comp.control.scenario import parse_assignment
    from motor_comp.control.sweep import (close_client, dask_client, default_batch_size,
                                          grid_size, iter_grid, iter_sweep, table,
                                          validate_grid)

    if args.workers is not None and args.workers < 1:
        raise ParameterError('--workers must be >= 1')
    if args.batch is not None and args.batch < 1:
        raise ParameterError('--batch must be >= 1')
    if args.csv:        # fail before the sweep, not after it
        check_output_file(args.csv, '--csv')
    base: dict[str, Any] = {'plant': args.plant, 'controller': args.controller,
                            'feedforward': args.feedforward, 'duration': args.duration,
                            'seed': args.seed}
    if args.trajectory:
        base['trajectory'] = args.trajectory
    base.update(dict(parse_assignment(s) for s in args.settings))
    grid: dict[str, list[Any]] = {}
    if args.grid_file:
        fbase, grid = _grid_file(args.grid_file)
        base.update(fbase)
    grid.update(_grid_from_args(args.grid))
    if not grid:
        raise ParameterError('nothing to sweep: give --grid name=v1,v2,... or --grid-file')
    total = grid_size(grid)
    validate_grid(base, grid)          # every value checked before any simulation
    scheduler = args.scheduler or os.environ.get('DASK_SCHEDULER_ADDRESS') or None
    client = dask_client(scheduler) if scheduler else None
    try:
        if client is not None:
            workers = args.workers or max(1, len(client.scheduler_info()['workers']))
            executor: Any = client
        else:
            workers = args.workers or os.cpu_count() or 1
        size = args.batch or default_batch_size(total, workers)
        if client is None:
            executor = concurrent.futures.ProcessPoolExecutor(
                max_workers=min(workers, math.ceil(total / size)))
        show = _ProgressLine(total, bool(args.progress or sys.stderr.isatty()))
        results: list[Any] = [None] * total
        done = 0
        try:
            for r in iter_sweep(iter_grid(base, grid), executor=executor,
                                metrics=AnalysisMetrics(args.glitch_window), batch_size=size,
                                max_pending=2 * workers + 2):
                results[r.index] = r
                done += 1
                show(done)
        finally:
            if client is None:
                executor.shutdown(cancel_futures=True)
    finally:
        if client is not None:
            close_client(client)
    failed = [r for r in results if not r.ok]
    for r in failed:
        label = ', '.join(f'{k}={v}' for k, v in r.point.items())
        print(f'motor-comp: error: sweep point ({label}): {r.error}', file=sys.stderr)
    header, rows = table(results, keys=METRIC_KEYS)
    ok = [r for r in results if r.ok]
    for name in grid:   # swept names stay in the table even if all values coincide
        if header and name not in header:
            header.insert(0, name)
            for r, row in zip(ok, rows):
                row.insert(0, r.point.get(name))
    if args.csv:
        try:
            with open(args.csv, 'w', newline='', encoding='utf-8') as f:
                w = csv.writer(f)
                w.writerow(header)
                w.writerows(rows)
        except OSError as exc:
            raise InputFileError(f'{args.csv}: cannot write ({exc.strerror or exc})') \
                from None
    status = 1 if failed else 0
    if args.json:
        out = {'grid': grid, 'base': base,
               'points': [{**r.point, **r.metrics, 'wall_s': r.wall_s} for r in ok],
               'failed': [{**r.point, 'error': r.error} for r in failed]}
        print(json.dumps(jsonable(out), allow_nan=False))
        return status
    widths = [max(len(h), 12) for h in header]
    print('  '.join(h.rjust(w) for h, w in zip(header, widths)))
    for row in rows:
        cells = []
        for h, v, w in zip(header, row, widths):
            if isinstance(v, float) and h in METRIC_KEYS:
                cells.append(f'{v * 1e6:.3f}µm'.rjust(w))
            elif isinstance(v, float):
                cells.append(f'{v:.4g}'.rjust(w))
            else:
                cells.append(str(v).rjust(w))
        print('  '.join(cells))
    if args.csv:
        print(f'table: {args.csv}')
    if failed:
        print(f'{len(failed)} of {total} points failed (see stderr)')
    return status
