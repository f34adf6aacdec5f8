"""``motor-comp autotune``'s node processes, and this process's ROS client.

One :class:`AxisSession` holds, for the whole autotune:

* **one ``controller_node`` process**, started unconfigured (``autostart: false``) and
  driven through its lifecycle (``<ns>/controller_node/change_state``) by this process:
  for each run it is cleaned up and configured again (a fresh law: every run starts from
  the same controller state, and a latched trip is cleared only by a new configure),
  then its ``compensation_model`` parameter is set through ``<ns>/controller_node/
  set_parameters`` — the node reads the model file (inside its ``model_dir``, under the
  :mod:`motor_comp.param_files` rules) and loads it into the configured law, or rejects
  it with a reason — and it is activated.  The compensation of the task runs is thus
  loaded into the running controller through its parameter, never by restarting it
  with another configuration;
* per run, a ``recorder_node`` (a new MCAP), a ``trajectory_node`` playing the run's
  table (``trajectory: table``, ``file`` inside ``model_dir``), a ``monitor_node`` with
  ``--monitor``, and — for a simulated axis — a ``plant_node`` starting at the table's
  first position; with an **external plant** no plant process is started: whatever node
  publishes ``<ns>/joint_states`` and subscribes ``<ns>/voltage`` (a real drive) is the
  axis.

The limits (travel, speed, acceleration, voltage, tracking error) are the controller's
and the trajectory's read-only parameters for the whole session: a trip stops the axis
(0 V, the controller exits with status 3), the run's recording is finalised, and
:meth:`AxisSession.run` raises :class:`~motor_comp.errors.LimitTripError` with the
controller's one-line reason.

A run ends with the plant's ``duration`` in lockstep, and in realtime when the
trajectory node has published its last reference (``exit_at_end``) and the controller,
seeing no reference, commands 0 V (observed on ``<ns>/voltage``) — a drive holds its
last command, so it is left at 0 V.  Every wait is for a condition (a process exit, a
service reply, a message), bounded by a timeout that raises a one-line error.

A drive is not a simulated plant that waits for its peers: it measures from power-on.
So, with an external plant, the controller is configured when the session starts (its
``voltage`` writer, kept for the node's life, is discovered by the drive long before
anything moves), a run activates it only once the recorder reads ``joint_states``, the
trajectory starts with the first measurement after the controller's first command
(``wait_for_command``), each run is led in from where the axis stands (the tables of
:func:`motor_comp.tuning.plan.segment_table`), and the recorder closes its file at once
when stopped (the topics never go quiet).

The process machinery (:class:`~motor_comp.cli.run.NodeGroup`, the private domain, the
params files) is ``motor-comp run``'s; what the nodes are given is
:class:`~motor_comp.tuning.spec.AxisSpec`.  :mod:`motor_comp.tuning.autotune` is given this
class as its axis factory by ``motor-comp autotune``.
"""
from __future__ import annotations

import contextlib
import os
import time
from pathlib import Path
from typing import Any, Callable, Iterator, Mapping

from motor_comp.cli.run import TRIP_EXIT_STATUS, NodeGroup, require_ros, ros_environment, \
    trip_reason, write_params_file
from motor_comp.errors import LimitTripError, ParameterError
from motor_comp.tuning.spec import AxisSpec, RunRecord, SessionError

#: lifecycle transition a server refuses in every state: pings a client's reply path
_NO_TRANSITION = 250
#: longest wait for a service reply or a lifecycle transition [s] (configure may compile)
SERVICE_TIMEOUT = 120.0
#: longest wait for an external drive to be seen on the graph [s]
DRIVE_TIMEOUT = 30.0
#: a run may take this much wall time beyond its sim time before it is abandoned [s]
RUN_SLACK = 120.0


