#!/usr/bin/env python3
"""Soak: long lockstep runs of the four node processes; the recorder's memory slope.

Each run records with the recorder logging ``memory: rss_mib=… messages=…`` every
``--interval`` seconds; after the warm-up (``--warmup`` of the samples: allocator pools,
DDS buffers, zstd context) a least-squares line RSS(messages) gives the steady growth
with its standard error, reported per hour of 1 kHz lockstep recording (the issue's
unit: 3.1 messages per step, /clock every 10 ticks, 11.2 M messages per hour), and the
growth between the warm-up and the end of the run.  ``--control`` repeats the run with
``discard:=true``: the same recorder, same DDS subscriptions and callbacks, but no MCAP
writer — the difference of the two slopes is what the writer costs; what the control
itself grows is outside the recording code (rmw/DDS, allocator).

Every node also logs ``resources: … rss_start_mib=… rss_end_mib=…`` at exit; the table
shows them per node.

Usage: ``python bench/soak.py [--duration S] [--control] [--trace-memory]`` (sim
seconds at 1 kHz; default 600).  ``--duration 3600`` is the full hour (≈ 30–60 min of
wall time on an idle 2-core machine, longer when loaded).
"""
from __future__ import annotations

import argparse
import math
import re
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from motor_comp.cli.run import RunSpec, private_domain_id, release_domain_id, run_nodes
from motor_comp.logs import read_run

_RES = re.compile(r'\[[\w.]*?(\w+_node)\]: resources: cpu_s=([\d.]+) rss_start_mib=([\d.na]+) '
                  r'rss_end_mib=([\d.]+)')
_TIME = re.compile(r'\[INFO\] \[(\d+\.\d+)\] \[[\w.]*plant_node\]: (peers matched|run complete)')
_MEM = re.compile(r'memory: rss_mib=([\d.]+) traced_mib=([\d.]+) messages=(\d+)')
#: messages per hour of 1 kHz lockstep recording: reference, joint_states and voltage each
#: tick, /clock every ``clock_every`` (10) ticks
MSGS_PER_HOUR = round((3 + 1 / 10) * 3_600_000)


def slope_per_hour(samples: list[tuple[float, float, int]], warmup: float
                   ) -> tuple[float, float, float, int]:
    """Steady RSS slope [MiB/h of 1 kHz recording], its standard error, growth, n used.

    ``samples`` are (rss MiB, traced MiB, messages); the first ``warmup`` fraction is
    dropped, the rest fitted by least squares (``numpy.polyfit`` with covariance).
    """
    use = samples[int(len(samples) * warmup):]
    if len(use) < 3:
        return math.nan, math.nan, math.nan, len(use)
    n = np.array([s[2] for s in use], dtype=float)
    rss = np.array([s[0] for s in use])
    (k, _), cov = np.polyfit(n, rss, 1, cov=True)
    return k * MSGS_PER_HOUR, math.sqrt(cov[0, 0]) * MSGS_PER_HOUR, rss[-1] - rss[0], len(use)


def soak_run(args: argparse.Namespace, work: Path, *, discard: bool) -> dict:
    """One lockstep run; the recorder's memory samples, node resources, loop timing."""
    work.mkdir(parents=True, exist_ok=True)
    out = work / 'soak.mcap'
    spec = RunSpec(output=out, plant=args.plant, controller=args.controller,
                   feedforward=args.feedforward, duration=args.duration,
                   extra_params={'recorder_node': {
                       'trace_memory': args.trace_memory, 'discard': discard,
                       'memory_log_interval': args.interval}})
    dom = private_domain_id()
    t0 = time.monotonic()
    try:
        run_nodes(spec, workdir=work, domain_id=dom, timeout=120 + 20 * args.duration,
                  progress=True)
    finally:
        release_domain_id(dom)
    wall = time.monotonic() - t0
    rows, stamps = {}, {}
    for log in work.glob('*.log'):
        text = log.read_text(errors='replace')
        for m in _RES.finditer(text):
            rows[m.group(1)] = tuple(float(g) for g in m.group(2, 3, 4))
        for m in _TIME.finditer(text):
            stamps[m.group(2)] = float(m.group(1))
    rec_log = (work / 'recorder_node.log').read_text(errors='replace')
    samples = [(float(m[1]), float(m[2]), int(m[3])) for m in _MEM.finditer(rec_log)]
    res = {'rows': rows, 'wall': wall, 'samples': samples,
           'loop_s': stamps['run complete'] - stamps['peers matched'],
           'trace': [ln.split(': memory: ', 1)[1] for ln in rec_log.splitlines()
                     if ': memory: +' in ln or 'traced Python heap' in ln]}
    if not discard:
        res['samples_read'] = len(read_run(out))
        res['size_mib'] = out.stat().st_size / 2**20
    return res


