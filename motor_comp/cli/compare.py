"""``motor-comp compare RUN --model MODEL.yaml``: how well a model explains a measured run.

Force residual of the inverse model (NRMSE, fit %), k-step-ahead position prediction
with the measured input (µm), closed-loop replay when the run names its controller;
``--report DIR`` writes the residual views (PNG) and an HTML page; ``--json`` prints one
object ``{force_nrmse, force_fit_percent, prediction: {…}, replay, whiteness, model}``.
"""
from __future__ import annotations

import argparse
import json
import sys
from typing import Any

from motor_comp.cli.common import (add_bag_options, add_json, add_report, jsonable,
                                   positive_float, run_topics)


def add_common(p: argparse.ArgumentParser, *, several: bool = False,
               several_joints: bool = False) -> None:
    """Arguments shared by compare, diagnose and fit (``several``: one or more runs)."""
    if several:
        p.add_argument('run', metavar='RUN', nargs='+',
                       help='measured run(s): MCAP files or rosbag2 directories (MCAP or '
                            'sqlite3 storage; import CSV/MAT first); several runs are one '
                            'experiment: one model is fitted on all of them')
    else:
        p.add_argument('run', metavar='RUN',
                       help='measured run: an MCAP file or a rosbag2 directory (import '
                            'CSV/MAT first)')
    p.add_argument('--model', required=True, metavar='MODEL.yaml', help='model file')
    add_json(p, help='print one JSON object to stdout')
    p.add_argument('--window', type=positive_float, default=0.02, metavar='S',
                   help='zero-phase derivative window [s] (default 0.02)')
    p.add_argument('--input-hold', choices=('zoh', 'sample'), default=None,
                   help='logged input is a held command (zoh, default for voltage) or a '
                        'sampled measurement (sample, default for current/force)')
    p.add_argument('--rotary', action='store_true',
                   help='treat the axis as rotary even if the model file has no '
                        '"axis: rotary" (angles in rad, torques in N·m, periods also in '
                        'cycles/rev)')
    add_bag_options(p, several_joints=several_joints)


def session(args: argparse.Namespace, *, joint: str | None = None) -> Any:
    """Open the runs and the model of ``args`` (the bag options say where the run is)."""
    from motor_comp.workbench import open_session
    return open_session(args.run, args.model, window_s=args.window, hold=args.input_hold,
                        rotary=args.rotary, topics=run_topics(args, joint=joint))


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``compare`` subcommand."""
    p = subparsers.add_parser('compare', help='compare a model with a measured run',
                              description=__doc__.splitlines()[0])
    add_common(p)
    add_report(p)
    p.add_argument('--horizon', type=positive_float, default=0.02, metavar='S',
                   help='position prediction horizon [s] (default 0.02)')
    p.set_defaults(func=run)


def emit(args: argparse.Namespace, data: dict[str, Any], text: str) -> None:
    """JSON on stdout with --json, else the text."""
    if args.json:
        json.dump(data, sys.stdout, allow_nan=False, default=float)
        sys.stdout.write('\n')
    else:
        print(text)


def run(args: argparse.Namespace) -> int:
    """Execute ``compare``."""
    from motor_comp.workbench import compare
    from motor_comp.workbench import report as rep
    s = session(args)
    rotary = s.model.units.rotary
    cmp = compare(s.run, s.kin, s.model, horizon=args.horizon)
    white = rep.whiteness(s.kin, cmp.residual, closed_loop=rep.is_closed_loop(s.run))
    text = cmp.summary(rotary=rotary) + '\n' + white.sentence()
    data = cmp.as_dict()
    data['whiteness'] = white.as_dict()
    if args.report:
        out = rep.prepare_dir(args.report)
        figs = rep.residual_figures(out, s.kin, cmp.residual, rotary=rotary)
        figs.append(rep.prediction_figure(out, s.kin, cmp.prediction))
        page = rep.write_html(out, f'compare: {s.kin.name} vs {args.model}', text, figs)
        data['report'] = str(page)
    emit(args, jsonable(data), text)
    if args.report:
        print(f'report: {data["report"]}', file=sys.stderr)
    return 0
