"""``motor-comp demo``: the study, run by the four ROS 2 nodes as separate processes.

Six lockstep runs, each recorded to MCAP by ``recorder_node`` and analysed from the file
(``compute_metrics``), in the spirit of the two papers:

* PMLM, point-to-point moves (Tan 2002): PID baseline vs adaptive sliding;
* ball-screw, slow sine with reversals (Chiew et al.): N-PID with feedforward
  ``none``, ``static``, ``gms``, ``static+gms``.

Prints a metrics table with the ratios the papers discuss (adaptive/PID max error;
feedforward vs none for RMS error and quadrant glitches) and writes ``DIR/*.mcap``,
``DIR/summary.json`` and ``DIR/summary.md``.

Then the workbench story (issue 12), on a ball-screw run with a hidden effect (cogging at
the 5 mm screw lead, absent from the user's model file ``config/ballscrew.yaml``):

1. **compare** — the model's force NRMSE and its prediction error in micrometres;
2. **diagnose** — the missing effect named, with its parameters;
3. **fit** — the effect added, every parameter refit: the error falls;
4. **compensate** — slow constant-velocity passes (where cogging shows) with the fitted
   model as feedforward (``--compensation``): the tracking error falls, next to no
   compensation and to the user's original model.

Everything goes into one HTML report, ``DIR/report/index.html`` (the node study, each
workbench step with its figures, the compensation runs), whose path is printed.
"""
from __future__ import annotations

import argparse
import base64
import contextlib
import html
import io
import json
import sys
import time
from pathlib import Path
from typing import Any, Callable

from motor_comp.cli.common import add_json, positive_float
from motor_comp.cli.run import RunSpec, metrics_row, print_table, require_ros, run_nodes
from motor_comp.errors import InputFileError, ParameterError

#: (name, plant, controller, feedforward)
RUNS = (
    ('pmlm_pid', 'pmlm', 'pid', 'none'),
    ('pmlm_adaptive', 'pmlm', 'adaptive_sliding', 'none'),
    ('ballscrew_npid_none', 'ballscrew', 'npid', 'none'),
    ('ballscrew_npid_static', 'ballscrew', 'npid', 'static'),
    ('ballscrew_npid_gms', 'ballscrew', 'npid', 'gms'),
    ('ballscrew_npid_static+gms', 'ballscrew', 'npid', 'static+gms'),
)


