"""Import test-rig tables (CSV, MATLAB .mat) into a :class:`Run`.

Column selection (``COL``):

* CSV — a header name, or a 0-based column index.  The first non-comment line is a
  header when any of its cells is not a number; ``#`` lines are comments; the
  delimiter (``,`` ``;`` tab or blanks) is detected.
* MAT — ``VAR`` (a vector variable), ``VAR:I`` / ``VAR[I]`` (signal ``I``, 0-based, of
  a 2-D variable), or just ``I`` when the file holds one 2-D variable.  Signals lie
  along the shorter axis unless ``mat_orient`` says ``rows`` or ``columns`` (e.g. the
  ODrive logs: ``data`` is 3×N, rows ``[t, counts, Iq]`` → ``--time 0 --position 1``).

Scaling: every signal is multiplied by its scale (e.g. ``position_scale`` = metres per
encoder count; ``time_scale`` = seconds per time unit).  The reference uses the
position scale and velocities ``velocity_scale`` (default: the position scale).

Policies (same as :func:`~motor_comp.logs.read_run`): rows with NaN/Inf in a selected
column are dropped with a warning; out-of-order time stamps are sorted and duplicate
stamps dropped (keeping the last row) with a warning; a non-numeric or empty cell is an
error naming the line and column.
"""
from __future__ import annotations

import csv
import math
import re
from pathlib import Path
from typing import Mapping

import numpy as np

from motor_comp.errors import InputFileError, ParameterError, check_finite
from motor_comp.logs.progress import warn
from motor_comp.logs.run import Run

#: file name extensions read as delimited text (anything else but .mat is refused: a
#: spreadsheet or JSON file parsed as CSV gives a misleading "no data rows" error)
TEXT_SUFFIXES = ('.csv', '.tsv', '.txt', '.dat')
#: Run fields that can be imported, in order; ``time`` and ``position`` are required
FIELDS = ('time', 'input', 'position', 'reference', 'velocity', 'reference_velocity',
          'effort')


class _Csv:
    """Numeric columns of a delimited text file.

    Columns are parsed by ``numpy.loadtxt`` (C parser, streaming); only when it fails
    is the file walked line by line to name the offending line and cell.
    """

    def __init__(self, path: Path) -> None:
        self.path = path
        head: list[tuple[int, str]] = []      # (line number, text) of the first rows
        try:
            with open(path, encoding='utf-8-sig') as f:
                for number, line in enumerate(f, 1):
                    if line.strip() and not line.lstrip().startswith('#'):
                        head.append((number, line.rstrip('\r\n')))
                        if len(head) >= 20:
                            break
        except UnicodeDecodeError:
            raise InputFileError(f'{path}: not a text (UTF-8) CSV file') from None
        if not head:
            raise InputFileError(f'{path}: no data rows')
        try:
            self.delim = csv.Sniffer().sniff('\n'.join(t for _, t in head),
                                             delimiters=',;\t ').delimiter
        except csv.Error:
            self.delim = ','
        first = self._split(head[0][1])
        self.header: list[str] | None = None
        self.skip = head[0][0] - 1            # physical lines before the first data row
        if any(not _is_number(c) for c in first):
            self.header = [c.strip() for c in first]
            self.skip = head[0][0]
            if len(head) < 2:
                raise InputFileError(f'{path}: header but no data rows')
            first = self._split(head[1][1])
        self.width = len(self.header) if self.header is not None else len(first)

    def _split(self, line: str) -> list[str]:
        cells = next(csv.reader([line], delimiter=self.delim, skipinitialspace=True))
        return [c for c in cells if c != ''] if self.delim == ' ' else cells

    def _index(self, spec: str, field: str) -> tuple[int, str]:
        if self.header is not None and spec in self.header:
            return self.header.index(spec), spec
        if re.fullmatch(r'\d+', spec.strip()):
            i = int(spec)
            if i >= self.width:
                raise InputFileError(f'{self.path}: --{field.replace("_", "-")} column '
                                     f'{i} out of range (file has {self.width} columns)')
            name = self.header[i] if self.header is not None and i < len(self.header) else spec
            return i, name
        cols = ', '.join(self.header) if self.header else f'{self.width} unnamed columns'
        raise InputFileError(f'{self.path}: no column {spec!r} for '
                             f'--{field.replace("_", "-")} (columns: {cols})')

    def column(self, spec: str, field: str) -> np.ndarray:
        i, name = self._index(spec, field)
        try:
            return np.loadtxt(self.path, delimiter=None if self.delim == ' ' else self.delim,
                              comments='#', skiprows=self.skip, usecols=(i,), ndmin=1,
                              encoding='utf-8-sig', dtype=float)
        except ValueError:
            pass
        self._culprit(i, name)
        raise InputFileError(f'{self.path}: column {name!r} is not numeric')

    def _culprit(self, i: int, name: str) -> None:
        """Raise the error naming the first bad cell of column ``i``."""
        with open(self.path, encoding='utf-8-sig') as f:
            for number, line in enumerate(f, 1):
                if number <= self.skip or not line.strip() or line.lstrip().startswith('#'):
                    continue
                cells = self._split(line.rstrip('\r\n'))
                if i >= len(cells) or cells[i].strip() == '':
                    raise InputFileError(f'{self.path}: line {number}, column {name!r}: '
                                         'empty cell')
                if not _is_number(cells[i]):
                    raise InputFileError(f'{self.path}: line {number}, column {name!r}: '
                                         f'{cells[i].strip()!r} is not a number')


