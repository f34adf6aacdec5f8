"""File parameters from another process (issue 24 item 1): nothing leaks, nothing hangs.

A ``monitor_node`` and a ``controller_node`` run as processes with ``model_dir`` set to
one directory; this test process (another rclpy participant on the private domain) sets
their file parameters — ``model``, ``compensation_model``, ``compensation_table`` —
through the standard ``set_parameters`` service, as anyone on the graph could:

* a path outside ``model_dir`` is refused and never opened (inotify on the file sees
  no open, no read), the reason saying why;
* a FIFO inside is refused, and the node keeps answering (its parameter service
  replies to the next request; SIGTERM at the end stops it cleanly);
* a file inside with invalid content holding a unique marker line is refused with a
  reason (returned to the caller, and logged: on ``/rosout`` too) that contains no line
  of the file — nor does any ``/rosout`` message or the node's log;
* a valid file inside is accepted.
Every wait is on a condition (a reply, a message count, a process exit).
"""
from __future__ import annotations

import ctypes
import ctypes.util
import os
import signal
import struct
import uuid
from pathlib import Path

import pytest
import yaml

pytestmark = pytest.mark.timeout(180)

IN_ACCESS, IN_OPEN = 0x1, 0x20


class Inotify:
    """The open/read events of a set of files (Linux inotify through libc)."""

    def __init__(self) -> None:
        self.libc = ctypes.CDLL(ctypes.util.find_library('c'), use_errno=True)
        self.fd = self.libc.inotify_init1(os.O_NONBLOCK | os.O_CLOEXEC)
        assert self.fd >= 0, os.strerror(ctypes.get_errno())
        self.names: dict[int, str] = {}

    def watch(self, path: Path) -> None:
        wd = self.libc.inotify_add_watch(self.fd, str(path).encode(), IN_OPEN | IN_ACCESS)
        assert wd >= 0, os.strerror(ctypes.get_errno())
        self.names[wd] = path.name

    def events(self) -> list[tuple[str, int]]:
        """(file name, mask) of every event queued so far (inotify queues at open time)."""
        out = []
        while True:
            try:
                buf = os.read(self.fd, 65536)
            except BlockingIOError:
                return out
            pos = 0
            while pos < len(buf):
                wd, mask, _, size = struct.unpack_from('iIII', buf, pos)
                out.append((self.names.get(wd, '?'), mask))
                pos += 16 + size

    def close(self) -> None:
        os.close(self.fd)


def test_file_parameters_from_another_process(tmp_path: Path, nodes, probe) -> None:
    from rcl_interfaces.msg import Log
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from motor_comp.control.compensation import position_table, write_table
    from motor_comp.physics.config import load_plant

    allowed, outside = tmp_path / 'allowed', tmp_path / 'outside'
    allowed.mkdir()
    outside.mkdir()
    marker = f'MARKER-{uuid.uuid4().hex}'
    model = load_plant('pmlm').model
    model.save(allowed / 'model.yaml')
    model.save(allowed / 'model2.yaml')
    write_table(allowed / 'table.csv', position_table(model, points=128))
    (allowed / 'bad.yaml').write_text(f'{marker}: 1\nmass: {marker}\n')
    (allowed / 'bad.csv').write_text(f'position_m,force_N,command_V\n0,1,{marker}\n'
                                     f'{marker}\n')
    os.mkfifo(allowed / 'fifo.yaml')
    secret = outside / 'secret.yaml'
    secret.write_text(f'# {marker}\n' + yaml.safe_dump(model.to_dict()))
    os.mkfifo(outside / 'fifo.yaml')

    watch = Inotify()
    for f in (secret, outside / 'fifo.yaml', allowed / 'fifo.yaml'):
        watch.watch(f)

    params = tmp_path / 'p.yaml'
    params.write_text(yaml.safe_dump({
        '/axis/monitor_node': {'ros__parameters': {'model': str(allowed / 'model.yaml'),
                                                   'model_dir': str(allowed)}},
        '/axis/controller_node': {'ros__parameters': {'model_dir': str(allowed)}}}))
    logs: list[str] = []
    probe.node.create_subscription(Log, '/rosout', lambda m: logs.append(m.msg),
                                   QoSProfile(depth=1000,
                                              reliability=ReliabilityPolicy.RELIABLE))
    nodes.start('monitor_node', params)
    nodes.start('controller_node', params)

    cases = [('monitor_node', 'model', 'model file', allowed / 'model2.yaml',
              allowed / 'bad.yaml'),
             ('controller_node', 'compensation_model', 'model file', allowed / 'model.yaml',
              allowed / 'bad.yaml'),
             ('controller_node', 'compensation_table', 'compensation table',
              allowed / 'table.csv', allowed / 'bad.csv')]
    rejections = 0
    for node, param, what, good, bad in cases:
        before = probe.get_parameter(node, param)

        def refused(path: Path, needle: str) -> str:
            res = probe.set_parameters(node, **{param: str(path)})[0]
            assert not res.successful, (node, param, path)
            assert needle in res.reason, res.reason
            assert marker not in res.reason, res.reason
            assert probe.get_parameter(node, param) == before   # old value kept
            return res.reason

        # outside model_dir: refused, never opened (no inotify open/access event)
        reason = refused(secret, 'is outside the allowed directories')
        assert reason.startswith(f'{param}: {secret} is outside'), reason
        refused(outside / 'fifo.yaml', 'is outside the allowed directories')
        # a FIFO inside: refused without blocking; the service answers the next request
        refused(allowed / 'fifo.yaml', 'is a FIFO; only regular files are read')
        assert watch.events() == [], (node, param)
        # invalid content inside: the reason names the file and the problem, not a line
        reason = refused(bad, f'{bad}: not a valid {what}')
        for line in bad.read_text().splitlines():
            assert line not in reason
        rejections += 4
        # a valid file inside: accepted
        res = probe.set_parameters(node, **{param: str(good)})[0]
        assert res.successful, res.reason
        assert probe.get_parameter(node, param) == str(good)
        if node == 'controller_node':   # exclusive with the next one: clear it again
            assert probe.set_parameters(node, **{param: ''})[0].successful

    # what was logged (on /rosout, where anyone on the graph reads it) quotes no file
    probe.spin_until(lambda: sum('rejected parameter update' in m for m in logs)
                     >= rejections, 30,
                     lambda: f'{rejections} rejection log lines on /rosout, got '
                             f'{sum("rejected parameter update" in m for m in logs)}')
    assert not [m for m in logs if marker in m]
    nodes.check_alive()

    # the watcher works: the test's own open of the secret is seen
    secret.read_text()
    assert any(name == 'secret.yaml' and mask & IN_OPEN for name, mask in watch.events())
    watch.close()

    # SIGTERM stops both promptly and cleanly (exit 0: no SIGABRT/SIGKILL was needed)
    for node in ('controller_node', 'monitor_node'):
        assert nodes.stop(node, sig=signal.SIGTERM, timeout=20) == 0, \
            nodes.procs[node].tail()
        log = nodes.procs[node].log.read_text(errors='replace')
        assert marker not in log and 'Traceback' not in log
