"""Fixtures for the node tests: real node processes on a private, localhost-only domain."""
from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from motor_comp.cli.run import NodeGroup, ros_environment

_COUNTER = [0]


def private_domain() -> int:
    """Return a ROS_DOMAIN_ID in 1..101 unique to this test process and call."""
    _COUNTER[0] += 1
    return 1 + (os.getpid() * 13 + _COUNTER[0] * 37) % 101


@pytest.fixture
def ros_env() -> dict[str, str]:
    """Environment for node processes; also applied to this process (test clients)."""
    env = ros_environment(private_domain())
    old = {k: os.environ.get(k) for k in ('ROS_DOMAIN_ID', 'ROS_AUTOMATIC_DISCOVERY_RANGE',
                                          'RMW_IMPLEMENTATION')}
    os.environ.update({k: env[k] for k in old})
    yield env
    for k, v in old.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


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

    Created after :func:`ros_env` so it joins the test's private domain.
    """

    def __init__(self, namespace: str = 'axis') -> None:
        import rclpy
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.qos import QoSProfile, ReliabilityPolicy
        from sensor_msgs.msg import JointState
        from std_msgs.msg import Float64

        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node('test_probe', namespace=namespace,
                                      context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        qos = QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE)
        self.voltages: list[float] = []
        self.positions: list[float] = []
        self.node.create_subscription(Float64, 'voltage',
                                      lambda m: self.voltages.append(m.data), qos)
        self.node.create_subscription(JointState, 'joint_states',
                                      lambda m: self.positions.append(m.position[0]), qos)
        self._qos = qos
        self._pubs: dict[str, object] = {}
        self._clients: dict[str, object] = {}

    def publish(self, topic: str, msg) -> None:
        """Inject ``msg`` on ``topic`` (publisher created on first use, then matched)."""
        pub = self._pubs.get(topic)
        if pub is None:
            from motor_comp.nodes.common import LOOP_QOS
            pub = self._pubs[topic] = self.node.create_publisher(type(msg), topic, LOOP_QOS)
            self.spin_until(lambda: pub.get_subscription_count() >= 1, 10, f'{topic} match')
            self.spin_for(0.3)
        pub.publish(msg)

    def spin_until(self, condition, timeout: float, what: str = 'condition') -> None:
        """Spin until ``condition()`` is true or fail after ``timeout`` seconds."""
        import time
        deadline = time.monotonic() + timeout
        while not condition():
            if time.monotonic() > deadline:
                raise AssertionError(f'timed out after {timeout} s waiting for {what}')
            self.executor.spin_once(timeout_sec=0.05)

    def spin_for(self, seconds: float) -> None:
        """Spin for a while."""
        import time
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.02)

    def _service(self, node: str, kind: str):
        from rcl_interfaces.srv import GetParameters, SetParameters
        key = f'{node}/{kind}'
        if key not in self._clients:
            srv = SetParameters if kind == 'set_parameters' else GetParameters
            client = self.node.create_client(srv, f'/axis/{node}/{kind}')
            self.spin_until(lambda: client.service_is_ready(), 20, f'{key} service')
            self._clients[key] = client
        return self._clients[key]

    def set_parameters(self, node: str, **values):
        """Call ``<node>/set_parameters``; the list of SetParametersResult."""
        from rcl_interfaces.srv import SetParameters
        from rclpy.parameter import Parameter
        client = self._service(node, 'set_parameters')
        req = SetParameters.Request(parameters=[Parameter(k.replace('__', '.'), value=v)
                                                .to_parameter_msg()
                                                for k, v in values.items()])
        future = client.call_async(req)
        self.spin_until(future.done, 20, f'{node} set_parameters reply')
        return future.result().results

    def get_parameter(self, node: str, name: str):
        """One parameter value of a node via ``<node>/get_parameters``."""
        from rcl_interfaces.srv import GetParameters
        from rclpy.parameter import parameter_value_to_python
        client = self._service(node, 'get_parameters')
        future = client.call_async(GetParameters.Request(names=[name]))
        self.spin_until(future.done, 20, f'{node} get_parameters reply')
        return parameter_value_to_python(future.result().values[0])

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
