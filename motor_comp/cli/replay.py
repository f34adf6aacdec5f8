"""``motor-comp replay``: publish a recorded run's topics with their recorded timing.

Every channel of the MCAP whose message type is importable here (the DESIGN.md §5
types, or any installed ROS message package) is published under its recorded topic
name, as the recorded CDR bytes (no decode/encode), paced by the recorded log times
divided by ``--rate``.  Sim time goes out on ``/clock``: the recorded ``/clock`` if the
file has one, else one Clock per distinct log time.  So a controller node, a
monitoring node or a live plotter (``use_sim_time:=true``) consumes a past run as if it
were live.  A rosbag2 directory (MCAP or sqlite3 storage, split or not) is replayed the
same way.

With ``--topic``/``--joint``/``--input``/``--reference`` one joint of a robot's bag is
published instead as the DESIGN.md §5 topics (``/axis/joint_states``,
``/axis/voltage``, ``/axis/reference``), so the project's nodes (e.g. ``monitor_node``)
consume a robot's joint as they consume an axis of ours.  Ctrl-C stops cleanly.
"""
from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import sys
import time
from pathlib import Path
from typing import Any, Iterator

from motor_comp.cli.common import add_bag_options, add_json, nonnegative_float, run_topics
from motor_comp.errors import InputFileError, ParameterError
from motor_comp.logs.progress import warn


def _message_class(type_name: str) -> Any | None:
    """Return the rclpy message class of ``pkg/msg/Type`` (None if not installed)."""
    parts = type_name.split('/')
    if len(parts) == 2:
        parts = [parts[0], 'msg', parts[1]]
    if len(parts) != 3:
        return None
    try:
        return getattr(importlib.import_module(f'{parts[0]}.{parts[1]}'), parts[2])
    except (ImportError, AttributeError):
        return None


def _messages(path: Path, damage: list[tuple[int, str]] | None = None
              ) -> Iterator[tuple[str, str, int, bytes]]:
    """(topic, type, log_time_ns, cdr) in log-time order; one-line errors.

    A file without a readable summary (truncated, or the recorder was killed) is read
    linearly in file order up to its damage, which is described in ``damage``.  A
    rosbag2 directory: its files in order (sqlite3 storage through rosbags).
    """
    from motor_comp.logs.bags import locate
    bag = locate(path)
    if bag.storage == 'sqlite3':
        from rosbags.rosbag2 import Reader
        with Reader(bag.path) as b:
            for conn, stamp, raw in b.messages():
                yield conn.topic, conn.msgtype, stamp, raw
        return
    for f in bag.files:
        yield from _mcap_messages(f, damage)


def _run_messages(path: Path, topics: Any) -> Iterator[tuple[str, str, int, bytes]]:
    """One joint of a bag as the §5 topics: (topic, type, stamp_ns, cdr) in time order."""
    import numpy as np

    from motor_comp.logs import cdr, read_run, schemas
    run = read_run(path, topics=topics)
    names = schemas.topics('axis')
    t = np.round(run.t * 1e9).astype(np.int64)
    streams = [(names['joint_states'], schemas.JOINT_STATE,
                cdr.encode_joint_states(t, run.position, run.velocity, run.effort))]
    if run.voltage is not None:
        streams.append((names['voltage'], schemas.FLOAT64, cdr.encode_float64(run.voltage)))
    if run.reference is not None:
        streams.append((names['reference'], schemas.JOINT_STATE,
                        cdr.encode_joint_states(t, run.reference, run.reference_velocity)))
    for i in range(t.size):
        for topic, type_name, rows in streams:
            yield topic, type_name, int(t[i]), rows[i].tobytes()


