"""``motor-comp run``: the four ROS 2 nodes as separate processes, one recorded run.

No ``ros2 launch`` needed (the PyPI ROS wheels have no launch): this module starts
``recorder_node``, ``controller_node``, ``trajectory_node`` and ``plant_node`` (and
``monitor_node`` with ``--monitor MODEL.yaml``) with ``python -m motor_comp.nodes.<name>
--ros-args --params-file <generated yaml>``, waits for the plant to finish
``--duration`` of sim time, stops the others with SIGINT (the recorder finalises its
MCAP), and prints the metrics of the recorded file (with ``--monitor``, the monitor's
verdicts recorded from ``/diagnostics``).

Limits (``--travel MIN MAX``, ``--vmax``, ``--amax``, ``--umax``, ``--max-error``): a
trajectory beyond them is refused before any process starts; during the run the
controller trips on them (0 V from then on, exit status 3 after ``trip_hold``), the
run stops, the recording is finalised and kept, and ``motor-comp run`` ends with the
controller's one-line reason (exit status 3).

Files: the nodes may read files only inside their ``model_dir``; the run sets it to the
working directory, the package ``config/`` and the directories of the files named on
its command line (``--plant FILE``, ``--monitor MODEL``).  The recorder only creates new
files: when ``-o`` exists it writes ``<stem>.partial-<pid>.mcap`` next to it, moved onto
``-o`` when the run ends or trips (a run that fails otherwise leaves the old ``-o`` as
it was and names the partial file in its error).

:class:`NodeGroup` (process start, wait, clean stop — also on errors) is shared with
``motor-comp demo`` and the node tests.
"""
from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any, Mapping, Sequence

import yaml

from motor_comp.cli.common import add_json, add_limits, check_output_file, jsonable, \
    positive_float
from motor_comp.control.limits import Limits
from motor_comp.errors import LimitTripError, MotorCompError, ParameterError
from motor_comp.nodes import PARENT_ENV

NODES = ('recorder_node', 'controller_node', 'trajectory_node', 'plant_node')
#: exit status of a controller process that tripped a limit (controller_node)
TRIP_EXIT_STATUS = 3
MODES = ('pid', 'adaptive_sliding', 'npid')
FEEDFORWARDS = ('none', 'static', 'gms', 'static+gms')
_counter = itertools.count()
#: SCHED_FIFO priority of the loop processes in realtime mode (ros2_control uses 50 for
#: its control thread; below it, so a co-running ros2_control keeps precedence)
DEFAULT_RT_PRIORITY = 40


class NodeProcessError(MotorCompError):
    """A node process failed (bad parameter, crash, timeout)."""


#: ROS_DOMAIN_IDs handed out by :func:`private_domain_id` (above the 20–89 that people
#: pick by hand here; ≤ 230 keeps Fast DDS's ports 7400 + 250·id + offsets below 65536)
DOMAIN_RANGE = (100, 230)
#: where the per-domain lock files live (one ``fcntl`` lock per domain id)
DOMAIN_LOCK_DIR = Path(tempfile.gettempdir())
_domain_locks: dict[int, int] = {}


def private_domain_id() -> int:
    """Reserve a ROS_DOMAIN_ID no other process on this machine holds; return it.

    A pid-derived guess collides when several test runs, benches or ``motor-comp run``
    go at once (two loops on one domain cross-talk: the lockstep plant answers the
    other loop's commands).  Each id in :data:`DOMAIN_RANGE` has a lock file
    ``motor_comp_domain_<id>.lock`` in :data:`DOMAIN_LOCK_DIR`; the first id whose
    ``flock`` this process gets is held until :func:`release_domain_id` or process exit
    (the kernel drops the lock with the process, so a crash never leaks an id).
    Raises :class:`NodeProcessError` when every id is taken.
    """
    import fcntl
    low, high = DOMAIN_RANGE
    span = high - low + 1
    start = (os.getpid() * 7 + next(_counter)) % span   # spread the first tries
    for i in range(span):
        dom = low + (start + i) % span
        if dom in _domain_locks:
            continue
        path = DOMAIN_LOCK_DIR / f'motor_comp_domain_{dom}.lock'
        fd = os.open(path, os.O_RDWR | os.O_CREAT | os.O_CLOEXEC, 0o666)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            continue
        _domain_locks[dom] = fd
        return dom
    raise NodeProcessError(f'no free ROS_DOMAIN_ID in {low}..{high}: every one is held by '
                           f'another process (lock files in {DOMAIN_LOCK_DIR})')


