"""Fixtures for the node tests: real node processes on a private, localhost-only domain."""
from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from motor_comp.cli.run import NodeGroup, private_domain_id, release_domain_id, \
    ros_environment


@pytest.fixture
def ros_env() -> dict[str, str]:
    """Environment for node processes; also applied to this process (test clients).

    The domain id is reserved with a lock file for the test's duration
    (:func:`~motor_comp.cli.run.private_domain_id`), so concurrent pytest runs, benches
    and ``motor-comp run`` never share a domain.
    """
    domain = private_domain_id()
    env = ros_environment(domain)
    old = {k: os.environ.get(k) for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE',
                                          'RMW_IMPLEMENTATION')}
    os.environ.update({k: env[k] for k in old})
    try:
        yield env
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        release_domain_id(domain)


@pytest.fixture
def nodes(tmp_path: Path, ros_env: dict[str, str]):
    """Yield a :class:`NodeGroup` whose processes are always killed at teardown."""
    group = NodeGroup(tmp_path, ros_env)
    try:
        yield group
    finally:
        for proc in group.procs.values():
            if proc.popen.poll() is None:
                try:
                    os.killpg(proc.popen.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                proc.popen.wait(5)


class Probe:
    """An rclpy node in the test process: watches the loop, sets parameters, injects.

    Created after :func:`ros_env` so it joins the test's private domain.  Its
    ``voltage``/``joint_states`` readers are served by the nodes' wait-set
    :class:`~motor_comp.nodes.common.LeanLoop` (≈ 3× the executor's message rate): a
    probe spun only by the executor falls behind a lockstep loop on a loaded machine,
    and a reader more than a publisher's history (1000) behind loses samples.
    """

    def __init__(self, namespace: str = 'axis') -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64

        from motor_comp.nodes.common import LeanLoop

        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('test_probe', namespace=namespace,
                                      context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        qos = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)
        self.voltages: list[float] = []
        self.positions: list[float] = []
        self.node.hot_subscriptions = [
            self.node.create_subscription(Float64, 'voltage',
                                          lambda m: self.voltages.append(m.data), qos),
            self.node.create_subscription(JointState, 'joint_states',
                                          lambda m: self.positions.append(m.position[0]),
                                          qos)]
        self.node.hot_timers = []
        self._lean = LeanLoop(self.node)
        self._last_service = 0.0
        self._qos = qos
        self._pubs: dict[str, object] = {}
        self._clients: dict[str, object] = {}

    def publish(self, topic: str, msg, readers: int = 1) -> None:
        """Inject ``msg`` on ``topic`` once ``readers`` other readers matched; wait for acks.

        The probe's own reader of the topic (if any) is not counted.  Reliable delivery:
        the call returns when every matched reader acknowledged the sample.
        """
        from rclpy.duration import Duration

        pub = self._pubs.get(topic)
        if pub is None:
            from motor_comp.nodes.common import LOOP_QOS
            pub = self._pubs[topic] = self.node.create_publisher(type(msg), topic, LOOP_QOS)
        own = 1 if topic in ('voltage', 'joint_states') else 0
        self.spin_until(lambda: pub.get_subscription_count() >= readers + own, 20,
                        f'{readers} reader(s) of {topic}')
        pub.publish(msg)
        assert pub.wait_for_all_acked(Duration(seconds=20)), f'{topic}: not acknowledged'

    def spin_once(self, timeout: float = 0.05) -> None:
        """Take what arrived on the watched topics, then serve services and clients."""
        import time
        ran = self._lean.spin_once(int(timeout * 1e9))
        now = time.monotonic()
        if not ran or now - self._last_service > 0.005:   # as the nodes' run_node does
            self.executor.spin_once(timeout_sec=0.0)
            self._last_service = now

    def spin_until(self, condition, timeout: float, what: str = 'condition') -> None:
        """Spin until ``condition()`` is true or fail after ``timeout`` seconds."""
        import time
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                what = what() if callable(what) else what   # e.g. counts at the failure
                raise AssertionError(f'timed out after {timeout} s waiting for {what}')
            self.spin_once(0.02)

    def service(self, srv_type, name: str, noop_request):
        """A client of service ``name`` whose replies are known to reach this process.

        ``service_is_ready`` only says the request path matched; a reply sent before the
        server's response writer matched our reader is dropped (Fast DDS logs "failed to
        send response (timeout)") and a single call would wait forever.  So the client
        is first pinged with ``noop_request`` (changes nothing) until a reply arrives.
        """
        if name not in self._clients:
            client = self.node.create_client(srv_type, name)
            self.spin_until(client.service_is_ready, 30, f'{name} service')
            self.call(client, noop_request, 60, f'{name} first reply', retry=True)
            self._clients[name] = client
        return self._clients[name]

    def call(self, client, request, timeout: float, what: str, *, retry: bool = False):
        """Call and wait for the reply; ``retry`` resends every 2 s (idempotent calls)."""
        import time
        deadline = time.monotonic() + timeout
        while True:
            future = client.call_async(request)
            resend = time.monotonic() + 2.0 if retry else deadline
            try:
                self.spin_until(future.done, max(0.0, min(resend, deadline)
                                                 - time.monotonic()), what)
                return future.result()
            except AssertionError:
                client.remove_pending_request(future)
                if time.monotonic() >= deadline:
                    raise

    def _service(self, node: str, kind: str):
        from rcl_interfaces.srv import GetParameters, SetParameters
        srv = SetParameters if kind == 'set_parameters' else GetParameters
        return self.service(srv, f'/axis/{node}/{kind}', srv.Request())

    def set_parameters(self, node: str, **values):
        """Call ``<node>/set_parameters``; the list of SetParametersResult."""
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter
        client = self._service(node, 'set_parameters')
        req = SetParameters.Request(parameters=[Parameter(k.replace('__', '.'), value=v)
                                                .to_parameter_msg()
                                                for k, v in values.items()])
        return self.call(client, req, 30, f'{node} set_parameters reply').results

    def get_parameter(self, node: str, name: str):
        """One parameter value of a node via ``<node>/get_parameters``."""
        from rcl_interfaces.srv import GetParameters
        from rclpy.parameter import parameter_value_to_python
        client = self._service(node, 'get_parameters')
        reply = self.call(client, GetParameters.Request(names=[name]), 30,
                          f'{node} get_parameters reply', retry=True)
        return parameter_value_to_python(reply.values[0])

    def close(self) -> None:
        """Destroy the node and shut the private context down."""
        self.node.destroy_node()
        self.context.try_shutdown()


@pytest.fixture
def probe(ros_env):
    """Yield a :class:`Probe` on the test's domain, always shut down."""
    p = Probe()
    try:
        yield p
    finally:
        p.close()
