"""Offline analysis of runs: metrics (tracking error, glitches), plots and reports."""
from __future__ import annotations

from motor_comp.analysis.glitches import Glitch, find_glitches, reversals
from motor_comp.analysis.metrics import Move, RunMetrics, Segment, compute_metrics

__all__ = ['Glitch', 'Move', 'RunMetrics', 'Segment', 'compute_metrics', 'find_glitches',
           'reversals']
