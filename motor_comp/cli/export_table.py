"""``motor-comp export-table MODEL.yaml --points N -o TABLE.csv``: a compensation table.

The position-dependent part of a model — ripple/cogging, gravity, spring, offset — on a
position grid, in force (torque) and in drive units (``force / input_gain``: volts,
amperes, or newtons for a force-input drive), for a drive's anticogging / gravity map or
for ``motor-comp simulate --compensation-table`` and ``controller_node``'s
``compensation_table``.  A periodic part covers one period (ripple) or one revolution
(gravity, ripple with a whole number of cycles per revolution); a non-periodic one
(spline) needs the travel ``--range MIN MAX``.  The CSV header states the units, the
period and the model it came from (:func:`motor_comp.control.compensation.write_table`).
``position_friction`` is position-dependent but acts against the motion; a table cannot
hold it, and the output names it with the reason (JSON ``left_out``).
"""
from __future__ import annotations

import argparse
import json
import sys

from motor_comp.cli.common import add_json, check_output_file, finite_float, jsonable


def _points(text: str) -> int:
    """Argparse type: an integer >= 2 (at most 1 000 000)."""
    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not an integer: {text!r}') from None
    if not 2 <= n <= 1_000_000:
        raise argparse.ArgumentTypeError(f'must be between 2 and 1000000, got {text!r}')
    return n


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``export-table`` subcommand."""
    p = subparsers.add_parser('export-table', help='position-dependent compensation table',
                              description=__doc__.splitlines()[0])
    p.add_argument('model', metavar='MODEL.yaml', help='model file (DESIGN.md §6)')
    p.add_argument('--points', type=_points, default=1024, metavar='N',
                   help='grid points (default 1024)')
    p.add_argument('--range', type=finite_float, nargs=2, metavar=('MIN', 'MAX'),
                   dest='span', default=None,
                   help='travel [m] or [rad] (needed when the part is not periodic)')
    p.add_argument('-o', '--output', required=True, metavar='TABLE.csv',
                   help='CSV file to write')
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``motor-comp export-table``."""
    from motor_comp.control.compensation import position_table, write_table
    from motor_comp.errors import InputFileError
    from motor_comp.physics.axis import AxisModel

    out = check_output_file(args.output, '-o')
    model = AxisModel.load(args.model)
    table = position_table(model, points=args.points,
                           span=tuple(args.span) if args.span else None, source=args.model)
    try:
        write_table(out, table)
    except OSError as exc:
        raise InputFileError(f'{out}: cannot write ({exc.strerror or exc})') from None
    u = table.units
    amp = float(max(abs(table.force.max()), abs(table.force.min())))
    info = {'path': str(out), 'points': len(table.position), 'period': table.period,
            'effects': list(table.effects), 'units': dict(u),
            'input_gain': table.input_gain, 'peak_force': amp,
            'peak_command': amp / table.input_gain, 'source_model': args.model,
            'left_out': dict(table.left_out)}
    if args.json:
        print(json.dumps(jsonable(info), allow_nan=False))
        return 0
    span = (f'one period {table.period:.6g} {u["position"]}' if table.period > 0 else
            f'{table.position[0]:.6g} … {table.position[-1]:.6g} {u["position"]}')
    print(f'{out}: {len(table.position)} points over {span}; '
          f'{" + ".join(table.effects)}; peak {amp:.4g} {u["force"]} = '
          f'{amp / table.input_gain:.4g} {u["command"]}')
    not_in = [n for n in model.names if n not in table.effects and n not in table.left_out]
    if not_in:
        print(f'  not position-dependent (not in the table): {", ".join(not_in)}')
    for name, why in table.left_out.items():
        print(f'  {name} not in the table: {why}')
    sys.stdout.flush()
    return 0
