"""An independent data generator for the workbench proof suites (issue 11 item 7, issue 23).

Deliberately different from the project's simulator (``motor_comp.physics`` /
``motor_comp.control``, which none of its modules imports — ``test_workbench_independent``
checks it):

* **integrator** — velocity-level time stepping (Moreau–Jean, as in non-smooth contact
  dynamics): semi-implicit Euler with the viscous force and the sticking GMS springs
  implicit, and dry friction as a set-valued law solved per step (the axis sticks when
  the friction needed to stop it within the step lies inside the break-away band).
  The project uses RK4 with a Karnopp switch and event location;
* **controller** — a P / PI cascade (position P, velocity PI) with velocity, acceleration
  and back-EMF feedforward, on a filtered backward-difference velocity; the project
  uses a PID on position error;
* **its own law implementations** of every effect of DESIGN.md §3/§6 (coulomb, viscous,
  Stribeck, GMS pre-sliding with 1–3 element shapes of its own, multi-harmonic ripple,
  offset, spring, asymmetry, dead time, backlash, gravity on rotary axes, and the new
  ``load_friction`` and ``position_friction`` — the latter through its own Hermite
  interpolation of the knots);
* **effects no unit of the library models** (issue 23): a friction drift over time
  (lubricant warm-up), a disturbance force at a fixed time frequency (a fan or pump),
  hydrodynamic drag ``c·v·|v|``, a localised force bump (a cable snag), a friction dip
  in a speed band (a lubrication regime) and a friction transient after each reversal
  (a lip seal flipping over) — each with the ground truth of where it acts;
* **experiments** users run: time-ordered back-and-forth speed sweeps (slow → fast, a
  dwell at every reversal), the same strokes with speeds interleaved in time, chirps and
  plain sine tracking; log rates 100 Hz – 2 kHz; quantised, noisy encoder; linear or
  rotary axes; input logged as a voltage command (ZOH), or as a measured current /
  force (sampled from a drive whose current loop has a lag, the controller running
  faster than the log).

The output is a :class:`motor_comp.logs.run.Run` (the project's run currency; the
:mod:`motor_comp.logs` writer turns it into MCAP), the TRUE model as a model-file
mapping (DESIGN.md §6), and what no model file holds: the planted out-of-library
effects (:class:`Planted`) and the noise added (:class:`NoiseTruth`).

Modules: :mod:`indgen_laws` (every law, the compiled closed loop), :mod:`indgen_excitation`
(the experiments), :mod:`indgen_rig` (rigs, drawn parameters, :func:`generate`),
:mod:`indgen_cases` (the case lists and their judging helpers); this module gathers
their public names and writes a case to files::

    python test/workbench/independent_generator.py "coulomb+viscous & drag [" -o DIR
    motor-comp fit DIR/run.mcap --model DIR/start.yaml --auto
"""
from __future__ import annotations

import sys
from pathlib import Path
from typing import Sequence

sys.path.insert(0, str(Path(__file__).resolve().parent))

from indgen_cases import ABS_TOLERANCE, ABS_TOLERANCE_ROTARY, ALONE, Case, CASE_LISTS, \
    CASES, COMBOS, COMPLETE_CASES, feature_matches, LOAD_FRICTION_SWEEP, main_params, \
    MASS_TOLERANCE, matching_feature, NEW_EFFECT_CASES, NEW_TOLERANCE, ORDINARY_PRESLIDING_CASES, \
    OUT_OF_LIBRARY_CASES, parameter_errors, TOLERANCE, WRONG  # noqa: E402
from indgen_excitation import chirp_reference, interleaved_reference, sine_reference, \
    sweep_reference, williams_orders  # noqa: E402
from indgen_laws import DRY_EXTRAS, EXTRA_NAMES  # noqa: E402
from indgen_rig import draw_case, draw_effect, draw_extra, draw_rig, draw_scenario, \
    drift_mean, EFFECT_NAMES, EXCITATIONS, Generated, generate, GMS_SHAPES, hermite, \
    NoiseTruth, Planted, position_friction_peak, reference, REQUIRES, Rig, start_model, \
    true_model, write  # noqa: E402

__all__ = [
    'ABS_TOLERANCE', 'ABS_TOLERANCE_ROTARY', 'ALONE', 'CASES', 'CASE_LISTS', 'COMBOS',
    'COMPLETE_CASES', 'Case', 'DRY_EXTRAS', 'EFFECT_NAMES', 'EXCITATIONS', 'EXTRA_NAMES',
    'GMS_SHAPES', 'Generated', 'LOAD_FRICTION_SWEEP', 'MASS_TOLERANCE', 'NEW_EFFECT_CASES',
    'NEW_TOLERANCE', 'NoiseTruth', 'ORDINARY_PRESLIDING_CASES', 'OUT_OF_LIBRARY_CASES',
    'Planted', 'REQUIRES', 'Rig', 'TOLERANCE', 'WRONG', 'chirp_reference', 'draw_case',
    'draw_effect', 'draw_extra', 'draw_rig', 'draw_scenario', 'drift_mean', 'feature_matches',
    'generate', 'hermite', 'interleaved_reference', 'main', 'main_params', 'matching_feature',
    'parameter_errors', 'position_friction_peak', 'reference', 'sine_reference', 'start_model',
    'sweep_reference', 'true_model', 'williams_orders', 'write']


def all_cases() -> list[Case]:
    """Every case of every list once (first list first), for lookups by label."""
    seen: dict[str, Case] = {}
    for cases in CASE_LISTS.values():
        for c in cases:
            seen.setdefault(c.label, c)
    return list(seen.values())


def main(argv: Sequence[str] | None = None) -> int:
    """Write one case as files: ``python independent_generator.py LABEL-PREFIX -o DIR``.

    Writes ``run.mcap``, ``truth.yaml`` (the true model), ``meta.yaml`` (noise and
    planted out-of-library effects) and ``start.yaml`` (the start model).  Then e.g.
    ``motor-comp fit DIR/run.mcap --model DIR/start.yaml --auto``.
    """
    import argparse
    p = argparse.ArgumentParser(description=main.__doc__.splitlines()[0],
                                allow_abbrev=False)
    p.add_argument('case', help='start of a case label, e.g. "coulomb+viscous [" (or "list")')
    p.add_argument('--seed', type=int, default=1)
    p.add_argument('--duration', type=float, default=20.0)
    p.add_argument('-o', '--out', default='indgen_case')
    a = p.parse_args(argv)
    cases = all_cases()
    if a.case == 'list':
        for name, lst in CASE_LISTS.items():
            print(f'# {name}')
            print('\n'.join(c.label for c in lst))
        return 0
    hits = [c for c in cases if c.label.startswith(a.case)]
    if not hits:
        p.error(f'no case label starts with {a.case!r} (try "list")')
    if not a.duration > 0 or a.seed < 0:
        p.error('--duration must be > 0 and --seed >= 0')
    case = hits[0]
    gen = case.make(a.seed, duration=a.duration)
    write(gen, a.out, start=case.start(gen.truth))
    print(f'{case.label} seed {a.seed}: {a.out}/run.mcap, truth.yaml, meta.yaml, start.yaml')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
