#!/usr/bin/env python3
"""The processing choice: force NRMSE of the TRUE model, new processing against Savitzky–Golay.

On data the project did not generate (``test/workbench/independent_generator.py``) and
with the model the generator planted, the force residual is what the processing adds
(plus the generator's noise, the same for both).  Per run, in the same process on the
same :class:`~motor_comp.workbench.derivatives.Kinematics`:

* **new** — the project's one figure definition,
  ``model_nrmse(dataset_for([kin], model), model)`` (:mod:`motor_comp.workbench.processing`:
  Blackman smoother ``S`` on the drive force and every effect's force, acceleration the
  3-point second difference of ``S·x``, sliding rows away from stops, every ``W/8``-th);
* **SG** — the reference, the Savitzky–Golay processing the first ``compare`` used
  (608b6eb ``motor_comp/workbench/residual.py``), reimplemented here because that
  module no longer exists in the tree: ``r = S[F_in(u(t − τ), ẋ)] − M·ẍ − S[Σ_k
  F_k(x, ẋ)]`` with ``S``, ``ẋ``, ``ẍ`` from ``scipy.signal.savgol_filter`` (window
  0.02 s, order 3), forces from :meth:`AxisModel.input_force` and
  :meth:`AxisModel.effect_forces`, rows the old sliding mask, ``RMS(r)/RMS(F_in −
  mean)`` on them.

Printed: one line per (case, seed) with both NRMSEs and their ratio new/SG, and — to
tell the row choice from the filters — the SG residual on the new processing's rows;
then the medians, the share of runs where the new processing leaves less, and the same
per list, input kind, log rate and experiment.  Out-of-library cases (``--list
out-of-library``) carry a planted effect the true model file lacks: there the residual
is that effect, not the processing alone.  A case in several lists is measured once,
under the first list given.

Usage: ``python bench/processing_choice.py [--seeds 3] [--first-seed 1] [--duration 20]
[--jobs 1] [--filter TEXT] [--list suite|out-of-library|new-effects|
ordinary-presliding|complete ...]``
"""
from __future__ import annotations

import argparse
import dataclasses
import math
import sys
import time
from collections import defaultdict
from pathlib import Path
from typing import Iterable

import numpy as np
from scipy.signal import savgol_coeffs

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'test' / 'workbench'))

from independent_generator import CASE_LISTS, Case  # noqa: E402
from test_workbench_independent import as_model  # noqa: E402

from motor_comp.physics.axis import AxisModel  # noqa: E402
from motor_comp.workbench.derivatives import Kinematics, kinematics  # noqa: E402
from motor_comp.workbench.library import dataset_for  # noqa: E402
from motor_comp.workbench.motion import motor_position  # noqa: E402
from motor_comp.workbench.residual import model_nrmse  # noqa: E402
from motor_comp.workbench.session import default_hold  # noqa: E402


@dataclasses.dataclass(frozen=True)
class Measured:
    """Both processings' NRMSE of the true model on one generated run.

    Parameters
    ----------
    label, list_name : str
        Case label and the case list it came from.
    seed : int
        Generator seed.
    input, excitation : str
        Logged input kind and experiment of the case.
    rate : float
        Log rate [Hz].
    new, sg : float
        Force NRMSE of the new processing and of the Savitzky–Golay reference.
    sg_on_new_rows : float
        The SG residual's NRMSE on the new processing's rows.
    rows_new, rows_sg : int
        Samples each figure is computed on.
    seconds : float
        Wall time of generating and measuring the run [s].
    """

    label: str
    list_name: str
    seed: int
    input: str
    rate: float
    excitation: str
    new: float
    sg: float
    sg_on_new_rows: float
    rows_new: int
    rows_sg: int
    seconds: float

    @property
    def ratio(self) -> float:
        """Return NRMSE new / NRMSE SG (below 1: the new processing leaves less)."""
        return self.new / self.sg if self.sg > 0 else math.inf


# ---------------------------------------------------------------- the SG reference
# Reimplemented from 608b6eb motor_comp/workbench/residual.py (``sliding_mask``,
# ``residual``, ``force_nrmse``): that module no longer exists in the tree.  The
# Kinematics it ran on (savgol_filter position, velocity, acceleration; ``smooth`` with
# mirror padding; ``input_at``) and the backlash reconstruction ``motor_position`` are
# unchanged in the current tree (``derivatives.py``, ``motion.py``), so they are used
# as they are.  Checked: on 10 suite cases (every 4th, seed 1) these functions give
# NRMSEs bit-identical to 608b6eb's own ``residual(kin, model).nrmse()``.

