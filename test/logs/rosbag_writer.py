"""Robots' bags for the tests, written by rosbags (not by the code under test).

A bag as a robot records it: one ``sensor_msgs/JointState`` topic holding every joint
(the axis one among several), the effort field filled, optionally the joints in a
different order in every message, other topics beside it; rosbag2 layout (a directory
with ``metadata.yaml``) in sqlite3 or MCAP storage.
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

#: a Jazzy ros2_control controller state (control_msgs), registered for the tests
CONTROLLER_STATE = 'control_msgs/msg/JointTrajectoryControllerState'
_CONTROLLER_STATE_MSG = """\
std_msgs/Header header
string[] joint_names
trajectory_msgs/JointTrajectoryPoint reference
trajectory_msgs/JointTrajectoryPoint feedback
trajectory_msgs/JointTrajectoryPoint error
trajectory_msgs/JointTrajectoryPoint output
string[] multi_dof_joint_names
"""


def typestore():
    """rosbags' Jazzy type store, with the controller state added."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    store.register(get_types_from_msg(_CONTROLLER_STATE_MSG, CONTROLLER_STATE))
    return store


def _time(store, ns: int):
    time_t = store.types['builtin_interfaces/msg/Time']
    return time_t(sec=int(ns // 1_000_000_000), nanosec=int(ns % 1_000_000_000))


def write_bag(path: Path, storage: str, stamps_ns: np.ndarray,
              joints: Mapping[str, Mapping[str, np.ndarray | None]], *,
              topic: str = '/joint_states', shuffle_seed: int | None = None,
              scalars: Mapping[str, np.ndarray] | None = None,
              controller: tuple[str, Sequence[str], Mapping[str, Mapping[str, np.ndarray]]]
              | None = None,
              states: Mapping[str, Mapping[str, np.ndarray]] | None = None) -> Path:
    """Write a rosbag2 directory; return it.

    Parameters
    ----------
    storage : {'sqlite3', 'mcap'}
    joints : mapping
        ``name -> {'position': a, 'velocity': a or None, 'effort': a or None}``, one
        value per stamp; a None array is left empty in every message.
    shuffle_seed : int, optional
        Permute the joints' order in every message.
    scalars : mapping, optional
        ``topic -> values``: ``std_msgs/Float64`` messages at the same log times.
    controller : (topic, joint names, {joint: {'position', 'velocity'}}), optional
        A ``control_msgs/JointTrajectoryControllerState`` with the joints' reference.
    states : mapping, optional
        ``topic -> {joint: effort}``: more JointState topics carrying efforts only
        (e.g. a drive's motor states).
    """
    from rosbags.rosbag2 import StoragePlugin, Writer
    store = typestore()
    js_t = store.types['sensor_msgs/msg/JointState']
    header_t = store.types['std_msgs/msg/Header']
    f64_t = store.types['std_msgs/msg/Float64']
    rng = np.random.default_rng(shuffle_seed) if shuffle_seed is not None else None
    names = list(joints)
    fields = ('position', 'velocity', 'effort')
    cols = {f: (np.column_stack([np.asarray(joints[n][f], float) for n in names])
                if all(joints[n].get(f) is not None for n in names) else None)
            for f in fields}
    plugin = StoragePlugin.SQLITE3 if storage == 'sqlite3' else StoragePlugin.MCAP
    with Writer(path, version=9, storage_plugin=plugin) as w:
        conn = w.add_connection(topic, js_t.__msgtype__, typestore=store)
        extra = {t: w.add_connection(t, f64_t.__msgtype__, typestore=store)
                 for t in (scalars or {})}
        more = {t: (w.add_connection(t, js_t.__msgtype__, typestore=store), j)
                for t, j in (states or {}).items()}
        ctrl = None
        if controller is not None:
            ctrl = w.add_connection(controller[0], CONTROLLER_STATE, typestore=store)
            point_t = store.types['trajectory_msgs/msg/JointTrajectoryPoint']
            dur_t = store.types['builtin_interfaces/msg/Duration']
        empty = np.empty(0)
        for i, ns in enumerate(np.asarray(stamps_ns, np.int64)):
            order = rng.permutation(len(names)) if rng is not None else np.arange(len(names))
            header = header_t(stamp=_time(store, int(ns)), frame_id='')
            msg = js_t(header=header, name=[names[k] for k in order],
                       **{f: (cols[f][i, order] if cols[f] is not None else empty)
                          for f in fields})
            w.write(conn, int(ns), store.serialize_cdr(msg, js_t.__msgtype__))
            for c, js in more.values():
                w.write(c, int(ns), store.serialize_cdr(js_t(
                    header=header, name=list(js), position=empty, velocity=empty,
                    effort=np.array([js[j][i] for j in js], float)), js_t.__msgtype__))
            for t, c in extra.items():
                w.write(c, int(ns), store.serialize_cdr(f64_t(data=float(scalars[t][i])),
                                                        f64_t.__msgtype__))
            if ctrl is not None:
                _, jn, ref = controller

                def point(pos, vel):
                    return point_t(positions=np.asarray(pos, float),
                                   velocities=np.asarray(vel, float), accelerations=empty,
                                   effort=empty, time_from_start=dur_t(sec=0, nanosec=0))
                none = point([], [])
                state = store.types[CONTROLLER_STATE](
                    header=header, joint_names=list(jn),
                    reference=point([ref[j]['position'][i] for j in jn],
                                    [ref[j]['velocity'][i] for j in jn]),
                    feedback=none, error=none, output=none, multi_dof_joint_names=[])
                w.write(ctrl, int(ns), store.serialize_cdr(state, CONTROLLER_STATE))
    return path
