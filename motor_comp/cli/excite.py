"""``motor-comp excite --model M.yaml --travel MIN MAX --vmax V -o EXC.csv``: identification run.

Designs an identification trajectory for the model's effects within the axis limits
(:mod:`motor_comp.design.excite`): constant-speed passes from creep to ``--vmax`` in
both directions in an interleaved order, reversals down to a few encoder counts, speed
sweeps for the mass and the dead time, rests, over a travel of at least two periods of
any position-dependent effect; the time shared out to minimise the predicted standard
errors (D-optimal).  Prints the standard errors ``fit`` is predicted to report on the
run (a closed-loop simulation of the start model along the trajectory, refitted) and
writes the trajectory as a ``table`` CSV ``t,x,v,a`` that ``motor-comp simulate
--trajectory table --set traj.file=EXC.csv``, ``motor-comp run --trajectory table
--trajectory-file EXC.csv`` and ``trajectory_node`` (parameter ``file``) play.
``--json`` prints one object: ``predicted_se`` ``{effect: {param: SE}}``, ``params``,
``limits``, ``peaks``, ``parts``, ``controller``, ``path`` … (DESIGN.md §6).
"""
from __future__ import annotations

import argparse
import json
import math
import sys

from motor_comp.cli.common import add_json, check_output_file, jsonable, \
    nonnegative_float, positive_float


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``excite`` subcommand."""
    p = subparsers.add_parser('excite', help='design an identification trajectory (table CSV)',
                              description=__doc__.splitlines()[0])
    p.add_argument('--model', required=True, metavar='MODEL.yaml',
                   help='start model: its effects are what the run must identify')
    p.add_argument('--travel', required=True, nargs=2, type=float, metavar=('MIN', 'MAX'),
                   help='usable travel [m] (rad on a rotary axis)')
    p.add_argument('--vmax', required=True, type=positive_float, metavar='V',
                   help='largest speed [m/s]')
    p.add_argument('--amax', type=positive_float, default=None, metavar='A',
                   help='largest acceleration [m/s²] (default π·bandwidth·vmax)')
    p.add_argument('--fmax', type=positive_float, default=math.inf, metavar='F',
                   help="largest drive force [N] the start model may ask for")
    p.add_argument('--umax', type=positive_float, default=math.inf, metavar='U',
                   help="largest command in the model's input unit [V, A or N]")
    p.add_argument('--bandwidth', type=positive_float, default=3.0, metavar='HZ',
                   help='highest frequency of the excitation [Hz] (default 3)')
    p.add_argument('--duration', type=positive_float, default=60.0, metavar='S',
                   help='length of the excitation [s] (default 60)')
    p.add_argument('--period', type=positive_float, action='append', default=[],
                   metavar='P', help='a spatial period the travel must cover twice '
                                     '(suspected cogging, screw lead), repeatable')
    p.add_argument('--plant', default=None, metavar='PLANT',
                   help='the loop of the run: pmlm, ballscrew or a plant YAML (its '
                        'controller, sensors and rates); default a PID placed on the '
                        'start model')
    p.add_argument('--controller', choices=('pid', 'npid', 'adaptive_sliding'),
                   default=None, help="with --plant: the control law (default the plant's)")
    p.add_argument('--loop-bandwidth', type=positive_float, default=None, metavar='HZ',
                   help='without --plant: closed-loop bandwidth of the PID (default 20)')
    p.add_argument('--encoder', type=nonnegative_float, default=None, metavar='Q',
                   help='encoder resolution [m] (default the plant\'s, or 1e-6)')
    p.add_argument('--noise-std', type=nonnegative_float, default=None, metavar='S',
                   help='position noise [m] (default the plant\'s, or 0)')
    p.add_argument('--seed', type=int, default=0, help='noise seed of the prediction')
    p.add_argument('-o', '--output', required=True, metavar='EXC.csv',
                   help='write the trajectory table here')
    add_json(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``excite``."""
    from motor_comp.control.excitation import ExcitationLimits
    from motor_comp.control.trajectories import write_table
    from motor_comp.design.excite import design, loop_for
    from motor_comp.errors import InputFileError, ParameterError
    from motor_comp.physics.axis import AxisModel

    out = check_output_file(args.output, '-o')
    model = AxisModel.load(args.model)
    if args.plant is None and args.controller not in (None, 'pid'):
        raise ParameterError('--controller needs --plant (without it the loop is a PID '
                             'placed on the start model)')
    if args.plant is not None and args.loop_bandwidth is not None:
        raise ParameterError('--loop-bandwidth is for the PID placed on the start model; '
                             'with --plant the controller is that plant\'s')
    lo, hi = args.travel
    amax = args.amax if args.amax is not None else math.pi * args.bandwidth * args.vmax
    limits = ExcitationLimits(travel=(lo, hi), vmax=args.vmax, amax=amax,
                              bandwidth=args.bandwidth, fmax=args.fmax, umax=args.umax)
    loop = loop_for(model, plant=args.plant, mode=args.controller, encoder=args.encoder,
                    noise_std=args.noise_std, loop_bandwidth=args.loop_bandwidth)

    def say(msg: str) -> None:
        print(msg, file=sys.stderr if args.json else sys.stdout, flush=True)
    d = design(model, limits, duration=args.duration, loop=loop, periods=args.period,
               seed=args.seed, progress=say)
    units = model.units
    comments = (f'motor-comp excite: identification trajectory for {args.model}',
                f'columns: t [s], x [{units.position}], v [{units.velocity}], '
                f'a [{units.acceleration}]',
                f'travel {lo:g}..{hi:g} {units.position}, vmax {args.vmax:g}, amax {amax:g}, '
                f'bandwidth {args.bandwidth:g} Hz, {d.table.duration:.1f} s')
    try:
        write_table(out, d.table, comments=comments)
    except OSError as exc:
        raise InputFileError(f'-o {out}: cannot write ({exc.strerror or exc})') from None
    params = {g: {k: v for k, v in _scalars(d.start, g).items()}
              for g in d.predicted_se}
    if args.json:
        data = d.as_dict()
        data.update(path=str(out), params=params, model=str(args.model))
        print(json.dumps(jsonable(data)))
        return 0
    print(f'wrote {out}: {d.table.duration:.1f} s, {d.table.t.shape[0]} rows; '
          f'peaks: speed {d.peaks.v:.4g} {units.velocity}, acceleration {d.peaks.a:.4g} '
          f'{units.acceleration}, drive force {d.peaks.force:.4g} {units.force}, '
          f'command {d.peaks.command:.4g}')
    counts = {}
    for p in d.parts:
        counts[p['kind']] = counts.get(p['kind'], 0) + p['count']
    print(f'parts: {counts.get("pass", 0)} passes at {len(set(d.speeds))} speeds '
          f'{d.creep:.3g}–{max(d.speeds):.3g} {units.velocity} (interleaved), '
          f'{counts.get("reversal", 0)} small-reversal bursts, {counts.get("sweep", 0)} '
          f'speed sweeps; loop {d.loop.mode}')
    print('predicted standard errors (fit on a simulated run of this excitation):')
    for g, dd in d.predicted_se.items():
        for k, se in dd.items():
            v = params.get(g, {}).get(k)
            rel = f'  ({100 * se / abs(v):.2g} %)' if v else ''
            val = f'{v:.5g}' if v is not None else '-'
            print(f'  {g + "." + k:<22} {val:>12} ± {se:.3g}{rel}')
    return 0


def _scalars(model: object, group: str) -> dict[str, float]:
    """Return the start model's value of each reported parameter of ``group`` (SI)."""
    if group == 'mass':
        return {'mass': model.mass}
    e = model.get(group)
    if e is None:
        return {}
    out = {k: v for k, v in e.params().items() if isinstance(v, (int, float))}
    if group == 'ripple':
        out.update({f'amplitude_{h + 1}': float(a) for h, a in enumerate(e.amplitudes)})
    return out
