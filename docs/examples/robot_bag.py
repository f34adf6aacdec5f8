"""Write the HSM150 runs of ``../shared/data`` as a robot would record them (tutorial §7b).

One rosbag2 bag per run, sqlite3 storage (the default before Iron), one
``/joint_states`` topic with three joints — ``base_joint`` (still), ``hsm150`` (the
motor: angle [rad], speed [rad/s], effort = the commanded torque [N·m]) and
``tool_joint`` (a slow swing) — with the joints in a different order in every message,
as some drivers publish them.  Written with rosbags, as ``ros2 bag record`` would.

Usage: ``python docs/examples/robot_bag.py ../shared/data/hsm150 OUT_DIR [RUN ...]``
"""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore
from scipy.io import loadmat


def write(mat: Path, out: Path, seed: int = 0) -> Path:
    """Write one HSM150 run as a three-joint bag ``out``; return it."""
    d = loadmat(mat)['data']
    t, angle, speed, torque = d[:, 0], d[:, 2], d[:, 3], d[:, 4]
    store = get_typestore(Stores.ROS2_JAZZY)
    js, hd = store.types['sensor_msgs/msg/JointState'], store.types['std_msgs/msg/Header']
    tm = store.types['builtin_interfaces/msg/Time']
    rng = np.random.default_rng(seed)
    names = ['base_joint', 'hsm150', 'tool_joint']
    swing = 0.3 * np.sin(2 * np.pi * 0.2 * t)
    pos = np.column_stack([np.zeros_like(t), angle, swing])
    vel = np.column_stack([np.zeros_like(t), speed, np.gradient(swing, t)])
    eff = np.column_stack([np.zeros_like(t), torque, 0.1 * swing])
    # a wall-clock-like stamp, in integer nanoseconds (as a float, 1.7e9 s holds only
    # 0.24 µs steps)
    ns = np.round(t * 1e9).astype(np.int64) + 1_700_000_000_000_000_000
    with Writer(out, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        c = w.add_connection('/joint_states', js.__msgtype__, typestore=store)
        for i in range(t.size):
            o = rng.permutation(3)
            s = int(ns[i])
            msg = js(header=hd(stamp=tm(sec=s // 10**9, nanosec=s % 10**9), frame_id=''),
                     name=[names[k] for k in o], position=pos[i, o], velocity=vel[i, o],
                     effort=eff[i, o])
            w.write(c, s, store.serialize_cdr(msg, js.__msgtype__))
    return out


def main(argv: list[str]) -> int:
    """Write the bags."""
    if len(argv) < 2:
        print(__doc__.strip().splitlines()[-1], file=sys.stderr)
        return 2
    data, out = Path(argv[0]), Path(argv[1])
    runs = argv[2:] or ['idf_pos_0.065_1', 'idf_neg_0.045_1']
    out.mkdir(parents=True, exist_ok=True)
    for k, name in enumerate(runs):
        print(write(data / f'{name}.mat', out / name, seed=k))
    return 0


if __name__ == '__main__':
    sys.exit(main(sys.argv[1:]))