def report(name: str, res: dict, args: argparse.Namespace) -> float:
    """Print one run's table; return its steady slope [MiB/h]."""
    steps = int(round(args.duration * 1000))
    print(f'\n== {name}: {steps} lockstep steps in {res["loop_s"]:.0f} s '
          f'({steps / res["loop_s"]:.0f} steps/s); {res["wall"]:.0f} s wall incl. start/stop')
    if 'samples_read' in res:
        print(f'   recorded {res["size_mib"]:.1f} MiB, read back {res["samples_read"]} samples '
              f'(expected {steps})')
    print(f'   {"node":<18} {"cpu [s]":>9} {"RSS start [MiB]":>16} {"RSS end [MiB]":>14}')
    for node in ('plant_node', 'trajectory_node', 'controller_node', 'recorder_node'):
        cpu, start, end = res['rows'].get(node, (math.nan,) * 3)
        print(f'   {node:<18} {cpu:>9.1f} {start:>16.2f} {end:>14.2f}')
    for line in res['trace']:
        print(f'   recorder {line}')
    k, err, grown, n = slope_per_hour(res['samples'], args.warmup)
    s = res['samples']
    if s:
        print(f'   recorder RSS samples: {len(s)} ({s[0][0]:.2f} → {s[-1][0]:.2f} MiB, '
              f'{s[-1][2]} messages); traced Python heap {s[0][1]:.2f} → {s[-1][1]:.2f} MiB')
    print(f'   recorder steady slope after {args.warmup:.0%} warm-up ({n} samples): '
          f'{k:+.2f} ± {err:.2f} MiB per hour of 1 kHz recording; grew {grown:+.2f} MiB '
          f'over the fitted part')
    # RSS moves in steps (allocator thresholds, DDS queue high-water marks), which a
    # line through a short run turns into a slope: show the steps and the second half
    if s:
        rss = np.array([x[0] for x in s])
        steps = [(int(s[i + 1][2]), rss[i + 1] - rss[i]) for i in range(len(s) - 1)
                 if abs(rss[i + 1] - rss[i]) >= 0.25]
        print('   RSS steps ≥ 0.25 MiB (at message, MiB): '
              + (', '.join(f'{m}: {d:+.2f}' for m, d in steps) or 'none'))
        k2, err2, grown2, n2 = slope_per_hour(s, 0.5)
        print(f'   second half ({n2} samples): {k2:+.2f} ± {err2:.2f} MiB/h, grew '
              f'{grown2:+.2f} MiB')
    return k


def main() -> int:
    """Run the soak (and the control) and print the tables."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument('--duration', type=float, default=600.0, help='sim seconds (1 kHz)')
    ap.add_argument('--interval', type=float, default=5.0,
                    help='recorder memory sample interval [s] (wall)')
    ap.add_argument('--warmup', type=float, default=0.3,
                    help='fraction of the samples left out of the fit (default 0.3)')
    ap.add_argument('--control', action='store_true',
                    help='also run the control: the recorder with discard:=true (no MCAP)')
    ap.add_argument('--control-only', action='store_true',
                    help='run only the control (e.g. with --trace-memory)')
    ap.add_argument('--plant', default='ballscrew')
    ap.add_argument('--controller', default='npid')
    ap.add_argument('--feedforward', default='static+gms')
    ap.add_argument('--keep', type=Path, default=None, help='keep the MCAP and logs here')
    ap.add_argument('--trace-memory', action='store_true',
                    help="recorder: tracemalloc growth sites in its log ('memory:' lines)")
    args = ap.parse_args()
    if not (args.duration > 0 and args.interval > 0 and 0 <= args.warmup < 1):
        ap.error('--duration and --interval must be > 0, --warmup in [0, 1)')
    with tempfile.TemporaryDirectory(prefix='motor_comp_soak_') as tmp:
        base = args.keep or Path(tmp)
        runs = {}
        if not args.control_only:
            runs['recording'] = soak_run(args, base / 'recording', discard=False)
        if args.control or args.control_only:
            runs['control (discard: DDS, no MCAP)'] = soak_run(args, base / 'control',
                                                               discard=True)
    slopes = {name: report(name, res, args) for name, res in runs.items()}
    if len(slopes) == 2:
        (a, b) = slopes.values()
        print(f'\nMCAP writer share of the slope: {a - b:+.2f} MiB/h (recording − control)')
    if 'recording' not in runs:
        return 0
    ok = runs['recording'].get('samples_read') == int(round(args.duration * 1000))
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