def _mcap_messages(path: Path, damage: list[tuple[int, str]] | None = None
                   ) -> Iterator[tuple[str, str, int, bytes]]:
    """One MCAP file's messages (see :func:`_messages`)."""
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader, make_reader

    from motor_comp.logs.mcap_io import MAGIC
    try:
        with open(path, 'rb') as f:
            if f.read(len(MAGIC)) != MAGIC:
                raise InputFileError(f'{path}: not an MCAP file (bad magic bytes)')
            f.seek(0)
            reader = make_reader(f)
            try:
                reader.get_summary()
                intact = True
            except Exception:  # noqa: BLE001 - any failure here means: no usable summary
                intact = False
            if intact:
                for schema, channel, message in reader.iter_messages(log_time_order=True):
                    if channel.message_encoding == 'cdr' and schema is not None:
                        yield channel.topic, schema.name, message.log_time, message.data
                return
            f.seek(0)
            n = 0
            try:
                for schema, channel, message in NonSeekingReader(f).iter_messages(
                        log_time_order=False):
                    if channel.message_encoding == 'cdr' and schema is not None:
                        n += 1
                        yield channel.topic, schema.name, message.log_time, message.data
            except Exception as exc:  # noqa: BLE001 - a parse failure is the damage
                if damage is not None:
                    why = f'{type(exc).__name__}: {exc}' if str(exc) else type(exc).__name__
                    damage.append((n, why[:100]))
    except FileNotFoundError:
        raise InputFileError(f'{path}: no such file') from None
    except (McapError, ValueError, EOFError, OSError) as exc:
        raise InputFileError(f'{path}: cannot replay ({type(exc).__name__}: {exc}); try '
                             f'`motor-comp analyze` to read what is recoverable') from None


#: a message reached later than this after its scheduled send time counts as late [s]
LATE_S = 0.005


@dataclasses.dataclass(frozen=True)
class ReplayResult:
    """What a replay published, and how well it kept the recorded timing.

    Attributes
    ----------
    published : dict[str, int]
        Messages published per topic.
    late : int
        Messages reached more than :data:`LATE_S` after their scheduled send time (the
        process was descheduled, or publishing is slower than the recorded rate); they
        are sent at once, so the replay catches up with its absolute schedule.
    max_late_s : float
        The largest such lateness [s].
    """

    published: dict[str, int]
    late: int = 0
    max_late_s: float = 0.0


