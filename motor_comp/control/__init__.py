"""Controllers (PID, adaptive sliding, N-PID), friction feedforward, trajectories, simulator.

Numpy + numba only (never rclpy): the ROS nodes import these step functions.
"""
from __future__ import annotations

from motor_comp.control._jitcache import refresh_stale_caches

refresh_stale_caches()  # before any kernel below is loaded from the numba cache

from motor_comp.control.adaptive_sliding import (  # noqa: E402
    ESTIMATES, AdaptiveParams)
from motor_comp.control.controller import (  # noqa: E402
    ControlMode, Controller, controller_step, default_params, make_controller)
from motor_comp.control.feedforward import Feedforward  # noqa: E402
from motor_comp.control.npid import NPIDParams  # noqa: E402
from motor_comp.control.pid import PIDParams  # noqa: E402
from motor_comp.control.simulator import SimResult, simulate  # noqa: E402
from motor_comp.control.trajectories import (  # noqa: E402
    Reference, Trajectory, default_trajectory, make_trajectory, traj_eval)

__all__ = ['ESTIMATES', 'AdaptiveParams', 'ControlMode', 'Controller', 'controller_step',
           'default_params', 'make_controller', 'Feedforward', 'NPIDParams', 'PIDParams',
           'SimResult', 'simulate', 'Reference', 'Trajectory', 'default_trajectory',
           'make_trajectory', 'traj_eval']
