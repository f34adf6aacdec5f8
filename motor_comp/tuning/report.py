"""The ``motor-comp autotune`` report: ``index.html``, its figures and ``autotune.json``.

One self-contained page (inline CSS, figures embedded and linked to their PNGs next to
it) with what the loop found and did:

* the task's tracking error without compensation, with the fitted model and with the
  true plant model (when known) over time (``task_error.png``) and in numbers, with the
  recovered shares of the true model's reduction;
* the fitted model's parameters with their standard errors, and the steps of
  ``fit --auto`` (``fit_steps.png``: held-out force NRMSE after each step);
* the model monitor's verdicts of each run (``monitor.png`` with ``--monitor``) and the
  limits (armed, or the trip);
* the steps of autotune with their wall time and files — also for a run that stopped
  early, whose page says where and why.

Core module (matplotlib Agg, no display; no rclpy).
"""
from __future__ import annotations

import base64
import dataclasses
import html
import json
import math
from pathlib import Path
from typing import Any

import numpy as np

#: figure files and their captions
CAPTIONS = {
    'task_error.png': 'Tracking error e = x_ref − x of the task: without compensation, with '
                      'the fitted model and with the true plant model (▲ quadrant glitches)',
    'fit_steps.png': 'fit --auto: held-out force NRMSE of the start model and after each step',
    'monitor.png': 'monitor_node: windowed force NRMSE of its model along each run '
                   '(the start model during the excitation, the fitted model during the task)',
}


def _um(v: float | None) -> str:
    return '—' if v is None or not math.isfinite(v) else f'{v * 1e6:.3f}'


def _pct(v: float | None) -> str:
    return '—' if v is None or not math.isfinite(v) else f'{100 * v:.1f} %'


def _parameters(model: Any, uncertainty: dict) -> list[tuple[str, str, float, float | None]]:
    """Rows ``(group, parameter, value, SE)`` of the fitted model (SI, the file's units)."""
    rows: list[tuple[str, str, float, float | None]] = []
    se = uncertainty or {}
    rows.append(('mass', 'mass', float(model.mass), se.get('mass', {}).get('mass')))
    for e in model.effects:
        values = {k: v for k, v in e.params().items() if isinstance(v, (int, float))}
        if e.name == 'ripple':
            values.update({f'amplitude_{h + 1}': float(a)
                           for h, a in enumerate(e.amplitudes)})
        for k, v in values.items():
            rows.append((e.name, k, float(v), se.get(e.name, {}).get(k)))
        for k, v in e.params().items():   # lists (GMS elements, knots): value only
            if isinstance(v, (list, tuple)):
                rows.append((e.name, k, float('nan'), None))
    return rows


def _fmt(v: float) -> str:
    return '—' if not math.isfinite(v) else f'{v:.6g}'


def _fmt_se(se: float | None) -> str:
    # infinite: the run never moved the parameter (see uncertainty.delta_se)
    if se is None or math.isnan(se):
        return '—'
    return 'not resolved by this run' if math.isinf(se) else f'{se:.3g}'


def _table(head: list[str], rows: list[list[str]]) -> str:
    h = ''.join(f'<th>{html.escape(c)}</th>' for c in head)
    body = ''.join('<tr>' + ''.join(f'<td>{c}</td>' for c in r) + '</tr>' for r in rows)
    return f'<table><tr>{h}</tr>{body}</table>'


def _figure(width: float = 9.0, height: float = 4.0) -> tuple[Any, Any]:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    fig = Figure(figsize=(width, height), dpi=110, layout='constrained')
    FigureCanvasAgg(fig)
    return fig, fig.add_subplot(1, 1, 1)


def task_figure(runs: dict, path: Path) -> Path | None:
    """Tracking error of the task runs over the task's time [µm] (None without runs)."""
    from motor_comp.analysis.metrics import compute_metrics
    from motor_comp.analysis.plots import plot_error_vs_time
    if not runs:
        return None
    names = {'none': 'without compensation', 'fitted': 'fitted model',
             'true': 'true plant model'}
    shifted = [dataclasses.replace(r, t=r.t - r.t[0], name=names.get(k, k))
               for k, r in runs.items()]
    return plot_error_vs_time(shifted, [compute_metrics(r) for r in shifted], path)


