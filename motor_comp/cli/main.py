"""``motor-comp`` entry point: dispatch to subcommands, turn errors into one line.

Each subcommand module exposes ``register(subparsers)`` which adds its parser and sets
``func`` (a callable taking the parsed namespace and returning an exit code).  Errors a
user can fix are :class:`~motor_comp.errors.MotorCompError`: printed as one line
``motor-comp: error: …`` with exit status 2; anything else is reported as one line
too (``MOTOR_COMP_DEBUG=1`` shows the traceback).
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
from typing import Sequence

from motor_comp.errors import MotorCompError

#: subcommand modules under motor_comp.cli, in help order
SUBCOMMANDS: tuple[str, ...] = (
    'simulate',
    'sweep',
    'run',
    'replay',
    'demo',
    'analyze',
    'import_cmd',
    'compare',
    'diagnose',
    'fit',
    'export_table',
    'excite',
    'autotune',
    'study',
)

DESCRIPTION = ('Precision servo axes: simulate with friction, GMS pre-sliding and force '
               'ripple; control (PID, adaptive sliding, N-PID + friction feedforward); run as '
               'ROS 2 nodes recorded to MCAP; analyse runs; find what a model is missing.')


class _Parser(argparse.ArgumentParser):
    """argparse with the project's one-line error format (exit status 2).

    Options are never abbreviated (``allow_abbrev=False``): ``--input`` must never be
    taken for ``--input-hold`` (DESIGN.md §6).
    """

    def __init__(self, *args: object, **kwargs: object) -> None:
        kwargs['allow_abbrev'] = False
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]

    def error(self, message: str) -> None:  # noqa: D102 - argparse API
        self.exit(2, f'motor-comp: error: {message}\n')


def build_parser(only: str | None = None) -> argparse.ArgumentParser:
    """Build the parser with every subcommand registered (or only the module ``only``)."""
    parser = _Parser(prog='motor-comp', description=DESCRIPTION)
    sub = parser.add_subparsers(dest='command', metavar='COMMAND', parser_class=_Parser)
    sub.required = True
    for name in (SUBCOMMANDS if only is None else (only,)):
        importlib.import_module(f'motor_comp.cli.{name}').register(sub)
    return parser


def _command_module(argv: Sequence[str]) -> str | None:
    """Return the module of the subcommand ``argv`` starts with (None, e.g. for --help)."""
    if argv:
        for name in SUBCOMMANDS:
            if argv[0] in (name, name.removesuffix('_cmd'), name.replace('_', '-')):
                return name
    return None


def main(argv: Sequence[str] | None = None) -> int:
    """Run the CLI; return the process exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    # Register only the command being run: importing every subcommand's dependencies
    # (numba kernels, physics, rclpy …) would add ~0.5 s and ~70 MB to each start-up.
    parser = build_parser(_command_module(argv))
    args = parser.parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except MotorCompError as exc:
        print(f'motor-comp: error: {exc}', file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        print('motor-comp: interrupted', file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0
    except Exception as exc:  # noqa: BLE001 - last line of defence: never a traceback
        if os.environ.get('MOTOR_COMP_DEBUG'):
            raise
        print(f'motor-comp: internal error: {type(exc).__name__}: {exc}', file=sys.stderr)
        return 1


if __name__ == '__main__':
    sys.exit(main())
