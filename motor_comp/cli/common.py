"""Argument types and options shared by the ``motor-comp`` subcommands.

One definition of each, so that every command answers the same bad value with the same
one-line message (``motor-comp: error: argument --X: …``, exit status 2).
"""
from __future__ import annotations

import argparse
import math
import os
from pathlib import Path
from typing import Any, Callable

from motor_comp.errors import InputFileError


def _float_type(requirement: str, ok: Callable[[float], bool]) -> Callable[[str], float]:
    """Return an argparse type accepting a number for which ``ok`` holds."""
    def parse(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f'not a number: {text!r}') from None
        if not (math.isfinite(v) and ok(v)):
            raise argparse.ArgumentTypeError(f'must be {requirement}, got {text!r}')
        return v
    parse.__doc__ = f'Argparse type: {requirement}.'
    return parse


#: argparse types: the number must be finite and ...
positive_float = _float_type('a finite number > 0', lambda v: v > 0)
nonnegative_float = _float_type('a finite number >= 0', lambda v: v >= 0)
finite_float = _float_type('finite', lambda v: True)
nonzero_float = _float_type('finite and non-zero', lambda v: v != 0)  # scale factors


def add_json(p: argparse.ArgumentParser, *, help: str = 'print one JSON object on stdout'
             ) -> None:
    """Add ``--json`` (one JSON object on stdout; progress and warnings go to stderr)."""
    p.add_argument('--json', action='store_true', help=help)


def add_report(p: argparse.ArgumentParser, *,
               help: str = 'write PNG figures and index.html here') -> None:
    """Add ``--report DIR``."""
    p.add_argument('--report', metavar='DIR', help=help)


def add_limits(p: argparse.ArgumentParser, description: str) -> None:
    """Add the axis limits' options (``--travel --vmax --amax --umax --max-error``).

    One definition for ``run`` and ``autotune``, which enforce them the same way
    (:class:`~motor_comp.control.limits.Limits`).
    """
    lim = p.add_argument_group('limits', description)
    lim.add_argument('--travel', nargs=2, type=finite_float, metavar=('MIN', 'MAX'),
                     help='travel limits of the position [m]')
    lim.add_argument('--vmax', type=positive_float, metavar='V', help='speed limit [m/s]')
    lim.add_argument('--amax', type=positive_float, metavar='A',
                     help='acceleration limit [m/s²]')
    lim.add_argument('--umax', type=positive_float, metavar='U',
                     help='voltage limit: the law asking for more trips [V]')
    lim.add_argument('--max-error', type=positive_float, metavar='E',
                     help='tracking-error limit |x_ref − x| [m]')


def add_bag_options(p: argparse.ArgumentParser, *, reference: bool = True,
                    several_joints: bool = False, signals: bool = True) -> None:
    """Add ``--topic --joint --input --reference``: where a run is in a robot's bag.

    DESIGN.md §6 "Runs from robots"; :func:`run_topics` turns them into the readers'
    :class:`~motor_comp.logs.topics.RunTopics`.  ``signals=False`` leaves out
    ``--input``/``--reference`` (a command that defines them itself, e.g. ``import``).
    """
    g = p.add_argument_group(
        'robot bags', 'an MCAP file or a rosbag2 directory (MCAP or sqlite3 storage); '
        'by default the topics of motor-comp run (/axis/joint_states, /axis/voltage, '
        '/axis/reference), then /joint_states')
    g.add_argument('--topic', metavar='T',
                   help='the JointState topic of the measurement (default '
                        '/axis/joint_states, then /joint_states)')
    g.add_argument('--joint', metavar='NAME',
                   help='the joint of a multi-joint JointState, matched by name in every '
                        'message' + ('; "all": every moving joint, one model each '
                                     '(with -o DIR/)' if several_joints else ''))
    if not signals:
        return
    g.add_argument('--input', metavar='effort|TOPIC',
                   help='the drive input: "effort" (the joint\'s effort, in the units of '
                        'the model\'s input: N or N·m for force, A for current) or a topic '
                        '(Float64, or a JointState\'s effort: TOPIC[:JOINT]); default '
                        '/axis/voltage')
    if reference:
        g.add_argument('--reference', metavar='TOPIC[:JOINT]',
                       help='the reference for tracking metrics: a JointState or a '
                            'control_msgs JointTrajectoryControllerState (default '
                            '/axis/reference)')


def run_topics(args: argparse.Namespace, *, joint: str | None = None) -> Any:
    """Return the :class:`~motor_comp.logs.topics.RunTopics` of the bag options in ``args``."""
    from motor_comp.logs.topics import RunTopics
    return RunTopics.of(namespace=getattr(args, 'namespace', 'axis'), topic=args.topic,
                        joint=joint if joint is not None else args.joint, input=args.input,
                        reference=getattr(args, 'reference', None))


def check_output_file(path: str | os.PathLike, option: str) -> Path:
    """Check, before any long computation, that ``path`` can be created as a file.

    Raises :class:`InputFileError` naming the option and the path when the path is a
    directory, or its directory does not exist, is not a directory or is not writable,
    so that a long run is not lost at the last step.
    """
    out = Path(path)
    parent = out.parent if str(out.parent) else Path('.')
    if out.is_dir():
        raise InputFileError(f'{option} {out}: is a directory, expected a file name')
    if not parent.exists():
        raise InputFileError(f'{option} {out}: directory {parent} does not exist')
    if not parent.is_dir():
        raise InputFileError(f'{option} {out}: {parent} is not a directory')
    if not os.access(parent, os.W_OK | os.X_OK):
        raise InputFileError(f'{option} {out}: directory {parent} is not writable')
    return out


def jsonable(x: Any) -> Any:
    """Replace non-finite floats by None, recursively (JSON has no NaN/Inf)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    return x
