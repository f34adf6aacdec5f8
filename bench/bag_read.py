"""Robots' bags: messages per second of read_run on a 6-joint sqlite3 rosbag2 bag vs rosbags.

Issue 25.  A robot's recording is usually a rosbag2 directory in sqlite3 storage with
one ``/joint_states`` topic (``sensor_msgs/msg/JointState``) carrying every joint, at the
rate of ros2_control's ``joint_state_broadcaster`` (100 Hz by default).  The script

1. generates such a bag (``--duration`` s at ``--rate`` Hz, 6 UR-style joints, smooth
   positions/velocities/efforts plus noise, header stamps = log times) with rosbags'
   ``Writer`` (sqlite3, version 9) and ``serialize_cdr``, in a child process; its time is
   printed apart, it is not part of the measurement;
2. measures, alternated ``--repeats`` times, each in a fresh child process (imports
   done before the clock starts: the reader's module and rosbags' ``rosbag2`` and
   ``typesys``; the child's peak RSS from ``os.wait4``):

   * motor_comp: ``read_run(bag, topics=RunTopics.of(topic='/joint_states',
     joint='elbow_joint', input='effort'))``;
   * the reference, what a user writes with rosbags: ``AnyReader`` over the bag,
     ``reader.messages()`` of the ``/joint_states`` connection, ``reader.deserialize``
     of each message, the elbow joint's position, velocity and effort picked by
     ``msg.name.index`` into lists, then numpy arrays;
   * for context, the floor under both: rosbags' ``rosbag2.Reader.messages()`` of the
     topic (the sqlite3 query and the iteration motor_comp also goes through), the
     payloads not decoded;

3. checks that both give the same stamps, positions, velocities and efforts exactly
   (exits non-zero otherwise) and prints the medians: messages, seconds, msg/s, the
   ratio motor_comp / rosbags and the peak RSS of each.

Usage: ``python bench/bag_read.py [--rate 100] [--duration 3600] [--repeats 3] [--dir D]``
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

TOPIC = '/joint_states'
JOINTS = ('shoulder_pan_joint', 'shoulder_lift_joint', 'elbow_joint', 'wrist_1_joint',
          'wrist_2_joint', 'wrist_3_joint')
JOINT = 'elbow_joint'
MSGTYPE = 'sensor_msgs/msg/JointState'


def generate(bag: Path, duration: float, rate: float) -> int:
    """Write the sqlite3 bag; return the number of JointState messages."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    joint_state = store.types[MSGTYPE]
    header_t = store.types['std_msgs/msg/Header']
    time_t = store.types['builtin_interfaces/msg/Time']
    n = int(round(duration * rate))
    t0_ns = 1_700_000_000 * 10**9                      # a plausible wall-clock start
    log_ns = t0_ns + np.round(np.arange(n) * (1e9 / rate)).astype(np.int64)
    t = (log_ns - t0_ns) / 1e9
    rng = np.random.default_rng(25)
    # per joint: a sum of two slow sines (a robot's moves), plus sensor noise
    amp = np.array([1.2, 0.8, 1.0, 0.6, 0.9, 1.5])
    f1 = np.array([0.05, 0.07, 0.11, 0.13, 0.17, 0.19])
    f2 = np.array([0.31, 0.23, 0.37, 0.41, 0.29, 0.43])
    w1, w2 = 2 * np.pi * f1, 2 * np.pi * f2
    tt = t[:, None]
    pos = amp * (np.sin(w1 * tt) + 0.2 * np.sin(w2 * tt + 0.5))
    vel = amp * (w1 * np.cos(w1 * tt) + 0.2 * w2 * np.cos(w2 * tt + 0.5))
    eff = (np.array([5.0, 40.0, 20.0, 3.0, 2.0, 1.0]) * np.cos(pos)
           + np.array([8.0, 10.0, 6.0, 2.0, 1.5, 1.0]) * np.tanh(vel / 0.01) * 0.2
           + 0.5 * vel)
    pos += 1e-5 * rng.standard_normal(pos.shape)
    vel += 1e-3 * rng.standard_normal(vel.shape)
    eff += 0.05 * rng.standard_normal(eff.shape)
    names = list(JOINTS)
    secs = (log_ns // 10**9).tolist()
    nsecs = (log_ns % 10**9).tolist()
    stamps = log_ns.tolist()
    serialize = store.serialize_cdr
    with Writer(bag, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conn = writer.add_connection(TOPIC, MSGTYPE, typestore=store)
        write = writer.write
        for i in range(n):
            msg = joint_state(header=header_t(stamp=time_t(sec=secs[i], nanosec=nsecs[i]),
                                              frame_id=''),
                              name=names, position=pos[i], velocity=vel[i], effort=eff[i])
            write(conn, stamps[i], serialize(msg, MSGTYPE))
    return n


def read_motor_comp(bag: Path) -> tuple[dict[str, np.ndarray], float]:
    """Arrays of the elbow joint through read_run, and the seconds it took."""
    from motor_comp.logs import read_run
    from motor_comp.logs.topics import RunTopics
    topics = RunTopics.of(topic=TOPIC, joint=JOINT, input='effort')
    t0 = time.perf_counter()
    run = read_run(bag, topics=topics)
    dt = time.perf_counter() - t0
    return {'t': run.t, 'position': run.position, 'velocity': run.velocity,
            'effort': run.voltage}, dt


def read_rosbags(bag: Path) -> tuple[dict[str, np.ndarray], float]:
    """The same arrays the way a user reads them with rosbags, and the seconds."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    t0 = time.perf_counter()
    stamp, pos, vel, eff = [], [], [], []
    with AnyReader([bag], default_typestore=store) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC]
        for conn, _log, raw in reader.messages(connections=conns):
            msg = reader.deserialize(raw, conn.msgtype)
            i = msg.name.index(JOINT)
            stamp.append(msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec)
            pos.append(msg.position[i])
            vel.append(msg.velocity[i])
            eff.append(msg.effort[i])
    out = {'t': np.asarray(stamp, np.int64) / 1e9, 'position': np.asarray(pos, np.float64),
           'velocity': np.asarray(vel, np.float64), 'effort': np.asarray(eff, np.float64)}
    return out, time.perf_counter() - t0


def read_raw(bag: Path) -> tuple[dict[str, np.ndarray], float]:
    """The floor: rosbags' ``Reader.messages()`` of the topic, nothing decoded."""
    from rosbags.rosbag2 import Reader
    t0 = time.perf_counter()
    log = []
    with Reader(bag) as reader:
        conns = [c for c in reader.connections if c.topic == TOPIC]
        for _conn, stamp, _raw in reader.messages(connections=conns):
            log.append(stamp)
    return {'log': np.asarray(log, np.int64)}, time.perf_counter() - t0


def child(mode: str, bag: Path, out: Path) -> None:
    """One measurement in this (fresh) process: imports first, then the timed read."""
    t0 = time.perf_counter()
    if mode == 'generate':
        n = generate(bag, *json.loads(out.read_text()))
        out.write_text(json.dumps({'messages': n, 'seconds': time.perf_counter() - t0}))
        return
    if mode == 'motor_comp':
        # not timed, as in the reference: the module and the rosbags modules it uses
        import motor_comp.logs.mcap_io  # noqa: F401
        import rosbags.rosbag2  # noqa: F401
        import rosbags.typesys  # noqa: F401
        reader = read_motor_comp
    elif mode == 'rosbags':
        import rosbags.highlevel  # noqa: F401
        reader = read_rosbags
    else:
        import rosbags.rosbag2  # noqa: F401
        reader = read_raw
    imports = time.perf_counter() - t0
    arrays, seconds = reader(bag)
    np.savez(out, **arrays)
    print(json.dumps({'seconds': seconds, 'imports': imports}))


def spawn(mode: str, bag: Path, out: Path) -> tuple[dict, int]:
    """Run a child; return its JSON line and its own peak RSS [kB]."""
    cmd = [sys.executable, str(Path(__file__).resolve()), '--child', mode, '--dir',
           str(bag), '--out', str(out)]
    with tempfile.TemporaryFile('w+') as so, tempfile.TemporaryFile('w+') as se:
        proc = subprocess.Popen(cmd, stdout=so, stderr=se, text=True)
        # wait4: this child's own rusage (RUSAGE_CHILDREN would take the max over all
        # children so far)
        _, status, usage = os.wait4(proc.pid, 0)
        so.seek(0)
        se.seek(0)
        if os.waitstatus_to_exitcode(status) != 0:
            raise SystemExit(f'{mode} child failed:\n{se.read()}')
        text = so.read().strip()
    return (json.loads(text.splitlines()[-1]) if text else {}), usage.ru_maxrss


def main() -> int:
    """Generate the bag, measure alternated, check, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument('--rate', type=float, default=100.0,
                    help='JointState rate [Hz] (joint_state_broadcaster default: 100)')
    ap.add_argument('--duration', type=float, default=3600.0, help='bag length [s]')
    ap.add_argument('--repeats', type=int, default=3,
                    help='measurements of each reader, alternated; medians reported')
    ap.add_argument('--dir', type=Path, default=None,
                    help='directory for the bag (kept; reused if it holds one of the same '
                         'rate and duration); default: a temporary directory, removed')
    ap.add_argument('--child', choices=('generate', 'motor_comp', 'rosbags', 'raw'),
                    help=argparse.SUPPRESS)
    ap.add_argument('--out', type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child, args.dir, args.out)
        return 0

    tmp = Path(tempfile.mkdtemp(prefix='bag_read_'))
    try:
        base = args.dir if args.dir is not None else tmp
        base.mkdir(parents=True, exist_ok=True)
        bag = base / f'joint_states_{args.rate:g}hz_{args.duration:g}s'
        n = int(round(args.duration * args.rate))
        if bag.exists() and (bag / 'metadata.yaml').is_file():
            print(f'# reusing {bag}', file=sys.stderr)
        else:
            if bag.exists():
                shutil.rmtree(bag)
            spec = tmp / 'gen.json'
            spec.write_text(json.dumps([args.duration, args.rate]))
            t0 = time.perf_counter()
            spawn('generate', bag, spec)
            gen = json.loads(spec.read_text())
            assert gen['messages'] == n, gen
            print(f'# generated {bag.name}: {n:,} messages, '
                  f'{sum(f.stat().st_size for f in bag.iterdir()) / 1e6:.0f} MB, in '
                  f'{time.perf_counter() - t0:.1f} s (not measured)', file=sys.stderr)
        size_mb = sum(f.stat().st_size for f in bag.iterdir()) / 1e6

        results: dict[str, list[tuple[float, int, float]]] = {
            'motor_comp': [], 'rosbags': [], 'raw': []}
        arrays: dict[str, dict[str, np.ndarray]] = {}
        for r in range(max(1, args.repeats)):
            for mode in results:          # alternated: load changes hit both alike
                out = tmp / f'{mode}.npz'
                info, rss = spawn(mode, bag, out)
                results[mode].append((info['seconds'], rss, info['imports']))
                print(f'# {r + 1}/{args.repeats} {mode}: {info["seconds"]:.2f} s, '
                      f'peak RSS {rss / 1024:.0f} MiB', file=sys.stderr)
                with np.load(out) as z:
                    got = {k: z[k] for k in z.files}
                if mode == 'raw':
                    if got['log'].size != n:
                        raise SystemExit(f'FAIL: raw iteration gave {got["log"].size} '
                                         f'messages, the bag has {n}')
                    continue
                if mode not in arrays:
                    arrays[mode] = got
                else:
                    check(arrays[mode], got, f'{mode} run 1', f'{mode} run {r + 1}')
        check(arrays['motor_comp'], arrays['rosbags'], 'motor_comp', 'rosbags')
        for mode, a in arrays.items():
            if a['position'].size != n:
                raise SystemExit(f'FAIL: {mode} returned {a["position"].size} samples, '
                                 f'the bag has {n} messages')

        med = {m: (statistics.median(s for s, _, _ in v), statistics.median(x for _, x, _ in v),
                   statistics.median(i for _, _, i in v)) for m, v in results.items()}
        rates = {m: n / v[0] for m, v in med.items()}
        ratio = rates['motor_comp'] / rates['rosbags']
        print(f'Bag: sqlite3, {args.duration:g} s at {args.rate:g} Hz, one `{TOPIC}` topic '
              f'with {len(JOINTS)} joints, {n:,} messages, {size_mb:.0f} MB; joint '
              f'`{JOINT}`.  Medians of {args.repeats}, alternated, each in a fresh process '
              '(imports not timed).  Arrays (stamps, position, velocity, effort) equal '
              'exactly.\n')
        print('| reader | messages | seconds | msg/s | × rosbags | peak RSS [MiB] | '
              'imports [s] |')
        print('|---|---:|---:|---:|---:|---:|---:|')
        names = {'motor_comp': "motor_comp `read_run(bag, topics=RunTopics.of(topic="
                               "'/joint_states', joint='elbow_joint', input='effort'))`",
                 'rosbags': 'rosbags `AnyReader` + `reader.deserialize` + `name.index` '
                            '(reference)',
                 'raw': 'rosbags `Reader.messages()` of the topic, nothing decoded (the '
                        'floor of any reader built on it)'}
        for m, (s, rss, imp) in med.items():
            print(f'| {names[m]} | {n:,d} | {s:.2f} | {rates[m]:,.0f} | '
                  f'{rates[m] / rates["rosbags"]:.2f} | {rss / 1024:.0f} | {imp:.2f} |')
        pairs = zip(results['motor_comp'], results['rosbags'])
        print(f'\nratio motor_comp / rosbags (msg/s): {ratio:.2f}; per repeat: '
              + ', '.join(f'{rb[0] / mc[0]:.2f}' for mc, rb in pairs))
        return 0
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def check(a: dict[str, np.ndarray], b: dict[str, np.ndarray], na: str, nb: str) -> None:
    """Exit loudly unless the arrays are exactly equal."""
    for key in ('t', 'position', 'velocity', 'effort'):
        x, y = a.get(key), b.get(key)
        if x is None or y is None or x.shape != y.shape or not np.array_equal(x, y):
            where = ''
            if x is not None and y is not None and x.shape == y.shape:
                bad = np.flatnonzero(x != y)
                where = f' ({bad.size} differ, first at {bad[0]}: {x[bad[0]]!r} vs ' \
                        f'{y[bad[0]]!r})'
            elif x is not None and y is not None:
                where = f' (shapes {x.shape} vs {y.shape})'
            raise SystemExit(f'FAIL: {key} of {na} and {nb} differ{where}')


if __name__ == '__main__':
    sys.exit(main())