def sg_sliding_mask(kin: Kinematics) -> np.ndarray:
    """Select the old sliding rows: |ẋ| above 5× its estimation noise, ≥ 0.2 % of peak.

    The velocity noise of the Savitzky–Golay derivative is the position noise (or the
    encoder quantum's, when larger) times the filter's noise gain; the first and last
    derivative window are excluded (the filter's transient).
    """
    coeff_noise = np.sqrt(np.sum(savgol_coeffs(kin.window, kin.polyorder, deriv=1) ** 2))
    sigma_x = max(kin.noise_std(), kin.quantum() / np.sqrt(12.0))
    v_min = 5.0 * sigma_x * coeff_noise / kin.dt
    v_min = max(v_min, 2e-3 * float(np.max(np.abs(kin.v))))
    m = np.abs(kin.v) > v_min
    m[:kin.window] = False
    m[-kin.window:] = False
    return m


def sg_residual(kin: Kinematics, model: AxisModel) -> tuple[np.ndarray, np.ndarray]:
    """Return the old ``(r, S·F_in)`` [N] at every sample (the 608b6eb inverse model).

    ``r = S[F_in(u(t − τ), ẋ_m)] − M·ẍ_m − S[Σ_k F_k(x_m, ẋ_m)]``, ``S`` the
    Savitzky–Golay smoothing of the position, ``x_m`` the measured position or, with
    ``backlash``, the motor position reconstructed across the gap.
    """
    bl = model.get('backlash')
    dly = model.get('delay')
    tau = dly.tau if dly is not None else 0.0
    u = kin.input_at(tau)
    if bl is not None and bl.width > 0:
        x, v, a = kin.derivatives(motor_position(kin, bl.width, model, kin.u, tau=tau))
    else:
        x, v, a = kin.x, kin.v, kin.a
    f_raw = model.input_force(u, v)
    f_in = kin.smooth(f_raw)
    # today's effect_forces needs the drive force for load_friction (an effect the old
    # code did not know); every other law ignores it
    forces = model.effect_forces(x, v, dt=kin.dt, f_in=f_raw)
    total = np.zeros(len(kin))
    for f in forces.values():
        total += kin.smooth(f)
    return f_in - model.mass * a - total, f_in


def force_nrmse(r: np.ndarray, f_in: np.ndarray) -> float:
    """Return ``RMS(r)/RMS(F_in − mean(F_in))`` (the old ``force_nrmse``)."""
    den = float(np.sqrt(np.mean((f_in - np.mean(f_in)) ** 2)))
    num = float(np.sqrt(np.mean(r ** 2)))
    return num / den if den > 0 else math.inf


# ---------------------------------------------------------------- one run

def measure(job: tuple[str, Case, int, float]) -> Measured | tuple[str, int, str]:
    """Generate one case and seed; return both NRMSEs of its true model (or the error)."""
    list_name, case, seed, duration = job
    t0 = time.perf_counter()
    try:
        gen = case.make(seed, duration=duration)
        model = as_model(gen.truth, source='truth')
        kin = kinematics(gen.run, hold=default_hold(model))
        data = dataset_for([kin], model)
        new = model_nrmse(data, model)
        r, f_in = sg_residual(kin, model)
        m = sg_sliding_mask(kin)
        rows = data.parts[0].rows
    except Exception as exc:  # a crash is reported as a row with its reason
        return case.label, seed, f'{type(exc).__name__}: {exc}'
    return Measured(label=case.label, list_name=list_name, seed=seed, input=case.input,
                    rate=case.rate, excitation=case.excitation, new=new,
                    sg=force_nrmse(r[m], f_in[m]),
                    sg_on_new_rows=force_nrmse(r[rows], f_in[rows]),
                    rows_new=len(rows), rows_sg=int(np.count_nonzero(m)),
                    seconds=time.perf_counter() - t0)


def _results(jobs: list, n_jobs: int) -> Iterable:
    if n_jobs <= 1 or len(jobs) < 2:
        return map(measure, jobs)
    import multiprocessing as mp
    # spawn: no fork of a process holding numba/BLAS threads; the workers import this
    # file, whose top level puts the repository and the generator on sys.path
    pool = mp.get_context('spawn').Pool(n_jobs)
    return _drain(pool, pool.imap(measure, jobs, chunksize=1))


def _drain(pool, it: Iterable) -> Iterable:
    with pool:
        yield from it


# ---------------------------------------------------------------- tables

def _line(o: Measured) -> str:
    return (f'| {o.label} | {o.seed} | {o.new:.5f} | {o.sg:.5f} | {o.ratio:.3f} | '
            f'{o.sg_on_new_rows:.5f} | {o.rows_new} / {o.rows_sg} | {o.seconds:.1f} |')


