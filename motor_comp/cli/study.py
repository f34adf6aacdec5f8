"""``motor-comp study compensate``: from an ordinary recorded run to better tracking.

The loop a user runs on a real axis, measured in simulation where the truth is known:

1. **record** a closed-loop run of a plant with effects the nominal controller does not
   know (cogging, a constant force offset, Stribeck friction on top of the plant's own
   friction) under the plain feedback controller (PMLM: PID; ball-screw: N-PID), on an
   identification trajectory (a chirp with reversals, many speeds and several cogging
   periods of travel);
2. **fit** a model with ``fit --auto`` (:func:`motor_comp.workbench.fit.fit`) starting
   from the *bare* model — the drive's data only (mass, input gain, back-EMF, damping),
   no effect at all;
3. **compensate**: re-run the same trajectory with the fitted model as compensation
   (:mod:`motor_comp.control.compensation`: its full inverse dynamics, or with
   ``--compensation-terms effects`` its effects only), next to the two bounds — no
   compensation (lower bound) and the same terms of the true plant model (upper bound).

Prints RMS/max error and quadrant glitches of the three runs and the fraction of the
possible RMS reduction the fitted model recovers,
``(rms_none − rms_fitted) / (rms_none − rms_true)``.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any, Callable

from motor_comp.cli.common import add_json, jsonable, positive_float

PLANTS = ('pmlm', 'ballscrew')

#: effects hidden from the nominal controller, added to each plant's own (SI)
HIDDEN: dict[str, dict[str, dict[str, Any]]] = {
    # PMLM: the config already has Coulomb 10 N, Stribeck 20 N, viscous, 8.5 N ripple
    # at 20 mm; the cogging gets a second harmonic and a cable-drag offset is added
    'pmlm': {'ripple': {'period': 0.02, 'harmonics': [[8.5, 0.0], [2.5, 1.5]]},
             'offset': {'f0': 6.0}},
    # ball-screw: GMS friction and 1.29 ms dead time already; add cogging at the 5 mm
    # lead, an offset, and raise the Stribeck breakaway
    'ballscrew': {'ripple': {'period': 0.005, 'harmonics': [[4.0, 2.0]]},
                  'offset': {'f0': 5.0},
                  'stribeck': {'fs': 22.0, 'vs': 0.002, 'delta': 1.0}},
}

#: identification/evaluation trajectory of each plant (a chirp with reversals)
TRAJECTORY: dict[str, dict[str, float]] = {
    'pmlm': {'amplitude': 0.04, 'f_start': 0.1, 'f_end': 0.5, 'fade': 1.0},
    'ballscrew': {'amplitude': 0.02, 'f_start': 0.2, 'f_end': 1.5, 'fade': 1.0},
}
CONTROLLER = {'pmlm': 'pid', 'ballscrew': 'npid'}
#: measurement noise of the study's encoder [m] (before its 1 µm quantisation)
NOISE_STD = 2e-7


@dataclasses.dataclass(frozen=True)
class LoopRow:
    """Tracking metrics of one run of the loop study (SI: m)."""

    label: str
    rms_error: float
    max_error: float
    max_glitch: float | None
    mean_glitch: float | None


@dataclasses.dataclass(frozen=True)
class LoopResult:
    """The three runs of one plant and the recovered share of the possible reduction."""

    plant: str
    rows: tuple
    fitted_model: dict
    fit_steps: tuple
    recovery_rms: float
    recovery_glitch: float | None
    wall_s: float
    terms: str = 'full'

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {'plant': self.plant, 'compensation_terms': self.terms,
                'runs': [dataclasses.asdict(r) for r in self.rows],
                'recovery_rms': self.recovery_rms, 'recovery_glitch': self.recovery_glitch,
                'fit_steps': list(self.fit_steps), 'fitted_model': self.fitted_model,
                'wall_s': self.wall_s}


def study_plant(kind: str) -> Any:
    """Return the true plant of the study: the config plant with :data:`HIDDEN` effects."""
    from motor_comp.physics.config import load_plant
    from motor_comp.physics.effects import make_effect
    from motor_comp.physics.plant import Sensors
    cfg = load_plant(kind)
    model = cfg.model
    for name, params in HIDDEN[kind].items():
        model = model.with_effect(make_effect(name, params))
    # a real encoder: 1 µm quantum and 0.2 µm of noise (the seed draws it)
    sensors = Sensors(encoder_resolution=cfg.sensors.encoder_resolution,
                      noise_std=NOISE_STD, saturation=cfg.sensors.saturation)
    return dataclasses.replace(cfg.with_model(model), sensors=sensors)


def bare_model(model: Any) -> Any:
    """Return the drive's data only (mass, input gain, back-EMF, damping): no effect."""
    return model.without(*model.names)


