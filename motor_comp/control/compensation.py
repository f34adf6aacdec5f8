"""Model-based compensation: a model file's effects as feedforward at the reference state.

A fitted model file (DESIGN.md §6) says which forces the axis fights.  The compensation
adds them to the command, evaluated at the **reference** state — position ``r``,
velocity ``ṙ``, and for the GMS pre-sliding elements a state driven by the reference
displacement, as the friction feedforward of Chiew et al. (Fig. 9) is — so measurement
noise never enters the feedforward.  In any controller mode the command becomes

    ``u = u_feedback + u_ff + F_comp(r, ṙ, z_ref) / input_gain``

where ``input_gain`` is the model file's own [N/V] (the force per command unit of the
drive the model was identified on).  Back-EMF and damping are affine in the velocity
and independent of the effects, so they do not enter the effect force; they stay the
feedback's business like the rigid-body dynamics.

One implementation of each law: the force is evaluated by the effect modules' own
compiled laws — sliding friction (Coulomb + Stribeck + viscous, and the GMS elements)
through :func:`~motor_comp.control.feedforward.friction_feedforward`, which calls
:func:`~motor_comp.physics.effects.stribeck.stribeck_curve` and
:func:`~motor_comp.physics.effects.presliding.gms_step`;
:func:`~motor_comp.physics.effects.asymmetry.asymmetry_force`,
:func:`~motor_comp.physics.effects.ripple.ripple_sum`,
:func:`~motor_comp.physics.effects.gravity.gravity_torque`; the offset and spring laws
``f0`` and ``k·(x − x0)`` are read exactly as the plant kernel reads them.

Effects a force feedforward cannot cancel are reported with the reason
(:data:`NOT_COMPENSABLE`): ``delay`` (a dead time delays the feedforward itself) and
``backlash`` (a gap in position, not a force).

A **position table** (``motor-comp export-table``) holds the position-dependent part
only — ripple/cogging, gravity, spring, offset — over one period (or revolution) when
the part is periodic; the controller interpolates it linearly (periodically wrapped, or
clamped to its ends).

Packed layout.  The compensation travels inside the controller's packed vectors so the
compiled step stays one function: parameters ``Q[qb:]`` (after the controller's own
``Q_SIZE`` entries) and state ``C[cb:]``; offsets ``K_*`` and ``CS_*`` below are
relative to those starts.
"""
from __future__ import annotations

import csv
import dataclasses
import enum
import io
import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.control._jitcache import JIT_INLINE, JIT_OPTIONS
from motor_comp.control.feedforward import friction_feedforward
from motor_comp.errors import InputFileError, ModelFileError, ParameterError, check_positive
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects.asymmetry import asymmetry_force
from motor_comp.physics.effects.gravity import gravity_torque
from motor_comp.physics.effects.presliding import MAX_ELEMENTS
from motor_comp.physics.effects.ripple import MAX_HARMONICS, ripple_sum

#: effects a force feedforward cannot cancel, with the reason shown to the user
NOT_COMPENSABLE: dict[str, str] = {
    'delay': 'a dead time delays the feedforward by the same time; it needs a predictor '
             '(e.g. Smith) or a reference advanced by tau, not a force',
    'backlash': 'a dead band is a gap in position between motor and load, not a force; '
                'a force feedforward cannot close it (it needs a position-domain inverse)',
}
#: effects the feedforward cancels
COMPENSABLE = ('coulomb', 'viscous', 'stribeck', 'presliding', 'ripple', 'offset',
               'spring', 'asymmetry', 'gravity')
#: the position-dependent effects a position table holds
POSITION_EFFECTS = ('ripple', 'gravity', 'spring', 'offset')
#: friction effects (the controller's own friction feedforward would count them twice)
FRICTION_EFFECTS = ('coulomb', 'viscous', 'stribeck', 'presliding', 'asymmetry')


class CompensationKind(enum.IntEnum):
    """What the packed block holds (``K_KIND``)."""

    MODEL = 1
    TABLE = 2