def _group_row(name: str, outs: list[Measured]) -> str:
    ratio = np.array([o.ratio for o in outs])
    new = np.array([o.new for o in outs])
    sg = np.array([o.sg for o in outs])
    own = np.array([o.new / o.sg_on_new_rows if o.sg_on_new_rows > 0 else math.inf
                    for o in outs])
    wins = int(np.count_nonzero(new < sg))
    return (f'| {name} | {len(outs)} | {np.median(new):.5f} | {np.median(sg):.5f} | '
            f'{np.median(ratio):.3f} ({np.quantile(ratio, 0.1):.3f}–'
            f'{np.quantile(ratio, 0.9):.3f}) | {wins}/{len(outs)} '
            f'({100 * wins / len(outs):.0f} %) | {np.median(own):.3f} |')


def summary(outs: list[Measured], n_crashed: int) -> None:
    """Print the overall and per-group summary of the measured runs."""
    print(f'\n## Summary over {len(outs)} runs ({n_crashed} crashed)\n')
    print('ratio = NRMSE new / NRMSE SG per run (median, 10–90 % in brackets); '
          '"same rows" = new / SG-on-the-new-rows (the filters alone)\n')
    print('| group | runs | median NRMSE new | median NRMSE SG | ratio | new < SG | '
          'ratio, same rows |')
    print('|---|---|---|---|---|---|---|')
    print(_group_row('all', outs))
    groups: dict[str, list[Measured]] = defaultdict(list)
    lists = {o.list_name for o in outs}
    for o in outs:
        if len(lists) > 1:
            groups[f'list {o.list_name}'].append(o)
        groups[f'input {o.input}'].append(o)
        groups[f'rate {o.rate:g} Hz'].append(o)
        groups[f'experiment {o.excitation}'].append(o)
    for name in sorted(groups, key=lambda k: (k.split()[0], _num(k))):
        print(_group_row(name, groups[name]))


def _num(key: str) -> tuple:
    # rates sort numerically, everything else by name
    word = key.split()[1]
    try:
        return (0, float(word), '')
    except ValueError:
        return (1, 0.0, word)


def main() -> int:
    """Measure both processings on the independent generator's cases; print the tables."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument('--seeds', type=int, default=3, help='seeds per case')
    p.add_argument('--first-seed', type=int, default=1, help='first seed')
    p.add_argument('--duration', type=float, default=20.0, help='run length [s]')
    p.add_argument('--jobs', type=int, default=1, help='parallel worker processes')
    p.add_argument('--filter', default='', help='only cases whose label contains this')
    p.add_argument('--list', action='append', choices=sorted(CASE_LISTS), dest='lists',
                   help='case list(s) to run (repeatable; default: suite, the CASES)')
    args = p.parse_args()
    if args.seeds < 1 or args.first_seed < 1 or args.jobs < 1 or not args.duration > 0:
        p.error('--seeds, --first-seed and --jobs must be >= 1 and --duration > 0')
    lists = list(dict.fromkeys(args.lists or ['suite']))
    # a case in several lists (``complete`` repeats the suite's in-library cases) is
    # the same run: measured once, under the first list that names it
    cases: dict[str, tuple[str, Case]] = {}
    for name in lists:
        for c in CASE_LISTS[name]:
            if args.filter in c.label:
                cases.setdefault(c.label, (name, c))
    if not cases:
        p.error(f'no case label contains {args.filter!r}')
    jobs = [(name, c, s, args.duration) for name, c in cases.values()
            for s in range(args.first_seed, args.first_seed + args.seeds)]
    print(f'command: python bench/processing_choice.py --seeds {args.seeds} '
          f'--first-seed {args.first_seed} --duration {args.duration:g} --jobs {args.jobs}'
          + (f' --filter {args.filter!r}' if args.filter else '')
          + ''.join(f' --list {n}' for n in (args.lists or ())))
    print(f'\n## True model, {len(jobs)} runs ({len(cases)} cases × {args.seeds} seeds): '
          'new processing vs Savitzky–Golay\n')
    print('| case | seed | NRMSE new | NRMSE SG | new / SG | SG on new rows | '
          'rows new / SG | [s] |')
    print('|---|---|---|---|---|---|---|---|')
    t0 = time.perf_counter()
    outs: list[Measured] = []
    for o in _results(jobs, args.jobs):
        if isinstance(o, tuple):
            print(f'| {o[0]} | {o[1]} | ERROR | | | | | {o[2]} |', flush=True)
            continue
        outs.append(o)
        print(_line(o), flush=True)
    if outs:
        summary(outs, len(jobs) - len(outs))
    print(f'\ntotal {time.perf_counter() - t0:.0f} s')
    return 0 if outs else 1


if __name__ == '__main__':
    sys.exit(main())
