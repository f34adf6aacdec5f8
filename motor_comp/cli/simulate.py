"""``motor-comp simulate``: one in-process closed-loop run (trajectory → controller → plant).

Prints the tracking-error table, or with ``--json`` one object
``{"runs": [{rms_error, max_error, max_glitch, mean_glitch, glitches: [{t, magnitude}],
…}]}`` (DESIGN.md §6); ``--compensation MODEL.yaml`` adds the model's inverse dynamics
as a feedforward at the reference state (``--compensation-terms effects``: its effects
only; ``--compensation-table TABLE.csv`` a position table,
:mod:`motor_comp.control.compensation`); ``--trajectory table --set traj.file=F.csv``
plays a CSV ``t, x[, v, a]``; ``-o RUN.mcap`` records the run
(DESIGN.md §5 topics) with the run parameters as MCAP metadata.  Heavy modules (MCAP
writer, plots) load lazily so a short command starts fast.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

from motor_comp.cli.common import add_json, check_output_file, jsonable, positive_float

CONTROLLERS = ('pid', 'adaptive_sliding', 'npid')
FEEDFORWARDS = ('none', 'static', 'gms', 'static+gms')
TRAJECTORIES = ('sine', 'p2p', 'cv', 'chirp', 'table')


def add_scenario_arguments(p: argparse.ArgumentParser, *, plant_required: bool) -> None:
    """Options shared by ``simulate`` and ``sweep``."""
    p.add_argument('--plant', required=plant_required, default='pmlm',
                   help='pmlm, ballscrew, or a plant YAML file')
    p.add_argument('--controller', choices=CONTROLLERS, default='pid', help='control law')
    p.add_argument('--feedforward', choices=FEEDFORWARDS, default='none',
                   help='friction feedforward from the reference velocity')
    p.add_argument('--trajectory', choices=TRAJECTORIES, default=None,
                   help='reference (default: p2p on the PMLM, sine on the ball-screw)')
    p.add_argument('--duration', type=positive_float, default=10.0, metavar='S',
                   help='simulated time [s] (default 10)')
    p.add_argument('--seed', type=int, default=0, help='measurement-noise seed')
    p.add_argument('--set', action='append', default=[], metavar='NAME=VALUE',
                   dest='settings',
                   help='override: controller gain (kp=…), plant.coulomb.fc=…, '
                        'nominal.…, sensors.noise_std=…, rates.control_hz=…, traj.period=…, '
                        'load.force=…, load.t_start=… (repeatable)')


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``simulate`` subcommand."""
    p = subparsers.add_parser('simulate', help='closed-loop simulation of one axis',
                              description=__doc__.splitlines()[0])
    add_scenario_arguments(p, plant_required=False)
    p.add_argument('--engine', choices=('jit', 'python'), default='jit',
                   help='compiled loop (default) or the node-by-node Python path')
    p.add_argument('--glitch-window', type=positive_float, default=0.2, metavar='S',
                   help='quadrant-glitch window W [s] (default 0.2)')
    p.add_argument('-o', '--output', metavar='RUN.mcap', help='record the run to MCAP')
    p.add_argument('--name', default=None, help='run name (default: output stem)')
    add_compensation_arguments(p)
    add_json(p)
    p.set_defaults(func=run)


def add_compensation_arguments(p: argparse.ArgumentParser) -> None:
    """``--compensation MODEL.yaml [--compensation-terms T]`` | ``--compensation-table``."""
    g = p.add_mutually_exclusive_group()
    g.add_argument('--compensation', metavar='MODEL.yaml',
                   help="feedforward of this model's inverse dynamics at the reference "
                        '(inertia, back-EMF, damping, friction, GMS, ripple, offset, spring, '
                        'gravity; the dead time by sending it earlier) in any controller, '
                        'less the terms the control law carries itself')
    g.add_argument('--compensation-table', metavar='TABLE.csv',
                   help='position-dependent compensation table (motor-comp export-table), '
                        'interpolated')
    p.add_argument('--compensation-terms', choices=('full', 'effects'), default=None,
                   help='with --compensation: the full inverse dynamics (default) or the '
                        "model's effects only")


def compensation_from_args(args: argparse.Namespace) -> Any:
    """Load the compensation the options name (None without one); one-line errors."""
    from motor_comp.control import compensation
    from motor_comp.errors import ParameterError
    terms = getattr(args, 'compensation_terms', None)
    if terms is not None and not getattr(args, 'compensation', None):
        raise ParameterError('--compensation-terms needs --compensation MODEL.yaml (a table '
                             'holds its position-dependent forces only)')
    if getattr(args, 'compensation', None):
        return compensation.load_model(args.compensation, terms=terms or 'full')
    if getattr(args, 'compensation_table', None):
        return compensation.load_table(args.compensation_table)
    return None


