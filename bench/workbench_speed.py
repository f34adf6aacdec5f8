#!/usr/bin/env python3
"""Workbench speed on every kind of run (issue 22 item 6), against the old code in the same run.

Goal: ``motor-comp fit RUN --model BARE.yaml --auto`` at least 20× faster than real time,
``motor-comp diagnose`` at least 60×, measured as the CPU time (user + system) of the
command's process less its start-up (the CPU time of ``motor-comp fit --help`` /
``diagnose --help``), on each kind of run the issue names:

* ``bench60``: the 60 s, 1 kHz bench run of ``bench/workbench.py`` (PMLM, PID, hidden
  ripple; bare model ``effects: {}`` with a 2× mass, as that script starts);
* ``ballscrew``: ``motor-comp simulate --plant ballscrew --controller npid --duration
  20`` (the ball-screw's N-PID run on its default trajectory; bare model: the
  controller's nominal model without its effects, mass 25 kg);
* ``hsm150``: a real run, substituting for the issue's 25 s, 1 kHz linear axis (no such
  data here): the HSM150 servo measurements of ``shared/data/hsm150`` (rotary, 1 kHz,
  20 s; imported with ``motor-comp import``), one run alone and the four first repeats
  as one experiment (80 s); bare model: rotary, torque input, the data set's nominal
  inertia J0 = 1.2153e-4 kg·m²;
* ``joint100``: substituting for robot-joint data (none here): a 60 s, 100 Hz rotary run
  with gravity, Coulomb and viscous friction from the independent generator
  (``test/workbench/independent_generator.py``, its case ``coulomb+viscous+gravity``
  at 100 Hz, current drive), written with the project's MCAP writer; bare model: the
  start model that case hands the workbench (``effects: {}``, 0.6× inertia).

Every command runs as a subprocess ``python -m motor_comp.cli.main …`` of this
interpreter, once per tree: this tree, and the reference commit (default ``608b6eb``,
the workbench before its rebuild) checked out in a temporary ``git worktree`` and run
with that worktree as the working directory (so ``motor_comp`` resolves to the old
tree; printed once).  Each tree is set up first as ``make setup`` sets it up: its
package byte-compiled (``compileall``), and its kernels compiled ahead of time where
the tree has ``motor_comp/physics/aot_build.py`` and they are not current.  Numba
compiles on first use and caches: one untimed ``fit --auto`` per run and tree comes
first.  The timed calls alternate tree by tree, and the median of ``--repeats`` calls
is reported.  CPU time, not wall time: the machine is shared, and another process
cannot inflate a child's own CPU account.

Usage: ``python bench/workbench_speed.py [--repeats N] [--reference REV | --no-reference]``
"""
from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Iterator, Sequence

import yaml

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
sys.path.insert(0, str(REPO))

#: the goals of issue 22 item 6 [× real time]
GOAL = {'fit': 20.0, 'diagnose': 60.0}
#: the workbench before its rebuild ("today's code" of issue 22)
REFERENCE = '608b6eb'
#: HSM150 data set (see its README.txt)
HSM_DIRS = (Path('/work/shared/data/hsm150'), REPO.parent / 'shared' / 'data' / 'hsm150',
            REPO.parents[1] / 'shared' / 'data' / 'hsm150')
#: HSM150 nominal inertia J0 [kg·m²] (Parameters_HSM150.m, quoted in the data's README)
HSM_J0 = 1.2153e-4


class UsageError(Exception):
    """A bad command-line option (reported on one line, exit 2)."""


class Parser(argparse.ArgumentParser):
    """Argument parser whose errors are one line (``workbench_speed.py: error: …``)."""

    def error(self, message: str) -> None:  # noqa: D102 - argparse's hook
        raise UsageError(message)


@dataclasses.dataclass(frozen=True)
class Case:
    """One kind of run: its MCAP file(s), bare start model and what it stands for."""

    key: str
    runs: tuple
    model: Path
    duration: float
    note: str
    extra: tuple = ()


@dataclasses.dataclass(frozen=True)
class Tree:
    """A source tree of motor_comp to run the CLI from (its directory is the cwd)."""

    label: str
    root: Path


