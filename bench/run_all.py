"""Run every benchmark of bench/ and collect their tables into bench/out/results.md.

``make bench`` calls this.  Each benchmark is a standalone script that prints a
Markdown table (command, figure, reference figure, ratio) measured in the same run as
its reference; this runner only sequences them (one at a time: they measure speed, so
they must not compete for the two cores) and keeps their output.
"""
from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent

#: benchmark scripts in the order they run (the quick ones first)
SCRIPTS = (
    'sim_speed.py',
    'sim_scaling.py',
    'analysis_speed.py',
    'analysis_scaling.py',
    'bag_read.py',
    'workbench.py',
    'workbench_speed.py',
    'workbench_independent.py',
    'processing_choice.py',
    'reproduce_papers.py',
    'compensation_loop.py',
    'excite_prediction.py',
    'autotune.py',
    'sweep_speed.py',
    'ros_loop.py',
    'soak.py',
)


def main() -> int:
    """Run the benchmarks; return non-zero if any failed."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    parser.add_argument('names', nargs='*', help='run only these scripts (e.g. sim_speed)')
    parser.add_argument('--timeout', type=float, default=1800.0, help='per script [s]')
    args = parser.parse_args()
    out_dir = HERE / 'out'
    out_dir.mkdir(exist_ok=True)
    wanted = {n if n.endswith('.py') else n + '.py' for n in args.names}
    env = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    sections = []
    failed = 0
    for script in SCRIPTS:
        if wanted and script not in wanted:
            continue
        path = HERE / script
        if not path.exists():
            print(f'-- {script}: missing', file=sys.stderr)
            failed += 1
            continue
        print(f'== {script}', flush=True)
        t0 = time.perf_counter()
        try:
            proc = subprocess.run([sys.executable, str(path)], env=env, text=True,
                                  capture_output=True, timeout=args.timeout)
            ok = proc.returncode == 0
            text = proc.stdout
            if not ok:
                text += f'\n(exit {proc.returncode}: {proc.stderr.strip().splitlines()[-1:]})\n'
        except subprocess.TimeoutExpired:
            ok, text = False, f'(timed out after {args.timeout:.0f} s)\n'
        failed += not ok
        print(text, flush=True)
        sections.append(f'## {script} ({time.perf_counter() - t0:.0f} s)\n\n{text}\n')
    (out_dir / 'results.md').write_text('# Benchmark results\n\n' + ''.join(sections),
                                        encoding='utf-8')
    print(f'wrote {out_dir / "results.md"}')
    return 1 if failed else 0


if __name__ == '__main__':
    sys.exit(main())