def release_domain_id(domain_id: int) -> None:
    """Give back a domain id reserved by :func:`private_domain_id` (no-op otherwise)."""
    fd = _domain_locks.pop(domain_id, None)
    if fd is not None:
        os.close(fd)   # closing the descriptor releases the flock


#: what the node processes import: rclpy and the message packages of DESIGN.md §5
ROS_MODULES = ('rclpy', 'rclpy.lifecycle', 'rcl_interfaces.msg', 'lifecycle_msgs.msg',
               'std_msgs.msg', 'sensor_msgs.msg', 'rosgraph_msgs.msg')


def require_ros(command: str) -> None:
    """Raise a one-line :class:`MotorCompError` if ROS 2 (rclpy + messages) is missing.

    Called before anything starts: without it the failure shows up as a node
    process's traceback fragment (``No module named 'rcl_interfaces'``) after the other
    nodes were already started.  The message names what is missing and both ways to
    get it.
    """
    import importlib
    missing = []
    for name in ROS_MODULES:
        try:
            importlib.import_module(name)
        except ImportError as exc:   # also a broken install (a native library missing)
            top = getattr(exc, 'name', None) or name
            top = top.split('.')[0]
            if top not in missing:
                missing.append(top)
    if missing:
        raise MotorCompError(
            f'{command} needs ROS 2 Jazzy, which is not installed here (missing: '
            f"{', '.join(missing)}): install the ROS wheels with `pip install -e '.[ros]'`, "
            f'or source a ROS 2 Jazzy setup (`source /opt/ros/jazzy/setup.bash`)')


def ros_environment(domain_id: int | None = None) -> dict[str, str]:
    """Return the environment for node processes: localhost-only DDS, a chosen domain."""
    env = dict(os.environ)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = env.get('ROS_AUTOMATIC_DISCOVERY_RANGE',
                                                   'LOCALHOST')
    env.setdefault('RMW_IMPLEMENTATION', 'rmw_fastrtps_cpp')
    if domain_id is not None:
        env['ROS_DOMAIN_ID'] = str(domain_id)
    elif 'ROS_DOMAIN_ID' not in env:
        env['ROS_DOMAIN_ID'] = str(private_domain_id())
    env['PYTHONUNBUFFERED'] = '1'
    return env


def write_params_file(path: Path, params: Mapping[str, Mapping[str, Any]],
                      namespace: str = 'axis') -> Path:
    """Write ``{node: {param: value}}`` as a ROS 2 params file (``/ns/node`` keys)."""
    data = {f'/{namespace}/{node}': {'ros__parameters': dict(values)}
            for node, values in params.items()}
    path.write_text(yaml.dump(data, Dumper=_NoAliasDumper, sort_keys=False),
                    encoding='utf-8')
    return path


class _NoAliasDumper(yaml.SafeDumper):
    """Write a value shared by two nodes twice: rcl's params parser refuses YAML aliases."""

    def ignore_aliases(self, data: Any) -> bool:
        """Never write an alias."""
        return True


@dataclasses.dataclass
class NodeProcess:
    """One node process and its log file."""

    name: str
    popen: subprocess.Popen
    log: Path

    def tail(self, n: int = 3) -> str:
        """Return the last ``n`` non-empty lines of the node's output (for error messages)."""
        try:
            lines = [ln for ln in self.log.read_text(errors='replace').splitlines()
                     if ln.strip()]
        except OSError:
            return ''
        return ' | '.join(lines[-n:])

    def warnings(self) -> list[str]:
        """Return the node's logged warnings and errors (what a user should see)."""
        try:
            text = self.log.read_text(errors='replace')
        except OSError:
            return []
        return [ln.strip() for ln in text.splitlines()
                if '[WARN]' in ln or '[ERROR]' in ln]


