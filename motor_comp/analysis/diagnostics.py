"""Summaries of a run's ``/diagnostics``: the model monitor's verdicts, the limits' trip.

Two kinds of ``DiagnosticStatus`` are recorded by ``motor-comp run`` (told apart by
their names): ``monitor_node``'s verdicts (``motor_comp/<ns>: model monitor``, one per
window, DESIGN.md §5) and ``controller_node``'s limits (``motor_comp/<ns>: limits``: OK
when armed, ERROR at a trip).  :func:`summarise` turns them into the keys
``motor-comp analyze --json`` and ``motor-comp run --json`` print per run::

    monitor: {statuses: {OK: n, WARN: n, ERROR: n, STALE: n}, verdicts, worst_nrmse,
              last_nrmse, candidate, candidate_status, candidate_verdicts}
    limits:  {tripped, cause, message, t, limits}

``candidate`` is the effect the monitor named in most of its non-OK verdicts (the latest
on a tie; null when every verdict was OK).  Core module: no rclpy.
"""
from __future__ import annotations

import collections
import math
from typing import Any, Sequence

from motor_comp.logs.diagnostics import DiagnosticRecord

#: name suffixes of the two kinds of status
MONITOR_SUFFIX = ': model monitor'
LIMITS_SUFFIX = ': limits'


def _number(text: str | None) -> float | None:
    try:
        v = float(text) if text is not None else math.nan
    except ValueError:
        return None
    return v if math.isfinite(v) else None


def monitor_summary(records: Sequence[DiagnosticRecord]) -> dict[str, Any] | None:
    """Summarise the model monitor's verdicts (None when there are none)."""
    verdicts = [r for r in records if r.name.endswith(MONITOR_SUFFIX)]
    if not verdicts:
        return None
    counts = {level: 0 for level in ('OK', 'WARN', 'ERROR', 'STALE')}
    for r in verdicts:
        counts[r.level] = counts.get(r.level, 0) + 1
    judged = [_number(r.values.get('force_nrmse')) for r in verdicts if r.level != 'STALE']
    judged = [v for v in judged if v is not None]
    named = [r for r in verdicts if r.level != 'OK' and r.values.get('candidate')]
    candidate = status = None
    votes = 0
    if named:
        tally = collections.Counter(r.values['candidate'] for r in named)
        top = max(tally.values())
        # the most named; on a tie the one named last
        last = next(r for r in reversed(named) if tally[r.values['candidate']] == top)
        candidate, status, votes = (last.values['candidate'],
                                    last.values.get('candidate_status'), top)
    return {'statuses': counts, 'verdicts': len(verdicts),
            'worst_nrmse': max(judged) if judged else None,
            'last_nrmse': judged[-1] if judged else None,
            'last_level': verdicts[-1].level,
            'candidate': candidate, 'candidate_status': status, 'candidate_verdicts': votes}


def limits_summary(records: Sequence[DiagnosticRecord]) -> dict[str, Any] | None:
    """Summarise the controller's limits: armed, and the trip if one happened."""
    statuses = [r for r in records if r.name.endswith(LIMITS_SUFFIX)]
    if not statuses:
        return None
    armed = next((r.values.get('limits') for r in statuses if r.level == 'OK'), None)
    trip = next((r for r in statuses if r.level == 'ERROR'), None)
    out: dict[str, Any] = {'tripped': trip is not None, 'limits': armed}
    if trip is not None:
        out.update(cause=trip.values.get('cause'), message=trip.message,
                   t=_number(trip.values.get('t')), value=_number(trip.values.get('value')))
    return out


def summarise(records: Sequence[DiagnosticRecord]) -> dict[str, Any]:
    """Return ``{'monitor': …, 'limits': …}`` for the kinds present (may be empty)."""
    out = {}
    mon = monitor_summary(records)
    if mon is not None:
        out['monitor'] = mon
    lim = limits_summary(records)
    if lim is not None:
        out['limits'] = lim
    return out


def format_summary(summary: dict[str, Any]) -> list[str]:
    """Return the summary as lines of text (``analyze``'s table, ``run``'s output)."""
    lines = []
    mon = summary.get('monitor')
    if mon is not None:
        counts = ', '.join(f'{k} {v}' for k, v in mon['statuses'].items() if v)
        worst = mon['worst_nrmse']
        text = f'monitor: {mon["verdicts"]} verdicts ({counts})'
        if worst is not None:
            text += f', worst force NRMSE {worst:.3f}'
        if mon['candidate']:
            text += f', candidate {mon["candidate"]} ({mon["candidate_status"]})'
        lines.append(text)
    lim = summary.get('limits')
    if lim is not None:
        lines.append(f'limits: TRIPPED: {lim["message"]}' if lim['tripped']
                     else f'limits: not tripped ({lim["limits"]})')
    return lines


__all__ = ['format_summary', 'limits_summary', 'monitor_summary', 'summarise']
