#!/usr/bin/env python3
"""ROS loop speed: lockstep steps/s and realtime jitter, beside a bare rclpy round trip.

Three measurements in the same run, same machine, same DDS (Fast DDS, localhost only,
private domain):

1. reference — a bare two-process rclpy ping-pong of ``std_msgs/Float64`` with the
   nodes' QoS, spun by rclpy's ``SingleThreadedExecutor`` (plain rclpy) and by the
   nodes' :class:`~motor_comp.nodes.common.LeanLoop` (wait-set loop): the ceiling of
   any lockstep loop (a lockstep control step needs at least one plant↔controller
   round trip);
2. lockstep — ``motor-comp run`` machinery, four node processes + recorder, control
   steps per second of wall time (goals: ≥ 2000 = 2× real time at 1 kHz, and ≥ 0.75 ×
   the ``spin_once`` reference, issue 14), and where its time goes: each node
   process's CPU per step (all its threads, DDS included, from its ``resources:``
   exit line) and the plant's waits for its readers' acknowledgements (``Pacer``);
3. realtime — the same nodes on wall-clock timers at 1 kHz (PMLM + PID), with normal
   scheduling and with the default SCHED_FIFO ``realtime_priority``: the delay from
   a sample's publication to the next command's arrival at the plant (p50/p99/max,
   from the plant's ``run complete`` log line), the control period jitter
   ``|tick interval − T|`` of the plant's timer (p50/p99/max; goal p99 < 0.5 ms), the
   backlog samples the controller skipped and the periods the plant's sim time
   slipped.  (Recorded stamps
   are the plant's sample grid t0 + k·T, so the recording itself no longer shows the
   timer jitter.)

Usage: ``python bench/ros_loop.py [--steps N] [--lockstep-s S] [--realtime-s S]``.
"""
from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path


from motor_comp.cli.run import DEFAULT_RT_PRIORITY, RunSpec, private_domain_id, \
    ros_environment, run_nodes