def _metrics_row(label: str, res: Any) -> LoopRow:
    from motor_comp.analysis.metrics import compute_metrics
    m = compute_metrics(res.to_run(name=label))
    return LoopRow(label=label, rms_error=m.rms_error, max_error=m.max_error,
                   max_glitch=m.max_glitch, mean_glitch=m.mean_glitch)


def compensation_loop(kind: str, *, duration: float = 20.0, seed: int = 0,
                      out: Path | None = None, terms: str = 'full',
                      say: Callable[[str], None] = lambda s: None) -> LoopResult:
    """Record → ``fit --auto`` from the bare model → compensate, on plant ``kind``.

    ``terms`` (``full | effects``) are the terms of the fitted and of the true model
    sent as compensation (:class:`~motor_comp.control.compensation.CompensationTerms`).
    """
    from motor_comp.control import compensation
    from motor_comp.control.controller import make_controller
    from motor_comp.control.simulator import simulate
    from motor_comp.control.trajectories import make_trajectory
    from motor_comp.physics.config import load_plant
    from motor_comp.workbench.derivatives import kinematics
    from motor_comp.workbench.fit import fit
    from motor_comp.workbench.session import default_hold

    t0 = time.monotonic()
    true = study_plant(kind)
    # the controller's nominal plant is the plant file: it does not know the hidden
    # effects (and with feedback only — no friction feedforward — it uses none of them)
    nominal = load_plant(kind)
    traj = make_trajectory('chirp', duration=max(duration, 1.0), **TRAJECTORY[kind])

    def closed_loop(comp: Any) -> Any:
        ctrl = make_controller(CONTROLLER[kind], plant=nominal)
        ctrl.set_compensation(comp)
        return simulate(true, ctrl, traj, duration=duration, seed=seed)

    say(f'{kind}: recording {duration:g} s under {CONTROLLER[kind]} (no compensation)')
    base = closed_loop(None)
    run = base.to_run(name=f'{kind}_record')
    if out is not None:
        from motor_comp.logs import write_run
        write_run(out / f'{kind}_record.mcap', run,
                  metadata={'generator': 'motor-comp study compensate', 'plant': kind})
        true.model.save(out / f'{kind}_true.yaml')
    say(f'{kind}: fit --auto from the bare model')
    start = bare_model(true.model)
    kin = kinematics(run, hold=default_hold(start))
    result = fit(kin, start, auto=True, progress=lambda s: say(f'  {s}'))
    fitted = result.model
    if out is not None:
        fitted.save(out / f'{kind}_fitted.yaml')
    comp_fit = compensation.from_model(fitted, source=f'{kind} fitted', terms=terms)
    comp_true = compensation.from_model(true.model, source=f'{kind} true', terms=terms)
    say(f'{kind}: re-running with the fitted and with the true compensation')
    rows = (_metrics_row('uncompensated', base),
            _metrics_row('fitted compensation', closed_loop(comp_fit)),
            _metrics_row('true-plant compensation', closed_loop(comp_true)))
    none, fit_row, best = rows
    possible = none.rms_error - best.rms_error
    rec = (none.rms_error - fit_row.rms_error) / possible if possible > 0 else float('nan')
    rec_g = None
    if none.max_glitch and best.max_glitch is not None and fit_row.max_glitch is not None:
        pg = none.max_glitch - best.max_glitch
        rec_g = (none.max_glitch - fit_row.max_glitch) / pg if pg > 0 else None
    steps = tuple({'effect': s.effect, 'force_nrmse': float(s.force_nrmse)}
                  for s in result.steps)
    return LoopResult(plant=kind, rows=rows, fitted_model=fitted.to_dict(), fit_steps=steps,
                      recovery_rms=float(rec), recovery_glitch=rec_g,
                      wall_s=time.monotonic() - t0, terms=terms)