def fit_figure(fit: Any, path: Path) -> Path | None:
    """Held-out force NRMSE after each ``fit --auto`` step (None without a fit)."""
    if fit is None:
        return None
    fig, ax = _figure(7.0, 3.6)
    labels = ['start'] + [('−' if getattr(s, 'action', 'add') == 'remove' else '+')
                          + str(s.effect) for s in fit.steps[1:]]
    y = [100 * s.force_nrmse for s in fit.steps]
    ax.plot(range(len(y)), y, 'o-')
    ax.set_xticks(range(len(y)), labels)
    ax.set_ylabel('held-out force NRMSE [%]')
    ax.set_yscale('log')
    ax.grid(alpha=0.3)
    ax.set_title('fit --auto from the start model')
    fig.savefig(path)
    return path


def monitor_figure(directory: Path, recordings: dict, path: Path) -> Path | None:
    """Plot the monitor's force NRMSE over each run's time (None without verdicts)."""
    from motor_comp.analysis.diagnostics import MONITOR_SUFFIX
    from motor_comp.logs.diagnostics import read_diagnostics
    series = {}
    for label, name in recordings.items():
        f = directory / name
        if not f.exists():
            continue
        try:
            recs = [r for r in read_diagnostics(f) if r.name.endswith(MONITOR_SUFFIX)
                    and r.level != 'STALE']
        except Exception:   # noqa: BLE001 - a damaged file has no figure, the page goes on
            continue
        pts = [(r.t, float(r.values['force_nrmse'])) for r in recs
               if r.values.get('force_nrmse') not in (None, '', 'nan')]
        if pts:
            series[label] = np.array(pts)
    if not series:
        return None
    fig, ax = _figure()
    for label, pts in series.items():
        ax.plot(pts[:, 0] - pts[0, 0], pts[:, 1], '.-', ms=3, lw=0.8, label=label)
    ax.set_xlabel('time in the run [s]')
    ax.set_ylabel('windowed force NRMSE')
    ax.set_yscale('log')
    ax.grid(alpha=0.3)
    ax.legend(fontsize='small')
    fig.savefig(path)
    return path


_CSS = ('body{font-family:sans-serif;max-width:64em;margin:1em auto;line-height:1.35}'
        'table{border-collapse:collapse;margin:.5em 0}td,th{border:1px solid #bbb;'
        'padding:.2em .5em;text-align:right}th{background:#eee}img{max-width:100%}'
        '.error{background:#fdd;border:1px solid #c00;padding:.6em}')


def _embed(path: Path) -> str:
    data = base64.b64encode(path.read_bytes()).decode()
    name = html.escape(path.name)
    return (f'<figure><a href="{name}"><img alt="{name}" src="data:image/png;base64,{data}">'
            f'</a><figcaption>{html.escape(CAPTIONS[path.name])} (<a href="{name}">{name}'
            f'</a>)</figcaption></figure>')


