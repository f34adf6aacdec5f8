"""``motor-comp analyze``: tracking error and quadrant glitches of recorded runs.

Prints a table per run (several runs side by side, with the relative change against
the first), or with ``--json`` one object ``{"runs": [...]}`` (DESIGN.md §6 keys).
``--report DIR`` writes the figures and a self-contained ``index.html``.

Without ``--report`` the metrics are computed by streaming the file
(:mod:`motor_comp.analysis.streaming`): memory does not grow with the run length.
The figures of ``--report`` need the whole series, so that option reads them into memory.

A run recorded with ``/diagnostics`` (``motor-comp run --monitor``, or with limits)
also gets ``monitor`` (the model monitor's verdicts: counts per level, worst force
NRMSE, the candidate effect) and ``limits`` (armed limits, the trip) keys
(:mod:`motor_comp.analysis.diagnostics`).
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from motor_comp.cli.common import (add_bag_options, add_json, add_report, jsonable,
                                   positive_float, run_topics)
from motor_comp.errors import ParameterError


_POLICY = ('Input handling: messages are aligned onto the /axis/joint_states stamps '
           '(latest value at or before each); out-of-order stamps are sorted and duplicate '
           'stamps keep the last message; NaN/Inf samples are dropped; a truncated or '
           'damaged file is read up to the damage. Each case prints a warning on stderr.')


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``analyze`` subcommand."""
    p = subparsers.add_parser(
        'analyze', help='tracking error and quadrant glitches of recorded runs',
        description=__doc__.splitlines()[0], epilog=_POLICY)
    p.add_argument('runs', nargs='+', metavar='RUN',
                   help='runs: MCAP files or rosbag2 directories (first = baseline)')
    p.add_argument('--glitch-window', type=positive_float, default=0.2, metavar='S',
                   help='window W after each reference reversal [s] (default 0.2)')
    p.add_argument('--settle-band', type=positive_float, default=None, metavar='M',
                   help='absolute settling band for point-to-point moves [m] '
                        '(default 2%% of the move)')
    p.add_argument('--chatter-cutoff', type=positive_float, default=100.0, metavar='HZ',
                   help='voltage content above this frequency counts as chattering [Hz]')
    p.add_argument('--namespace', default='axis', help='topic namespace (default axis)')
    add_bag_options(p)
    add_json(p)
    add_report(p, help='write figures and index.html here')
    p.add_argument('--progress', action='store_true',
                   help='show reading progress on stderr (default: only on a terminal)')
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Analyse the runs; return the exit status."""
    from motor_comp.analysis.metrics import compute_metrics
    from motor_comp.analysis.report import format_table, relative_change, write_report
    from motor_comp.logs import read_run

    from motor_comp.analysis.streaming import stream_metrics

    from motor_comp.analysis.diagnostics import summarise
    from motor_comp.logs.diagnostics import read_diagnostics

    progress = bool(args.progress or sys.stderr.isatty())
    topics = run_topics(args)
    runs, metrics = [], []
    for path in args.runs:
        try:
            if not args.report:     # streamed: memory independent of the run length
                metrics.append(stream_metrics(
                    path, progress=progress, topics=topics,
                    glitch_window=args.glitch_window, settle_band=args.settle_band,
                    chatter_cutoff=args.chatter_cutoff))
                continue
            r = read_run(path, progress=progress, topics=topics,
                         signals=('reference', 'reference_velocity', 'voltage'),
                         require={'reference': 'the tracking error is reference − position'})
            runs.append(r)
            metrics.append(compute_metrics(r, glitch_window=args.glitch_window,
                                           settle_band=args.settle_band,
                                           chatter_cutoff=args.chatter_cutoff))
        except ParameterError as exc:
            raise ParameterError(f'{path}: {exc}') from None
    # after the metrics: a bad file is reported by the reader of the loop's topics
    args.diagnostics = [summarise(read_diagnostics(path)) for path in args.runs]
    report = None
    if args.report:
        try:
            report = write_report(args.report, runs, metrics, sources=args.runs)
        except OSError as exc:
            raise ParameterError(f'--report {args.report}: cannot write '
                                 f'({exc.strerror or exc})') from None
    if args.json:
        _write_json(args, metrics, report, relative_change)
    else:
        from motor_comp.analysis.diagnostics import format_summary
        print(format_table(metrics))
        for path, summary in zip(args.runs, args.diagnostics):
            for line in format_summary(summary):
                print(f'{path}: {line}')
        if report is not None:
            print(f'report: {report}')
    return 0


def _write_json(args: argparse.Namespace, metrics: list, report: Any,
                relative_change: Any) -> None:
    """Print ``{"runs": [...], "glitch_window": W}`` piece by piece.

    The per-reversal lists (one glitch and one stroke per reversal: 72 000 entries for
    10 h of a 0.5 Hz sine) are written item by item instead of being built as one
    structure and one string, so the output does not multiply the memory.
    """
    def dump(x: Any) -> str:
        return json.dumps(jsonable(x), allow_nan=False)

    out = sys.stdout
    out.write('{"runs": [')
    for i, (path, m) in enumerate(zip(args.runs, metrics)):
        d = m.as_dict(records=False)
        d['path'] = str(path)
        d['relative_to_first'] = relative_change(metrics[0], m)
        d.update(args.diagnostics[i])
        out.write((', ' if i else '') + dump(d)[:-1])
        for name, items in m.records():
            out.write(f', {json.dumps(name)}: [')
            for j, item in enumerate(items):
                out.write((', ' if j else '') + dump(item))
            out.write(']')
        out.write('}')
    tail = {'glitch_window': args.glitch_window}
    if report is not None:
        tail['report'] = str(report)
    out.write('], ' + dump(tail)[1:] + '\n')
    out.flush()
