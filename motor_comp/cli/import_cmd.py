"""``motor-comp import``: a CSV/MAT test-rig table to a canonical MCAP run.

Columns are selected by header name or 0-based index (CSV) or ``VAR``/``VAR:INDEX``
(MAT); scales convert to SI (e.g. ``--position-scale`` metres per encoder count).
"""
from __future__ import annotations

import argparse
import json

from motor_comp.cli.common import add_json, check_output_file, finite_float, nonzero_float
from motor_comp.errors import InputFileError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``import`` subcommand."""
    p = subparsers.add_parser('import', help='convert a CSV/MAT table to an MCAP run',
                              description=__doc__.splitlines()[0])
    p.add_argument('data', metavar='DATA.{csv,mat}', help='input table')
    p.add_argument('--time', required=True, metavar='COL', help='time column')
    p.add_argument('--input', required=True, metavar='COL',
                   help='input column (voltage; or current/force for such drives)')
    p.add_argument('--position', required=True, metavar='COL', help='measured position column')
    p.add_argument('--reference', metavar='COL', help='reference position column')
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
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Import the table and write the MCAP; return the exit status."""
    from pathlib import Path

    from motor_comp.logs import write_run
    from motor_comp.logs.importers import import_table

    out = check_output_file(args.output, '-o')
    if out.resolve() == Path(args.data).resolve():
        raise InputFileError(f'{out}: output would overwrite the input')
    r = import_table(args.data, time=args.time, input=args.input, position=args.position,
                     reference=args.reference, velocity=args.velocity,
                     reference_velocity=args.reference_velocity, effort=args.effort,
                     time_scale=args.time_scale, time_offset=args.time_offset,
                     position_scale=args.position_scale, input_scale=args.input_scale,
                     velocity_scale=args.velocity_scale, effort_scale=args.effort_scale,
                     mat_orient=args.mat_orient, name=out.stem)
    try:
        write_run(out, r)
    except OSError as exc:
        raise InputFileError(f'{out}: cannot write ({exc.strerror or exc})') from None
    signals = [s for s in r.SIGNALS if getattr(r, s) is not None]
    if args.json:
        print(json.dumps({'output': str(out), 'samples': len(r), 't_start': float(r.t[0]),
                          't_end': float(r.t[-1]), 'signals': signals}))
    else:
        print(f'{args.data} -> {out}: {len(r)} samples, {r.t[0]:.6g}–{r.t[-1]:.6g} s '
              f'({", ".join(signals)})')
    return 0