@contextlib.contextmanager
def _ros_environment(env: Mapping[str, str]) -> Iterator[None]:
    """Apply the session's DDS settings to this process while its client lives."""
    keys = ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE', 'RMW_IMPLEMENTATION')
    old = {k: os.environ.get(k) for k in keys}
    os.environ.update({k: env[k] for k in keys if k in env})
    try:
        yield
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class RosClient:
    """This process's node on the session's domain: services, lifecycle, a look at topics.

    Service replies can be lost while the server's reply writer has not yet matched
    this reader (Fast DDS drops them), so each client is first pinged with a request
    that changes nothing until a reply arrives; idempotent calls are resent.
    """

    def __init__(self, namespace: str) -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        self.ns = '/' + namespace.strip('/')
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('motor_comp_autotune', namespace=self.ns,
                                      context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._clients: dict[str, Any] = {}

    def close(self) -> None:
        """Destroy the node and shut the private context down."""
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        self.context.try_shutdown()

    def spin_until(self, condition: Callable[[], bool], timeout: float, what: str, *,
                   check: Callable[[], None] = lambda: None) -> None:
        """Spin until ``condition()``; ``check()`` may raise; a one-line error on timeout."""
        deadline = time.monotonic() + timeout
        while not condition():
            check()
            if time.monotonic() > deadline:
                raise SessionError(f'timed out after {timeout:g} s waiting for {what}')
            self.executor.spin_once(timeout_sec=0.02)

    def _call(self, client: Any, request: Any, timeout: float, what: str, *,
              retry: bool, check: Callable[[], None]) -> Any:
        deadline = time.monotonic() + timeout
        while True:
            future = client.call_async(request)
            resend = time.monotonic() + 2.0 if retry else deadline
            try:
                self.spin_until(future.done, max(0.0, min(resend, deadline) -
                                                 time.monotonic()), what, check=check)
                return future.result()
            except SessionError:
                client.remove_pending_request(future)
                if time.monotonic() >= deadline:
                    raise

    def _service(self, srv_type: Any, name: str, noop: Any,
                 check: Callable[[], None]) -> Any:
        if name not in self._clients:
            client = self.node.create_client(srv_type, name)
            self.spin_until(client.service_is_ready, SERVICE_TIMEOUT, f'the {name} service',
                            check=check)
            self._call(client, noop, SERVICE_TIMEOUT, f'a first reply of {name}',
                       retry=True, check=check)
            self._clients[name] = client
        return self._clients[name]

    def change_state(self, node: str, transition: str, *,
                     check: Callable[[], None] = lambda: None) -> bool:
        """Request a lifecycle transition (``configure``, ``activate`` …); its success."""
        from lifecycle_msgs.msg import Transition
        from lifecycle_msgs.srv import ChangeState
        client = self._service(ChangeState, f'{self.ns}/{node}/change_state',
                               ChangeState.Request(transition=Transition(id=_NO_TRANSITION)),
                               check)
        req = ChangeState.Request(transition=Transition(label=transition))
        return bool(self._call(client, req, SERVICE_TIMEOUT, f'{node} {transition}',
                               retry=False, check=check).success)

    def state(self, node: str, *, check: Callable[[], None] = lambda: None) -> str:
        """Return the lifecycle state label of ``node``."""
        from lifecycle_msgs.srv import GetState
        client = self._service(GetState, f'{self.ns}/{node}/get_state', GetState.Request(),
                               check)
        return self._call(client, GetState.Request(), SERVICE_TIMEOUT, f'{node} state',
                          retry=True, check=check).current_state.label

    def set_parameter(self, node: str, name: str, value: Any, *,
                      check: Callable[[], None] = lambda: None) -> tuple[bool, str]:
        """Set one parameter of ``node``; ``(accepted, reason)``."""
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter
        client = self._service(SetParameters, f'{self.ns}/{node}/set_parameters',
                               SetParameters.Request(), check)
        req = SetParameters.Request(parameters=[Parameter(name, value=value)
                                                .to_parameter_msg()])
        res = self._call(client, req, SERVICE_TIMEOUT, f'{node} set_parameters',
                         retry=False, check=check).results[0]
        return bool(res.successful), str(res.reason)

    def counts(self) -> tuple[int, int]:
        """Return (publishers of ``joint_states``, subscribers of ``voltage``), not ours."""
        return (self.node.count_publishers(f'{self.ns}/joint_states'),
                self.node.count_subscribers(f'{self.ns}/voltage'))

    def latest(self, topic: str, msg_type: Any, timeout: float, what: str, *,
               accept: Callable[[Any], bool] = lambda m: True,
               check: Callable[[], None] = lambda: None) -> Any:
        """Return the first message on ``topic`` that ``accept`` takes (best effort).

        A best-effort reader of depth 1, created for the wait and destroyed after it:
        it never slows a reliable loop writer and costs the loop nothing otherwise.
        """
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        got: list[Any] = []
        sub = self.node.create_subscription(
            msg_type, f'{self.ns}/{topic}', lambda m: got.append(m) if accept(m) else None,
            QoSProfile(depth=1, reliability=ReliabilityPolicy.BEST_EFFORT))
        try:
            self.spin_until(lambda: bool(got), timeout, what, check=check)
        finally:
            self.node.destroy_subscription(sub)
        return got[0]


class AxisSession:
    """The controller for the whole autotune, the other processes per run (context manager).

    Parameters
    ----------
    spec : AxisSpec
        What the nodes are given.
    logdir : Path
        Where the params files and the node logs go (kept: the user's record).
    domain_id : int, optional
        ``ROS_DOMAIN_ID`` (default ``$ROS_DOMAIN_ID`` or a private one).
    """

    def __init__(self, spec: AxisSpec, logdir: Path, *, domain_id: int | None = None
                 ) -> None:
        self.spec = spec
        self.logdir = Path(logdir)
        self.domain_id = domain_id
        self.group: Any = None
        self.client: RosClient | None = None
        self._env_cm: Any = None
        self._configured = False

    # -- start and stop ------------------------------------------------------------------
    def __enter__(self) -> 'AxisSession':
        require_ros('motor-comp autotune')
        self.logdir.mkdir(parents=True, exist_ok=True)
        env = ros_environment(self.domain_id)
        self.env = env
        self.group = NodeGroup(self.logdir, env)
        try:
            params = write_params_file(self.logdir / 'controller_node.params.yaml',
                                       {'controller_node': self.spec.controller_params()},
                                       namespace=self.spec.namespace)
            self.group.start('controller_node', params,
                             ['-r', f'__ns:=/{self.spec.namespace.strip("/")}'])
            self._env_cm = _ros_environment(env)
            self._env_cm.__enter__()
            self.client = RosClient(self.spec.namespace)
            state = self.client.state('controller_node', check=self._controller_alive)
            if state != 'unconfigured':
                raise SessionError(f'controller_node is {state}, expected unconfigured')
            if self.spec.external:
                self._find_drive()
                # configured now: its voltage writer (kept for the node's life) is
                # discovered by the drive long before the first run moves the axis
                self._prepare_controller('')
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc: Any) -> None:
        if self.client is not None:
            self.client.close()
            self.client = None
        if self._env_cm is not None:
            self._env_cm.__exit__(None, None, None)
            self._env_cm = None
        if self.group is not None:
            self.group.stop_all()
            self.group = None

    @property
    def domain(self) -> str:
        """The session's ``ROS_DOMAIN_ID``."""
        return self.env['ROS_DOMAIN_ID']

    def _controller_alive(self) -> None:
        code = self.group.procs['controller_node'].popen.poll()
        if code is not None:
            raise SessionError(f'controller_node exited with status {code}: '
                               f'{self.group.procs["controller_node"].tail()}')

    def _find_drive(self) -> None:
        """Wait for the external drive: a ``joint_states`` writer, a ``voltage`` reader."""
        ns = self.spec.namespace.strip('/')
        self.client.spin_until(
            lambda: self.client.counts()[0] >= 1 and self.client.counts()[1] >= 1,
            DRIVE_TIMEOUT, f'an external drive: a node publishing /{ns}/joint_states and '
            f'subscribing /{ns}/voltage (start the drive\'s node, or use --plant)',
            check=self._controller_alive)

    def position(self) -> float:
        """Return the axis's measured position now (external drive; one sample)."""
        from sensor_msgs.msg import JointState
        msg = self.client.latest('joint_states', JointState, DRIVE_TIMEOUT,
                                 'a joint_states sample of the drive',
                                 accept=lambda m: len(m.position) > 0,
                                 check=self._controller_alive)
        return float(msg.position[0])

    # -- one run ------------------------------------------------------------------------
    def _transition(self, label: str) -> None:
        if not self.client.change_state('controller_node', label,
                                        check=self._controller_alive):
            raise SessionError(f'controller_node refused the lifecycle transition {label} '
                               f'({self.group.procs["controller_node"].tail()})')

    def _prepare_controller(self, compensation: str) -> None:
        """Build a fresh law (cleanup + configure), load the compensation by parameter."""
        if self._configured:
            self._transition('cleanup')
        self._transition('configure')
        self._configured = True
        ok, reason = self.client.set_parameter('controller_node', 'compensation_model',
                                               compensation, check=self._controller_alive)
        if not ok:
            raise ParameterError(f'controller_node rejected compensation_model: {reason}')

    def run(self, name: str, table_file: Path, *, duration: float, x0: float,
            output: Path, compensation: str = '', monitor_model: str = '') -> RunRecord:
        """Play ``table_file`` (``duration`` [s], starting at ``x0``), record to ``output``.

        Raises :class:`LimitTripError` (the controller's reason) after a trip, with the
        recording finalised; :class:`SessionError` when a process fails.
        """
        spec = self.spec
        t_start = time.monotonic()
        params = spec.run_params(table_file, duration=duration, x0=x0, output=output,
                                 monitor_model=monitor_model)
        pfile = write_params_file(self.logdir / f'{name}.params.yaml', params,
                                  namespace=spec.namespace)
        remap = ['-r', f'__ns:=/{spec.namespace.strip("/")}']
        labels = {node: f'{name}.{node}' for node in params}
        group = self.group
        for node in ('recorder_node', 'monitor_node', 'trajectory_node', 'plant_node'):
            if node in params:
                group.start_as(labels[node], node, pfile, remap)
        tripped = ''
        try:
            self._prepare_controller(compensation)
            if spec.external:
                self._wait_for_recorder(labels)
            self._transition('activate')
            tripped = self._wait_for_end(labels, duration)
            if not tripped:
                self._settle()
                self._transition('deactivate')
        finally:
            self._stop_run(labels)
        code = group.procs[labels['recorder_node']].popen.returncode
        if code not in (0, None):
            raise SessionError(f'recorder_node exited with status {code}: '
                               f'{group.procs[labels["recorder_node"]].tail()}')
        logs = tuple(group.procs[label].log for label in labels.values())
        if tripped:
            raise LimitTripError(tripped)
        if group.procs['controller_node'].popen.poll() == TRIP_EXIT_STATUS:
            raise LimitTripError(self._trip_reason())
        return RunRecord(path=Path(output), seconds=time.monotonic() - t_start, logs=logs)

    def _wait_for_recorder(self, labels: Mapping[str, str]) -> None:
        """External drive: activate only once the recorder reads ``joint_states``.

        Our plant waits for its readers before its first sample; a drive measures all
        along, and the recorder subscribes ``joint_states`` only once the other nodes'
        parameters are stored (seconds on a loaded machine): the trajectory, which
        starts when the controller answers, must not start before it.
        """
        node = self.client.node
        topic = f'/{self.spec.namespace.strip("/")}/joint_states'

        def check() -> None:
            self._controller_alive()
            for label in labels.values():
                code = self.group.procs[label].popen.poll()
                if code is not None:
                    raise SessionError(f'{label.split(".", 1)[1]} exited with status {code}: '
                                       f'{self.group.procs[label].tail()}')
        self.client.spin_until(
            lambda: any(i.node_name == 'recorder_node'
                        for i in node.get_subscriptions_info_by_topic(topic)),
            SERVICE_TIMEOUT, 'the recorder to read joint_states', check=check)

    def _trip_reason(self) -> str:
        return trip_reason(self.group.procs['controller_node'])

    def _wait_for_end(self, labels: Mapping[str, str], duration: float) -> str:
        """Wait for the run's end; return the trip reason ('' when it ended normally)."""
        group = self.group
        ctl = group.procs['controller_node']
        # lockstep: the plant ends the run; realtime: the trajectory (exit_at_end)
        ender = labels['plant_node'] if self.spec.lockstep else labels['trajectory_node']
        slack = RUN_SLACK + (20.0 * duration if self.spec.lockstep else duration)
        deadline = time.monotonic() + slack
        watched = [label for label in labels.values() if label != ender]
        while True:
            code = group.procs[ender].popen.poll()
            if code is not None:
                if code != 0:
                    raise SessionError(f'{ender.split(".", 1)[1]} exited with status '
                                       f'{code}: {group.procs[ender].tail()}')
                return ''
            status = ctl.popen.poll()
            if status == TRIP_EXIT_STATUS:
                return self._trip_reason()
            if status is not None:
                self._controller_alive()
            for label in watched:
                c = group.procs[label].popen.poll()
                if c is not None:
                    raise SessionError(f'{label.split(".", 1)[1]} exited with status {c}: '
                                       f'{group.procs[label].tail()}')
            if time.monotonic() > deadline:
                raise SessionError(f'the run did not end within {slack:g} s (last output: '
                                   f'{group.procs[ender].tail()})')
            self.client.executor.spin_once(timeout_sec=0.05)

    def _settle(self) -> None:
        """Realtime: wait for the controller's 0 V (no reference any more) before it stops.

        A drive holds its last command; the controller commands 0 V once the reference
        is older than its ``stale_timeout``.  Lockstep needs nothing: the plant stopped.
        """
        if self.spec.lockstep:
            return
        from std_msgs.msg import Float64
        self.client.latest('voltage', Float64, 10.0,
                           'the controller\'s 0 V after the end of the trajectory',
                           accept=lambda m: m.data == 0.0, check=self._controller_alive)

    def _stop_run(self, labels: Mapping[str, str]) -> None:
        """Stop the run's processes: the loop's drivers first, the recorder last."""
        order = [labels[n] for n in ('plant_node', 'trajectory_node', 'monitor_node',
                                     'recorder_node') if n in labels]
        for label in order:   # labels are per run: the group keeps them (logs, statuses)
            self.group.stop(label)


__all__ = ['AxisSession', 'RosClient']
