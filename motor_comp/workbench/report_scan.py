"""The report's view of what a model leaves: the structure scan and the noise floor.

Two figures for the ``--report`` pages of ``diagnose`` and ``fit``: the step functions
the scan fitted to the held-out residual against each variable, each beside the same
scan on the floor's record, with every feature's span shaded; and the force NRMSE of
each step (or candidate) against the noise floor, so a reader sees how far above what
the measurement explains the model still is.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from motor_comp.workbench.report import _plt

#: how each scan variable is labelled and scaled on a linear / rotary axis
_AXES = {'position': (('position [mm]', 1e3), ('angle [rad]', 1.0)),
         'velocity': (('velocity [mm/s]', 1e3), ('velocity [rad/s]', 1.0)),
         'force': (('drive force the model explains', 1.0),) * 2,
         'time': (('time [s]', 1.0),) * 2,
         'reversal': (('time since a reversal [ms]', 1e3),) * 2}


def scan_figure(out: Path, unexplained: Any, *, rotary: bool = False,
                name: str = 'scan.png') -> tuple[str, str]:
    """Write the structure scan's step functions with the features marked."""
    plt = _plt()
    profiles = [p for p in unexplained.scans if len(p.means)]
    n = max(len(profiles), 1)
    cols = 2
    rows = math.ceil(n / cols)
    fig, axes = plt.subplots(rows, cols, figsize=(9, 2.4 * rows), dpi=90, squeeze=False)
    feats = {(f.against, f.odd): f for f in unexplained.features}
    for ax, p in zip(axes.ravel(), profiles):
        label, k = _AXES[p.against][1 if rotary else 0]
        e = np.asarray(p.edges, dtype=float)
        finite = np.isfinite(e)
        e = np.where(finite, e, np.nan)
        centres = 0.5 * (e[1:] + e[:-1])
        ax.step(k * centres, p.means, where='mid', color='C3', lw=1.2)
        ax.axhline(0.0, color='k', lw=0.5)
        f = feats.get((p.against, p.odd))
        if f is not None:
            ax.axvspan(k * f.where[0], k * f.where[1], color='C1', alpha=0.25)
        ax.set_xlabel(label + (' (|·|)' if p.odd and p.against in ('velocity', 'force')
                               else ''))
        ax.set_title(f'{"friction" if p.odd else "force"}: held-out share '
                     f'{100 * p.share:.0f} % (floor record {100 * p.floor_share:.0f} %)',
                     fontsize=8)
    for ax in axes.ravel()[len(profiles):]:
        ax.axis('off')
    fig.tight_layout()
    fig.savefig(out / name)
    plt.close(fig)
    return (name, 'The residual the model leaves, as a step function of one variable at a '
            'time (as a force, and times the direction of motion as a friction); shaded: a '
            'feature, a structure beyond what the noise floor\'s record shows.')


def floor_figure(out: Path, labels: Sequence[str], nrmse: Sequence[float], floor: float, *,
                 name: str = 'nrmse_floor.png') -> tuple[str, str]:
    """Write the force NRMSE of each step (or candidate) against the noise floor."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7, 3.0), dpi=90)
    x = np.arange(len(labels))
    ax.bar(x, [100 * v for v in nrmse], color='C0')
    if math.isfinite(floor):
        ax.axhline(100 * floor, color='C3', ls='--', lw=1.2, label='noise floor')
        ax.legend(fontsize=8)
    ax.set_xticks(x)
    ax.set_xticklabels(labels, rotation=30, ha='right', fontsize=8)
    ax.set_yscale('log')
    ax.set_ylabel('force NRMSE [%] (held-out)')
    fig.tight_layout()
    fig.savefig(out / name)
    plt.close(fig)
    return (name, 'Force NRMSE of each model against the noise floor (dashed): what a '
            'perfect model would leave on this run with this sensor.')


__all__ = ['floor_figure', 'scan_figure']