# ---- packed parameters, relative to the block start qb ---------------------------------
K_KIND, K_INVGAIN = 0, 1
K_FRIC, K_FC, K_FS, K_VS, K_DELTA, K_FV, K_DFC, K_DFV = 2, 3, 4, 5, 6, 7, 8, 9
K_GMS_N, K_GMS_C = 10, 11
K_GMS_ALPHA = 12
K_GMS_K = K_GMS_ALPHA + MAX_ELEMENTS
K_GMS_SIGMA = K_GMS_K + MAX_ELEMENTS      # GMS micro-damping [N·s/m]; K_GMS_C is C [N/s]
K_RIP_NH = K_GMS_SIGMA + MAX_ELEMENTS
K_RIP_PERIOD = K_RIP_NH + 1
K_RIP_A = K_RIP_PERIOD + 1
K_RIP_B = K_RIP_A + MAX_HARMONICS
K_F0 = K_RIP_B + MAX_HARMONICS
K_SPRING_K, K_SPRING_X0, K_GRAV_MGL, K_GRAV_Q0 = K_F0 + 1, K_F0 + 2, K_F0 + 3, K_F0 + 4
K_MODEL_SIZE = K_F0 + 5
# table: n points, period (0 = not periodic), then n positions and n forces
K_TAB_N, K_TAB_PERIOD, K_TAB_X = 2, 3, 4

# ---- state, relative to the block start cb -----------------------------------------------
CS_F, CS_U = 0, 1                      # last force [N] and command [V] of the compensation
CS_GMS_F = 2
CS_GMS_SLIP = CS_GMS_F + MAX_ELEMENTS
CS_SIZE = CS_GMS_SLIP + MAX_ELEMENTS


@njit(**JIT_INLINE)
def _table_force(Q, qb, x):
    """Linear interpolation of the table force [N] at ``x`` (wrapped or clamped)."""
    n = int(Q[qb + K_TAB_N])
    ix = qb + K_TAB_X
    iff = ix + n
    period = Q[qb + K_TAB_PERIOD]
    x0 = Q[ix]
    if period > 0.0:
        x = x0 + (x - x0) - period * np.floor((x - x0) / period)
    if x <= x0:
        return Q[iff]
    if x >= Q[ix + n - 1]:
        if period > 0.0:   # between the last point and the first one a period later
            x1 = Q[ix + n - 1]
            w = (x - x1) / (x0 + period - x1)
            return (1.0 - w) * Q[iff + n - 1] + w * Q[iff]
        return Q[iff + n - 1]
    lo = 0
    hi = n - 1
    while hi - lo > 1:     # bisection: a table may have any (increasing) spacing
        mid = (lo + hi) // 2
        if Q[ix + mid] <= x:
            lo = mid
        else:
            hi = mid
    w = (x - Q[ix + lo]) / (Q[ix + hi] - Q[ix + lo])
    return (1.0 - w) * Q[iff + lo] + w * Q[iff + hi]


@njit(**JIT_INLINE)
def compensation_force(Q, qb, C, cb, r, rv, dx, dt):
    """Compensation force [N] at the reference state; GMS elements in ``C`` stepped.

    Parameters
    ----------
    Q, qb : ndarray, int
        Packed parameters and the start of the compensation block.
    C, cb : ndarray, int
        Controller state and the start of the compensation state (updated in place).
    r, rv : float
        Reference position [m] (or [rad]) and velocity [m/s].
    dx : float
        Reference displacement since the previous control step [m] (drives the GMS).
    dt : float
        Control period [s].
    """
    kind = int(Q[qb + K_KIND])
    if kind == 2:
        return _table_force(Q, qb, r)
    f = 0.0
    mode = int(Q[qb + K_FRIC])
    if mode > 0:
        f_fric, _, _ = friction_feedforward(
            mode, rv, dx, dt, Q[qb + K_FC], Q[qb + K_FS], Q[qb + K_VS], Q[qb + K_DELTA],
            Q[qb + K_FV], C, cb + CS_GMS_F, cb + CS_GMS_SLIP, Q, qb + K_GMS_ALPHA,
            qb + K_GMS_K, qb + K_GMS_SIGMA, int(Q[qb + K_GMS_N]), Q[qb + K_GMS_C])
        f += f_fric
    if Q[qb + K_DFC] != 0.0 or Q[qb + K_DFV] != 0.0:
        f += asymmetry_force(rv, Q[qb + K_DFC], Q[qb + K_DFV])
    nh = int(Q[qb + K_RIP_NH])
    if nh > 0:
        f += ripple_sum(r, Q[qb + K_RIP_PERIOD], Q, qb + K_RIP_A, Q, qb + K_RIP_B, nh)
    f += Q[qb + K_F0] + Q[qb + K_SPRING_K] * (r - Q[qb + K_SPRING_X0])
    if Q[qb + K_GRAV_MGL] != 0.0:
        f += gravity_torque(r, Q[qb + K_GRAV_MGL], Q[qb + K_GRAV_Q0])
    return f