class NodeGroup:
    """Start node processes, watch them, and always stop them (context manager).

    Parameters
    ----------
    workdir : Path
        Where the generated params file and the node logs go.
    env : Mapping[str, str]
        Environment of the processes (see :func:`ros_environment`).
    """

    def __init__(self, workdir: Path, env: Mapping[str, str]) -> None:
        self.workdir = Path(workdir)
        self.env = dict(env)
        self.procs: dict[str, NodeProcess] = {}

    def start(self, node: str, params_file: Path | None = None,
              extra: Sequence[str] = ()) -> NodeProcess:
        """Start ``python -m motor_comp.nodes.<node>`` with a params file and extra args."""
        return self.start_as(node, node, params_file, extra)

    def start_as(self, name: str, node: str, params_file: Path | None = None,
                 extra: Sequence[str] = ()) -> NodeProcess:
        """Start node module ``node`` under the label ``name`` (e.g. a second recorder)."""
        log = self.workdir / f'{name}.log'
        ros_args = ['--ros-args', '--log-level', 'info']
        if params_file is not None:
            ros_args += ['--params-file', str(params_file)]
        cmd = [sys.executable, '-m', f'motor_comp.nodes.{node}', *ros_args, *extra]
        with open(log, 'wb') as out:
            # the node stops by itself when this process is gone (PARENT_ENV)
            env = {**self.env, PARENT_ENV: str(os.getpid())}
            popen = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env,
                                     stdin=subprocess.DEVNULL, start_new_session=True)
        proc = NodeProcess(name, popen, log)
        self.procs[name] = proc
        return proc

    def check_alive(self, *, except_: Sequence[str] = ()) -> None:
        """Raise :class:`NodeProcessError` if a node (not in ``except_``) has exited."""
        for name, proc in self.procs.items():
            if name in except_:
                continue
            code = proc.popen.poll()
            if code is not None:
                raise NodeProcessError(f'{name} exited with status {code}: {proc.tail()}')

    def wait(self, node: str, timeout: float, *, watch: bool = True) -> int:
        """Wait for ``node`` to exit (others must stay alive if ``watch``); its status."""
        proc = self.procs[node]
        deadline = time.monotonic() + timeout
        while True:
            code = proc.popen.poll()
            if code is not None:
                return code
            if watch:
                self.check_alive(except_=(node,))
            if time.monotonic() > deadline:
                raise NodeProcessError(f'{node} did not finish within {timeout:g} s '
                                       f'(last output: {proc.tail()})')
            time.sleep(0.05)

    def stop(self, node: str, *, sig: int = signal.SIGINT, timeout: float = 10.0) -> int:
        """Signal ``node`` and wait for it to exit (SIGABRT, then SIGKILL after ``timeout``).

        SIGABRT first: the node's fault handler writes every thread's stack to its log,
        so a stop that hangs says where.
        """
        popen = self.procs[node].popen
        if popen.poll() is None:
            try:
                popen.send_signal(sig)
                return popen.wait(timeout)
            except subprocess.TimeoutExpired:
                popen.send_signal(signal.SIGABRT)
                try:
                    return popen.wait(5.0)
                except subprocess.TimeoutExpired:
                    popen.kill()
        return popen.wait()

    def stop_all(self, order: Sequence[str] | None = None) -> dict[str, int]:
        """Stop every node (in ``order``, then the rest); their exit statuses."""
        names = list(order or ()) + [n for n in self.procs if n not in (order or ())]
        return {n: self.stop(n) for n in names if n in self.procs}

    def __enter__(self) -> 'NodeGroup':
        return self

    def __exit__(self, *exc: Any) -> None:
        # stop the loop's drivers first so the recorder sees a quiet graph when it drains
        self.stop_all(['plant_node', 'trajectory_node', 'monitor_node', 'controller_node',
                       'recorder_node'])