@dataclasses.dataclass
class Timing:
    """CPU seconds of the timed calls of one command on one run in one tree."""

    cpu: list = dataclasses.field(default_factory=list)
    found: str = ''
    error: str = ''


# -- building the runs --------------------------------------------------------------
def run_duration(paths: Sequence[Path]) -> float:
    """Return the summed duration [s] of the MCAP runs ``paths`` (samples × median step)."""
    import numpy as np

    from motor_comp.logs import read_run
    total = 0.0
    for p in paths:
        t = np.asarray(read_run(p).t, dtype=float)
        total += len(t) * float(np.median(np.diff(t)))
    return total


def save_model(path: Path, data: dict) -> Path:
    """Write a model-file mapping (DESIGN.md §6) to ``path``."""
    path.write_text(yaml.safe_dump(data, sort_keys=False), encoding='utf-8')
    return path


def build_bench60(out: Path) -> Case:
    """Build the 60 s, 1 kHz bench run and bare model of ``bench/workbench.py``."""
    from motor_comp.logs import write_run
    from motor_comp.workbench.synthetic import scenario
    sc = scenario('ripple', seed=1)
    run = out / 'bench60.mcap'
    write_run(run, sc.run(duration=60.0, seed=1))
    p = sc.plant
    model = save_model(out / 'bench60.yaml', {
        'axis': 'linear', 'input': p.input.value, 'input_gain': float(p.input_gain),
        'back_emf': float(p.back_emf), 'damping': float(p.damping),
        'mass': 2.0 * float(p.mass), 'effects': {}})
    return Case('bench60', (run,), model, run_duration([run]),
                'PMLM, PID, hidden ripple, 1 kHz (bench/workbench.py); bare model with a '
                '2x mass')


def build_ballscrew(out: Path) -> Case:
    """Build the ball-screw's 20 s N-PID run (``motor-comp simulate``) and bare model."""
    from motor_comp.control.nominal import derive_nominal
    from motor_comp.physics.config import load_plant
    run = out / 'ballscrew.mcap'
    cmd = [sys.executable, '-m', 'motor_comp.cli.main', 'simulate', '--plant', 'ballscrew',
           '--controller', 'npid', '--duration', '20', '-o', str(run)]
    proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, env=child_env())
    if proc.returncode != 0:
        raise RuntimeError(f'simulate failed: {last_line(proc.stderr)}')
    nominal = derive_nominal(load_plant('ballscrew')).model.to_dict()
    nominal['effects'] = {}
    model = save_model(out / 'ballscrew.yaml', nominal)
    return Case('ballscrew', (run,), model, run_duration([run]),
                'motor-comp simulate --plant ballscrew --controller npid --duration 20; '
                f'bare nominal model, mass {nominal["mass"]:g} kg')


def hsm_dir() -> Path | None:
    """Return the HSM150 data folder, or None."""
    return next((d for d in HSM_DIRS if (d / 'idf_pos_0.065_1.mat').is_file()), None)


def build_hsm(out: Path, data: Path) -> tuple[Case, Case]:
    """HSM150 runs imported with ``motor-comp import``: one alone, four as one experiment."""
    runs = []
    for name in ('idf_pos_0.065_1', 'idf_pos_0.06_1', 'idf_neg_0.045_1', 'idf_neg_0.04_1'):
        dst = out / f'{name}.mcap'
        # columns: 0 time [s], 2 position [rad], 4 input torque command [N·m]
        cmd = [sys.executable, '-m', 'motor_comp.cli.main', 'import', str(data / f'{name}.mat'),
               '--time', '0', '--position', '2', '--input', '4', '-o', str(dst)]
        proc = subprocess.run(cmd, cwd=REPO, capture_output=True, text=True, env=child_env())
        if proc.returncode != 0:
            raise RuntimeError(f'import {name}: {last_line(proc.stderr)}')
        runs.append(dst)
    model = save_model(out / 'hsm150.yaml', {
        'axis': 'rotary', 'input': 'force', 'input_gain': 1.0, 'back_emf': 0.0,
        'mass': HSM_J0, 'effects': {}})
    # the logged input is the torque command: held, not a sampled measurement
    extra = ('--input-hold', 'zoh')
    one = Case('hsm150', (runs[0],), model, run_duration(runs[:1]),
               'REAL data, substitutes for the 25 s 1 kHz linear axis: HSM150 rotary servo, '
               'idf_pos_0.065_1 (1 kHz, 20 s); bare model, J0 = 1.2153e-4 kg m^2', extra)
    four = Case('hsm150x4', tuple(runs), model, run_duration(runs),
                'same, the four first repeats (+0.065, +0.06, -0.045, -0.04 N m) as one '
                'experiment', extra)
    return one, four


