"""Analysis scaling: ``motor-comp analyze`` time and memory vs run length (10 s … 1 h).

Each run is a 1 kHz recording of three topics (3000 messages per second of run),
generated once into ``bench/out/`` by the writer of :mod:`analysis_speed`.  For each
length the end-to-end ``analyze --json`` wall time and the process's peak RSS are
measured in a fresh process (best of ``--repeat`` sweeps); a least-squares line
``time = start-up + slope·messages`` shows the cost is linear in the length, and RSS vs
file size shows the file is never held in memory (only the decoded arrays are).

Usage: ``python bench/analysis_scaling.py [--lengths 10 60 300 1000 3600]``
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from analysis_speed import OUT, make_file  # noqa: E402,I100  (bench-local helper)

# peak RSS from /proc (VmHWM of the new process image): getrusage's ru_maxrss would
# carry over the parent's peak across fork/exec
_ANALYZE = """
import sys
from motor_comp.cli import main as m
code = m.main(['analyze', sys.argv[1], '--json'])
with open('/proc/self/status') as f:
    print([ln.split()[1] for ln in f if ln.startswith('VmHWM')][0], file=sys.stderr)
sys.exit(code)
"""


def analyze(path: Path) -> tuple[float, float]:
    """(wall seconds, peak RSS MiB) of ``motor-comp analyze`` in a new process."""
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, '-c', _ANALYZE, str(path)], capture_output=True,
                         text=True, check=False)
    dt = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f'analyze {path} failed: {out.stderr.strip()}')
    return dt, int(out.stderr.strip().splitlines()[-1]) / 1024


def main() -> None:
    """Measure every length and print the table and the linear fit."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--lengths', type=int, nargs='+', default=[10, 60, 300, 1000, 3600],
                    help='run lengths [s] at 1 kHz')
    ap.add_argument('--repeat', type=int, default=3,
                    help='runs per length; the best (least disturbed by other load) counts')
    args = ap.parse_args()
    files = [make_file(s, OUT / f'analysis_{s}s.mcap') for s in args.lengths]
    analyze(files[0])                                   # warm imports/page cache
    best: dict[int, tuple[float, float]] = {}
    for _ in range(max(1, args.repeat)):                # sweep repeatedly: load hits all
        for s, f in zip(args.lengths, files):
            dt, rss = analyze(f)
            b = best.get(s, (float('inf'), 0.0))
            best[s] = (min(b[0], dt), max(b[1], rss))
    rows = [(s, 3000 * s, f.stat().st_size / 2**20, *best[s])
            for s, f in zip(args.lengths, files)]
    print('| run length [s] | messages | file [MiB] | `motor-comp analyze` [s] | msg/s '
          '| peak RSS [MiB] |')
    print('|---:|---:|---:|---:|---:|---:|')
    for s, n, mb, dt, rss in rows:
        print(f'| {s} | {n:,d} | {mb:.1f} | {dt:.2f} | {n / dt:,.0f} | {rss:.0f} |')
    n = np.array([r[1] for r in rows], float)
    t = np.array([r[3] for r in rows])
    slope, intercept = np.polyfit(n, t, 1)
    r2 = 1 - np.sum((t - (slope * n + intercept)) ** 2) / np.sum((t - t.mean()) ** 2)
    print(f'\nLinear fit: time = {intercept:.2f} s + {slope * 1e6:.3f} µs/message '
          f'(R² = {r2:.4f}; asymptotic {1 / slope:,.0f} msg/s).')


if __name__ == '__main__':
    main()