@njit(**JIT_INLINE)
def compensation_command(Q, qb, C, cb, r, rv, dx, dt):
    """Compensation command [V]: :func:`compensation_force` / the model's input gain.

    Zero when no compensation block follows the controller's parameters
    (``Q.shape[0] <= qb``).  The force and the command are kept in ``C[cb + CS_F]``,
    ``C[cb + CS_U]`` for drivers and diagnostics.
    """
    if Q.shape[0] <= qb:
        return 0.0
    f = compensation_force(Q, qb, C, cb, r, rv, dx, dt)
    u = f * Q[qb + K_INVGAIN]
    C[cb + CS_F] = f
    C[cb + CS_U] = u
    return u


@njit(**JIT_OPTIONS)
def _force_along(Q, C, r, rv, dt, out):
    """Compensation force along a reference (fresh GMS state at the first sample)."""
    for k in range(r.shape[0]):
        dx = r[k] - r[k - 1] if k > 0 else 0.0
        out[k] = compensation_force(Q, 0, C, 0, r[k], rv[k], dx, dt)


@dataclasses.dataclass(frozen=True)
class Compensation:
    """A packed compensation block and what it does.

    Attributes
    ----------
    kind : CompensationKind
        From a model file or from a position table.
    source : str
        File it came from.
    packed : ndarray
        Parameter block (layout ``K_*``), appended to the controller's parameters.
    input_gain : float
        Force per command unit [N/V] used for ``u = F/input_gain``.
    compensated : tuple of str
        Effects the feedforward cancels.
    not_compensated : Mapping[str, str]
        Effects of the model it cannot cancel, with the reason.
    units : Mapping[str, str]
        Position and force units (``m``/``N`` or ``rad``/``N·m``).
    """

    kind: CompensationKind
    source: str
    packed: np.ndarray
    input_gain: float
    compensated: tuple
    not_compensated: Mapping[str, str]
    units: Mapping[str, str]

    @property
    def has_friction(self) -> bool:
        """Whether it cancels friction (then the friction feedforward must be ``none``)."""
        return any(e in FRICTION_EFFECTS for e in self.compensated)

    def force_along(self, r: np.ndarray, rv: np.ndarray, dt: float) -> np.ndarray:
        """Force [N] the controller adds along a sampled reference (fresh state)."""
        r = np.ascontiguousarray(r, dtype=float)
        rv = np.ascontiguousarray(rv, dtype=float)
        if r.shape != rv.shape:
            raise ParameterError('reference position and velocity differ in length')
        out = np.empty(len(r))
        _force_along(self.packed, np.zeros(CS_SIZE), r, rv, float(dt), out)
        return out

    def describe(self) -> dict[str, Any]:
        """Plain-value summary (node logs, run metadata, JSON)."""
        return {'compensation': self.source, 'compensation_kind': self.kind.name.lower(),
                'compensated': list(self.compensated),
                'not_compensated': dict(self.not_compensated)}

    def summary(self) -> str:
        """One line: what is compensated and what is not (and why)."""
        text = (f'compensation from {self.source}: '
                f'{", ".join(self.compensated) or "nothing"}')
        for name, why in self.not_compensated.items():
            text += f'; {name} not compensated ({why})'
        return text


def _units(model: AxisModel) -> dict[str, str]:
    u = model.units
    return {'position': u.position, 'force': u.force}


