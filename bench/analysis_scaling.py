"""Analysis memory vs run length: ``motor-comp analyze`` on 1 min, 1 h and 10 h at 1 kHz.

Each run is a 1 kHz recording of the three DESIGN.md §5 topics (reference and
joint_states as ``sensor_msgs/JointState``, voltage as ``Float64``: 3000 messages per
second of run; a 0.5 Hz sine reference, so one reversal per second).  The files are
generated in a temporary directory with the project's MCAP writer
(:class:`~motor_comp.logs.mcap_io.McapRecorder` for header, schemas, channels and
metadata; the message chunks, built in bulk with numpy from the project's CDR encoders,
are what ``write_run`` would write, only ~100× faster, so a 36 M-sample file takes
minutes instead of hours) and deleted afterwards.

For each length, in fresh processes: ``motor-comp analyze FILE --json`` (streaming
path) — wall time and peak RSS (``VmHWM``) — and the array path it replaced
(``compute_metrics(read_run(FILE))``) as the reference, with its own peak RSS; the
metrics of both must agree to 1e-12 (relative).  The ratio column is peak RSS ÷ the
1-min file's (goal ≤ 1.2).

Usage: ``python bench/analysis_scaling.py [--lengths 60 3600 36000] [--no-array 36000]``
"""
from __future__ import annotations

import argparse
import json
import shutil
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from pathlib import Path

import numpy as np

# peak RSS from /proc (VmHWM of the new process image): getrusage's ru_maxrss would
# carry over the parent's peak across fork/exec
_STREAM = """
import sys
from motor_comp.cli import main as m
m.SUBCOMMANDS = ('analyze',)
code = m.main(['analyze', sys.argv[1], '--json'])
with open('/proc/self/status') as f:
    print([ln.split()[1] for ln in f if ln.startswith('VmHWM')][0], file=sys.stderr)
sys.exit(code)
"""
_ARRAY = """
import json, sys
from motor_comp.analysis.metrics import compute_metrics
from motor_comp.cli.common import jsonable
from motor_comp.logs import read_run
run = read_run(sys.argv[1], signals=('reference', 'reference_velocity', 'voltage'),
               require=('reference',))
print(json.dumps({'runs': [jsonable(compute_metrics(run).as_dict())]}))
with open('/proc/self/status') as f:
    print([ln.split()[1] for ln in f if ln.startswith('VmHWM')][0], file=sys.stderr)
"""

_MSG = 0x05
_CHUNK, _INDEX = 0x06, 0x07
STAMPS_PER_CHUNK = 2048        # ~0.5 MiB of records per chunk, like write_run's 1 MiB


def _records(ns: np.ndarray, payloads: list[np.ndarray], ids: list[int],
             seq0: int) -> tuple[bytes, list[np.ndarray]]:
    """Message records of one chunk, per stamp in topic order; (bytes, offsets per topic)."""
    n = ns.size
    fields, sizes = [], []
    for k, p in enumerate(payloads):
        fields += [(f'op{k}', 'u1'), (f'len{k}', '<u8'), (f'cid{k}', '<u2'),
                   (f'seq{k}', '<u4'), (f'log{k}', '<u8'), (f'pub{k}', '<u8'),
                   (f'data{k}', 'u1', (p.shape[1],))]
        sizes.append(31 + p.shape[1])
    rec = np.zeros(n, np.dtype(fields))
    for k, (p, cid) in enumerate(zip(payloads, ids)):
        rec[f'op{k}'] = _MSG
        rec[f'len{k}'] = 22 + p.shape[1]
        rec[f'cid{k}'] = cid
        rec[f'seq{k}'] = (seq0 + np.arange(n)) & 0xFFFFFFFF
        rec[f'log{k}'] = ns
        rec[f'pub{k}'] = ns
        rec[f'data{k}'] = p
    row = sum(sizes)
    starts = np.cumsum([0] + sizes[:-1])
    offsets = [np.arange(n, dtype=np.uint64) * row + s for s in starts]
    return rec.tobytes(), offsets