def _pingpong(role: str, n: int, loop: str) -> None:
    """One side of the bare round trip (runs in its own process)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_msgs.msg import Float64

    from motor_comp.nodes.common import LOOP_QOS, LeanLoop, ParamNode, SUB_QOS

    rclpy.init()
    node = ParamNode(f'bench_{role}')
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    lean = LeanLoop(node)
    out, inp = ('ping', 'pong') if role == 'ping' else ('pong', 'ping')
    pub = node.create_publisher(Float64, out, LOOP_QOS)
    state = {'n': 0, 't0': 0.0}
    msg = Float64()

    def on_msg(m: Float64) -> None:
        state['n'] += 1
        if role == 'ping' and state['n'] == 1:
            state['t0'] = time.perf_counter()
        msg.data = m.data + 1.0
        if role == 'pong' or state['n'] < n:
            pub.publish(msg)

    node.mark_hot(node.create_subscription(Float64, inp, on_msg, SUB_QOS))
    deadline = time.monotonic() + 60.0

    def spin() -> None:
        if loop == 'lean':
            lean.spin_once(500_000_000)
        else:
            ex.spin_once(timeout_sec=0.5)

    if role == 'ping':
        while pub.get_subscription_count() < 1 or node.count_publishers(inp) < 1:
            ex.spin_once(timeout_sec=0.05)
        time.sleep(0.5)
        pub.publish(msg)
        while state['n'] < n and time.monotonic() < deadline:
            spin()
        print(f'{(state["n"] - 1) / (time.perf_counter() - state["t0"]):.1f}')
    else:
        while time.monotonic() < deadline and state['n'] < n:
            spin()
    rclpy.shutdown()


def bare_round_trip(n: int, loop: str) -> float:
    """Round trips per second of the two-process ping-pong."""
    env = ros_environment(private_domain_id())
    args = ['--steps', str(n), '--loop', loop]
    pong = subprocess.Popen([sys.executable, __file__, '--role', 'pong', *args], env=env)
    try:
        out = subprocess.run([sys.executable, __file__, '--role', 'ping', *args],
                             env=env, capture_output=True, text=True, timeout=120)
        return float(out.stdout.strip().splitlines()[-1])
    finally:
        pong.kill()
        pong.wait()


_LOG_TIME = re.compile(r'\[INFO\] \[(\d+\.\d+)\] \[[^\]]*plant_node\]: (.*)')
_LOOP_CPU = re.compile(r'resources: .*loop_cpu_s=([\d.]+)')
_PACED = re.compile(r'paced on the readers\' acknowledgements (\d+) times, ([\d.]+) s')
NODE_NAMES = ('plant_node', 'controller_node', 'trajectory_node', 'recorder_node')


def loop_costs(workdir: Path, steps: int) -> dict[str, float]:
    """CPU per lockstep step [µs] of each node process, and the plant's paced waits [s].

    From the nodes' own exit lines: ``resources: … loop_cpu_s`` (the process's CPU time,
    all its threads — DDS included — from its first loop callback to the end) and the
    plant's ``paced on the readers' acknowledgements N times, S s``.
    """
    out: dict[str, float] = {}
    for node in NODE_NAMES:
        log = workdir / f'{node}.log'
        text = log.read_text(errors='replace') if log.exists() else ''
        m = _LOOP_CPU.search(text)
        if m:
            out[node] = float(m.group(1)) / steps * 1e6
        paced = _PACED.search(text)
        if paced:
            out['paced_s'] = float(paced.group(2))
    return out


def lockstep_rate(duration: float, workdir: Path,
                  profile: Path | None = None) -> tuple[float, int]:
    """Control steps per wall second of a lockstep run of ``duration`` sim seconds."""
    spec = RunSpec(output=workdir / 'lockstep.mcap', plant='pmlm', controller='pid',
                   duration=duration)
    if profile is not None:   # the node processes inherit it (common._profiler)
        profile.mkdir(parents=True, exist_ok=True)
        os.environ['MOTOR_COMP_PROFILE'] = str(profile.resolve())
    try:
        run_nodes(spec, workdir=workdir, domain_id=private_domain_id(), progress=False)
    finally:
        os.environ.pop('MOTOR_COMP_PROFILE', None)
    if profile is not None:
        import pstats
        for prof in sorted(profile.glob('*.prof')):
            print(f'--- {prof.stem}: top functions by own time')
            pstats.Stats(str(prof)).sort_stats('tottime').print_stats(8)
    start = end = None
    for line in (workdir / 'plant_node.log').read_text().splitlines():
        m = _LOG_TIME.search(line)
        if not m:
            continue
        if m.group(2).startswith('peers matched'):
            start = float(m.group(1))
        elif m.group(2).startswith('run complete'):
            end = float(m.group(1))
    steps = int(round(duration * 1000))
    return steps / (end - start), steps


def realtime_latency(duration: float, workdir: Path, priority: int) -> dict[str, str]:
    """One realtime run; the controller's and the plant's timing summary lines."""
    spec = RunSpec(output=workdir / 'realtime.mcap', plant='pmlm', controller='pid',
                   timing='realtime', duration=duration, realtime_priority=priority)
    run_nodes(spec, workdir=workdir, domain_id=private_domain_id(), progress=False)
    ctl = (workdir / 'controller_node.log').read_text(errors='replace')
    plant = (workdir / 'plant_node.log').read_text(errors='replace')
    age = re.search(r'timing: (\d+) commands, (\d+) backlog samples skipped', ctl)
    slip = re.search(r'slipped (\d+) periods .*?after the last sample: p50 ([\d.]+) ms, '
                     r'p99 ([\d.]+) ms, max ([\d.]+) ms', plant)
    jit = re.search(r'control period jitter: p50 ([\d.]+) ms, p99 ([\d.]+) ms, '
                    r'max ([\d.]+) ms', plant)
    return {'p50/p99/max [ms]': '/'.join(slip.group(2, 3, 4)) if slip else '?',
            'jitter': '/'.join(jit.group(1, 2, 3)) if jit else '?',
            'skipped': age[2] if age else '?', 'commands': age[1] if age else '?',
            'slipped': slip[1] if slip else '?'}


def main() -> int:
    """Run the three measurements and print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument('--role', choices=('ping', 'pong'))
    ap.add_argument('--steps', type=int, default=5000)
    ap.add_argument('--loop', choices=('executor', 'lean'), default='executor')
    ap.add_argument('--lockstep-s', type=float, default=10.0)
    ap.add_argument('--realtime-s', type=float, default=5.0,
                    help='realtime run length [s] (0 = skip the realtime runs)')
    ap.add_argument('--repeat', type=int, default=1,
                    help='alternate reference and lockstep runs this often (median)')
    ap.add_argument('--profile', type=Path, default=None, metavar='DIR',
                    help="lockstep: cProfile each node's spin loop into DIR/<node>.prof "
                         'and print the top functions')
    args = ap.parse_args()
    if args.role:
        _pingpong(args.role, args.steps, args.loop)
        return 0
    for name in ('steps', 'repeat'):
        if getattr(args, name) < 1:
            ap.error(f'--{name} must be >= 1')
    if not args.lockstep_s > 0 or not args.realtime_s >= 0:
        ap.error('--lockstep-s must be > 0 and --realtime-s >= 0')
    # interleaved: the machine's load drifts (other work on the shared cores), so each
    # lockstep run sits between reference runs, and the medians are compared
    rts, leans, rates, costs = [], [], [], []
    for _ in range(args.repeat):
        rts.append(bare_round_trip(args.steps, 'executor'))
        leans.append(bare_round_trip(args.steps, 'lean'))
        with tempfile.TemporaryDirectory() as tmp:
            rate, steps = lockstep_rate(args.lockstep_s, Path(tmp), args.profile)
            costs.append(loop_costs(Path(tmp), steps))
        rates.append(rate)
    rt, rt_lean, rate = (statistics.median(v) for v in (rts, leans, rates))
    if args.repeat > 1:
        print('runs (reference round trips/s, LeanLoop, lockstep steps/s, ratio): ' + '; '.join(
            f'{a:.0f}, {b:.0f}, {c:.0f}, {c / a:.2f}' for a, b, c in zip(rts, leans, rates)))
    lat = {}
    for prio in ((0, DEFAULT_RT_PRIORITY) if args.realtime_s > 0 else ()):
        with tempfile.TemporaryDirectory() as tmp:
            lat[prio] = realtime_latency(args.realtime_s, Path(tmp), prio)
    print(f'{"measurement":<46} {"value":>12} {"ratio":>10}')
    print('-' * 70)
    print(f'{"bare 2-process rclpy round trips/s (reference)":<46} {rt:>12.0f} '
          f'{1.0:>10.2f}   (SingleThreadedExecutor.spin_once)')
    print(f'{"bare 2-process round trips/s, LeanLoop":<46} {rt_lean:>12.0f} '
          f'{rt_lean / rt:>10.2f}   (wait-set loop the nodes use)')
    print(f'{"lockstep control steps/s, 4 nodes + recorder":<46} {rate:>12.0f} '
          f'{rate / rt:>10.2f}   ({steps} steps; ×{rate / 1000:.2f} real time at 1 kHz)')
    # where the time goes: the loop is CPU-bound across its processes on a small machine
    cpu = {k: statistics.median(c.get(k, float('nan')) for c in costs)
           for k in (*NODE_NAMES, 'paced_s')}
    total = sum(cpu[n] for n in NODE_NAMES)
    print(f'{"lockstep CPU per step [µs], all processes":<46} {total:>12.0f}   ('
          + ', '.join(f'{n.removesuffix("_node")} {cpu[n]:.0f}' for n in NODE_NAMES)
          + f'; plant waited {cpu["paced_s"]:.3f} s on acknowledgements)')
    for prio, row in lat.items():
        label = f'realtime command delay at plant, priority {prio}'
        print(f'{label:<46} {row["p50/p99/max [ms]"]:>12}   ({row["commands"]} commands, '
              f'{row["skipped"]} backlog samples skipped, plant slipped {row["slipped"]} '
              f'periods)')
        label = f'realtime period jitter p50/p99/max [ms], prio {prio}'
        print(f'{label:<46} {row["jitter"]:>12}   (|tick interval − 1 ms| at the plant; '
              f'goal p99 < 0.5 ms; 0.1 ms bins)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