def from_model(model: AxisModel, *, source: str = 'model') -> Compensation:
    """Pack the compensable effects of ``model`` (see module docstring)."""
    K = np.zeros(K_MODEL_SIZE)
    K[K_KIND] = float(CompensationKind.MODEL)
    K[K_INVGAIN] = 1.0 / model.input_gain
    names = model.names
    gms = model.get('presliding')
    if any(n in names for n in ('coulomb', 'stribeck', 'viscous', 'presliding')):
        K[K_FRIC] = 3.0 if gms is not None else 1.0
    fc, fs, vs, delta = model.stribeck_curve_params()
    K[K_FC], K[K_FS], K[K_VS], K[K_DELTA], K[K_FV] = fc, fs, vs, delta, model.fv
    if gms is not None:
        n = len(gms.alpha)
        K[K_GMS_N], K[K_GMS_C] = n, gms.C
        K[K_GMS_ALPHA:K_GMS_ALPHA + n] = gms.alpha
        K[K_GMS_K:K_GMS_K + n] = gms.k
        K[K_GMS_SIGMA:K_GMS_SIGMA + n] = gms.sigma
    asym = model.get('asymmetry')
    if asym is not None:
        K[K_DFC], K[K_DFV] = asym.dfc, asym.dfv
    rip = model.get('ripple')
    if rip is not None:
        nh = len(rip.harmonics)
        K[K_RIP_NH], K[K_RIP_PERIOD] = nh, rip.period
        K[K_RIP_A:K_RIP_A + nh] = rip.a
        K[K_RIP_B:K_RIP_B + nh] = rip.b
    off = model.get('offset')
    if off is not None:
        K[K_F0] = off.f0
    spr = model.get('spring')
    if spr is not None:
        K[K_SPRING_K], K[K_SPRING_X0] = spr.k, spr.x0
    grav = model.get('gravity')
    if grav is not None:
        K[K_GRAV_MGL], K[K_GRAV_Q0] = grav.mgl, grav.q0
    return Compensation(kind=CompensationKind.MODEL, source=source, packed=K,
                        input_gain=float(model.input_gain),
                        compensated=tuple(n for n in names if n in COMPENSABLE),
                        not_compensated={n: NOT_COMPENSABLE[n] for n in names
                                         if n in NOT_COMPENSABLE},
                        units=_units(model))


def load_model(path: str | Path) -> Compensation:
    """Compensation from a model YAML file (one-line :class:`ModelFileError` if bad)."""
    model = AxisModel.load(path)
    return from_model(model, source=str(path))


# ---- position tables -------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class PositionTable:
    """The position-dependent force of a model on a grid.

    Attributes
    ----------
    position : ndarray
        Grid [m] or [rad], increasing.
    force : ndarray
        Force [N] (torque [N·m]) to add at each position.
    command : ndarray
        The same in drive units, ``force / input_gain`` [V] (or [A], or [N]).
    period : float
        Period of the table [m]/[rad]; 0 when it is not periodic (clamped at its ends).
    input_gain : float
        Force per command unit of the model.
    units : Mapping[str, str]
        ``position``, ``force``, ``command`` unit strings.
    effects : tuple of str
        The effects the table holds.
    source : str
        Model file.
    """

    position: np.ndarray
    force: np.ndarray
    command: np.ndarray
    period: float
    input_gain: float
    units: Mapping[str, str]
    effects: tuple
    source: str


_COMMAND_UNIT = {'voltage': 'V', 'current': 'A', 'force': 'N'}


def table_period(model: AxisModel) -> float:
    """Period [m]/[rad] of the position-dependent part of ``model``, 0 if not periodic.

    Ripple alone: its period; gravity: one revolution (2π); both: one revolution when
    it holds a whole number of ripple periods.  A spring makes the part non-periodic.
    """
    if model.has('spring'):
        return 0.0
    rip, grav = model.get('ripple'), model.get('gravity')
    if grav is not None:
        if rip is not None:
            cycles = 2.0 * math.pi / rip.period
            if abs(cycles - round(cycles)) > 1e-6 * max(1.0, cycles):
                return 0.0
        return 2.0 * math.pi
    if rip is not None:
        return float(rip.period)
    return 0.0