def write_long(path: Path, seconds: int) -> Path:
    """Write a ``seconds``-long 1 kHz run (same signals as ``analysis_speed.make_file``)."""
    import zstandard

    from motor_comp.logs import cdr, schemas
    from motor_comp.logs.mcap_io import METADATA_NAME, McapRecorder
    names = schemas.topics('axis')
    t0 = time.perf_counter()
    comp = zstandard.ZstdCompressor(level=1)
    rng = np.random.default_rng(0)
    with McapRecorder(path, flush_interval=0) as rec:
        rec.add_metadata(METADATA_NAME, {'bench': 'analysis_scaling', 'seconds': seconds})
        ids = [rec.add_channel(names['reference'], schemas.JOINT_STATE),
               rec.add_channel(names['joint_states'], schemas.JOINT_STATE),
               rec.add_channel(names['voltage'], schemas.FLOAT64)]
        out = rec._file                      # raw chunks go after the writer's first one
        n = seconds * 1000
        first = True
        for k0 in range(0, n, STAMPS_PER_CHUNK):
            k = np.arange(k0, min(n, k0 + STAMPS_PER_CHUNK))
            ns = (k + 1) * 1_000_000
            t = ns / 1e9
            ref = 0.01 * np.sin(2 * np.pi * 0.5 * t)
            err = 2e-6 * np.sin(2 * np.pi * 5 * t) + 1e-7 * rng.standard_normal(k.size)
            x = ref - err
            payloads = [
                cdr.encode_joint_states(ns, ref, 0.01 * np.pi * np.cos(2 * np.pi * 0.5 * t)),
                cdr.encode_joint_states(ns, x, 0.01 * np.pi * np.cos(np.pi * t), 10 * np.sin(t)),
                cdr.encode_float64(np.sin(2 * np.pi * 0.5 * t) +
                                   0.01 * rng.standard_normal(k.size))]
            if first:
                # the first stamp through the writer's own path: its chunk carries the
                # schema and channel records, flushed before the bulk chunks
                for tp, p in zip(('reference', 'joint_states', 'voltage'), payloads):
                    rec.write_cdr(names[tp], p[0].tobytes(), int(ns[0]))
                rec.flush()
                ns, payloads, first = ns[1:], [p[1:] for p in payloads], False
            raw, offsets = _records(ns, payloads, ids, k0)
            data = comp.compress(raw)
            body = (struct.pack('<QQQI', int(ns[0]), int(ns[-1]), len(raw), zlib.crc32(raw))
                    + struct.pack('<I', 4) + b'zstd' + struct.pack('<Q', len(data)) + data)
            out.write(struct.pack('<BQ', _CHUNK, len(body)) + body)
            for cid, off in zip(ids, offsets):
                pairs = np.empty((off.size, 2), '<u8')
                pairs[:, 0] = ns
                pairs[:, 1] = off
                ib = struct.pack('<HI', cid, pairs.nbytes) + pairs.tobytes()
                out.write(struct.pack('<BQ', _INDEX, len(ib)) + ib)
    print(f'# wrote {path.name}: {path.stat().st_size / 2**20:.0f} MiB, {3 * n:,d} messages, '
          f'in {time.perf_counter() - t0:.0f} s', file=sys.stderr)
    return path


def _run(code: str, path: Path) -> tuple[float, float, dict]:
    """(wall s, peak RSS MiB, first run's metrics) of a snippet in a new process."""
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, '-c', code, str(path)], capture_output=True,
                         text=True, check=False)
    dt = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f'{path.name} failed: {out.stderr.strip()[-2000:]}')
    rss = int(out.stderr.strip().splitlines()[-1]) / 1024
    return dt, rss, json.loads(out.stdout)['runs'][0]


def _max_rel(a, b) -> float:
    """Largest relative difference between two JSON metric trees (inf on a mismatch)."""
    if isinstance(a, dict):
        keys = set(a) - {'path', 'relative_to_first'}      # added by the CLI only
        if keys != set(b) - {'path', 'relative_to_first'}:
            return float('inf')
        return max([_max_rel(a[k], b[k]) for k in keys] or [0.0])
    if isinstance(a, list):
        if len(a) != len(b):
            return float('inf')
        return max([_max_rel(x, y) for x, y in zip(a, b)] or [0.0])
    if isinstance(a, float) and isinstance(b, float):
        return 0.0 if a == b else abs(a - b) / max(abs(a), abs(b))
    return 0.0 if a == b else float('inf')


def main() -> None:
    """Generate, measure, print the table, delete the files."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument('--lengths', type=int, nargs='+', default=[60, 3600, 36000],
                    help='run lengths [s] at 1 kHz (the first is the reference)')
    ap.add_argument('--no-array', type=int, nargs='*', default=[],
                    help='lengths for which the array path is not run')
    ap.add_argument('--dir', default=None, help='temporary directory (default: system)')
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix='analysis_scaling_', dir=args.dir))
    rows = []
    try:
        for s in args.lengths:
            f = write_long(tmp / f'run_{s}s.mcap', s)
            ts, rs, ms = _run(_STREAM, f)
            if s in args.no_array:
                ta = ra = float('nan')
                rel = float('nan')
            else:
                ta, ra, ma = _run(_ARRAY, f)
                rel = _max_rel(ma, ms)
            rows.append((s, f.stat().st_size / 2**20, ts, rs, ta, ra, rel,
                         ms['glitch_count'], ms['samples']))
            print(f'# {s} s: stream {ts:.1f} s {rs:.0f} MiB; array {ta:.1f} s {ra:.0f} MiB; '
                  f'max rel diff {rel:.1e}', file=sys.stderr)
            f.unlink()
    finally:
        shutil.rmtree(tmp, ignore_errors=True)
    base = rows[0][3]
    print(f'Command: `python bench/analysis_scaling.py --lengths '
          f'{" ".join(str(r[0]) for r in rows)}`\n')
    print('| run length | samples per topic | file [MiB] | reversals | streamed `analyze` [s] '
          '| streamed peak RSS [MiB] | ratio to 1st | array path [s] | array path peak RSS '
          '[MiB] | max relative difference of all metrics |')
    print('|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|')
    for s, mb, ts, rs, ta, ra, rel, ng, n in rows:
        label = f'{s / 3600:g} h' if s >= 3600 else f'{s / 60:g} min'
        print(f'| {label} | {n:,d} | {mb:.0f} | {ng:,d} | {ts:.1f} | {rs:.0f} | '
              f'{rs / base:.2f} | {ta:.1f} | {ra:.0f} | {rel:.1e} |')


if __name__ == '__main__':
    main()
