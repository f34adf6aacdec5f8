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

``--joint all -o DIR/`` fits every moving joint of a robot's bag (one model each, from
the same start model): ``DIR/<joint>.yaml`` and ``DIR/joints.csv``, one row per joint
with what was found or why it was skipped.
"""
from __future__ import annotations

import argparse
import math
import sys
from typing import Any

from motor_comp.cli.common import add_report, check_output_file, jsonable, run_topics
from motor_comp.cli.compare import add_common, emit, session
from motor_comp.cli.diagnose import add_diagnose_options
from motor_comp.errors import MotorCompError, ParameterError

#: ``--joint all``: a joint moves when its travel exceeds this many position quanta
#: (or noise standard deviations): a joint held by its brake shows a few counts
MOVING_QUANTA = 20.0


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``fit`` subcommand."""
    from motor_comp.physics.effects import VOCABULARY
    p = subparsers.add_parser('fit', help='add effects to a model and refit it on a run',
                              description=__doc__.splitlines()[0])
    add_common(p, several=True, several_joints=True)
    add_diagnose_options(p)
    p.add_argument('--add', action='append', default=[], metavar='EFFECT',
                   choices=list(VOCABULARY) + ['mass'],
                   help=f'effect to add ({", ".join(VOCABULARY)}; or mass), repeatable')
    p.add_argument('--auto', action='store_true',
                   help='repeat diagnose -> add until nothing pays for its parameters')
    p.add_argument('-o', '--output', metavar='NEW.yaml',
                   help='write the fitted model here (with --joint all: a directory)')
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


def _say(args: argparse.Namespace, msg: str) -> None:
    # progress goes to stderr with --json so stdout holds exactly one object
    print(msg, file=sys.stderr if args.json else sys.stdout)


def run(args: argparse.Namespace) -> int:
    """Execute ``fit``."""
    from motor_comp.workbench import fit, predict
    if args.joint == 'all':
        return _all_joints(args)
    if args.output:     # fail before the fit, not after it
        check_output_file(args.output, '-o')
    s = session(args)

    def say(msg: str) -> None:
        _say(args, msg)
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


def _moves(position: Any) -> bool:
    """Whether a joint moved: travel beyond :data:`MOVING_QUANTA` quanta or noise σ."""
    import numpy as np
    x = np.asarray(position, float)
    steps = np.abs(np.diff(x))
    quantum = float(np.min(steps[steps > 0])) if np.any(steps > 0) else 0.0
    d2 = np.diff(x, 2)
    noise = float(np.median(np.abs(d2 - np.median(d2)))) / 0.6745 / math.sqrt(6) \
        if d2.size else 0.0
    travel = float(np.ptp(x)) if x.size else 0.0
    return travel > 0 and travel > MOVING_QUANTA * max(quantum, noise)


def _all_joints(args: argparse.Namespace) -> int:
    """``fit --joint all -o DIR/``: one model per moving joint, and a table."""
    import csv
    from pathlib import Path

    from motor_comp.logs.bags import joint_names
    from motor_comp.workbench import fit
    if not args.output:
        raise ParameterError('--joint all fits every moving joint: give -o DIR/ for their '
                             'model files')
    out = Path(args.output)
    if out.exists() and not out.is_dir():
        raise ParameterError(f'-o {out}: --joint all writes a directory; that is a file')
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ParameterError(f'-o {out}: cannot create ({exc.strerror or exc})') from None
    probe = run_topics(args, joint='all')
    topic, joints = joint_names(args.run[0], probe.joint_states)
    rows: list[dict[str, Any]] = []
    for joint in joints:
        row: dict[str, Any] = {'joint': joint, 'topic': topic}
        try:
            s = session(args, joint=joint)
            row['samples'] = sum(len(r) for r in s.runs)
            if not any(_moves(r.position) for r in s.runs):
                row.update(status='skipped', reason='does not move')
                rows.append(row)
                _say(args, f'{joint}: skipped (does not move)')
                continue
            _say(args, f'{joint}: fitting {row["samples"]} samples')
            result = fit(list(s.kins), s.model, add=args.add, auto=args.auto,
                         folds=args.folds, min_gain=args.min_gain,
                         progress=lambda m, j=joint: _say(args, f'{j}: {m}'))
        except MotorCompError as exc:
            row.update(status='skipped', reason=str(exc))
            rows.append(row)
            _say(args, f'{joint}: skipped ({exc})')
            continue
        safe = ''.join(c if c.isalnum() or c in '-_.' else '_' for c in joint) or 'joint'
        path = out / f'{safe}.yaml'
        try:
            result.model.save(path)
        except OSError as exc:
            raise MotorCompError(f'{path}: cannot write model ({exc.strerror})') from None
        un = result.unexplained
        row.update(status='fitted', output=str(path),
                   effects=sorted(result.model.to_dict()['effects']),
                   force_nrmse_before=result.steps[0].force_nrmse,
                   force_nrmse_after=result.steps[-1].force_nrmse,
                   noise_floor_nrmse=un.noise_floor_nrmse if un is not None else None,
                   model=result.model.to_dict())
        rows.append(row)
    table = out / 'joints.csv'
    cols = ('joint', 'status', 'samples', 'effects', 'force_nrmse_before',
            'force_nrmse_after', 'noise_floor_nrmse', 'output', 'reason')
    with open(table, 'w', newline='', encoding='utf-8') as f:
        w = csv.writer(f)
        w.writerow(cols)
        for r in rows:
            w.writerow([' '.join(r[c]) if c == 'effects' and c in r else r.get(c, '')
                        for c in cols])
    fitted = [r for r in rows if r['status'] == 'fitted']
    lines = [f'{len(fitted)} of {len(rows)} joints of {topic} fitted; table {table}']
    for r in rows:
        if r['status'] == 'fitted':
            lines.append(f'  {r["joint"]}: {", ".join(r["effects"]) or "no effect"}; force '
                         f'NRMSE {100 * r["force_nrmse_before"]:.2f} % -> '
                         f'{100 * r["force_nrmse_after"]:.2f} % -> {r["output"]}')
        else:
            lines.append(f'  {r["joint"]}: skipped: {r["reason"]}')
    emit(args, jsonable({'topic': topic, 'joints': rows, 'table': str(table)}),
         '\n'.join(lines))
    return 0 if fitted else 2
