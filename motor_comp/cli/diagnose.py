"""``motor-comp diagnose RUN [RUN2 ...] --model MODEL.yaml``: what is wrong with a model.

First the model's own parameters are refitted jointly (a wrong parameter is the first
finding: "fc is 10.0 ± 0.1 N, not 5.0 N"); then every effect the model lacks is scored
as model + effect with all linear parameters re-estimated together, on held-out folds
of short interleaved blocks; prints the finding in plain words, the pairs this run
cannot tell apart and what the experiment lacks.  Several runs are one experiment.
``--json`` prints ``{baseline: {force_nrmse, …}, refit, candidates: [{effect,
explained, force_nrmse, params, uncertainty, supported, …}], identifiability,
experiment}`` (DESIGN.md §6), best first; ``--report DIR`` adds the residual views.
"""
from __future__ import annotations

import argparse
import sys

from motor_comp.cli.common import add_report, jsonable, positive_float
from motor_comp.cli.compare import add_common, emit, session


def fraction(text: str) -> float:
    """Argparse type: a number in [0, 1)."""
    v = positive_float(text) if text.strip() not in ('0', '0.0') else 0.0
    if v >= 1:
        raise argparse.ArgumentTypeError(f'must be in [0, 1), got {text!r}')
    return v


def add_diagnose_options(p: argparse.ArgumentParser) -> None:
    """Options shared with ``fit --auto``."""
    p.add_argument('--folds', type=int, default=5, choices=range(2, 21), metavar='K',
                   help='validation folds; short time blocks are dealt to them in turn '
                        '(default 5)')
    p.add_argument('--min-gain', type=fraction, default=0.1, metavar='F',
                   help='least held-out fraction of the residual a supported effect '
                        'removes (default 0.1)')


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``diagnose`` subcommand."""
    p = subparsers.add_parser('diagnose', help='find the physical effect a model is missing',
                              description=__doc__.splitlines()[0])
    add_common(p, several=True)
    add_diagnose_options(p)
    add_report(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``diagnose``."""
    from motor_comp.workbench import diagnose
    from motor_comp.workbench import report as rep
    from motor_comp.workbench.report_scan import floor_figure, scan_figure
    s = session(args)
    d = diagnose(list(s.kins), s.model, folds=args.folds, min_gain=args.min_gain)
    text = d.summary()
    data = d.as_dict()
    if args.report:
        out = rep.prepare_dir(args.report)
        figs = rep.residual_figures(out, s.kin, d.residual, rotary=d.rotary,
                                    closed_loop=rep.is_closed_loop(s.run))
        figs.insert(0, rep.candidates_figure(out, d.candidates))
        un = d.unexplained
        if un is not None:
            figs.insert(1, scan_figure(out, un, rotary=d.rotary))
            figs.insert(2, floor_figure(out, ['as given', 'refitted'] +
                                        [c.effect for c in d.candidates],
                                        [d.baseline_nrmse, d.refit_nrmse] +
                                        [c.force_nrmse for c in d.candidates],
                                        un.noise_floor_nrmse))
        page = rep.write_html(out, f'diagnose: {", ".join(d.runs)} with {args.model}', text,
                              figs)
        data['report'] = str(page)
    emit(args, jsonable(data), text)
    if args.report:
        print(f'report: {data["report"]}', file=sys.stderr)
    return 0