class _Mat:
    """Signals (rows or columns of numeric variables) of a MATLAB v4–v7 file."""

    def __init__(self, path: Path, orient: str) -> None:
        self.path = path
        import scipy.io
        try:
            raw = scipy.io.loadmat(str(path))
        except NotImplementedError:
            raise InputFileError(f'{path}: MATLAB v7.3 (HDF5) files are not supported; '
                                 'save with -v7') from None
        except Exception as exc:  # noqa: BLE001 - scipy raises many types for bad files
            raise InputFileError(f'{path}: not a readable MATLAB file ({exc})') from None
        self.vars = {k: v for k, v in raw.items() if not k.startswith('__')}
        if not self.vars:
            raise InputFileError(f'{path}: no variables')
        if orient not in ('auto', 'rows', 'columns'):
            raise ParameterError(f'mat_orient must be auto, rows or columns, got {orient!r}')
        self.orient = orient

    def _signals(self, name: str, field: str) -> np.ndarray:
        v = self.vars.get(name)
        if v is None:
            raise InputFileError(f'{self.path}: no variable {name!r} for '
                                 f'--{field.replace("_", "-")} (variables: '
                                 f'{", ".join(sorted(self.vars))})')
        if v.dtype == object:
            raise InputFileError(f'{self.path}: variable {name!r} is a cell array/struct '
                                 f'{v.shape}; export one numeric matrix per trial')
        if not np.issubdtype(v.dtype, np.number):
            raise InputFileError(f'{self.path}: variable {name!r} is not numeric')
        v = np.asarray(v, dtype=float)
        if v.ndim == 2 and min(v.shape) == 1:
            return v.reshape(1, -1)        # a vector, whichever way it was saved
        if v.ndim != 2:
            raise InputFileError(f'{self.path}: variable {name!r} has {v.ndim} dimensions')
        rows = (v.shape[0] <= v.shape[1]) if self.orient == 'auto' else self.orient == 'rows'
        return v if rows else v.T          # one signal per row

    def column(self, spec: str, field: str) -> np.ndarray:
        m = re.fullmatch(r'\s*([A-Za-z_]\w*)?\s*(?:[:\[(]\s*(\d+)\s*[\])]?)?\s*', spec)
        if re.fullmatch(r'\s*\d+\s*', spec):     # a bare index: the only 2-D variable
            mats = [k for k, v in self.vars.items() if v.dtype != object and v.ndim == 2
                    and min(v.shape) > 1]
            if len(mats) != 1:
                raise InputFileError(f'{self.path}: index {spec.strip()} is ambiguous; '
                                     'write VAR:INDEX (variables: '
                                     f'{", ".join(sorted(self.vars))})')
            name, idx = mats[0], int(spec)
        elif m and m.group(1):
            name, idx = m.group(1), (int(m.group(2)) if m.group(2) else None)
        else:
            raise InputFileError(f'{self.path}: bad column {spec!r} for '
                                 f'--{field.replace("_", "-")} (use VAR, VAR:INDEX or INDEX)')
        sig = self._signals(name, field)
        if idx is None:
            if sig.shape[0] != 1:
                raise InputFileError(f'{self.path}: variable {name!r} holds {sig.shape[0]} '
                                     f'signals; select one with {name}:INDEX')
            return sig[0]
        if idx >= sig.shape[0]:
            raise InputFileError(f'{self.path}: {name}:{idx} out of range '
                                 f'({name} holds {sig.shape[0]} signals)')
        return sig[idx]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def import_table(path: str | Path, *, time: str, input: str, position: str,
                 reference: str | None = None, velocity: str | None = None,
                 reference_velocity: str | None = None, effort: str | None = None,
                 time_scale: float = 1.0, time_offset: float = 0.0,
                 position_scale: float = 1.0, input_scale: float = 1.0,
                 velocity_scale: float | None = None, effort_scale: float = 1.0,
                 mat_orient: str = 'auto', name: str | None = None) -> Run:
    """Read selected columns of a CSV or .mat file into a :class:`Run` (SI units).

    Parameters
    ----------
    path : str or Path
        ``.csv`` / ``.tsv`` / ``.txt`` / ``.dat`` or ``.mat`` file.
    time, input, position : str
        Column specs (see the module docstring) of time, the input (voltage, current or
        force — whatever the model's ``input_gain`` converts) and measured position.
    reference, velocity, reference_velocity, effort : str, optional
        Further columns.
    time_scale, time_offset : float
        ``t = time_scale · column + time_offset`` [s].
    position_scale : float
        Metres per unit of the position and reference columns.
    input_scale, effort_scale : float
        Factors of the input and effort columns.
    velocity_scale : float, optional
        Factor of the velocity columns (default ``position_scale``).
    mat_orient : {'auto', 'rows', 'columns'}
        Layout of 2-D MAT variables.
    name : str, optional
        Run name (default: the file stem).

    Raises
    ------
    InputFileError
        Missing/unreadable file, unknown column, non-numeric cell, no usable rows.
    """
    path = Path(path)
    if not path.is_file():
        raise InputFileError(f'{path}: no such file')
    if path.stat().st_size == 0:
        raise InputFileError(f'{path}: empty file')
    scales = {'time': check_finite('time_scale', time_scale),
              'position': check_finite('position_scale', position_scale),
              'input': check_finite('input_scale', input_scale),
              'effort': check_finite('effort_scale', effort_scale)}
    scales['reference'] = scales['position']
    vs = scales['position'] if velocity_scale is None else check_finite('velocity_scale',
                                                                        velocity_scale)
    scales['velocity'] = scales['reference_velocity'] = vs
    offset = check_finite('time_offset', time_offset)
    if any(s == 0 for s in scales.values()):
        raise ParameterError('scales must be non-zero')
    suffix = path.suffix.lower()
    if suffix not in TEXT_SUFFIXES + ('.mat',):
        raise InputFileError(f'{path}: unsupported file type {suffix or "(no extension)"!r}; '
                             f'import reads delimited text ({", ".join(TEXT_SUFFIXES)}) '
                             'or MATLAB .mat (export other formats to CSV)')
    table: _Csv | _Mat = _Mat(path, mat_orient) if suffix == '.mat' else _Csv(path)
    specs = {'time': time, 'input': input, 'position': position, 'reference': reference,
             'velocity': velocity, 'reference_velocity': reference_velocity,
             'effort': effort}
    cols = {f: table.column(str(s), f) * scales[f] for f, s in specs.items() if s is not None}
    n = {c.shape[0] for c in cols.values()}
    if len(n) != 1:
        raise InputFileError(f'{path}: selected columns have different lengths '
                             f'{sorted(n)}')
    cols['time'] = cols['time'] + offset
    cols = _clean_rows(path, cols, specs)
    t = cols.pop('time')
    if t[0] < 0:
        raise InputFileError(f'{path}: time starts at {t[0]:g} s < 0; MCAP stamps are '
                             'unsigned — shift with --time-offset')
    meta: dict[str, str] = {'source': str(path)}
    meta.update({f'import.{f}': str(s) for f, s in specs.items() if s is not None})
    meta.update({'import.time_scale': repr(scales['time']), 'import.time_offset': repr(offset),
                 'import.position_scale': repr(scales['position']),
                 'import.input_scale': repr(scales['input'])})
    return Run(t=t, position=cols['position'], velocity=cols.get('velocity'),
               reference=cols.get('reference'),
               reference_velocity=cols.get('reference_velocity'), voltage=cols['input'],
               effort=cols.get('effort'), metadata=meta, name=name or path.stem)


