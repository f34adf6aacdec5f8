"""Simulation scaling: wall time of ``simulate`` against the simulated run length.

PMLM + adaptive sliding (physics 10 kHz, control 1 kHz) for 10 s … 1 h of simulated
time, in-process after a warm-up run; a least-squares line ``wall = a + b·length`` shows
that the cost is linear (constant per step, no growth with history).  The reference is
real time (b = 1).  The machine may be shared: the fit uses the process CPU time
(``time.process_time``), which other processes cannot inflate; wall time is shown too.

The cost per step depends on the motion: a sliding physics step costs ~95 ns, a stuck
one ~10 ns, so a run whose axis slides more of the time costs more per second.

Usage: ``python bench/sim_scaling.py [--lengths 10,30,100,300,1000,3600]``
"""
from __future__ import annotations

import argparse
import gc
import sys
import time

import numpy as np


def main() -> int:
    """Measure and print the Markdown table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument('--lengths', default='10,30,100,300,1000,3600',
                    help='simulated lengths [s], comma separated')
    args = ap.parse_args()
    lengths = [float(v) for v in args.lengths.split(',')]

    from motor_comp.control import default_trajectory, make_controller, simulate
    from motor_comp.physics import load_plant
    plant = load_plant('pmlm')
    traj = default_trajectory('pmlm')
    simulate(plant, make_controller('adaptive_sliding', plant=plant), traj, duration=0.1)
    walls = []
    print('| simulated length [s] | CPU [s] | wall [s] | real-time factor (CPU) | '
          'µs per control step |')
    print('|---|---|---|---|---|')
    for length in lengths:
        ctrl = make_controller('adaptive_sliding', plant=plant)
        gc.collect()
        t0, c0 = time.perf_counter(), time.process_time()
        res = simulate(plant, ctrl, traj, duration=length)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
        walls.append(cpu)
        print(f'| {length:g} | {cpu:.3f} | {wall:.3f} | {length / cpu:.0f}× | '
              f'{cpu / res.t.size * 1e6:.2f} |')
        del res
    x, y = np.array(lengths), np.array(walls)
    slope, intercept = np.polyfit(x, y, 1)
    pred = intercept + slope * x
    r2 = 1.0 - np.sum((y - pred) ** 2) / np.sum((y - y.mean()) ** 2)
    print(f'\nlinear fit: CPU = {intercept:.4f} s + {slope * 1e3:.3f} ms per simulated s '
          f'(R² = {r2:.4f}); asymptotic {1.0 / slope:.0f}× real time '
          f'(reference: real time, slope 1000 ms/s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
