"""Run logs: the :class:`Run` arrays, MCAP read/write, CSV/MAT import (never rclpy)."""
from __future__ import annotations

from motor_comp.logs.importers import import_table
from motor_comp.logs.mcap_io import McapRecorder, read_run, write_run
from motor_comp.logs.run import Run

__all__ = ['McapRecorder', 'Run', 'import_table', 'read_run', 'write_run']
