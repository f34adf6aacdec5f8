"""The nodes' wait-set loop runs no callback once its node is done; a realtime reader
takes the newest queued message.

In lockstep a peer answers within one burst of queued messages: a tripped controller
whose hold had ended kept answering the measurements taken in the same burst, and the
recording held 61 samples of 0 V where the hold is 50 (CI, a loaded machine).  Here the
messages are all queued before the loop runs (reliable, acknowledged), so one burst
would take them all; the node is done after the second.
"""
from __future__ import annotations

import time

import pytest

pytestmark = pytest.mark.timeout(120)   # failure bound only


def test_lean_loop_stops_taking_when_the_node_is_done(ros_env) -> None:
    import rclpy
    from rclpy.duration import Duration
    from rclpy.node import Node
    from std_msgs.msg import Float64

    from motor_comp.nodes.common import LOOP_QOS, LeanLoop

    class Reader(Node):
        """A node that is ``done`` (as the motor_comp nodes say it) after two messages."""

        def __init__(self, context) -> None:
            super().__init__('lean_loop_test', context=context)
            self.seen: list[float] = []
            self.hot_subscriptions = [self.create_subscription(
                Float64, 'x', lambda m: self.seen.append(m.data), LOOP_QOS)]
            self.hot_timers = []
            self.take_burst = 64   # as a motor_comp node: everything queued in one wait

        @property
        def done(self) -> bool:
            return len(self.seen) >= 2

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = Reader(context)
        pub = node.create_publisher(Float64, 'x', LOOP_QOS)
        deadline = time.monotonic() + 20.0   # failure bound: the condition is the match
        while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert pub.get_subscription_count() == 1
        for i in range(5):
            pub.publish(Float64(data=float(i)))
        assert pub.wait_for_all_acked(Duration(seconds=20))   # all five queued

        loop = LeanLoop(node)
        assert loop.spin_once(int(5e9)) == 2
        assert node.seen == [0.0, 1.0]
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)


def test_take_newest_skips_the_backlog_and_keeps_the_newest_reception_time(ros_env) -> None:
    """A realtime reader starts from the newest queued sample and when it arrived.

    ``trajectory_node`` counts trajectory time from that reception: started from a
    queued sample instead, every reference of an autotune run on a drive was 58–116 ms
    late in 4 of 10 starts.
    """
    import rclpy
    from rclpy.duration import Duration
    from std_msgs.msg import Float64

    from motor_comp.nodes.common import LOOP_QOS, take_newest

    context = rclpy.Context()
    rclpy.init(context=context)
    try:
        node = rclpy.create_node('take_newest_test', context=context)
        sub = node.create_subscription(Float64, 'x', lambda m: None, LOOP_QOS)
        pub = node.create_publisher(Float64, 'x', LOOP_QOS)
        deadline = time.monotonic() + 20.0   # failure bound: the condition is the match
        while pub.get_subscription_count() < 1 and time.monotonic() < deadline:
            time.sleep(0.01)
        assert pub.get_subscription_count() == 1
        before = time.time_ns()
        for i in range(5):
            pub.publish(Float64(data=float(i)))
        assert pub.wait_for_all_acked(Duration(seconds=20))   # all five queued
        after = time.time_ns()
        first, info = sub.handle.take_message(sub.msg_type, sub.raw)
        msg, newest, skipped = take_newest(sub, first, info)
        assert (first.data, msg.data, skipped) == (0.0, 4.0, 4)
        # the middleware's reception time, on the system clock, of the newest sample
        assert before <= info['received_timestamp'] <= newest['received_timestamp'] <= after
        assert newest['publication_sequence_number'] > info['publication_sequence_number']
        # nothing queued: the message given is the newest
        again, same, none = take_newest(sub, msg, newest)
        assert (again.data, same, none) == (4.0, newest, 0)
        node.destroy_node()
    finally:
        rclpy.shutdown(context=context)
