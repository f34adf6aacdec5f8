"""Run logs: the :class:`Run` arrays, MCAP read/write, CSV/MAT import (never rclpy)."""
from __future__ import annotations

from motor_comp.logs.run import Run

__all__ = ['Run']
