"""motor_comp: precision servo-axis simulation, friction/ripple compensation and model workbench.

The numpy core (``physics``, ``control``, ``logs``, ``analysis``, ``workbench``) never
imports rclpy; the ROS 2 adapters live in ``motor_comp.nodes``.
"""
from __future__ import annotations

__version__ = '0.1.0'