def _clean_rows(path: Path, cols: Mapping[str, np.ndarray],
                specs: Mapping[str, str | None]) -> dict[str, np.ndarray]:
    ok = np.ones(next(iter(cols.values())).shape[0], bool)
    for f, c in cols.items():
        bad = ~np.isfinite(c)
        if bad.any():
            warn(f'{path.name}: {f} (column {specs[f]!r}): {int(bad.sum())} NaN/Inf '
                 'values; those rows dropped')
            ok &= ~bad
    out = {f: c[ok] for f, c in cols.items()}
    t = out['time']
    if t.size < 2:
        raise InputFileError(f'{path}: fewer than 2 usable rows')
    d = np.diff(t)
    if np.any(d <= 0):
        order = np.argsort(t, kind='stable')
        out = {f: c[order] for f, c in out.items()}
        t = out['time']
        keep = np.append(t[1:] != t[:-1], True)
        warn(f'{path.name}: time: {int(np.count_nonzero(d < 0))} out-of-order stamps '
             f'sorted, {int(keep.size - keep.sum())} duplicate stamps dropped (kept the last)')
        out = {f: c[keep] for f, c in out.items()}
    if not math.isfinite(float(out['time'][-1] - out['time'][0])):
        raise InputFileError(f'{path}: time column is not finite')
    return out