@dataclasses.dataclass(frozen=True)
class RunSpec:
    """Everything that defines one run of the four nodes."""

    output: Path
    plant: str = 'pmlm'
    controller: str = 'pid'
    feedforward: str = 'none'
    trajectory: str = ''
    #: the CSV a ``table`` trajectory plays (its directory becomes the node's model_dir)
    trajectory_file: str = ''
    timing: str = 'lockstep'
    duration: float = 2.0
    control_rate: float = 1000.0
    seed: int = 0
    namespace: str = 'axis'
    #: realtime: SCHED_FIFO priority of the plant, trajectory and controller (0 = off)
    realtime_priority: int = 0
    #: the axis limits (controller trips, trajectory refuses); none by default
    limits: Limits = dataclasses.field(default_factory=Limits)
    #: a model file for ``monitor_node`` ('' = no monitor)
    monitor: str = ''
    extra_params: Mapping[str, Mapping[str, Any]] = dataclasses.field(default_factory=dict)

    @property
    def trajectory_kind(self) -> str:
        """The trajectory this run plays (p2p on the PMLM, sine otherwise, by default)."""
        return self.trajectory or ('p2p' if self.plant == 'pmlm' else 'sine')

    def trajectory_object(self) -> Any:
        """Return the :class:`~motor_comp.control.trajectories.Trajectory` this run plays.

        A ``table`` is read from :attr:`trajectory_file` (one-line errors naming it).
        """
        from motor_comp.control.trajectories import make_trajectory
        kind = self.trajectory_kind
        if kind == 'table':
            return make_trajectory(kind, file=self.trajectory_file)
        return make_trajectory(kind)

    def model_dirs(self) -> list[str]:
        """Return the directories the nodes may read files from (``model_dir``).

        The working directory and the package ``config/`` (the nodes' defaults), and
        the directories of the files this run names (a plant file, the monitor's model,
        a table trajectory's CSV).
        """
        from motor_comp.param_files import default_dirs
        dirs = [str(d) for d in default_dirs()]
        for f in (self.plant if self.plant not in ('pmlm', 'ballscrew') else '',
                  self.monitor, self.trajectory_file if self.trajectory_kind == 'table'
                  else ''):
            if f:
                d = str(Path(f).expanduser().resolve().parent)
                if d not in dirs:
                    dirs.append(d)
        return dirs

    def node_params(self) -> dict[str, dict[str, Any]]:
        """Return the parameters of each node for this run."""
        traj = self.trajectory_kind
        # the plant starts at rest on the reference, as the in-process simulator does
        x0 = self.trajectory_object().at(0.0).position
        # a table's file is read by the node inside its model_dir (model_dirs names it)
        table = ({'file': str(Path(self.trajectory_file).expanduser().resolve())}
                 if traj == 'table' else {})
        common = {'timing': self.timing, 'control_rate': float(self.control_rate),
                  'realtime_priority': int(self.realtime_priority)}
        files = {'model_dir': os.pathsep.join(self.model_dirs())}
        monitor = 1 if self.monitor else 0
        params = {
            'plant_node': {**common, **files, 'plant': self.plant,
                           'duration': float(self.duration),
                           'seed': int(self.seed), 'x0': float(x0),
                           # joint_states readers: controller, recorder (+ the realtime
                           # trajectory, which takes its time origin from it, + the
                           # monitor, which pairs every sample with its command)
                           'expected_subscribers': (3 if self.timing == 'realtime' else 2)
                           + monitor},
            'trajectory_node': {**common, **files, 'trajectory': traj,
                                'duration': float(self.duration), **table},
            'controller_node': {**common, **files, 'plant': self.plant,
                                'mode': self.controller, 'feedforward': self.feedforward},
            # the recorder knows which nodes come: it waits for them and their
            # parameters as long as the run may take (the run's own timeout bounds it;
            # a request lost in discovery is asked again, see recorder_node).  Its 10 s
            # default gave up under two CPU hogs, and the plant ran its 1.5 s lockstep
            # and exited before the recorder had its parameters (params:plant_node
            # missing from the recording)
            'recorder_node': {**files, 'output': str(self.output), 'timing': self.timing,
                              'match_timeout': 600.0},
        }
        if self.limits.active:
            lim = self.limits
            motion = {'travel': [float(v) for v in lim.travel], 'vmax': lim.vmax,
                      'amax': lim.amax}
            params['trajectory_node'].update(motion)
            # its limits status (armed, a trip) reaches the recorder from the start on
            params['controller_node'].update(motion, umax=lim.umax,
                                             max_error=lim.max_error, exit_on_trip=True,
                                             diagnostics_readers=1)
        if self.monitor:
            params['monitor_node'] = {**files, 'model': str(Path(self.monitor).resolve()),
                                      'timing': self.timing, 'diagnostics_readers': 1}
            # voltage readers: plant, recorder, monitor
            params['controller_node']['expected_subscribers'] = 3
            params['recorder_node']['nodes'] = ('plant_node,trajectory_node,'
                                                'controller_node,monitor_node')
        for node, values in self.extra_params.items():
            params.setdefault(node, {}).update(values)
        return params


