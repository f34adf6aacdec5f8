"""ROS 2 message definitions and channel metadata for the DESIGN.md §5 topics.

MCAP files with the ``ros2`` profile carry each message type as a ``ros2msg`` schema:
the type's own ``.msg`` text followed by every type it depends on, each introduced by a
line of 80 ``=`` and ``MSG: pkg/Type`` — the concatenation rosbag2 writes, which
rosbags, the ``mcap`` readers, Foxglove and PlotJuggler parse.  The definitions below
state the fields only (the field lists are the ROS interface contract; the long
explanatory comments of the upstream files are not needed to decode).

The type hashes (``RIHS01_…``) are those of ROS 2 Jazzy's interface packages; rosbag2
(Jazzy) stores them as channel metadata ``topic_type_hash`` next to the offered QoS.
"""
from __future__ import annotations

from typing import Mapping

#: separator between a definition and each of its dependencies (rosbag2 / MCAP appendix)
SEPARATOR = '=' * 80

_TIME = """\
# Time since the epoch of the clock that stamped it.
int32 sec
uint32 nanosec
"""

_HEADER = """\
# Stamp and coordinate frame of stamped data.
builtin_interfaces/Time stamp
string frame_id
"""

_JOINT_STATE = """\
# State of a set of joints; arrays are parallel to name (or empty when not measured).
# motor_comp: position [m], velocity [m/s], effort [N] of the joint named 'axis'.
std_msgs/Header header

string[] name
float64[] position
float64[] velocity
float64[] effort
"""

_FLOAT64 = """\
# One double-precision value (motor_comp: command voltage [V]).
float64 data
"""

_CLOCK = """\
# Current time of the simulated clock.
builtin_interfaces/Time clock
"""


_DIAGNOSTIC_ARRAY = """\
# Diagnostic information about the state of the robot (motor_comp: the live model
# monitor's verdicts and the controller's limits, each one DiagnosticStatus).
std_msgs/Header header
DiagnosticStatus[] status
"""

_DIAGNOSTIC_STATUS = """\
# Status of one component.
byte OK=0
byte WARN=1
byte ERROR=2
byte STALE=3
byte level
string name
string message
string hardware_id
KeyValue[] values
"""

_KEY_VALUE = """\
# A labelled value.
string key
string value
"""


def _concat(main: str, *deps: tuple[str, str]) -> str:
    parts = [main.rstrip('\n')]
    for name, text in deps:
        parts.append(f'{SEPARATOR}\nMSG: {name}\n{text.rstrip(chr(10))}')
    return '\n'.join(parts) + '\n'


JOINT_STATE = 'sensor_msgs/msg/JointState'
FLOAT64 = 'std_msgs/msg/Float64'
CLOCK = 'rosgraph_msgs/msg/Clock'
DIAGNOSTIC_ARRAY = 'diagnostic_msgs/msg/DiagnosticArray'

#: full ros2msg schema text per message type (with dependencies, as rosbag2 writes it)
DEFINITIONS: Mapping[str, str] = {
    JOINT_STATE: _concat(_JOINT_STATE, ('std_msgs/Header', _HEADER),
                         ('builtin_interfaces/Time', _TIME)),
    FLOAT64: _concat(_FLOAT64),
    CLOCK: _concat(_CLOCK, ('builtin_interfaces/Time', _TIME)),
    DIAGNOSTIC_ARRAY: _concat(_DIAGNOSTIC_ARRAY, ('std_msgs/Header', _HEADER),
                              ('builtin_interfaces/Time', _TIME),
                              ('diagnostic_msgs/DiagnosticStatus', _DIAGNOSTIC_STATUS),
                              ('diagnostic_msgs/KeyValue', _KEY_VALUE)),
}

#: ROS 2 Jazzy type description hashes (from the installed interface packages)
TYPE_HASHES: Mapping[str, str] = {
    JOINT_STATE: 'RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e',
    FLOAT64: 'RIHS01_705ba9c3d1a09df43737eb67095534de36fd426c0587779bda2bc51fe790182a',
    CLOCK: 'RIHS01_692f7a66e93a3c83e71765d033b60349ba68023a8c689a79e48078bcb5c58564',
    DIAGNOSTIC_ARRAY:
        'RIHS01_5a8a36efb05fb25070fa0fb3810290c0e6cd4862b54a8fb975a1ee8dc55a333e',
}

_INFINITE = '    sec: 9223372036\n    nsec: 854775807\n'

#: offered QoS of a default reliable, volatile publisher (rosbag2 Jazzy YAML layout)
DEFAULT_QOS_YAML = (
    '- history: keep_last\n'
    '  depth: 10\n'
    '  reliability: reliable\n'
    '  durability: volatile\n'
    '  deadline:\n' + _INFINITE +
    '  lifespan:\n' + _INFINITE +
    '  liveliness: automatic\n'
    '  liveliness_lease_duration:\n' + _INFINITE +
    '  avoid_ros_namespace_conventions: false\n'
)


def normalise_type(msgtype: str) -> str:
    """Return ``pkg/msg/Type`` for ``pkg/Type`` or ``pkg/msg/Type`` spellings."""
    parts = msgtype.strip().split('/')
    if len(parts) == 2:
        return f'{parts[0]}/msg/{parts[1]}'
    return msgtype.strip()


def channel_metadata(msgtype: str, *, qos_yaml: str | None = None) -> dict[str, str]:
    """Channel metadata as rosbag2 (Jazzy) records it: offered QoS and type hash."""
    meta = {'offered_qos_profiles': qos_yaml if qos_yaml is not None else DEFAULT_QOS_YAML}
    h = TYPE_HASHES.get(normalise_type(msgtype))
    if h is not None:
        meta['topic_type_hash'] = h
    return meta


def topics(namespace: str = 'axis') -> dict[str, str]:
    """DESIGN.md §5 topic names in a namespace (keys: reference, joint_states, voltage)."""
    ns = '/' + namespace.strip('/') if namespace.strip('/') else ''
    return {'reference': f'{ns}/reference', 'joint_states': f'{ns}/joint_states',
            'voltage': f'{ns}/voltage'}