def finite(x: Any) -> Any:
    """Replace non-finite floats by None, recursively (JSON has no NaN or infinity)."""
    if isinstance(x, float) and not math.isfinite(x):
        return None
    if isinstance(x, dict):
        return {k: finite(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite(v) for v in x]
    return x


def write_report(out: Any, *, figures: bool = True) -> tuple[str, ...]:
    """Write ``index.html``, the figures and ``autotune.json`` of an :class:`Outcome`.

    Returns the names of the files written.  ``figures=False`` rewrites the page and
    the JSON only (the figures of an earlier call stay).
    """
    d = Path(out.directory)
    written = []
    figs: list[Path] = []
    makers = (('task_error.png', lambda p: task_figure(out.task_runs, p)),
              ('fit_steps.png', lambda p: fit_figure(out.fit, p)),
              ('monitor.png', lambda p: monitor_figure(d, out.recordings, p)))
    for name, make in makers:
        p = d / name
        if figures:
            made = make(p)
            if made is not None:
                written.append(name)
                figs.append(made)
        elif p.exists():
            figs.append(p)
    data = finite(out.as_dict())
    (d / 'autotune.json').write_text(json.dumps(data, indent=1), encoding='utf-8')
    (d / 'index.html').write_text(_page(out, data, figs), encoding='utf-8')
    return tuple(written) + ('autotune.json', 'index.html')


def _page(out: Any, data: dict, figs: list[Path]) -> str:
    o = out.options
    e = html.escape
    parts = [f'<!DOCTYPE html><html lang="en"><head><meta charset="utf-8"><title>motor-comp '
             f'autotune</title><style>{_CSS}</style></head><body>',
             '<h1>motor-comp autotune</h1>',
             f'<p>Axis: {e(o.plant or "external drive")} (controller '
             f'{e(out.controller)} on the nominal plant '
             f'{e(str(o.nominal or o.plant))}), {e(o.timing)}; start model '
             f'<code>{e(str(o.model))}</code>; task {e(out.task_label)}.</p>']
    if out.error:
        parts.append(f'<p class="error">Stopped in stage <b>{e(out.stage)}</b>: '
                     f'{e(out.error)}. The axis was stopped; everything recorded up to '
                     f'then is in this directory.</p>')
    lim = data.get('limits')
    if lim:
        parts.append('<p>Limits enforced by the nodes: ' + e(out.axis_limits.describe())
                     + '; the excitation was designed within travel '
                     f'{e(str([round(v, 9) for v in data["excitation_limits"]["travel"]]))}, '
                     f'vmax {data["excitation_limits"]["vmax"]:.4g}, amax '
                     f'{data["excitation_limits"]["amax"]:.4g}.</p>')
    # -- the task -------------------------------------------------------------------------
    if out.scores:
        parts.append('<h2>The task, without and with compensation</h2>')
        rows = []
        names = {'none': 'without compensation', 'fitted': 'fitted model',
                 'true': 'true plant model'}
        for k, s in out.scores.items():
            rows.append([e(names.get(k, k)), _um(s.rms_error), _um(s.max_error),
                         _um(s.max_glitch), _um(s.mean_glitch)])
        parts.append(_table(['run', 'RMS error [µm]', 'max error [µm]', 'max glitch [µm]',
                             'mean glitch [µm]'], rows))
        if out.recovered_rms is not None:
            parts.append(f'<p>The fitted model recovers <b>{_pct(out.recovered_rms)}</b> of '
                         f'the RMS-error reduction and <b>{_pct(out.recovered_glitch)}</b> of '
                         f'the quadrant-glitch reduction that the true plant model gives '
                         f'(<code>(none − fitted) / (none − true)</code>).</p>')
    # -- the model ------------------------------------------------------------------------
    if out.fit is not None:
        parts.append('<h2>The fitted model</h2>')
        rows = [[e(g), e(k), _fmt(v), _fmt_se(se)]
                for g, k, v, se in _parameters(out.fit.model, out.fit.uncertainty)]
        parts.append(_table(['effect', 'parameter', 'value (SI)', 'standard error'], rows))
        rows = [[str(i), e(str(s.effect or 'start model')),
                 e(getattr(s, 'action', 'add') if s.effect else ''), f'{s.force_nrmse:.4f}']
                for i, s in enumerate(out.fit.steps)]
        parts.append('<h3>Steps of fit --auto</h3>')
        parts.append(_table(['step', 'effect', 'action', 'held-out force NRMSE'], rows))
        notes = (list(getattr(out.fit, 'identifiability', ()))
                 + list(getattr(out.fit, 'experiment', ())))
        for note in notes:
            parts.append(f'<p>{e(str(note))}</p>')
    # -- diagnostics ----------------------------------------------------------------------
    if out.diagnostics:
        parts.append('<h2>Monitor and limits</h2>')
        rows = []
        for label, summ in out.diagnostics.items():
            mon, lim = summ.get('monitor'), summ.get('limits')
            mon_text = '—' if not mon else (
                ', '.join(f'{k} {v}' for k, v in mon['statuses'].items() if v)
                + (f'; worst NRMSE {mon["worst_nrmse"]:.3f}' if mon['worst_nrmse'] is not None
                   else '') + (f'; candidate {mon["candidate"]}' if mon['candidate'] else ''))
            lim_text = '—' if not lim else (f'TRIPPED: {lim["message"]}' if lim['tripped']
                                            else 'armed, not tripped')
            rows.append([e(label), e(mon_text), e(lim_text)])
        parts.append(_table(['run', 'monitor verdicts', 'limits'], rows))
    # -- figures and steps ---------------------------------------------------------------
    if figs:
        parts.append('<h2>Figures</h2>' + ''.join(_embed(p) for p in figs))
    parts.append('<h2>What autotune did</h2>')
    rows = [[e(s.name), f'{s.seconds:.1f}',
             ' '.join(f'<a href="{e(f)}">{e(f)}</a>' for f in s.files), e(s.note)]
            for s in out.steps]
    parts.append(_table(['step', 'wall time [s]', 'files', 'what'], rows))
    parts.append('<p>Node logs and parameter files: <a href="logs/">logs/</a>; all numbers: '
                 '<a href="autotune.json">autotune.json</a>.</p></body></html>')
    return '\n'.join(parts)


__all__ = ['CAPTIONS', 'finite', 'fit_figure', 'monitor_figure', 'task_figure',
           'write_report']
