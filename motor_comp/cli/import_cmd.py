"""``motor-comp import``: a CSV/MAT table, or a robot bag's joint, to a canonical MCAP run.

Columns are selected by header name or 0-based index (CSV) or ``VAR``/``VAR:INDEX``
(MAT); scales convert to SI (e.g. ``--position-scale`` metres per encoder count).
A bag (an MCAP file or a rosbag2 directory, MCAP or sqlite3 storage) is read with
``--topic``/``--joint`` and ``--input effort | TOPIC``/``--reference TOPIC[:JOINT]``
instead of columns: the joint becomes the run's ``/axis`` topics.
"""
from __future__ import annotations

import argparse
import json
from typing import Any

from motor_comp.cli.common import (add_bag_options, add_json, check_output_file,
                                   finite_float, nonzero_float, run_topics)
from motor_comp.errors import InputFileError, ParameterError

#: what is read as a bag (anything else is a table for ``import_table``)
BAG_SUFFIXES = ('.mcap', '.db3')


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``import`` subcommand."""
    p = subparsers.add_parser('import', help='convert a CSV/MAT table or a bag\'s joint to '
                              'an MCAP run', description=__doc__.splitlines()[0])
    p.add_argument('data', metavar='DATA', help='input table (.csv, .mat) or bag')
    p.add_argument('--time', metavar='COL', help='time column (tables: required)')
    p.add_argument('--input', metavar='COL',
                   help='tables: input column (voltage; or current/force for such drives), '
                        'required; bags: effort | TOPIC (default /axis/voltage)')
    p.add_argument('--position', metavar='COL',
                   help='measured position column (tables: required)')
    p.add_argument('--reference', metavar='COL',
                   help='tables: reference position column; bags: TOPIC[:JOINT]')
    p.add_argument('--velocity', metavar='COL', help='measured velocity column')
    p.add_argument('--reference-velocity', metavar='COL', help='reference velocity column')
    p.add_argument('--effort', metavar='COL', help='actuator force column')
    p.add_argument('--time-scale', type=nonzero_float, default=1.0, metavar='X',
                   help='seconds per time unit (e.g. 1e-3 for ms)')
    p.add_argument('--time-offset', type=finite_float, default=0.0, metavar='S',
                   help='added to the scaled time [s]')
    p.add_argument('--position-scale', type=nonzero_float, default=1.0, metavar='X',
                   help='metres per position unit (e.g. counts->m); also for --reference')
    p.add_argument('--velocity-scale', type=nonzero_float, default=None, metavar='X',
                   help='(m/s) per velocity unit (default: the position scale)')
    p.add_argument('--input-scale', type=nonzero_float, default=1.0, metavar='X',
                   help='factor of the input column')
    p.add_argument('--effort-scale', type=nonzero_float, default=1.0, metavar='X',
                   help='newtons per effort unit')
    p.add_argument('--mat-orient', choices=('auto', 'rows', 'columns'), default='auto',
                   help='MAT 2-D variables: signals are rows or columns (default: shorter axis)')
    p.add_argument('-o', '--output', required=True, metavar='RUN.mcap', help='output MCAP')
    add_bag_options(p, signals=False)
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Import the table and write the MCAP; return the exit status."""
    from pathlib import Path

    from motor_comp.logs.importers import import_table

    out = check_output_file(args.output, '-o')
    if out.resolve() == Path(args.data).resolve():
        raise InputFileError(f'{out}: output would overwrite the input')
    if not (Path(args.data).is_dir() or Path(args.data).suffix.lower() in BAG_SUFFIXES):
        missing = [f'--{k}' for k in ('time', 'input', 'position') if getattr(args, k) is None]
        if missing:
            raise ParameterError(f'{args.data}: a table needs {", ".join(missing)} COL')
        if args.topic is not None or args.joint is not None:
            raise ParameterError('--topic/--joint select a joint in a bag, not in a table')
    else:
        return _bag(args, out)
    r = import_table(args.data, time=args.time, input=args.input, position=args.position,
                     reference=args.reference, velocity=args.velocity,
                     reference_velocity=args.reference_velocity, effort=args.effort,
                     time_scale=args.time_scale, time_offset=args.time_offset,
                     position_scale=args.position_scale, input_scale=args.input_scale,
                     velocity_scale=args.velocity_scale, effort_scale=args.effort_scale,
                     mat_orient=args.mat_orient, name=out.stem)
    _write(args, out, r)
    return 0


def _bag(args: argparse.Namespace, out: Any) -> int:
    """``import BAG``: one joint of a robot's bag to a canonical run."""
    from motor_comp.logs import read_run
    table_only = [f'--{k.replace("_", "-")}' for k in (
        'time', 'position', 'velocity', 'reference_velocity', 'effort')
        if getattr(args, k) is not None]
    if table_only:
        raise ParameterError(f'{", ".join(table_only)}: column options of tables; a bag '
                             'is read with --topic, --joint, --input, --reference')
    _write(args, out, read_run(args.data, topics=run_topics(args)))
    return 0


def _write(args: argparse.Namespace, out: Any, r: Any) -> None:
    """Write the run and say what was written (one JSON object with ``--json``)."""
    from motor_comp.logs import write_run
    try:
        write_run(out, r)
    except OSError as exc:
        raise InputFileError(f'{out}: cannot write ({exc.strerror or exc})') from None
    signals = [s for s in r.SIGNALS if getattr(r, s) is not None]
    if args.json:
        print(json.dumps({'output': str(out), 'samples': len(r), 't_start': float(r.t[0]),
                          't_end': float(r.t[-1]), 'signals': signals}))
    else:
        print(f'{args.data} -> {out}: {len(r)} samples over {r.duration:.6g} s from '
              f't = {r.t[0]:.9g} s ({", ".join(signals)})')