def _partial_path(out: Path) -> Path:
    """Return a new file next to ``out`` for the recorder (it never overwrites a file)."""
    for i in itertools.count():
        tag = f'{os.getpid()}' + (f'-{i}' if i else '')
        tmp = out.with_name(f'{out.stem}.partial-{tag}{out.suffix or ".mcap"}')
        if not os.path.lexists(tmp):
            return tmp
    raise AssertionError('unreachable')


def trip_reason(proc: NodeProcess) -> str:
    """Return the controller's one-line trip reason (its ``<node>: error: …`` line)."""
    try:
        lines = proc.log.read_text(errors='replace').splitlines()
    except OSError:
        lines = []
    marker = f'{proc.name}: error: '
    reason = next((ln.split(marker, 1)[1] for ln in reversed(lines) if marker in ln), '')
    return reason or f'limit trip ({proc.tail()})'


def run_nodes(spec: RunSpec, *, workdir: Path | None = None, timeout: float | None = None,
              domain_id: int | None = None, progress: bool = True) -> Path:
    """Run the nodes for ``spec`` and return the recorded MCAP path.

    Raises :class:`NodeProcessError` (one line, with the failing node's last output)
    if a node exits early or the run does not finish within ``timeout`` seconds, and
    :class:`LimitTripError` (the controller's one-line reason) after a limit trip — the
    recording, finalised up to the stop, is at ``spec.output`` in both the normal and
    the trip case.
    """
    from motor_comp.control.limits import check_reference
    require_ros('running the ROS 2 nodes')
    # the recorder would only fail after every node has started: check the path first
    out = check_output_file(spec.output, '-o')
    # a reference beyond the limits is refused before anything starts
    check_reference(spec.trajectory_object(), spec.limits, duration=spec.duration,
                    rate=spec.control_rate)
    if timeout is None:
        timeout = 60.0 + 20.0 * spec.duration
    # the recorder only creates new files: an existing -o is replaced at the end
    partial = _partial_path(out) if os.path.lexists(out) else out
    spec = dataclasses.replace(spec, output=partial)
    with tempfile.TemporaryDirectory(prefix='motor_comp_run_') as tmp:
        work = Path(workdir or tmp)
        ns = spec.namespace.strip('/')
        if not ns or not all(part.isidentifier() for part in ns.split('/')):
            raise ParameterError(f'namespace must be a ROS name like axis or arm/x, '
                                 f'got {spec.namespace!r}')
        node_params = spec.node_params()
        params_file = write_params_file(work / 'params.yaml', node_params, namespace=ns)
        env = ros_environment(domain_id)
        t0 = time.monotonic()
        tripped: str | None = None
        try:
            with NodeGroup(work, env) as group:
                for node in (*NODES, *(['monitor_node'] if 'monitor_node' in node_params
                                       else [])):
                    group.start(node, params_file, ['-r', f'__ns:=/{ns}'])
                if progress:
                    print(f'motor-comp run: {spec.plant}/{spec.controller}/'
                          f'{spec.feedforward} {spec.timing} {spec.duration:g} s '
                          f'(ROS_DOMAIN_ID {env["ROS_DOMAIN_ID"]}) …', file=sys.stderr)
                code = _wait_for_end(group, timeout)
                if code is not None and code != 0:
                    raise NodeProcessError(f'plant_node exited with status {code}: '
                                           f'{group.procs["plant_node"].tail()}')
                statuses = group.stop_all(['plant_node', 'trajectory_node', 'monitor_node',
                                           'controller_node', 'recorder_node'])
                if statuses.get('controller_node') == TRIP_EXIT_STATUS:
                    tripped = trip_reason(group.procs['controller_node'])
                if progress:
                    # a recording without some node's parameters, or that started
                    # without a publisher, says so here, not only in a deleted log
                    for line in group.procs['recorder_node'].warnings():
                        print(f'motor-comp run: {line}', file=sys.stderr)
                if statuses.get('recorder_node', 0) != 0:
                    raise NodeProcessError(f'recorder_node exited with status '
                                           f'{statuses["recorder_node"]}: '
                                           f'{group.procs["recorder_node"].tail()}')
        except MotorCompError as exc:
            if partial != out and os.path.exists(partial):   # the old -o stays as it was
                raise type(exc)(f'{exc} (what was recorded is in {partial})') from None
            raise
        if partial != out:
            os.replace(partial, out)   # the run ended or tripped: its recording is -o
        if progress:
            print(f'motor-comp run: done in {time.monotonic() - t0:.1f} s wall → {out}',
                  file=sys.stderr)
    if tripped is not None:
        raise LimitTripError(f'{tripped} (the axis was stopped at 0 V; the recording up to '
                             f'the stop is {out})')
    return out


