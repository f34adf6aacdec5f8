"""The controller's direct CDR reader equals rclpy's deserialization, for any JointState."""
from __future__ import annotations

import math

from hypothesis import given, settings, strategies as st
from rclpy.serialization import serialize_message
from sensor_msgs.msg import JointState

from motor_comp.nodes.common import read_joint_state

_text = st.text(st.characters(min_codepoint=32, max_codepoint=0x2FF), max_size=9)
_vals = st.lists(st.floats(allow_nan=True, allow_infinity=True), max_size=3)


def _same(a, b) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float)
                      and math.isnan(a) and math.isnan(b))


@settings(max_examples=300, deadline=None)
@given(sec=st.integers(0, 2**31 - 1), nsec=st.integers(0, 999_999_999), frame=_text,
       names=st.lists(_text, max_size=3), pos=_vals, vel=_vals, eff=_vals)
def test_read_joint_state_matches_rclpy(sec, nsec, frame, names, pos, vel, eff) -> None:
    """Stamp and first entries from the raw bytes = from the message object (any layout)."""
    msg = JointState(name=names, position=pos, velocity=vel, effort=eff)
    msg.header.stamp.sec, msg.header.stamp.nanosec = sec, nsec
    msg.header.frame_id = frame
    data = serialize_message(msg)
    raw = read_joint_state(data)
    obj = read_joint_state(msg)
    # the second read may take the fast path of a layout learned from the first one
    again = read_joint_state(data)
    assert all(_same(a, b) for a, b in zip(raw, again)), (raw, again)
    assert raw[0] == obj[0] == sec * 1_000_000_000 + nsec
    assert all(_same(a, b) for a, b in zip(raw[1:], obj[1:])), (raw, obj)
    for got, seq in zip(raw[1:], (pos, vel, eff)):
        assert (got is None) == (len(seq) == 0)


def test_learned_layout_is_not_applied_to_another_layout_of_the_same_length() -> None:
    """Equal length, other frame_id/names: the values still come from their own offsets."""
    def serialized(frame: str, names: list[str], k: float) -> bytes:
        msg = JointState(name=names, position=[k], velocity=[k + 1], effort=[k + 2])
        msg.header.frame_id = frame
        msg.header.stamp.sec = int(k)
        return serialize_message(msg)

    layouts = [('abcd', ['x']), ('a', ['xyzw']), ('ab', ['x', 'y'])]
    data = [serialized(f, n, 10.0 * (i + 1)) for i, (f, n) in enumerate(layouts)]
    assert len({len(d) for d in data}) == 1                     # same length: one cache slot
    for _ in range(2):                                          # learned, then reused
        for i, d in enumerate(data):
            k = 10.0 * (i + 1)
            assert read_joint_state(d) == (int(k) * 1_000_000_000, k, k + 1, k + 2)
