"""Sweep throughput: points/s of a 2 000-point sweep, Dask vs process pool vs one process.

Each point is a 5 s closed-loop PMLM run (PID, physics 10 kHz, control 1 kHz) plus the
``motor-comp sweep`` metrics (DESIGN.md §6), varied over true Coulomb friction, gain
and noise seed.  Measured in one run, on warm workers (numba caches loaded, cluster
started — a real cluster is long-lived):

* **one process** — the points one after the other in this process: the single-run
  speed; ``single × cores`` is the limit of any parallel executor on this machine;
* **process pool** — :func:`run_sweep` on a local ``ProcessPoolExecutor`` (cores
  workers), points grouped into batches (default batch size);
* **Dask local** — :func:`run_sweep` on a ``LocalCluster`` of 2 single-threaded
  workers (loopback only), batched; and the same with 1 point per task, to show what
  grouping buys.

The ratio column is points/s ÷ (single × cores).  On a shared machine other processes
take cores away from the parallel runs, which lowers that ratio without any fault of
the executor; so the table also gives the CPU cost per point (CPU seconds of this
process, the scheduler and all workers, via ``psutil``) against the one-process CPU
cost per point: a ratio near 1 means the executor adds no overhead, whatever the load.

Usage: ``python bench/sweep_speed.py [--points 2000] [--duration 5]``
"""
from __future__ import annotations

import argparse
import concurrent.futures
import os
import sys
import time

import psutil


def _cpu(pids) -> float:
    """CPU seconds (user + system) of this process and the processes ``pids``."""
    total = 0.0
    for pid in [os.getpid(), *pids]:
        try:
            c = psutil.Process(pid).cpu_times()
        except psutil.Error:
            continue
        total += c.user + c.system
    return total


def main() -> int:
    """Measure and print the Markdown table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument('--points', type=int, default=2000, help='grid points (multiple of 20)')
    ap.add_argument('--duration', type=float, default=5.0, help='simulated time per point [s]')
    ap.add_argument('--single', type=int, default=200,
                    help='points timed in one process (the reference)')
    args = ap.parse_args()

    from motor_comp.cli.sweep import AnalysisMetrics
    from motor_comp.control.sweep import (SweepStats, close_client, dask_client,
                                          default_batch_size, expand_grid, run_point,
                                          run_sweep)
    cores = os.cpu_count() or 1
    n_gain = max(1, args.points // 20)
    grid = {'kp': [2.0e4 + 200.0 * i for i in range(n_gain)],
            'plant.coulomb.fc': [5.0, 7.5, 10.0, 12.5, 15.0],
            'seed': [0, 1, 2, 3]}
    base = {'plant': 'pmlm', 'controller': 'pid', 'duration': args.duration}
    points = expand_grid(base, grid)
    metrics = AnalysisMetrics(0.2)
    print(f'grid: {len(points)} points of {args.duration:g} s PMLM + PID; {cores} cores',
          file=sys.stderr)

    # one process: the single-run speed (after a warm-up run)
    run_point(points[0], metrics)
    sample = points[:max(2, args.single)]
    half = len(sample) // 2
    rates, cpus = [], []
    for part in (sample[:half], sample[half:]):
        t0, c0 = time.perf_counter(), time.process_time()
        for p in part:
            r = run_point(p, metrics)
            assert r.ok, r.error
        rates.append(len(part) / (time.perf_counter() - t0))
        cpus.append((time.process_time() - c0) / len(part))
    single = max(rates)
    cpu_single = min(cpus)
    limit = single * cores

    rows = [('one process (reference: single-run speed)', single, len(sample), '1 run',
             cpu_single)]

    def timed(label: str, executor, batch: int | None, workers: int, pids) -> None:
        stats = SweepStats()
        c0 = _cpu(pids)
        t0 = time.perf_counter()
        res = run_sweep(points, executor=executor, metrics=metrics, batch_size=batch,
                        max_workers=workers, validate=False, stats=stats)
        dt = time.perf_counter() - t0
        cpu = (_cpu(pids) - c0) / len(points)
        assert len(res) == len(points) and all(r.ok for r in res)
        size = batch or default_batch_size(len(points), workers)
        rows.append((label, len(points) / dt, len(points),
                     f'{size} ({stats.tasks} tasks, ≤ {stats.peak_pending} pending)', cpu))
        print(f'{label}: {len(points) / dt:.1f} points/s', file=sys.stderr)

    with concurrent.futures.ProcessPoolExecutor(max_workers=cores) as pool:
        list(pool.map(run_point, points[:cores], [metrics] * cores))     # warm workers
        timed(f'process pool, {cores} workers, batched', pool, None, cores,
              list(pool._processes))

    client = dask_client('local:2', timeout=120)
    try:
        client.wait_for_workers(2, timeout=120)
        run_sweep(points[:4], executor=client, metrics=metrics, batch_size=1,
                  validate=False)                                        # warm workers
        pids = list(client.run(os.getpid, nanny=False).values())
        timed('Dask LocalCluster, 2 workers, batched', client, None, 2, pids)
        timed('Dask LocalCluster, 2 workers, 1 point per task', client, 1, 2, pids)
    finally:
        close_client(client)

    print(f'Command: `python bench/sweep_speed.py --points {len(points)} '
          f'--duration {args.duration:g}`; {cores} cores; limit = single-run speed × cores '
          f'= {limit:.1f} points/s; load average {os.getloadavg()[0]:.1f} '
          f'(other processes share the cores).\n')
    print('| executor | points | points/s | ratio to single × cores | CPU ms per point | '
          'CPU per point: single / this | points per task |')
    print('|---|---|---|---|---|---|---|')
    for label, rate, n, batch, cpu in rows:
        print(f'| {label} | {n} | {rate:.1f} | {rate / limit:.2f} | {cpu * 1e3:.1f} | '
              f'{cpu_single / cpu:.2f} | {batch} |')
    return 0


if __name__ == '__main__':
    sys.exit(main())