def _wait_for_end(group: NodeGroup, timeout: float) -> int | None:
    """Wait for the plant to finish or the controller to stop on a trip.

    Returns the plant's exit status, or None when the controller exited after a limit
    trip (status :data:`TRIP_EXIT_STATUS`).  Any other node exiting is a
    :class:`NodeProcessError`.
    """
    plant, ctl = group.procs['plant_node'], group.procs['controller_node']
    deadline = time.monotonic() + timeout
    while True:
        code = plant.popen.poll()
        if code is not None:
            return code
        if ctl.popen.poll() == TRIP_EXIT_STATUS:
            return None
        group.check_alive(except_=('plant_node',))
        if time.monotonic() > deadline:
            raise NodeProcessError(f'plant_node did not finish within {timeout:g} s '
                                   f'(last output: {plant.tail()})')
        time.sleep(0.05)


def metrics_row(path: Path, namespace: str = 'axis') -> dict[str, Any]:
    """Read a recorded run and compute its metrics (DESIGN.md §6 keys) plus its name.

    A run with ``/diagnostics`` also gets the ``monitor`` / ``limits`` summaries
    (:mod:`motor_comp.analysis.diagnostics`).
    """
    from motor_comp.analysis.diagnostics import summarise
    from motor_comp.analysis.metrics import compute_metrics
    from motor_comp.logs import read_run
    from motor_comp.logs.diagnostics import read_diagnostics
    run = read_run(path, namespace=namespace.strip('/'))
    row = {'name': run.name, 'path': str(path)}
    row.update(compute_metrics(run).as_dict())
    row.update(summarise(read_diagnostics(path)))
    return row


def print_table(rows: Sequence[Mapping[str, Any]], *, label: str = 'run') -> None:
    """Print a fixed-width metrics table in micrometres."""
    head = f'{label:<28} {"rms_error":>11} {"max_error":>11} {"max_glitch":>11} ' \
           f'{"mean_glitch":>11}'
    print(head + '\n' + '-' * len(head))
    for r in rows:
        cells = ' '.join(_um(r.get(k)) for k in ('rms_error', 'max_error', 'max_glitch',
                                                 'mean_glitch'))
        print(f'{str(r.get(label, r.get("name"))):<28} {cells}')


def _um(value: float | None) -> str:
    """Format metres as micrometres; ``-`` when undefined (e.g. no reversal, no glitch)."""
    return f'{value * 1e6:>8.3f} µm' if value is not None else f'{"-":>11}'


