"""Simulation speed: the compiled closed loop against python-control and a plain-Python loop.

Loop: PMLM (config/pmlm.yaml: Coulomb + Stribeck + viscous friction, ripple, 1 µm
encoder) + adaptive sliding controller, physics 10 kHz, control 1 kHz, p2p trajectory.
Measured in the same run:

* ``simulate(engine='jit')`` in-process, start-up (numba cache load) excluded;
* ``motor-comp simulate --duration 600 --json`` end to end in a fresh process
  (interpreter, imports, cache load, simulation, metrics, JSON; no recording);
* references: python-control ``input_output_response`` on a comparable nonlinear PMLM +
  PID loop (a continuous ``nlsys`` closed loop with the same friction, ripple and PID
  gains, solved by scipy's RK45 and sampled at 1 kHz), and the plain-Python path
  ``simulate(engine='python')`` that steps the node wrappers one call at a time.
* a breakdown: the plant kernel alone (constant command) over the same span, which
  bounds what any loop around it can reach.

The machine may be shared by other jobs, so every figure is the CPU time of the work
(``time.process_time``; for the CLI the child's user+system time from ``getrusage``),
which other processes cannot inflate; the CLI's wall time is printed as well.

Usage: ``python bench/sim_speed.py [--seconds 120] [--ref-seconds 2]``
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time

import numpy as np


def _timed(fn, *args, **kw):
    """(CPU seconds of this process, result) of one call."""
    t0 = time.process_time()
    out = fn(*args, **kw)
    return time.process_time() - t0, out


def jit_loop(seconds: float) -> float:
    """CPU time [s] of ``seconds`` of in-process simulation (after a warm-up run)."""
    from motor_comp.control import default_trajectory, make_controller, simulate
    from motor_comp.physics import load_plant
    plant = load_plant('pmlm')
    traj = default_trajectory('pmlm')
    simulate(plant, make_controller('adaptive_sliding', plant=plant), traj, duration=0.1)
    ctrl = make_controller('adaptive_sliding', plant=plant)
    wall, _ = _timed(simulate, plant, ctrl, traj, duration=seconds)
    return wall


def python_loop(seconds: float) -> float:
    """CPU time [s] of the plain-Python engine (node wrappers stepped one by one)."""
    from motor_comp.control import default_trajectory, make_controller, simulate
    from motor_comp.physics import load_plant
    plant = load_plant('pmlm')
    traj = default_trajectory('pmlm')
    simulate(plant, make_controller('pid', plant=plant), traj, duration=0.01,
             engine='python')
    wall, _ = _timed(simulate, plant, make_controller('adaptive_sliding', plant=plant),
                     traj, duration=seconds, engine='python')
    return wall


def plant_only(seconds: float) -> float:
    """CPU time [s] of the plant kernel alone at 10 kHz (held command)."""
    from numba import njit

    from motor_comp.physics import Plant, load_plant
    from motor_comp.physics import kernel as K

    @njit
    def run(P, S, n, nsub):
        for k in range(n):
            K.plant_advance(P, S, 2.0 * np.sin(1e-3 * k), 0.0, nsub)

    pc = load_plant('pmlm')
    p = Plant(pc.model, sensors=pc.sensors)
    run(p.params, p.state, 10, 10)
    wall, _ = _timed(run, p.params, p.state, int(seconds * 1000), 10)
    return wall


def python_control(seconds: float) -> float:
    """CPU time [s] of python-control ``input_output_response`` on a PMLM + PID loop."""
    import control as ct

    from motor_comp.control import AdaptiveParams, default_trajectory
    from motor_comp.physics import load_plant
    m = load_plant('pmlm').model
    fc, fs, vs, delta = m.stribeck_curve_params()
    rip = m.get('ripple')
    w = 2 * np.pi / rip.period
    a1 = rip.harmonics[0][0]
    kp, ki, kd = AdaptiveParams().pid_gains
    tf = AdaptiveParams().tf
    traj = default_trajectory('pmlm')

    def update(t, s, u, params):
        x, v, integ, ed = s
        ref = traj.at(t)
        e = ref.position - x
        de = ref.velocity - v
        ed_dot = (de - ed) / tf           # first-order derivative filter
        volts = kp * e + ki * integ + kd * ed
        fric = np.sign(v) * (fc + (fs - fc) * np.exp(-abs(v / vs) ** delta)) + m.fv * v
        force = m.input_gain * (volts - m.back_emf * v) - fric - a1 * np.sin(w * x)
        return [v, force / m.mass, e, ed_dot]

    sys_ = ct.nlsys(update, None, states=4, inputs=0, outputs=4, name='pmlm_pid')
    t = np.arange(0.0, seconds, 1e-3)
    wall, _ = _timed(ct.input_output_response, sys_, t, 0.0, X0=[0, 0, 0, 0])
    return wall


def cli_end_to_end(seconds: float) -> float:
    """(CPU, wall) time [s] of ``motor-comp simulate … --json`` in a fresh process."""
    prog = ('import sys, motor_comp.cli.main as m; m.SUBCOMMANDS = ("simulate",); '
            'sys.exit(m.main(sys.argv[1:]))')
    cmd = [sys.executable, '-c', prog, 'simulate', '--plant', 'pmlm', '--controller',
           'adaptive_sliding', '--duration', str(seconds), '--json']
    subprocess.run(cmd, capture_output=True, check=True)   # warm the numba cache
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    out = subprocess.run(cmd, capture_output=True, check=True, text=True)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    json.loads(out.stdout)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return cpu, wall


def main() -> int:
    """Measure and print the Markdown table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--seconds', type=float, default=120.0, help='simulated span, jit [s]')
    ap.add_argument('--cli-seconds', type=float, default=600.0, help='span of the CLI run')
    ap.add_argument('--ref-seconds', type=float, default=2.0,
                    help='span of the slow references [s]')
    args = ap.parse_args()
    rows = []
    t_jit = jit_loop(args.seconds)
    rt_jit = args.seconds / t_jit
    t_ref = python_control(args.ref_seconds)
    rt_ref = args.ref_seconds / t_ref
    t_py = python_loop(args.ref_seconds)
    rt_py = args.ref_seconds / t_py
    t_plant = plant_only(args.seconds)
    rt_plant = args.seconds / t_plant
    t_cli, wall_cli = cli_end_to_end(args.cli_seconds)
    rt_cli = args.cli_seconds / t_cli
    rows.append((f'simulate jit, PMLM+adaptive, {args.seconds:g} s', f'{rt_jit:.0f}× RT',
                 'python-control input_output_response', f'{rt_ref:.2f}× RT',
                 f'{rt_jit / rt_ref:.0f}'))
    rows.append(('', '', "simulate engine='python'", f'{rt_py:.2f}× RT',
                 f'{rt_jit / rt_py:.0f}'))
    rows.append(('', '', 'plant kernel alone (bound)', f'{rt_plant:.0f}× RT',
                 f'{rt_jit / rt_plant:.2f}'))
    rows.append((f'motor-comp simulate --duration {args.cli_seconds:g} --json (process)',
                 f'{rt_cli:.0f}× RT ({t_cli:.2f} s CPU, {wall_cli:.2f} s wall)',
                 'real time', '1× RT', f'{rt_cli:.0f}'))
    rows.append(('', '', 'python-control input_output_response', f'{rt_ref:.2f}× RT',
                 f'{rt_cli / rt_ref:.0f}'))
    print('| command | figure | reference | reference figure | ratio |')
    print('|---|---|---|---|---|')
    for r in rows:
        print('| ' + ' | '.join(r) + ' |')
    print(f'\ngoals: in-process ≥ 1000× RT ({"met" if rt_jit >= 1000 else "NOT met"}), '
          f'CLI end to end ≥ 200× RT ({"met" if rt_cli >= 200 else "NOT met"})')
    return 0


if __name__ == '__main__':
    sys.exit(main())
