"""``motor-comp sweep``: a grid of closed-loop simulations in parallel, one summary table.

``--grid name=v1,v2,…`` (repeatable; names as ``simulate --set`` plus ``controller``,
``feedforward``, ``plant``, ``seed``, ``duration``) or ``--grid-file GRID.yaml`` with
``{base: {name: value}, grid: {name: [values]}}``.  Points run on a local process pool
(``--workers``, default all cores); the library behind it
(:mod:`motor_comp.control.sweep`) accepts a Dask or Ray executor for clusters
(``docs/sweep.md``).  Prints the table, ``--csv FILE`` writes it, ``--json`` prints
``{"points": [{settings…, metrics…}], "grid": {…}}``.
"""
from __future__ import annotations

import argparse
import csv
import json
import sys
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


def run(args: argparse.Namespace) -> int:
    """Run the sweep; return the exit status."""
    from motor_comp.control.scenario import parse_assignment
    from motor_comp.control.sweep import expand_grid, run_sweep, table

    if args.workers is not None and args.workers < 1:
        raise ParameterError('--workers must be >= 1')
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
    points = expand_grid(base, grid)

    def progress(done: int, total: int) -> None:
        if sys.stderr.isatty():
            print(f'\rsweep: {done}/{total}', end='' if done < total else '\n',
                  file=sys.stderr, flush=True)

    results = run_sweep(points, max_workers=args.workers,
                        metrics=AnalysisMetrics(args.glitch_window), progress=progress)
    header, rows = table(results, keys=METRIC_KEYS)
    for name in grid:   # swept names stay in the table even if all values coincide
        if name not in header:
            header.insert(0, name)
            for r, row in zip(results, rows):
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
    if args.json:
        out = {'grid': grid, 'base': base,
               'points': [{**r.point, **r.metrics, 'wall_s': r.wall_s} for r in results]}
        print(json.dumps(jsonable(out), allow_nan=False))
        return 0
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
    return 0