def register(subparsers: argparse._SubParsersAction) -> None:
    """Add the ``run`` subcommand."""
    p = subparsers.add_parser('run', help='run the four ROS 2 nodes as processes, record MCAP',
                              description=__doc__.splitlines()[0])
    p.add_argument('--plant', default='pmlm',
                   help='pmlm, ballscrew or a plant YAML file (default pmlm)')
    p.add_argument('--controller', choices=MODES, default='pid')
    p.add_argument('--feedforward', choices=FEEDFORWARDS, default='none')
    p.add_argument('--trajectory', choices=('sine', 'p2p', 'cv', 'chirp', 'table'),
                   default='', help='default: p2p on the PMLM, sine on the ball-screw')
    p.add_argument('--trajectory-file', default='', metavar='F.csv',
                   help='with --trajectory table: the CSV t, x[, v, a] to play (e.g. from '
                        'motor-comp excite)')
    p.add_argument('--mode', choices=('lockstep', 'realtime'), default='lockstep',
                   help='timing mode (default lockstep)')
    p.add_argument('--duration', type=positive_float, default=2.0,
                   help='sim time [s] (default 2)')
    p.add_argument('--rate', type=positive_float, default=1000.0, help='control rate [Hz]')
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--namespace', default='axis',
                   help='namespace of the axis topics and nodes (default axis)')
    p.add_argument('--timeout', type=positive_float, default=None,
                   help='wall-time limit [s] (default 60 + 20·duration)')
    p.add_argument('--domain-id', type=int, default=None,
                   help='ROS_DOMAIN_ID (default: $ROS_DOMAIN_ID or a private one)')
    p.add_argument('--rt-priority', type=int, default=None, metavar='N',
                   help='realtime mode: SCHED_FIFO priority 1..98 of the plant, trajectory '
                        'and controller processes (default 40 where permitted, else normal '
                        'scheduling with a warning; 0 = off)')
    add_limits(p, 'enforced by the nodes: a trajectory beyond them is refused before the '
               'run; during it the controller trips (0 V), the run stops and ends with a one-line '
               'error (exit status 3), the recording kept; units of the axis (m or rad)')
    p.add_argument('--monitor', metavar='MODEL.yaml', default='',
                   help='also run monitor_node on this model; its /diagnostics are '
                        'recorded and summarised (JSON key monitor)')
    p.add_argument('-o', '--output', required=True, type=Path, help='RUN.mcap to write')
    add_json(p, help='print one JSON object')
    p.set_defaults(func=run)


def run(args: argparse.Namespace) -> int:
    """Execute ``motor-comp run``."""
    require_ros('motor-comp run')
    if not args.duration > 0:
        raise ParameterError(f'--duration must be > 0, got {args.duration:g}')
    if args.domain_id is not None and not 0 <= args.domain_id <= 232:
        raise ParameterError(f'--domain-id must be in 0..232, got {args.domain_id}')
    prio = args.rt_priority
    if prio is None:
        prio = DEFAULT_RT_PRIORITY if args.mode == 'realtime' else 0
    if not 0 <= prio <= 98:
        raise ParameterError(f'--rt-priority must be in 0..98, got {prio}')
    from motor_comp.physics.axis import AxisModel
    from motor_comp.physics.config import load_plant
    load_plant(args.plant)   # a bad plant name/file is a one-line error before any process
    if args.monitor:
        AxisModel.load(args.monitor)   # and a bad monitor model
    if bool(args.trajectory_file) != (args.trajectory == 'table'):
        raise ParameterError('--trajectory table and --trajectory-file F.csv go together')
    travel = tuple(args.travel) if args.travel else (-math.inf, math.inf)
    if not travel[0] < travel[1]:
        raise ParameterError(f'--travel: expected MIN < MAX, got {travel[0]:g} {travel[1]:g}')
    limits = Limits(travel=travel, vmax=args.vmax or math.inf, amax=args.amax or math.inf,
                    umax=args.umax or math.inf, max_error=args.max_error or math.inf)
    spec = RunSpec(output=args.output, plant=args.plant, controller=args.controller,
                   feedforward=args.feedforward, trajectory=args.trajectory,
                   trajectory_file=args.trajectory_file,
                   timing=args.mode, duration=args.duration, control_rate=args.rate,
                   seed=args.seed, namespace=args.namespace, realtime_priority=prio,
                   limits=limits, monitor=args.monitor)
    path = run_nodes(spec, timeout=args.timeout, domain_id=args.domain_id)
    row = metrics_row(path, args.namespace)
    row.update(plant=args.plant, controller=args.controller, feedforward=args.feedforward,
               mode=args.mode)
    if args.json:
        print(json.dumps(jsonable({'runs': [row]})))
    else:
        from motor_comp.analysis.diagnostics import format_summary
        print_table([row], label='name')
        for line in format_summary(row):
            print(line)
    return 0