def build_joint(out: Path) -> Case:
    """Build a 60 s, 100 Hz rotary run with gravity with the independent generator."""
    sys.path.insert(0, str(REPO / 'test' / 'workbench'))
    import independent_generator as ig

    from motor_comp.logs import write_run
    case = next(c for c in ig.all_cases()
                if c.names == ('coulomb', 'viscous', 'gravity') and c.axis == 'rotary'
                and c.rate == 100.0 and not c.extra and not c.changes)
    gen = case.make(1, duration=60.0)
    run = out / 'joint100.mcap'
    write_run(run, gen.run)
    start = case.start(gen.truth)
    model = save_model(out / 'joint100.yaml', start)
    return Case('joint100', (run,), model, run_duration([run]),
                'SYNTHETIC, substitutes for robot-joint data: independent generator case '
                f'"{case.label}" seed 1, 60 s at 100 Hz, current drive; bare model '
                f'(effects {{}}, inertia {start["mass"] / gen.truth["mass"]:.1f}x true)')


def build_cases(out: Path, wanted: set) -> list[Case]:
    """Build the runs named in ``wanted`` (all if empty) in ``out``."""
    def want(key: str) -> bool:
        return not wanted or key in wanted
    cases: list[Case] = []
    if want('bench60'):
        cases.append(build_bench60(out))
    if want('ballscrew'):
        cases.append(build_ballscrew(out))
    if want('hsm150') or want('hsm150x4'):
        data = hsm_dir()
        if data is None:
            print('HSM150 data not found (shared/data/hsm150): its rows are skipped')
        else:
            cases += [c for c in build_hsm(out, data) if want(c.key)]
    if want('joint100'):
        cases.append(build_joint(out))
    return cases


# -- running and timing ----------------------------------------------------------------
def child_env() -> dict:
    """Environment of the CLI subprocesses (no stray PYTHONPATH; DDS on this host)."""
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    env.pop('PYTHONPATH', None)
    return env


def last_line(text: str) -> str:
    """Return the last non-empty line of ``text`` (a CLI's one-line error)."""
    lines = [ln for ln in text.splitlines() if ln.strip()]
    return lines[-1] if lines else '(no message)'