def scenario_from_args(args: argparse.Namespace) -> Any:
    """Build the :class:`~motor_comp.control.scenario.Scenario` the arguments describe."""
    from motor_comp.control.scenario import Scenario, parse_assignment
    settings = tuple(parse_assignment(s) for s in args.settings)
    return Scenario(plant=args.plant, controller=args.controller,
                    feedforward=args.feedforward, duration=args.duration, seed=args.seed,
                    trajectory=args.trajectory, settings=settings)


def run_scenario(scenario: Any, comp: Any, *, engine: str = 'jit') -> tuple[Any, Any]:
    """``scenario.run`` with the compensation ``comp`` (or None) loaded in the controller."""
    import dataclasses

    from motor_comp.control.simulator import simulate
    if comp is None:
        return scenario.run(engine=engine)
    true, _nominal, ctrl, traj, load = scenario.build()
    ctrl.set_compensation(comp)
    res = simulate(true, ctrl, traj, duration=scenario.duration, seed=scenario.seed,
                   load=load, engine=engine)
    meta = dict(res.metadata)
    meta['settings'] = {k: v for k, v in scenario.settings}
    meta['plant'] = scenario.plant
    return dataclasses.replace(res, metadata=meta), ctrl


def run_metadata(scenario: Any, ctrl: Any, result: Any) -> dict[str, str]:
    """Run parameters as MCAP metadata strings (plant, controller, gains, ff, seed, …)."""
    meta = {'plant': scenario.plant, 'controller': scenario.controller,
            'feedforward': scenario.feedforward, 'seed': str(scenario.seed),
            'duration_s': repr(scenario.duration),
            'trajectory': json.dumps(result.metadata['trajectory']),
            'settings': json.dumps(dict(scenario.settings)),
            'gains': json.dumps(jsonable(ctrl.params.as_dict())),
            'control_rate_hz': repr(result.metadata['control_rate_hz']),
            'physics_rate_hz': repr(result.metadata['physics_rate_hz']),
            'generator': 'motor-comp simulate'}
    if scenario.controller == 'adaptive_sliding':
        meta['final_estimates'] = json.dumps(ctrl.estimates)
    if ctrl.compensation is not None:
        meta['compensation'] = json.dumps(ctrl.compensation.describe())
    return meta


def run(args: argparse.Namespace) -> int:
    """Simulate, report, optionally record; return the exit status."""
    from pathlib import Path

    from motor_comp.analysis.metrics import compute_metrics
    from motor_comp.errors import InputFileError

    scenario = scenario_from_args(args)
    if args.output:
        check_output_file(args.output, '-o')  # fail now, not after the simulation
    comp = compensation_from_args(args)
    t0 = time.perf_counter()
    result, ctrl = run_scenario(scenario, comp, engine=args.engine)
    wall = time.perf_counter() - t0
    name = args.name or (Path(args.output).stem if args.output else
                         f'{scenario.plant}-{scenario.controller}-{scenario.feedforward}')
    meta = run_metadata(scenario, ctrl, result)
    sim_run = result.to_run(name=name)
    metrics = compute_metrics(sim_run, glitch_window=args.glitch_window)
    if args.output:
        from motor_comp.logs import write_run
        try:
            write_run(args.output, sim_run, metadata=meta)
        except OSError as exc:
            raise InputFileError(f'{args.output}: cannot write ({exc.strerror or exc})') \
                from None
    entry = metrics.as_dict()
    entry.update({'plant': scenario.plant, 'controller': scenario.controller,
                  'feedforward': scenario.feedforward, 'seed': scenario.seed,
                  'simulated_s': scenario.duration, 'wall_s': wall,
                  'realtime_factor': scenario.duration / wall if wall > 0 else None})
    if scenario.controller == 'adaptive_sliding':
        entry['estimates'] = ctrl.estimates
        entry['nominal'] = ctrl.nominal
    if comp is not None:
        entry.update(comp.describe())
    if args.output:
        entry['path'] = str(args.output)
    if args.json:
        print(json.dumps(jsonable({'runs': [entry]}), allow_nan=False))
        return 0
    um = 1e6
    print(f'{name}: {scenario.duration:g} s simulated in {wall:.3f} s '
          f'({scenario.duration / max(wall, 1e-9):.0f}× real time)')
    print(f'  rms error   {metrics.rms_error * um:10.3f} µm')
    print(f'  max error   {metrics.max_error * um:10.3f} µm')
    if comp is not None:
        print(f'  {comp.summary()}')
    if metrics.max_glitch is not None:
        print(f'  glitches    {len(metrics.glitches):10d}   max {metrics.max_glitch * um:.3f} µm'
              f'   mean {metrics.mean_glitch * um:.3f} µm')
    if scenario.controller == 'adaptive_sliding':
        nominal = ctrl.nominal
        for k, v in ctrl.estimates.items():
            print(f'  {k:<12}{v:10.4g}   (nominal {nominal[k]:.4g})')
    if args.output:
        print(f'  recorded    {args.output}')
    sys.stdout.flush()
    return 0
