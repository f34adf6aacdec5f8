"""Figures of one or several runs (matplotlib, Agg canvas: no display needed).

Long runs are decimated before plotting with a min/max envelope per pixel column
(matplotlib draws every vertex; an hour at 1 kHz would take minutes and a plain
stride would hide the glitch peaks the plots are for).
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from motor_comp.analysis.glitches import reference_velocity
from motor_comp.analysis.metrics import RunMetrics
from motor_comp.logs.run import Run

#: figure files written by :func:`plot_all`, with captions
FIGURES = {
    'error_vs_time.png': 'Tracking error e = x_ref − x over time; glitches marked (▲)',
    'error_vs_position.png': 'Tracking error against measured position',
    'error_vs_reference_velocity.png': 'Tracking error against reference velocity',
    'voltage.png': 'Command voltage over time',
}

UM = 1e6   # m -> µm for axis labels


def _decimate(y: np.ndarray, bins: int = 2000) -> np.ndarray:
    """Return indices of the min and max sample of ``bins`` blocks (peaks survive)."""
    n = y.size
    if n <= 2 * bins:
        return np.arange(n)
    size = n // bins
    m = size * bins
    blocks = y[:m].reshape(bins, size)
    base = np.arange(bins) * size
    lo = base + np.argmin(blocks, axis=1)
    hi = base + np.argmax(blocks, axis=1)
    idx = np.concatenate((np.sort(np.stack((lo, hi), axis=1), axis=1).ravel(),
                          np.arange(m, n)))
    return idx


def _figure(width: float = 9.0, height: float = 4.0) -> tuple[Figure, object]:
    fig = Figure(figsize=(width, height), dpi=110, layout='constrained')
    FigureCanvasAgg(fig)
    return fig, fig.add_subplot(1, 1, 1)


def _save(fig: Figure, path: Path) -> Path:
    fig.savefig(path)
    return path


def plot_error_vs_time(runs: Sequence[Run], metrics: Sequence[RunMetrics], path: Path) -> Path:
    """Error [µm] over time for each run, glitch peaks marked."""
    fig, ax = _figure()
    if metrics and 0 < len(metrics[0].glitches) <= 100:
        for g in metrics[0].glitches:          # reversal instants of the first run
            ax.axvline(g.t, color='0.85', lw=0.6, zorder=0)
    for run, m in zip(runs, metrics):
        e = run.error
        i = _decimate(e)
        line, = ax.plot(run.t[i], e[i] * UM, lw=0.8, label=run.name)
        if m.glitches:
            tp = np.array([g.t_peak for g in m.glitches])
            k = np.searchsorted(run.t, tp).clip(0, len(run) - 1)
            ax.plot(tp, e[k] * UM, '^', ms=5, color=line.get_color(), mec='k', mew=0.4)
    ax.set_xlabel('time [s]')
    ax.set_ylabel('error x_ref − x [µm]')
    ax.set_title('Tracking error (▲ quadrant glitches, grey lines: reversals)')
    ax.grid(alpha=0.3)
    ax.legend(loc='upper right', fontsize='small')
    return _save(fig, path)


def plot_error_vs(runs: Sequence[Run], path: Path, *, against: str) -> Path:
    """Error [µm] against measured position [mm] or reference velocity [mm/s]."""
    fig, ax = _figure(6.5, 4.5)
    for run in runs:
        e = run.error
        i = _decimate(e, 4000)
        if against == 'position':
            x = run.position * 1e3
        else:
            x = reference_velocity(run.t, run.reference, run.reference_velocity) * 1e3
        ax.plot(x[i], e[i] * UM, '.', ms=1.5, alpha=0.6, label=run.name)
    ax.set_xlabel('position [mm]' if against == 'position' else 'reference velocity [mm/s]')
    ax.set_ylabel('error x_ref − x [µm]')
    ax.set_title('Tracking error against ' + ('position' if against == 'position'
                                              else 'reference velocity'))
    ax.grid(alpha=0.3)
    ax.legend(loc='upper right', fontsize='small', markerscale=6)
    return _save(fig, path)


def plot_voltage(runs: Sequence[Run], path: Path) -> Path | None:
    """Command voltage [V] over time (None if no run has one)."""
    with_u = [r for r in runs if r.voltage is not None]
    if not with_u:
        return None
    fig, ax = _figure()
    for run in with_u:
        i = _decimate(run.voltage)
        ax.plot(run.t[i], run.voltage[i], lw=0.7, label=run.name)
    ax.set_xlabel('time [s]')
    ax.set_ylabel('voltage [V]')
    ax.set_title('Command voltage')
    ax.grid(alpha=0.3)
    ax.legend(loc='upper right', fontsize='small')
    return _save(fig, path)


def plot_all(runs: Sequence[Run], metrics: Sequence[RunMetrics], out: Path) -> list[Path]:
    """Write every figure of :data:`FIGURES` that applies into ``out``; return the paths."""
    out.mkdir(parents=True, exist_ok=True)
    paths = [plot_error_vs_time(runs, metrics, out / 'error_vs_time.png'),
             plot_error_vs(runs, out / 'error_vs_position.png', against='position'),
             plot_error_vs(runs, out / 'error_vs_reference_velocity.png',
                           against='velocity')]
    v = plot_voltage(runs, out / 'voltage.png')
    if v is not None:
        paths.append(v)
    return paths
