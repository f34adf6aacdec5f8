"""``motor-comp demo``: the study, run by the four ROS 2 nodes as separate processes.

Six lockstep runs, each recorded to MCAP by ``recorder_node`` and analysed from the file
(``compute_metrics``), in the spirit of the two papers:

* PMLM, point-to-point moves (Tan 2002): PID baseline vs adaptive sliding;
* ball-screw, slow sine with reversals (Chiew et al.): N-PID with feedforward
  ``none``, ``static``, ``gms``, ``static+gms``.

Prints a metrics table with the ratios the papers discuss (adaptive/PID max error;
feedforward vs none for RMS error and quadrant glitches) and writes ``DIR/*.mcap``,
``DIR/summary.json`` and ``DIR/summary.md``.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

from motor_comp.cli.common import add_json, positive_float
from motor_comp.cli.run import RunSpec, metrics_row, print_table, run_nodes
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
    add_json(p, help='print one JSON object')
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``motor-comp demo``."""
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
    wall = time.monotonic() - t0
    comparisons = ratios(rows)
    summary = {'runs': list(rows.values()),
               'ratios': [{'comparison': c, 'ratio': r} for c, r in comparisons],
               'wall_time_s': wall}
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
    print(f'\n{len(rows)} runs recorded to {out}/ in {wall:.0f} s wall time '
          f'(four node processes each, lockstep)')
    return 0
