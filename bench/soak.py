#!/usr/bin/env python3
"""Soak: one long lockstep run of the four node processes; memory growth per node.

Each node logs ``resources: cpu_s=… rss_start_mib=… rss_end_mib=…`` at a clean exit
(RSS sampled 5 s after start, i.e. after imports, numba cache loads and discovery, and
again at the end).  The table reports the growth per node, the loop rate, and checks
that the recorded MCAP holds every step (read back with ``read_run``).

Usage: ``python bench/soak.py [--duration S]`` (sim seconds at 1 kHz; default 600 s,
≈ 5–8 minutes of wall time on a 2-core machine; ``--duration 3600`` is the full hour).
"""
from __future__ import annotations

import argparse
import re
import sys
import tempfile
import time
from pathlib import Path

from motor_comp.cli.run import RunSpec, private_domain_id, run_nodes
from motor_comp.logs import read_run

_RES = re.compile(r'\[axis\.(\w+)\]: resources: cpu_s=([\d.]+) rss_start_mib=([\d.na]+) '
                  r'rss_end_mib=([\d.]+)')
_TIME = re.compile(r'\[INFO\] \[(\d+\.\d+)\] \[axis\.plant_node\]: (peers matched|run complete)')


def main() -> int:
    """Run the soak and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--duration', type=float, default=600.0, help='sim seconds (1 kHz)')
    ap.add_argument('--plant', default='ballscrew')
    ap.add_argument('--controller', default='npid')
    ap.add_argument('--feedforward', default='static+gms')
    ap.add_argument('--keep', type=Path, default=None, help='keep the MCAP and logs here')
    ap.add_argument('--trace-memory', action='store_true',
                    help="recorder: tracemalloc growth sites in its log ('memory:' lines)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix='motor_comp_soak_') as tmp:
        work = args.keep or Path(tmp)
        work.mkdir(parents=True, exist_ok=True)
        spec = RunSpec(output=work / 'soak.mcap', plant=args.plant,
                       controller=args.controller, feedforward=args.feedforward,
                       duration=args.duration,
                       extra_params={'recorder_node': {'trace_memory': args.trace_memory,
                                                       'memory_log_interval': 20.0}})
        t0 = time.monotonic()
        run_nodes(spec, workdir=work, domain_id=private_domain_id(),
                  timeout=120 + 10 * args.duration, progress=True)
        wall = time.monotonic() - t0
        rows, stamps = {}, {}
        for log in work.glob('*.log'):
            text = log.read_text(errors='replace')
            for m in _RES.finditer(text):
                rows[m.group(1)] = tuple(float(g) for g in m.group(2, 3, 4))
            for m in _TIME.finditer(text):
                stamps[m.group(2)] = float(m.group(1))
        memory = [ln.split(': memory: ', 1)[1] for ln in
                  (work / 'recorder_node.log').read_text(errors='replace').splitlines()
                  if ': memory: ' in ln]
        t_read = time.monotonic()
        run = read_run(spec.output)
        t_read = time.monotonic() - t_read
        size = spec.output.stat().st_size / 2**20
        run_msgs = sum(int(v) for k, v in run.metadata.items() if k.startswith('run/count:'))
    steps = int(round(args.duration * 1000))
    loop_s = stamps['run complete'] - stamps['peers matched']
    print(f'soak: {args.plant}/{args.controller}/{args.feedforward}, {args.duration:g} s sim '
          f'time = {steps} lockstep steps in {loop_s:.1f} s ({steps / loop_s:.0f} steps/s, '
          f'×{args.duration / loop_s:.2f} real time); {wall:.0f} s wall incl. start/stop')
    print(f'recorded {size:.1f} MiB; read back {len(run)} samples (expected {steps}) '
          f'in {t_read:.1f} s')
    print(f'{"node":<18} {"cpu [s]":>9} {"RSS start [MiB]":>16} {"RSS end [MiB]":>14} '
          f'{"growth [MiB]":>13} {"growth/h [MiB]":>15}')
    for name in ('plant_node', 'trajectory_node', 'controller_node', 'recorder_node'):
        cpu, start, end = rows.get(name, (float('nan'),) * 3)
        per_hour = (end - start) * 3600.0 / loop_s
        print(f'{name:<18} {cpu:>9.1f} {start:>16.2f} {end:>14.2f} {end - start:>13.2f} '
              f'{per_hour:>15.2f}')
    for line in memory:
        print(f'recorder {line}')
    # steady state: slope between the second sample (past the warm-up of allocator pools
    # and DDS buffers) and the last one, per hour of 1 kHz sim time
    rss = [(float(m.group(1)), int(m.group(2))) for m in
           (re.search(r'rss_mib=([\d.]+) .*messages=(\d+)', ln) for ln in memory) if m]
    if len(rss) >= 3:
        (r1, n1), (r2, n2) = rss[1], rss[-1]
        per_msg = (r2 - r1) / max(n2 - n1, 1)
        msgs_per_step = run_msgs / steps
        print(f'recorder steady-state RSS slope: {per_msg * 2**20:.2f} B/message = '
              f'{per_msg * msgs_per_step * 3.6e6:.2f} MiB per hour of 1 kHz sim time')
    return 0 if len(run) == steps else 1


if __name__ == '__main__':
    sys.exit(main())