def timed(tree: Tree, args: Sequence[str]) -> tuple[float, subprocess.CompletedProcess]:
    """Run ``python -m motor_comp.cli.main ARGS`` in ``tree``; (child CPU s, process)."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', *args], cwd=tree.root,
                          capture_output=True, text=True, env=child_env())
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, proc


def command(kind: str, case: Case) -> list[str]:
    """CLI arguments of ``fit --auto`` or ``diagnose`` of ``case`` from its bare model."""
    head = ['fit'] if kind == 'fit' else ['diagnose']
    tail = ['--auto'] if kind == 'fit' else []
    return [*head, *map(str, case.runs), '--model', str(case.model), *case.extra, *tail,
            '--json']


def found(kind: str, stdout: str) -> str:
    """Say what a call found: the fitted effects (fit) or best candidate (diagnose)."""
    try:
        data = json.loads(stdout)
    except json.JSONDecodeError:
        return '(no JSON)'
    if kind == 'fit':
        model = data.get('model') or {}
        return '+'.join(model.get('effects') or {}) or '(none)'
    cands = data.get('candidates') or []
    best = next((c for c in cands if c.get('supported')), None)
    return best.get('effect', '?') if best else '(none supported)'


def which_motor_comp(tree: Tree) -> str:
    """``motor_comp.__file__`` as a child started in ``tree`` imports it."""
    proc = subprocess.run([sys.executable, '-c', 'import motor_comp; print(motor_comp.__file__)'],
                          cwd=tree.root, capture_output=True, text=True, env=child_env())
    return proc.stdout.strip() if proc.returncode == 0 else f'(import failed: ' \
        f'{last_line(proc.stderr)})'


def aot_check(tree: Tree) -> subprocess.CompletedProcess:
    """Run ``python -m motor_comp.physics.aot_build --check`` in ``tree`` (exit 0: current)."""
    return subprocess.run([sys.executable, '-m', 'motor_comp.physics.aot_build', '--check'],
                          cwd=tree.root, capture_output=True, text=True, env=child_env(),
                          check=False)


def compiled_kernels(tree: Tree) -> str:
    """Whether ``tree``'s kernels compiled ahead of time are in use (the build's own check)."""
    if not (tree.root / 'motor_comp' / 'physics' / 'aot_build.py').is_file():
        return 'none in this tree (the JIT)'
    return aot_check(tree).stdout.strip().removeprefix('compiled kernels: ')


@contextlib.contextmanager
def reference_tree(rev: str) -> Iterator[Tree | None]:
    """Check out ``rev`` in a temporary detached ``git worktree`` (None if unavailable)."""
    git = ['git', '-C', str(REPO)]
    try:
        probe = subprocess.run([*git, 'rev-parse', '--verify', '--quiet',
                                f'{rev}^{{commit}}'], capture_output=True, text=True)
    except OSError:     # no git on this machine
        probe = subprocess.CompletedProcess([], 1, '', '')
    if probe.returncode != 0:
        print(f'reference {rev}: not available in this clone (shallow, or git missing) — '
              f'reference skipped')
        yield None
        return
    sha = probe.stdout.strip()
    tmp = Path(tempfile.mkdtemp(prefix='wbspeed-ref-'))
    path = tmp / 'tree'
    add = subprocess.run([*git, 'worktree', 'add', '--detach', str(path), sha],
                         capture_output=True, text=True)
    if add.returncode != 0:
        print(f'reference {rev}: git worktree add failed ({last_line(add.stderr)}) — '
              f'reference skipped')
        tmp.rmdir()
        yield None
        return
    try:
        yield Tree(f'old {sha[:7]}', path)
    finally:
        subprocess.run([*git, 'worktree', 'remove', '--force', str(path)],
                       capture_output=True, text=True)
        subprocess.run([*git, 'worktree', 'prune'], capture_output=True, text=True)
        with contextlib.suppress(OSError):
            tmp.rmdir()


def prepare(tree: Tree) -> None:
    """Set ``tree`` up as ``make setup`` does: byte-compiled, its kernels compiled ahead of time.

    As installed: byte-compiled (pip compiles a regular install; an editable one compiles
    on first import unless PYTHONDONTWRITEBYTECODE is set, as here).  A tree with
    ``motor_comp/physics/aot_build.py`` gets its kernels built unless they are current
    (13–140 s): a reference without them would be timed with numba's JIT, which the
    setup of that commit did not leave in place.
    """
    subprocess.run([sys.executable, '-m', 'compileall', '-q', 'motor_comp'], cwd=tree.root,
                   capture_output=True, env=child_env(), check=False)
    if not (tree.root / 'motor_comp' / 'physics' / 'aot_build.py').is_file() \
            or aot_check(tree).returncode == 0:
        return
    built = subprocess.run([sys.executable, '-m', 'motor_comp.physics.aot_build'],
                           cwd=tree.root, capture_output=True, text=True, env=child_env(),
                           check=False)
    print(f'{tree.label}: {last_line(built.stdout + built.stderr)}')


def measure(cases: Sequence[Case], trees: Sequence[Tree], repeats: int) \
        -> tuple[dict, dict]:
    """Time start-up and both commands on every case in every tree, alternating trees.

    Returns ``(startup, timings)``: ``startup[(tree, kind)]`` the median CPU s of
    ``KIND --help``; ``timings[(case, kind, tree)]`` a :class:`Timing`.
    """
    startup: dict = {}
    timings: dict = {}
    for tree in trees:           # warm-up: numba compiles (and caches) on first use
        for case in cases:
            _, proc = timed(tree, command('fit', case))
            if proc.returncode != 0:
                print(f'warm-up {tree.label} {case.key}: {last_line(proc.stderr)}')
    for kind in ('fit', 'diagnose'):
        samples: dict = {t.label: [] for t in trees}
        for _ in range(repeats + 1):
            for tree in trees:
                samples[tree.label].append(timed(tree, [kind, '--help'])[0])
        for tree in trees:       # the first call of each tree is a warm-up too
            startup[(tree.label, kind)] = statistics.median(samples[tree.label][1:])
    for case in cases:
        for kind in ('fit', 'diagnose'):
            for tree in trees:
                timings[(case.key, kind, tree.label)] = Timing()
            for _ in range(repeats):
                for tree in trees:
                    cpu, proc = timed(tree, command(kind, case))
                    tm = timings[(case.key, kind, tree.label)]
                    if proc.returncode != 0:
                        tm.error = last_line(proc.stderr)
                        continue
                    tm.cpu.append(cpu)
                    tm.found = found(kind, proc.stdout)
            print(f'  measured {case.key} {kind}', file=sys.stderr, flush=True)
    return startup, timings


# -- report ----------------------------------------------------------------------------
def report(cases: Sequence[Case], trees: Sequence[Tree], startup: dict, timings: dict,
           repeats: int) -> None:
    """Print the Markdown tables: per run and command, CPU, × real time, speed-up, found."""
    new = trees[0].label
    old = trees[1].label if len(trees) > 1 else None
    print('\n## Start-up (CPU s of `KIND --help`, subtracted below)\n')
    print('| command | ' + ' | '.join(t.label for t in trees) + ' |')
    print('|---|' + '---|' * len(trees))
    for kind in ('fit', 'diagnose'):
        print(f'| {kind} --help | '
              + ' | '.join(f'{startup[(t.label, kind)]:.2f}' for t in trees) + ' |')
    for kind in ('fit', 'diagnose'):
        title = 'fit --auto' if kind == 'fit' else 'diagnose'
        print(f'\n## `{title}` from the bare model (goal >= {GOAL[kind]:g}x real time; '
              f'net CPU = median of {repeats} less start-up)\n')
        head = ['run', 'duration [s]', 'net CPU new [s]']
        if old:
            head += ['net CPU old [s]']
        head += ['x RT new']
        if old:
            head += ['x RT old', 'speed-up new/old']
        if kind == 'diagnose':
            head += ['x RT new, start-up = fit --help']
        # judged as the issue defines it: start-up is `fit --help` for both commands
        head += ['goal met (new, start-up = fit --help)', 'found new']
        if old:
            head += ['found old']
        print('| ' + ' | '.join(head) + ' |')
        print('|' + '---|' * len(head))
        for case in cases:
            cells = [case.key, f'{case.duration:.1f}']
            net = {}
            for tree in trees:
                tm = timings[(case.key, kind, tree.label)]
                if tm.cpu:
                    net[tree.label] = statistics.median(tm.cpu) - startup[(tree.label, kind)]
            cells.append(f'{net[new]:.2f}' if new in net else 'failed')
            if old:
                cells.append(f'{net[old]:.2f}' if old in net else 'failed')
            ratio = {k: case.duration / v for k, v in net.items() if v > 0}
            cells.append(f'{ratio[new]:.1f}' if new in ratio else '—')
            if old:
                cells.append(f'{ratio[old]:.1f}' if old in ratio else '—')
                cells.append(f'{net[old] / net[new]:.2f}' if new in ratio and old in ratio
                             else '—')
            met = new in ratio and ratio[new] >= GOAL[kind]
            if kind == 'diagnose':
                # the issue names one start-up, `fit --help`, which imports the library
                # (numpy, numba); `diagnose --help` imports none of it
                tm = timings[(case.key, kind, new)]
                alt = statistics.median(tm.cpu) - startup[(new, 'fit')] if tm.cpu else 0.0
                cells.append(f'{case.duration / alt:.1f}' if alt > 0 else '—')
                met = alt > 0 and case.duration / alt >= GOAL[kind]
            cells.append('yes' if met else '**no**')
            for tree in trees:
                tm = timings[(case.key, kind, tree.label)]
                cells.append(tm.found or f'error: {tm.error}')
            print('| ' + ' | '.join(cells) + ' |')
    print('\nruns:')
    for case in cases:
        print(f'- {case.key} ({case.duration:.1f} s): {case.note}')
    spread = []
    for (key, kind, label), tm in timings.items():
        if len(tm.cpu) > 1:
            spread.append(f'{key}/{kind}/{label.split()[0]} {min(tm.cpu):.2f}–{max(tm.cpu):.2f}')
    if spread:
        print('\nspread of the raw CPU s (min–max over the repeats, start-up included): '
              + '; '.join(spread))


def parse(argv: Sequence[str] | None) -> argparse.Namespace:
    """Parse and check the options (:class:`UsageError` on a bad one)."""
    ap = Parser(prog='workbench_speed.py', description=__doc__.splitlines()[0])
    ap.add_argument('--repeats', type=int, default=3,
                    help='timed calls per command, run and tree; the median is reported '
                         '(default 3)')
    ap.add_argument('--reference', default=REFERENCE, metavar='REV',
                    help=f'commit to compare with (default {REFERENCE}, the workbench before '
                         f'its rebuild)')
    ap.add_argument('--no-reference', action='store_true', help='time this tree only')
    ap.add_argument('--keep', metavar='DIR',
                    help='write the runs and bare models to DIR (a new or empty folder) and '
                         'keep them')
    ap.add_argument('--runs', nargs='+', metavar='KEY',
                    choices=('bench60', 'ballscrew', 'hsm150', 'hsm150x4', 'joint100'),
                    help='only these runs (default: all)')
    args = ap.parse_args(argv)
    if args.repeats < 1:
        raise UsageError(f'--repeats must be >= 1, got {args.repeats}')
    if args.keep:
        keep = Path(args.keep)
        if keep.exists() and (not keep.is_dir() or any(keep.iterdir())):
            raise UsageError(f'--keep {args.keep}: exists and is not an empty folder')
    if not args.reference.strip() or args.reference.startswith('-'):
        raise UsageError(f'--reference must name a commit, got {args.reference!r}')
    return args


def main(argv: Sequence[str] | None = None) -> int:
    """Build the runs, time both trees, print the tables."""
    try:
        args = parse(argv)
    except UsageError as exc:
        print(f'workbench_speed.py: error: {exc}', file=sys.stderr)
        return 2
    wanted = set(args.runs or ())
    t0 = time.perf_counter()
    print('# Workbench speed on every kind of run (issue 22 item 6)\n')
    print(f'measured {time.strftime("%Y-%m-%d %H:%M UTC", time.gmtime())}; load average '
          f'{" ".join(f"{x:.2f}" for x in os.getloadavg())} at the start '
          f'({os.cpu_count()} cores)')
    with contextlib.ExitStack() as stack:
        if args.keep:
            out = Path(args.keep)
            out.mkdir(parents=True, exist_ok=True)
        else:
            out = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix='wbspeed-')))
        try:
            cases = build_cases(out, wanted)
        except (RuntimeError, OSError) as exc:
            print(f'workbench_speed.py: error: building the runs: {exc}', file=sys.stderr)
            return 1
        if args.keep:
            print(f'runs and bare models kept in {out}')
        new = Tree('new', REPO)
        ref_ctx = contextlib.nullcontext(None) if args.no_reference \
            else reference_tree(args.reference)
        with ref_ctx as ref:
            trees = [new] + ([ref] if ref is not None else [])
            for tree in trees:
                prepare(tree)
                print(f'{tree.label}: motor_comp from {which_motor_comp(tree)}; kernels '
                      f'compiled ahead of time: {compiled_kernels(tree)}')
            startup, timings = measure(cases, trees, args.repeats)
        report(cases, trees, startup, timings, args.repeats)
    print(f'\nload average at the end {" ".join(f"{x:.2f}" for x in os.getloadavg())}; '
          f'{time.perf_counter() - t0:.0f} s in all')
    failed = any(tm.error for tm in timings.values())
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