def position_table(model: AxisModel, *, points: int = 1024,
                   span: tuple[float, float] | None = None,
                   source: str = 'model') -> PositionTable:
    """Tabulate the position-dependent effects of ``model`` (effects' own force laws).

    Parameters
    ----------
    points : int
        Grid points (>= 2).  A periodic table covers ``[0, period)`` (the point at
        ``period`` would repeat the first); otherwise ``span`` inclusive.
    span : (float, float), optional
        ``(x_min, x_max)`` [m]/[rad]; required when the part is not periodic (spring, or
        ripple and gravity that do not share a revolution); with a periodic part it
        replaces the one-period grid.
    """
    if not isinstance(points, (int, np.integer)) or isinstance(points, bool) or points < 2:
        raise ParameterError(f'--points must be an integer >= 2, got {points!r}')
    effects = tuple(n for n in model.names if n in POSITION_EFFECTS)
    if not effects:
        raise ParameterError(f'{source}: the model has no position-dependent effect '
                             f'({", ".join(POSITION_EFFECTS)}); nothing to tabulate')
    period = table_period(model)
    if span is not None:
        lo, hi = (float(s) for s in span)
        if not (math.isfinite(lo) and math.isfinite(hi) and hi > lo):
            raise ParameterError(f'--range must be two finite numbers MIN < MAX, got {span}')
        x = np.linspace(lo, hi, points)
        period = 0.0
    elif period > 0.0:
        x = np.arange(points) * (period / points)
    else:
        raise ParameterError(f'{source}: the position-dependent part '
                             f'({", ".join(effects)}) is not periodic; give the travel '
                             f'with --range MIN MAX')
    f = np.zeros(points)
    for name in effects:
        f += model.get(name).force(x, np.zeros(points))
    units = dict(_units(model))
    units['command'] = _COMMAND_UNIT[model.input.value]
    return PositionTable(position=x, force=f, command=f / model.input_gain, period=period,
                         input_gain=float(model.input_gain), units=units, effects=effects,
                         source=source)


def write_table(path: str | Path, table: PositionTable) -> None:
    """Write ``table`` as CSV with a ``#`` header stating units, period and source."""
    u = table.units
    lines = [
        '# motor-comp compensation table: position-dependent force to ADD to the command',
        f'# source_model: {table.source}',
        f'# effects: {" ".join(table.effects)}',
        f'# period: {table.period!r}' + ('  (0 = not periodic: clamped at both ends)'
                                         if table.period == 0.0 else
                                         f' {u["position"]} (wrapped)'),
        f'# input_gain: {table.input_gain!r} {u["force"]}/{u["command"]}',
        f'# units: position [{u["position"]}], force [{u["force"]}], '
        f'command [{u["command"]}] = force / input_gain',
    ]
    buf = io.StringIO()
    buf.write('\n'.join(lines) + '\n')
    w = csv.writer(buf, lineterminator='\n')
    w.writerow([f'position_{u["position"]}', f'force_{u["force"]}',
                f'command_{u["command"]}'])
    for x, f, c in zip(table.position, table.force, table.command):
        w.writerow([repr(float(x)), repr(float(f)), repr(float(c))])
    Path(path).write_text(buf.getvalue(), encoding='utf-8')


def read_table(path: str | Path) -> PositionTable:
    """Read a table written by :func:`write_table` (one-line error naming the problem)."""
    path = Path(path)
    try:
        text = path.read_text(encoding='utf-8')
    except FileNotFoundError:
        raise InputFileError(f'{path}: no such compensation table') from None
    except IsADirectoryError:
        raise InputFileError(f'{path}: is a directory, expected a table CSV') from None
    except (OSError, UnicodeDecodeError) as exc:
        raise InputFileError(f'{path}: cannot read compensation table ({exc})') from None
    return table_from_text(text, source=str(path))


