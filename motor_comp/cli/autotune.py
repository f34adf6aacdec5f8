"""``motor-comp autotune``: excite, record, ``fit --auto``, compensate — through the nodes.

``motor-comp autotune --plant {pmlm,ballscrew,FILE} | --external-plant --model START.yaml
[--task TRAJ] [--mode {lockstep,realtime}] -o DIR [--json]`` designs an identification
trajectory from the start model and the axis limits, plays it through the ROS node
processes (a simulated plant in lockstep by default, or with ``--external-plant``
whatever node publishes ``/<ns>/joint_states`` and takes ``/<ns>/voltage``: a real drive),
fits the model on the recording, and runs the task without and with the fitted model as
compensation (loaded into the running controller through its ``compensation_model``
parameter) — and, on a simulated plant, with the true plant model.  The limits are
enforced by the nodes throughout: a trip stops the axis and autotune with a one-line
error naming the stage (exit status 3), and what was recorded stays in ``DIR``.
Writes ``DIR/index.html`` and ``DIR/autotune.json`` (:mod:`motor_comp.tuning`).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from motor_comp.cli.common import add_json, add_limits, jsonable, positive_float
from motor_comp.errors import ParameterError


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``autotune`` subcommand."""
    from motor_comp.tuning.autotune import BANDWIDTH, EXCITE_DURATION
    p = subparsers.add_parser('autotune', help='excite → record → fit --auto → compensate, '
                              'through the ROS 2 nodes', description=__doc__.splitlines()[0])
    axis = p.add_mutually_exclusive_group(required=True)
    axis.add_argument('--plant', metavar='PLANT',
                      help='simulate this axis with plant_node: pmlm, ballscrew or a plant '
                           'YAML file (its model is the true model, the upper bound)')
    axis.add_argument('--external-plant', action='store_true',
                      help='start no plant_node: the node already publishing '
                           '/<ns>/joint_states and subscribing /<ns>/voltage (a real drive) '
                           'is the axis; realtime; needs --nominal')
    p.add_argument('--model', required=True, type=Path, metavar='START.yaml',
                   help='the start model (effects: {} and a rough mass are fine)')
    p.add_argument('--nominal', metavar='PLANT', default=None,
                   help='the controller\'s plant (nominal model, default gains, encoder): '
                        'pmlm, ballscrew or a plant file (default: --plant)')
    p.add_argument('--controller', choices=('pid', 'adaptive_sliding', 'npid'), default=None,
                   help='control law (default: PID on the PMLM, N-PID on the ball-screw)')
    p.add_argument('--task', default='', metavar='TRAJ',
                   help='the task: sine, p2p, cv, chirp or a table CSV t, x[, v, a] '
                        '(default: p2p on the PMLM, the slow sine on the ball-screw)')
    p.add_argument('--task-duration', type=positive_float, default=None, metavar='S',
                   help='length of each task run [s] (default 10; a table: its own)')
    p.add_argument('--mode', choices=('lockstep', 'realtime'), default=None,
                   help='timing (default lockstep with --plant, realtime with '
                        '--external-plant)')
    p.add_argument('--excite-duration', type=positive_float, default=EXCITE_DURATION,
                   metavar='S', help=f'length of the excitation [s] (default '
                                     f'{EXCITE_DURATION:g})')
    p.add_argument('--bandwidth', type=positive_float, default=BANDWIDTH, metavar='HZ',
                   help=f'highest frequency of the excitation [Hz] (default {BANDWIDTH:g})')
    add_limits(p, 'enforced by the nodes throughout (a trip stops the axis at 0 V and '
               'autotune with a one-line error, exit status 3); not given: travel = the task\'s '
               'range ± 25 %, vmax/amax = 1.5×/3× the task\'s peaks plus the encoder noise, '
               'umax/max-error none; the excitation keeps a margin inside them')
    p.add_argument('--monitor', action='store_true',
                   help='also run monitor_node (the start model during the excitation, the '
                        'fitted model during the task); its /diagnostics are recorded and '
                        'summarised')
    p.add_argument('--seed', type=int, default=0, help='noise seed of the simulated plant')
    p.add_argument('--namespace', default='axis', help='namespace of the axis topics')
    p.add_argument('--domain-id', type=int, default=None,
                   help='ROS_DOMAIN_ID (default: $ROS_DOMAIN_ID or a private one)')
    p.add_argument('--rt-priority', type=int, default=None, metavar='N',
                   help='realtime: SCHED_FIFO priority of the loop processes (default 40 '
                        'where permitted; 0 = off)')
    p.add_argument('-o', '--output', required=True, type=Path, metavar='DIR',
                   help='a new (or empty) directory for the recordings and the report')
    add_json(p, help='print one JSON object (progress on stderr)')
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``motor-comp autotune``."""
    from motor_comp.cli.axis_session import AxisSession
    from motor_comp.cli.run import DEFAULT_RT_PRIORITY, require_ros
    from motor_comp.tuning.autotune import Options, autotune
    require_ros('motor-comp autotune')
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        raise ParameterError(f'--domain-id must be in 0..232, got {args.domain_id}')
    ns = args.namespace.strip('/')
    if not ns or not all(part.isidentifier() for part in ns.split('/')):
        raise ParameterError(f'--namespace must be a ROS name like axis or arm/x, got '
                             f'{args.namespace!r}')
    mode = args.mode or ('realtime' if args.external_plant else 'lockstep')
    prio = args.rt_priority
    if prio is None:
        prio = DEFAULT_RT_PRIORITY if mode == 'realtime' else 0
    if not 0 <= prio <= 98:
        raise ParameterError(f'--rt-priority must be in 0..98, got {prio}')
    opts = Options(output=args.output, model=args.model,
                   plant=None if args.external_plant else args.plant, nominal=args.nominal,
                   controller=args.controller, mode=mode, task=args.task,
                   task_duration=args.task_duration, excite_duration=args.excite_duration,
                   bandwidth=args.bandwidth,
                   travel=tuple(args.travel) if args.travel else None, vmax=args.vmax,
                   amax=args.amax, umax=args.umax, max_error=args.max_error,
                   monitor=args.monitor, seed=args.seed, namespace=ns,
                   domain_id=args.domain_id, realtime_priority=prio)

    def say(msg: str) -> None:
        print(msg, file=sys.stderr if args.json else sys.stdout, flush=True)
    out = autotune(opts, axis=lambda spec, logdir, domain: AxisSession(
        spec, logdir, domain_id=domain), say=say)
    if args.json:
        print(json.dumps(jsonable(out.as_dict())))
        return 0
    for k, s in out.scores.items():
        glitch = '-' if s.max_glitch is None else f'{1e6 * s.max_glitch:.3f} µm'
        print(f'task {k:<7} RMS error {1e6 * s.rms_error:8.3f} µm   max '
              f'{1e6 * s.max_error:8.3f} µm   max glitch {glitch}')
    if out.recovered_rms is not None:
        glitch = '-' if out.recovered_glitch is None else f'{100 * out.recovered_glitch:.1f} %'
        print(f'the fitted model recovers {100 * out.recovered_rms:.1f} % of the RMS-error '
              f'reduction and {glitch} of the glitch reduction of the true plant model')
    print(f'report: {out.directory / "index.html"}')
    return 0