def replay(path: Path, *, rate: float = 1.0, wait_for_subscribers: int = 0,
           startup_delay: float = 1.0, timeout: float = 30.0,
           topics: Any = None) -> ReplayResult:
    """Publish ``path``'s topics at ``rate`` × recorded speed; counts and lateness.

    ``rate`` 0 publishes as fast as possible.  Before the first message, waits until
    ``wait_for_subscribers`` readers have matched any replayed topic (at most
    ``timeout`` s) and then ``startup_delay`` s, so DDS discovery completes.
    ``topics`` (a :class:`~motor_comp.logs.topics.RunTopics`): publish that joint of
    the bag as the §5 topics instead of every channel as recorded.
    """
    path = Path(path)
    from motor_comp.logs.bags import locate
    bag = locate(path)
    if bag.storage == 'mcap' and any(f.stat().st_size == 0 for f in bag.files):
        raise InputFileError(f'{path}: empty file')
    if not (rate >= 0.0 and rate < float('inf')):
        raise ParameterError(f'--rate must be >= 0, got {rate:g}')
    if not (startup_delay >= 0.0 and startup_delay < float('inf')):
        raise ParameterError(f'--startup-delay must be a finite number >= 0, '
                             f'got {startup_delay:g}')
    # pre-scan: the channels to publish (and a corrupt file fails before any publish)
    types: dict[str, str] = {}
    damage: list[tuple[int, str]] = []

    def messages(damage: list[tuple[int, str]] | None = None
                 ) -> Iterator[tuple[str, str, int, bytes]]:
        return _messages(path, damage) if topics is None else _run_messages(path, topics)
    for topic, type_name, _, _ in messages(damage):
        types.setdefault(topic, type_name)
    if damage and not types:
        raise InputFileError(f'{path}: corrupt or truncated ({damage[0][1]}); '
                             'no messages could be read')
    if not types:
        raise InputFileError(f'{path}: no CDR messages to replay')
    if damage:
        warn(f'{path.name}: damaged or unfinished file; replaying the {damage[0][0]} '
             f'messages recovered before the damage ({damage[0][1]})')

    import rclpy
    from rclpy.duration import Duration
    from rosgraph_msgs.msg import Clock

    from motor_comp.nodes.common import LOOP_QOS, set_stamp
    rclpy.init(args=[])
    node = rclpy.create_node('replay', namespace='/')
    counts = {t: 0 for t in types}
    try:
        pubs = {}
        for topic, type_name in types.items():
            cls = _message_class(type_name)
            if cls is None:
                print(f'motor-comp replay: skipping {topic} ({type_name} not installed)',
                      file=sys.stderr)
                continue
            pubs[topic] = node.create_publisher(cls, topic, LOOP_QOS)
        synth_clock = '/clock' not in pubs
        clock_pub = node.create_publisher(Clock, '/clock', LOOP_QOS) if synth_clock else None
        deadline = time.monotonic() + timeout
        while sum(p.get_subscription_count() for p in pubs.values()) < wait_for_subscribers:
            if time.monotonic() > deadline:
                raise InputFileError(f'replay: no {wait_for_subscribers} subscriber(s) '
                                     f'matched within {timeout:g} s')
            rclpy.spin_once(node, timeout_sec=0.05)
        time.sleep(startup_delay)
        clock = Clock()
        t0_log = None
        t0_wall = time.monotonic()
        last_clock = None
        late, max_late = 0, 0.0
        for topic, _, log_ns, data in messages():
            pub = pubs.get(topic)
            if pub is None:
                continue
            if t0_log is None:
                t0_log = log_ns
            if rate > 0:
                delay = t0_wall + (log_ns - t0_log) * 1e-9 / rate - time.monotonic()
                if delay > 0:
                    time.sleep(delay)
                elif delay < -LATE_S:
                    late += 1
                    max_late = max(max_late, -delay)
            if synth_clock and log_ns != last_clock:
                set_stamp(clock.clock, log_ns)
                clock_pub.publish(clock)
                last_clock = log_ns
            pub.publish(data)   # the recorded CDR bytes, unchanged
            counts[topic] += 1
        for pub in pubs.values():   # let reliable readers receive the tail
            pub.wait_for_all_acked(Duration(seconds=2.0))
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return ReplayResult(published=counts, late=late, max_late_s=max_late)


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``replay`` subcommand."""
    p = subparsers.add_parser('replay', help='publish a recorded run with its timing',
                              description=__doc__.splitlines()[0])
    p.add_argument('run', type=Path, help='an MCAP file or a rosbag2 directory')
    p.add_argument('--rate', type=nonnegative_float, default=1.0,
                   help='speed factor (default 1 = recorded speed; 0 = as fast as possible)')
    p.add_argument('--wait-for-subscribers', type=int, default=0, metavar='N',
                   help='wait until N readers matched before publishing (default 0)')
    p.add_argument('--startup-delay', type=nonnegative_float, default=1.0,
                   help='seconds for DDS discovery before the first message (default 1)')
    add_json(p, help='print the counts as one JSON object')
    add_bag_options(p)
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``motor-comp replay``."""
    from motor_comp.cli.run import require_ros
    require_ros('motor-comp replay')
    if args.startup_delay < 0 or args.wait_for_subscribers < 0:
        raise ParameterError('--startup-delay and --wait-for-subscribers must be >= 0')
    one_joint = any(getattr(args, k) is not None
                    for k in ('topic', 'joint', 'input', 'reference'))
    res = replay(args.run, rate=args.rate, wait_for_subscribers=args.wait_for_subscribers,
                 startup_delay=args.startup_delay,
                 topics=run_topics(args) if one_joint else None)
    if args.json:
        print(json.dumps({'run': str(args.run), 'published': res.published,
                          'late': res.late, 'max_late_s': res.max_late_s}))
    else:
        for topic, n in res.published.items():
            print(f'{topic:<28} {n:>8} messages')
        if res.late:
            print(f'{res.late} messages sent more than {LATE_S * 1e3:g} ms behind the '
                  f'recorded timing (at most {res.max_late_s * 1e3:.1f} ms)')
    return 0