def ratios(rows: dict[str, dict[str, Any]]) -> list[tuple[str, float]]:
    """Return the comparisons of the papers, as ratios of the recorded runs' metrics."""
    out = []
    if 'pmlm_pid' in rows and 'pmlm_adaptive' in rows:
        out.append(('PMLM max error, adaptive / PID (Tan: ≈ 0.5)',
                    rows['pmlm_adaptive']['max_error'] / rows['pmlm_pid']['max_error']))
    base = rows.get('ballscrew_npid_none')
    if base is not None:
        for ff in ('static', 'gms', 'static+gms'):
            r = rows.get(f'ballscrew_npid_{ff}')
            if r is None:
                continue
            out.append((f'ball-screw RMS error, {ff} / none',
                        r['rms_error'] / base['rms_error']))
            if base.get('max_glitch') and r.get('max_glitch') is not None:
                out.append((f'ball-screw max glitch, {ff} / none',
                            r['max_glitch'] / base['max_glitch']))
    return out


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``demo`` subcommand."""
    p = subparsers.add_parser('demo', help='the study as ROS 2 node processes, with metrics',
                              description=__doc__.splitlines()[0])
    p.add_argument('--out', type=Path, default=Path('demo_out'),
                   help='output directory (created; default demo_out)')
    p.add_argument('--pmlm-duration', type=positive_float, default=4.0,
                   help='sim seconds of each PMLM run (default 4: two out-and-back moves)')
    p.add_argument('--ballscrew-duration', type=positive_float, default=8.0,
                   help='sim seconds of each ball-screw run (default 8: four reversals)')
    p.add_argument('--only', nargs='*', choices=[r[0] for r in RUNS],
                   help='run only these (default: all six)')
    p.add_argument('--skip-workbench', action='store_true',
                   help='only the node study (no compare/diagnose/fit/compensate story)')
    add_json(p, help='print one JSON object')
    p.set_defaults(func=run)


#: the hidden effect of the workbench story: cogging at the ball-screw's 5 mm lead [m, N]
HIDDEN_RIPPLE = {'period': 0.005, 'harmonics': [[4.0, 2.0]]}
#: its trajectory: a chirp with reversals over several leads (identification-rich)
STORY_TRAJECTORY = {'amplitude': 0.02, 'f_start': 0.2, 'f_end': 1.5, 'fade': 1.0}
STORY_DURATION = 10.0
#: where cogging shows in the tracking error: slow constant-velocity passes over 4 leads
STORY_CHECK = {'speeds': [0.005, 0.01, 0.02], 'stroke': 0.02, 'acceleration': 0.5}


def _cli_json(argv: list[str]) -> dict[str, Any]:
    """Run a ``motor-comp`` subcommand in-process with ``--json``; return its object."""
    from motor_comp.cli.main import main
    from motor_comp.errors import MotorCompError
    buf, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(buf), contextlib.redirect_stderr(err):
        code = main([*argv, '--json'])
    if code != 0:
        last = (err.getvalue().strip().splitlines() or ['?'])[-1]
        raise MotorCompError(f'motor-comp {argv[0]} failed in the demo: {last}')
    return json.loads(buf.getvalue())


def _fmt_params(params: dict[str, Any]) -> str:
    def one(v: Any) -> str:
        if isinstance(v, list):
            return '[' + ', '.join(one(e) for e in v) + ']'
        return f'{v:.4g}' if isinstance(v, float) else str(v)
    return ', '.join(f'{k}={one(v)}' for k, v in params.items())


def workbench_story(out: Path, say: Callable[[str], None]) -> dict[str, Any]:
    """Compare → diagnose → fit → compensate on a run with a hidden effect (module doc)."""
    from motor_comp.analysis.metrics import compute_metrics
    from motor_comp.analysis.report import write_report
    from motor_comp.control import compensation
    from motor_comp.control.controller import make_controller
    from motor_comp.control.simulator import simulate
    from motor_comp.control.trajectories import make_trajectory
    from motor_comp.logs import write_run
    from motor_comp.physics.config import load_plant
    from motor_comp.physics.effects import make_effect

    wdir = out / 'workbench'
    rep = out / 'report'
    wdir.mkdir(parents=True, exist_ok=True)
    rep.mkdir(parents=True, exist_ok=True)
    user = load_plant('ballscrew')          # what the user believes the axis is
    true = user.with_model(user.model.with_effect(make_effect('ripple', HIDDEN_RIPPLE)))
    traj = make_trajectory('chirp', duration=STORY_DURATION, **STORY_TRAJECTORY)

    def closed_loop(comp: Any, name: str, trajectory: Any = traj,
                    duration: float = STORY_DURATION) -> Any:
        ctrl = make_controller('npid', plant=user)
        ctrl.set_compensation(comp)
        return simulate(true, ctrl, trajectory, duration=duration).to_run(name=name)

    say('workbench: recording a ball-screw run with a hidden effect')
    run_path, model_path, fitted_path = (wdir / 'run.mcap', wdir / 'model.yaml',
                                         wdir / 'fitted.yaml')
    write_run(run_path, closed_loop(None, 'recorded'),
              metadata={'generator': 'motor-comp demo (workbench story)'})
    user.model.save(model_path)
    say('workbench: compare')
    before = _cli_json(['compare', str(run_path), '--model', str(model_path),
                        '--report', str(rep / 'compare')])
    say('workbench: diagnose')
    diag = _cli_json(['diagnose', str(run_path), '--model', str(model_path),
                      '--report', str(rep / 'diagnose')])
    cands = diag.get('candidates') or []
    if not cands:
        raise ParameterError('demo: diagnose found no candidate on the hidden-effect run')
    best = cands[0]
    say(f'workbench: fit --add {best["effect"]}')
    fitted = _cli_json(['fit', str(run_path), '--model', str(model_path), '--add',
                        best['effect'], '-o', str(fitted_path)])
    say('workbench: compensate (fitted model as feedforward)')
    comps = (('no compensation', None),
             ('compensation from the user model', compensation.load_model(model_path)),
             ('compensation from the fitted model', compensation.load_model(fitted_path)))
    check = make_trajectory('cv', **STORY_CHECK)
    runs = [closed_loop(c, name, check, check.period) for name, c in comps]
    metrics = [compute_metrics(r) for r in runs]
    write_report(rep / 'compensate', runs, metrics,
                 title='Tracking with the fitted compensation')
    steps = [{'effect': s.get('effect'), 'force_nrmse': s.get('force_nrmse')}
             for s in fitted.get('steps', [])]
    return {
        'hidden': {'ripple': HIDDEN_RIPPLE},
        'compare': {'force_nrmse': before['force_nrmse'],
                    'prediction_rms_error': before.get('prediction', {}).get('rms_error')},
        'diagnose': {'effect': best['effect'], 'title': best.get('title', best['effect']),
                     'explained': best.get('explained'), 'params': best.get('params', {}),
                     'force_nrmse': best.get('force_nrmse'),
                     'baseline_force_nrmse': diag.get('baseline', {}).get('force_nrmse')},
        'fit': {'steps': steps, 'force_nrmse': steps[-1]['force_nrmse'],
                'model': str(fitted_path)},
        'compensate': [{'run': r.name, 'rms_error': m.rms_error, 'max_error': m.max_error,
                        'max_glitch': m.max_glitch} for r, m in zip(runs, metrics)],
    }


def _say(text: str) -> None:
    print(f'motor-comp demo: {text}', file=sys.stderr, flush=True)


def _embed_pngs(d: Path, limit: int = 4) -> str:
    """Inline the first PNGs of a sub-report directory (one self-contained page)."""
    parts = []
    for p in sorted(d.glob('*.png'))[:limit]:
        data = base64.b64encode(p.read_bytes()).decode()
        parts.append(f'<figure><img alt="{html.escape(p.name)}" '
                     f'src="data:image/png;base64,{data}"><figcaption>'
                     f'{html.escape(d.name)}/{html.escape(p.name)}</figcaption></figure>')
    return ''.join(parts)


_CSS = ('body{font-family:sans-serif;max-width:64em;margin:1em auto}'
        'table{border-collapse:collapse}td,th{border:1px solid #bbb;padding:.2em .6em;'
        'text-align:right}td:first-child{text-align:left}img{max-width:100%}')


def _cell(v: Any) -> str:
    return '-' if v is None else f'{v * 1e6:.3f}'


def _metric_rows(rows: list[dict[str, Any]], key: str) -> str:
    return ''.join(f'<tr><td>{html.escape(r[key])}</td><td>{_cell(r.get("rms_error"))}</td>'
                   f'<td>{_cell(r.get("max_error"))}</td><td>{_cell(r.get("max_glitch"))}'
                   f'</td></tr>' for r in rows)


_HEAD = ('<tr><th>run</th><th>rms error [µm]</th><th>max error [µm]</th>'
         '<th>max glitch [µm]</th></tr>')


def _story_html(rep: Path, wb: dict[str, Any]) -> str:
    e = html.escape
    d, f, c = wb['diagnose'], wb['fit'], wb['compare']
    pred0 = c.get('prediction_rms_error')
    nr0, nr1 = 100 * (d['baseline_force_nrmse'] or 0.0), 100 * f['force_nrmse']
    return (
        '<h2>2. The workbench: a ball-screw run with a hidden effect</h2>'
        '<p>The plant has cogging at the 5 mm screw lead that the user\'s model file '
        '(<code>config/ballscrew.yaml</code>) does not know.</p>'
        f'<h3>Compare</h3><p>Force NRMSE <b>{100 * c["force_nrmse"]:.1f} %</b>; 20 ms-ahead '
        f'prediction error '
        f'{_cell(pred0)} µm RMS (<a href="compare/index.html">compare report</a>).</p>'
        f'{_embed_pngs(rep / "compare", 2)}'
        f'<h3>Diagnose</h3><p>Missing effect: <b>{e(d["title"])}</b> '
        f'({e(_fmt_params(d["params"]))}), removes {100 * (d.get("explained") or 0):.0f} % '
        f'of the residual on held-out data (<a href="diagnose/index.html">diagnose '
        f'report</a>).</p>{_embed_pngs(rep / "diagnose", 2)}'
        f'<h3>Fit</h3><p>{e(d["effect"])} added, every parameter refit: held-out force '
        f'NRMSE <b>{nr0:.1f} % → {nr1:.1f} %</b>; model <code>{e(f["model"])}</code>.</p>'
        '<h3>Compensate</h3><p>Slow constant-velocity passes over four screw leads (where '
        'cogging shows in the tracking error), with each model as feedforward at the '
        'reference state (<code>motor-comp simulate --compensation fitted.yaml</code>):'
        f'</p><table>{_HEAD}{_metric_rows(wb["compensate"], "run")}</table>'
        '<p>(<a href="compensate/index.html">tracking report</a>)</p>'
        f'{_embed_pngs(rep / "compensate", 1)}')


def write_mission_report(out: Path, summary: dict[str, Any]) -> Path:
    """Write ``out/report/index.html``: the node study and the workbench story."""
    rep = out / 'report'
    rep.mkdir(parents=True, exist_ok=True)
    ratios_html = ''.join(f'<tr><td>{html.escape(x["comparison"])}</td>'
                          f'<td>{x["ratio"]:.3f}</td></tr>'
                          for x in summary.get('ratios', []))
    parts = ['<!DOCTYPE html><html lang="en"><head><meta charset="utf-8">'
             f'<title>motor_comp demo</title><style>{_CSS}</style></head><body>',
             '<h1>motor_comp: from the papers\' controllers to a better model and better '
             'tracking</h1>',
             '<h2>1. The study, as ROS 2 node processes (lockstep, recorded to MCAP)</h2>',
             f'<table>{_HEAD}{_metric_rows(summary.get("runs", []), "name")}</table>',
             f'<p>Ratios the papers discuss:</p><table>{ratios_html}</table>']
    if summary.get('workbench'):
        parts.append(_story_html(rep, summary['workbench']))
    parts.append('</body></html>')
    path = rep / 'index.html'
    path.write_text('\n'.join(parts), encoding='utf-8')
    return path


def run(args: argparse.Namespace) -> int:
    """Execute ``motor-comp demo``."""
    require_ros('motor-comp demo')   # one line before any run starts
    for name in ('pmlm_duration', 'ballscrew_duration'):
        if not getattr(args, name) > 0:
            raise ParameterError(f'--{name.replace("_", "-")} must be > 0')
    out: Path = args.out
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise InputFileError(f'{out}: cannot create output directory ({exc.strerror})') \
            from None
    t0 = time.monotonic()
    story = pool = None
    if not args.skip_workbench:
        # in-process numerics next to the node runs (which mostly wait on each other in
        # lockstep): a worker process runs the story meanwhile
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor
        pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context('spawn'))
        story = pool.submit(workbench_story, out, _say)
    rows: dict[str, dict[str, Any]] = {}
    selected = [r for r in RUNS if not args.only or r[0] in args.only]
    for i, (name, plant, controller, ff) in enumerate(selected, 1):
        duration = args.pmlm_duration if plant == 'pmlm' else args.ballscrew_duration
        print(f'motor-comp demo: [{i}/{len(selected)}] {name} ({duration:g} s sim time)',
              file=sys.stderr)
        logs = out / f'{name}_logs'
        logs.mkdir(exist_ok=True)
        spec = RunSpec(output=out / f'{name}.mcap', plant=plant, controller=controller,
                       feedforward=ff, duration=duration)
        path = run_nodes(spec, workdir=logs, progress=False)
        row = metrics_row(path)
        row.update(name=name, plant=plant, controller=controller, feedforward=ff,
                   duration=duration)
        rows[name] = row
    comparisons = ratios(rows)
    summary: dict[str, Any] = {
        'runs': list(rows.values()),
        'ratios': [{'comparison': c, 'ratio': r} for c, r in comparisons]}
    if story is not None:
        try:
            summary['workbench'] = story.result()
        finally:
            pool.shutdown(cancel_futures=True)
    wall = time.monotonic() - t0
    summary['wall_time_s'] = wall
    report = write_mission_report(out, summary)
    summary['report'] = str(report)
    (out / 'summary.json').write_text(json.dumps(summary, indent=1), encoding='utf-8')
    lines = ['| run | rms error [µm] | max error [µm] | max glitch [µm] | mean glitch [µm] |',
             '|---|---|---|---|---|']
    for r in rows.values():
        cells = ' | '.join('-' if r.get(k) is None else f'{r[k] * 1e6:.3f}'
                           for k in ('rms_error', 'max_error', 'max_glitch', 'mean_glitch'))
        lines.append(f'| {r["name"]} | {cells} |')
    lines += ['', '| comparison | ratio |', '|---|---|']
    lines += [f'| {c} | {r:.3f} |' for c, r in comparisons]
    (out / 'summary.md').write_text('\n'.join(lines) + '\n', encoding='utf-8')
    if args.json:
        print(json.dumps(summary))
        return 0
    print_table(list(rows.values()), label='name')
    print()
    for c, r in comparisons:
        print(f'{c:<48} {r:7.3f}')
    wb = summary.get('workbench')
    if wb:
        d, c, f = wb['diagnose'], wb['compare'], wb['fit']
        print('\nworkbench, ball-screw run with a hidden effect:')
        print(f'  compare    force NRMSE {100 * c["force_nrmse"]:.1f} %, prediction error '
              f'{(c["prediction_rms_error"] or 0) * 1e6:.1f} µm RMS')
        print(f'  diagnose   missing: {d["title"]} ({_fmt_params(d["params"])})')
        print(f'  fit        held-out force NRMSE {100 * d["baseline_force_nrmse"]:.1f} % -> '
              f'{100 * f["force_nrmse"]:.1f} %')
        for r in wb['compensate']:
            print(f'  compensate {r["run"]:<36} rms {r["rms_error"] * 1e6:8.3f} µm')
    print(f'\n{len(rows)} node runs recorded to {out}/; {wall:.0f} s wall time in all')
    print(f'report: {report.resolve()}')
    return 0