def print_loop(res: LoopResult) -> None:
    """Print one plant's table (µm) and the recovery."""
    um = 1e6
    print(f'{res.plant}: effects found by fit --auto from the bare model: '
          f'{", ".join(s["effect"] for s in res.fit_steps if s["effect"]) or "none"}; '
          f'compensation terms: {res.terms}')
    print(f'  {"run":<26}{"rms [µm]":>10}{"max [µm]":>10}{"max glitch":>12}'
          f'{"mean glitch":>13}')
    for r in res.rows:
        g = '-' if r.max_glitch is None else f'{r.max_glitch * um:.3f}'
        mg = '-' if r.mean_glitch is None else f'{r.mean_glitch * um:.3f}'
        print(f'  {r.label:<26}{r.rms_error * um:10.3f}{r.max_error * um:10.3f}'
              f'{g:>12}{mg:>13}')
    text = f'  fitted compensation recovers {100 * res.recovery_rms:.1f} % of the possible ' \
           f'RMS reduction'
    if res.recovery_glitch is not None:
        text += f' ({100 * res.recovery_glitch:.1f} % of the max-glitch reduction)'
    print(text + f'  [{res.wall_s:.0f} s]')


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``study`` subcommand (``study compensate``)."""
    p = subparsers.add_parser('study', help='measured studies: study compensate',
                              description=__doc__.splitlines()[0])
    sub = p.add_subparsers(dest='study', metavar='STUDY')
    sub.required = True
    c = sub.add_parser('compensate', help='record → fit --auto → compensate, vs the bounds',
                       description=__doc__.splitlines()[0])
    c.add_argument('--plant', choices=PLANTS + ('both',), default='both',
                   help='plant(s) to study (default both)')
    c.add_argument('--duration', type=positive_float, default=20.0, metavar='S',
                   help='recorded (and re-run) time [s] (default 20)')
    c.add_argument('--seed', type=int, default=0, help='measurement-noise seed')
    c.add_argument('--compensation-terms', choices=('full', 'effects'), default='full',
                   help='terms of the fitted and the true model sent: the full inverse '
                        'dynamics (default) or the effects only')
    c.add_argument('--out', type=Path, default=None, metavar='DIR',
                   help='keep the recorded run and the true/fitted models here')
    add_json(c)
    c.set_defaults(func=run)
    p.set_defaults(func=lambda a: p.error('choose a study: compensate'))


def run(args: argparse.Namespace) -> int:
    """Execute ``motor-comp study compensate``."""
    from motor_comp.errors import InputFileError
    if args.out is not None:
        try:
            args.out.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise InputFileError(f'--out {args.out}: cannot create directory '
                                 f'({exc.strerror or exc})') from None
    plants = PLANTS if args.plant == 'both' else (args.plant,)
    say = (lambda s: print(s, file=sys.stderr)) if args.json else \
        (lambda s: print(s, file=sys.stderr, flush=True))
    results = [compensation_loop(k, duration=args.duration, seed=args.seed, out=args.out,
                                 terms=args.compensation_terms, say=say) for k in plants]
    if args.json:
        print(json.dumps(jsonable({'plants': [r.as_dict() for r in results]})))
        return 0
    for r in results:
        print_loop(r)
    return 0