def table_from_text(text: str, *, source: str = 'table') -> PositionTable:
    """Parse the text of a table CSV (already read); errors name ``source``.

    The entry point for text read under rules of its own (``controller_node`` reads the
    file ``compensation_table`` names with :mod:`motor_comp.param_files`).
    """
    path = source
    header: dict[str, str] = {}
    rows: list[list[str]] = []
    for i, line in enumerate(text.splitlines(), 1):
        if not line.strip():
            continue
        if line.startswith('#'):
            key, sep, value = line[1:].partition(':')
            if sep:
                header[key.strip()] = value.strip()
            continue
        rows.append([c.strip() for c in line.split(',')])
    if not rows:
        raise ModelFileError(f'{path}: empty compensation table')
    names = rows[0]
    if len(names) != 3 or not names[0].startswith('position') \
            or not names[1].startswith('force') or not names[2].startswith('command'):
        raise ModelFileError(f'{path}: expected columns position, force, command '
                             f'(motor-comp export-table), got {",".join(names)!r}')
    if any(len(r) != 3 for r in rows[1:]):
        bad = next(i for i, r in enumerate(rows[1:], 2) if len(r) != 3)
        raise ModelFileError(f'{path}: row {bad} does not have 3 columns')
    try:
        data = np.array([[float(c) for c in r] for r in rows[1:]], dtype=float)
    except ValueError as exc:
        raise ModelFileError(f'{path}: non-numeric value in the table ({exc})') from None
    if data.shape[0] < 2:
        raise ModelFileError(f'{path}: a table needs at least 2 rows, got {data.shape[0]}')
    if not np.all(np.isfinite(data)):
        raise ModelFileError(f'{path}: non-finite value in the table')
    x, f, c = data[:, 0], data[:, 1], data[:, 2]
    if np.any(np.diff(x) <= 0):
        raise ModelFileError(f'{path}: positions must be strictly increasing')
    try:
        period = float(header.get('period', '0').split()[0])
    except (ValueError, IndexError):
        raise ModelFileError(f'{path}: header period is not a number') from None
    if not (math.isfinite(period) and period >= 0.0):
        raise ModelFileError(f'{path}: header period must be >= 0, got {period!r}')
    if period > 0.0 and x[-1] - x[0] >= period:
        raise ModelFileError(f'{path}: positions span {x[-1] - x[0]:g}, more than one '
                             f'period ({period:g})')
    gain_text = header.get('input_gain')
    if gain_text is not None:
        try:
            gain = check_positive('input_gain', gain_text.split()[0])
        except (ParameterError, IndexError):
            raise ModelFileError(f'{path}: header input_gain must be a number > 0, got '
                                 f'{gain_text!r}') from None
    else:   # a hand-made table: the ratio of its own columns
        nz = np.abs(c) > 0
        if not np.any(nz):
            raise ModelFileError(f'{path}: no input_gain in the header and no non-zero '
                                 f'command to infer it from')
        gain = float(np.median(f[nz] / c[nz]))
        if not gain > 0:
            raise ModelFileError(f'{path}: force/command ratio is not positive')
    pos_unit = names[0].partition('_')[2] or 'm'
    force_unit = names[1].partition('_')[2] or 'N'
    cmd_unit = names[2].partition('_')[2] or 'V'
    return PositionTable(position=x, force=f, command=c, period=period, input_gain=gain,
                         units={'position': pos_unit, 'force': force_unit,
                                'command': cmd_unit},
                         effects=tuple(header.get('effects', '').split()),
                         source=header.get('source_model', source))


def from_table(table: PositionTable, *, source: str = 'table') -> Compensation:
    """Pack a position table for the controller (linear interpolation)."""
    n = len(table.position)
    K = np.zeros(K_TAB_X + 2 * n)
    K[K_KIND] = float(CompensationKind.TABLE)
    K[K_INVGAIN] = 1.0 / table.input_gain
    K[K_TAB_N] = n
    K[K_TAB_PERIOD] = table.period
    K[K_TAB_X:K_TAB_X + n] = table.position
    K[K_TAB_X + n:] = table.force
    return Compensation(kind=CompensationKind.TABLE, source=source, packed=K,
                        input_gain=float(table.input_gain),
                        compensated=table.effects or ('position table',),
                        not_compensated={}, units=dict(table.units))


def load_table(path: str | Path) -> Compensation:
    """Compensation from a table CSV (:func:`read_table`)."""
    return from_table(read_table(path), source=str(path))


def load(path: str | Path) -> Compensation:
    """Load a model YAML or a table CSV, by its suffix."""
    if Path(path).suffix.lower() == '.csv':
        return load_table(path)
    return load_model(path)


__all__ = ['COMPENSABLE', 'NOT_COMPENSABLE', 'POSITION_EFFECTS', 'Compensation',
           'CompensationKind', 'PositionTable', 'compensation_command',
           'compensation_force', 'from_model', 'from_table', 'load', 'load_model',
           'load_table', 'position_table', 'read_table', 'table_from_text', 'table_period',
           'write_table']
