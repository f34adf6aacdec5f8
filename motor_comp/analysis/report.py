"""Tables (text, HTML) of run metrics and the ``--report DIR`` page.

The HTML page is self-contained (inline CSS, figures embedded as data URIs) and each
figure links to its PNG file next to it, so the directory can be browsed or the page
mailed on its own.
"""
from __future__ import annotations

import base64
import html
import math
from pathlib import Path
from typing import Any, Sequence

from motor_comp.analysis.metrics import RunMetrics
from motor_comp.logs.run import Run

#: (key, label, scale, unit) of the compared quantities, in table order
ROWS: tuple[tuple[str, str, float, str], ...] = (
    ('rms_error', 'RMS error', 1e6, 'µm'),
    ('max_error', 'max error', 1e6, 'µm'),
    ('max_glitch', 'max glitch', 1e6, 'µm'),
    ('mean_glitch', 'mean glitch', 1e6, 'µm'),
    ('glitch_count', 'glitches', 1.0, ''),
    ('rms_voltage', 'RMS voltage', 1.0, 'V'),
    ('max_voltage', 'max |voltage|', 1.0, 'V'),
    ('chattering', 'chattering', 1.0, 'V'),
    ('duration', 'duration', 1.0, 's'),
)
#: quantities for which the relative change against the first run is reported
COMPARED = ('rms_error', 'max_error', 'max_glitch', 'mean_glitch', 'rms_voltage',
            'max_voltage', 'chattering')


def relative_change(first: RunMetrics, other: RunMetrics) -> dict[str, float | None]:
    """``(other − first) / first`` per compared quantity (None where undefined)."""
    out: dict[str, float | None] = {}
    for key in COMPARED:
        a, b = getattr(first, key), getattr(other, key)
        out[key] = (b - a) / a if (a not in (None, 0) and b is not None) else None
    return out


def _value(m: RunMetrics, key: str) -> Any:
    return m.glitch_count if key == 'glitch_count' else getattr(m, key)


def _fmt(v: Any, scale: float) -> str:
    if v is None or (isinstance(v, float) and math.isnan(v)):
        return '—'
    if isinstance(v, int):
        return str(v)
    return f'{v * scale:.4g}'


def table_rows(metrics: Sequence[RunMetrics]) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the comparison table (relative change vs the first run)."""
    header = ['metric'] + [m.name for m in metrics]
    rows = []
    for key, label, scale, unit in ROWS:
        row = [f'{label} [{unit}]' if unit else label]
        for i, m in enumerate(metrics):
            cell = _fmt(_value(m, key), scale)
            if i > 0 and key in COMPARED:
                rel = relative_change(metrics[0], m)[key]
                if rel is not None:
                    cell += f' ({rel:+.1%})'
            row.append(cell)
        rows.append(row)
    moves = [m.moves for m in metrics]
    if any(moves):
        row_o = ['max overshoot [µm]']
        row_s = ['max settling time [s]']
        for mv in moves:
            row_o.append(_fmt(max((x.overshoot for x in mv), default=None), 1e6))
            st = [x.settling_time for x in mv]
            row_s.append('not settled' if any(s is None for s in st)
                         else _fmt(max(st, default=None), 1.0))
        rows += [row_o, row_s]
    return header, rows


def format_table(metrics: Sequence[RunMetrics]) -> str:
    """Plain-text table, one column per run (relative change vs the first in brackets)."""
    header, rows = table_rows(metrics)
    cols = [header] + rows
    widths = [max(len(r[i]) for r in cols) for i in range(len(header))]
    lines = ['  '.join(c.ljust(w) if i == 0 else c.rjust(w)
                       for i, (c, w) in enumerate(zip(r, widths))) for r in cols]
    lines.insert(1, '  '.join('-' * w for w in widths))
    return '\n'.join(lines)


def _html_table(metrics: Sequence[RunMetrics]) -> str:
    header, rows = table_rows(metrics)
    head = ''.join(f'<th>{html.escape(h)}</th>' for h in header)
    body = ''.join('<tr>' + ''.join(f'<td>{html.escape(c)}</td>' for c in r) + '</tr>'
                   for r in rows)
    return f'<table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table>'


def _glitch_table(m: RunMetrics, limit: int = 50) -> str:
    if not m.glitches:
        return '<p>No reference-velocity reversals.</p>'
    rows = ''.join(f'<tr><td>{g.t:.4f}</td><td>{g.magnitude * 1e6:.3f}</td>'
                   f'<td>{"+" if g.direction > 0 else "−"}</td></tr>'
                   for g in m.glitches[:limit])
    more = (f'<p>… {len(m.glitches) - limit} more in the JSON output.</p>'
            if len(m.glitches) > limit else '')
    return ('<table><thead><tr><th>reversal t [s]</th><th>glitch [µm]</th>'
            f'<th>direction</th></tr></thead><tbody>{rows}</tbody></table>{more}')


_CSS = """
body{font-family:system-ui,sans-serif;margin:2em;max-width:70em;color:#222}
table{border-collapse:collapse;margin:1em 0}
td,th{border:1px solid #ccc;padding:.25em .6em;text-align:right}
td:first-child,th:first-child{text-align:left}
figure{margin:1.5em 0}img{max-width:100%;border:1px solid #eee}
figcaption{color:#555;font-size:.9em}
"""


def write_report(out: str | Path, runs: Sequence[Run], metrics: Sequence[RunMetrics], *,
                 sources: Sequence[str] = (), title: str = 'motor_comp run analysis') -> Path:
    """Write the figures and ``index.html`` into ``out``; return the HTML path."""
    from motor_comp.analysis.plots import FIGURES, plot_all   # matplotlib: only when plotting
    out = Path(out)
    pngs = plot_all(runs, metrics, out)
    figs = []
    for p in pngs:
        data = base64.b64encode(p.read_bytes()).decode()
        figs.append(f'<figure><a href="{html.escape(p.name)}"><img alt="{p.name}" '
                    f'src="data:image/png;base64,{data}"></a>'
                    f'<figcaption>{html.escape(FIGURES[p.name])} '
                    f'(<a href="{html.escape(p.name)}">{html.escape(p.name)}</a>)'
                    '</figcaption></figure>')
    src = ''.join(f'<li><code>{html.escape(str(s))}</code></li>' for s in sources)
    window = metrics[0].glitch_window if metrics else 0.2
    per_run = ''.join(f'<h3>{html.escape(m.name)}</h3>{_glitch_table(m)}' for m in metrics)
    page = f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>{_CSS}</style></head><body>
<h1>{html.escape(title)}</h1>
<ul>{src}</ul>
<p>Error e = x_ref − x. Glitch: max |e| within {window:g} s after each sign change of the
reference velocity. Relative changes are against the first run.</p>
<h2>Metrics</h2>
{_html_table(metrics)}
<h2>Figures</h2>
{''.join(figs)}
<h2>Quadrant glitches</h2>
{per_run}
</body></html>
"""
    index = out / 'index.html'
    index.write_text(page, encoding='utf-8')
    return index
