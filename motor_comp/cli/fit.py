"""``motor-comp fit RUN [RUN2 ...] --model MODEL.yaml [--add EFFECT] [--auto] -o NEW.yaml``.

Without ``--add``/``--auto``: every parameter of the model refitted jointly.
``--add`` names effects of the vocabulary (repeatable, in order); ``--auto`` is
stepwise selection from the model as given (``effects: {}`` and a rough mass are a
fine start): add the effect with the best held-out gain while it pays for its
parameters, and after each addition remove any effect that no longer pays.  Several
runs are one experiment: one model fitted on all.  Prints each step, the parameters
with standard errors, the pairs the run cannot separate, the force error before/after
(held-out) and the position prediction error; writes the model file with ``-o``;
``--json`` prints ``{steps: [{effect, action, force_nrmse}], model: {…}, uncertainty,
identifiability, experiment, position: {before, after}}``.
"""
from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from motor_comp.cli.common import add_report, check_output_file, jsonable
from motor_comp.cli.compare import add_common, emit
from motor_comp.cli.diagnose import add_diagnose_options
from motor_comp.errors import MotorCompError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``fit`` subcommand."""
    from motor_comp.physics.effects import VOCABULARY
    p = subparsers.add_parser('fit', help='add effects to a model and refit it on a run',
                              description=__doc__.splitlines()[0])
    add_common(p, several=True)
    add_diagnose_options(p)
    p.add_argument('--add', action='append', default=[], metavar='EFFECT',
                   choices=list(VOCABULARY) + ['mass'],
                   help=f'effect to add ({", ".join(VOCABULARY)}; or mass), repeatable')
    p.add_argument('--auto', action='store_true',
                   help='repeat diagnose -> add until nothing pays for its parameters')
    p.add_argument('-o', '--output', metavar='NEW.yaml', help='write the fitted model here')
    add_report(p)
    p.set_defaults(func=run)


def _report(args: argparse.Namespace, s: Any, result: Any, text: str) -> Any:
    """Write ``--report DIR``: the fitted model's residual views, scan and floor."""
    from motor_comp.workbench import report as rep
    from motor_comp.workbench import residual
    from motor_comp.workbench.report_scan import floor_figure, scan_figure
    out = rep.prepare_dir(args.report)
    rotary = s.model.units.rotary
    figs = rep.residual_figures(out, s.kin, residual(s.kin, result.model), rotary=rotary,
                                closed_loop=rep.is_closed_loop(s.run))
    un = result.unexplained
    if un is not None:
        figs.insert(0, scan_figure(out, un, rotary=rotary))
        figs.insert(0, floor_figure(out, [st.effect or 'start' for st in result.steps],
                                    [st.force_nrmse for st in result.steps],
                                    un.noise_floor_nrmse))
    return rep.write_html(out, f'fit: {s.kin.name} from {args.model}', text, figs)


def run(args: argparse.Namespace) -> int:
    """Execute ``fit``."""
    from motor_comp.workbench import fit, open_session, predict
    if args.output:     # fail before the fit, not after it
        check_output_file(args.output, '-o')
    s = open_session(args.run, args.model, window_s=args.window, hold=args.input_hold,
                     rotary=args.rotary)

    def say(msg: str) -> None:
        # progress goes to stderr with --json so stdout holds exactly one object
        print(msg, file=sys.stderr if args.json else sys.stdout)
    result = fit(list(s.kins), s.model, add=args.add, auto=args.auto, folds=args.folds,
                 min_gain=args.min_gain, progress=say)
    before = predict(s.kin, s.model)
    after = predict(s.kin, result.model)
    first, last = result.steps[0], result.steps[-1]
    rotary = s.model.units.rotary
    unit, k = ('mrad', 1e3) if rotary else ('µm', 1e6)
    un = result.unexplained
    floor = (f'; noise floor {100 * un.noise_floor_nrmse:.2f} %'
             if un is not None and math.isfinite(un.noise_floor_nrmse) else '')
    lines = [f'force NRMSE: before {100 * first.force_nrmse:.2f} %, after '
             f'{100 * last.force_nrmse:.2f} % (held-out{floor})']
    if un is not None:
        lines.append(un.summary)
    lines += [f'cannot tell apart: {n}' for n in result.identifiability]
    lines += [f'experiment: {n}' for n in result.experiment]
    lines.append(f'position, {1e3 * before.horizon:.0f} ms-ahead prediction RMS error '
                 f'({s.kin.name}): before {k * before.rms_error:.2f} {unit}, after '
                 f'{k * after.rms_error:.2f} {unit}')
    if args.output:
        try:
            result.model.save(args.output)
        except OSError as exc:
            raise MotorCompError(f'{args.output}: cannot write model ({exc.strerror})') \
                from None
        lines.append(f'model written to {args.output}')
    data = result.as_dict()
    data['position'] = {'horizon': before.horizon, 'before': before.rms_error,
                        'after': after.rms_error}
    if args.report:
        data['report'] = str(_report(args, s, result, '\n'.join(lines)))
    if args.output:
        data['output'] = str(args.output)
    emit(args, jsonable(data), '\n'.join(lines))
    return 0
