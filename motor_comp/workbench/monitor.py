"""Live model health: the force residual of a model over a sliding window of a run.

The core of ``monitor_node`` (no rclpy here): a window of measured position and drive
input goes through the workbench's one processing and inverse model
(:mod:`motor_comp.workbench.dataset`, :mod:`motor_comp.workbench.library`), giving the
windowed force NRMSE ``RMS(r)/RMS(F_in − mean)`` (DESIGN.md §6) — the figure
``compare`` and ``diagnose`` report for the same data — and the RMS residual [N].
The level is OK / WARN / ERROR by two thresholds on the NRMSE.

When the residual is large, a cheap on-line version of ``diagnose`` names the effect
that would explain it: the residual is regressed, one candidate at a
time, on the columns of every force term of the library (the same processing and
library as the residual; a term whose evidence needs other rows, on those) and on the
mass, and the candidate removing the largest share of the residual, after a price per
parameter (BIC-like, on the window's independent samples), is named.  A term the model
has is screened at its own nonlinear parameters, another at the starts it declares
(:meth:`~motor_comp.physics.effects.identification.Term.initial`, else the grid of
its search space); a term the window cannot judge (an input or output effect, too few
reversals, a needed term missing) is skipped with the reason.  An effect the model
already has is reported as *changed* (with the change of its level, e.g. ``fc +9.8 N``),
an absent one as *missing*.  It is a screening, not a fit: no local search of the
nonlinear parameters (period, Stribeck velocity, delay…), which ``motor-comp diagnose``
does offline.
"""
from __future__ import annotations

import dataclasses
import enum
import itertools
import math

import numpy as np

from motor_comp.errors import MotorCompError, ParameterError
from motor_comp.logs.run import Run
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import EFFECTS, TERMS, EffectKind
from motor_comp.physics.effects.identification import MASS, Signal, Summary, Term
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.derivatives import Kinematics, kinematics
from motor_comp.workbench.library import Design, Spec, context, dataset_for, design, \
    processing_for, spec_of, theta_of, values_of
from motor_comp.workbench.processing import Processing
from motor_comp.workbench.session import default_hold


class Level(enum.IntEnum):
    """Health level (the values of ``diagnostic_msgs/DiagnosticStatus``)."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


#: the candidate that is no effect of the vocabulary
MASS_TITLE = 'mass/inertia'


@dataclasses.dataclass(frozen=True)
class Candidate:
    """The effect that best explains a window's residual.

    Attributes
    ----------
    effect : str
        Vocabulary name (or ``mass``).
    status : str
        ``changed`` (the model has it, its level moved) or ``missing``.
    explained : float
        Fraction of the residual energy it removes in the window (0–1).
    change : dict[str, float]
        Fitted change of its linear parameters (SI; ``fc`` [N], ``fv`` [N·s/m], …).
    """

    effect: str
    status: str
    explained: float
    change: dict

    @property
    def title(self) -> str:
        """Human name, e.g. ``Coulomb friction``."""
        cls = EFFECTS.get(self.effect)
        return cls.title if cls is not None else MASS_TITLE

    def sentence(self) -> str:
        """E.g. ``Coulomb friction changed (fc +9.8), explains 85 % of the residual``."""
        ch = ', '.join(f'{k} {v:+.4g}' for k, v in self.change.items())
        return (f'{self.title} {self.status} ({ch}), explains '
                f'{100 * self.explained:.0f} % of the residual')


@dataclasses.dataclass(frozen=True)
class Health:
    """One window's verdict.

    Attributes
    ----------
    level : Level
        OK / WARN / ERROR by the NRMSE thresholds; STALE without enough motion.
    nrmse : float
        Force NRMSE over the window's sliding samples (NaN when STALE).
    rms_residual : float
        RMS force residual [N] (or [N·m]) over the sliding samples.
    samples : int
        Sliding samples used.
    duration : float
        Window length covered [s].
    candidate : Candidate or None
        The effect that would explain the residual (only when not OK).
    message : str
        One line for the diagnostic status.
    unscreened : tuple of (str, str)
        The library's effects the screen left out, with the reason (only when not OK).
    """

    level: Level
    nrmse: float
    rms_residual: float
    samples: int
    duration: float
    candidate: Candidate | None
    message: str
    unscreened: tuple = ()


def check_thresholds(warn: float, error: float) -> None:
    """Raise :class:`ParameterError` unless ``0 < warn < error``."""
    if not (math.isfinite(warn) and math.isfinite(error) and 0 < warn < error):
        raise ParameterError(f'NRMSE thresholds must satisfy 0 < warn_nrmse < error_nrmse, '
                             f'got warn {warn:g}, error {error:g}')


@dataclasses.dataclass(frozen=True)
class _Residual:
    """The model's force residual on one processing's rows, and what a screen needs of it."""

    data: Dataset
    design: Design
    r: np.ndarray
    values: dict
    x: np.ndarray


def _residual(data: Dataset, spec: Spec, model: AxisModel) -> _Residual:
    """Return ``model``'s residual on ``data`` (its own design, coefficients as given)."""
    d = design(data, spec, model)
    theta = theta_of(model, spec, d.ctx)
    return _Residual(data, d, d.y - d.X @ theta, values_of(spec, d.labels, theta),
                     d.view.gather(lambda p, mo: mo.x))


def _unscreenable(name: str, t: Term, spec: Spec, s: Summary) -> str | None:
    """Return why the window cannot screen term ``name`` against ``spec`` (None: it can).

    Only the terms' declarations are read: where the effect acts, what the run must
    show (:meth:`Term.applicable`) and what it needs beside it (``requires``,
    ``requires_any``, ``excludes``, as the selection reads them).
    """
    if t.kind is not EffectKind.FORCE:
        return (f'{name} acts on the {t.kind.value}, not as a force: it has no column to '
                f'screen (motor-comp diagnose searches it)')
    why = t.applicable(s)
    if why is not None:
        return why
    if name in spec.names:
        return None
    present = set(spec.names)
    missing = [r for r in t.requires if r not in present]
    if missing:
        return f'{name} is defined relative to {", ".join(missing)}, which the model lacks'
    if t.requires_any and not set(t.requires_any) & present:
        return f'{name} needs one of {", ".join(t.requires_any)} in the model'
    clash = sorted(set(t.excludes) & present
                   | {m for m in present if name in TERMS[m].excludes})
    if clash:
        return f'{name} cannot stand beside {", ".join(clash)} (two models of one phenomenon)'
    return None


def _starts(name: str, t: Term, spec: Spec, res: _Residual) -> list[dict] | str:
    """Return the nonlinear parameters to screen ``name`` at, or why there are none.

    A term of the model: its own.  Another: the term's starts from the residual
    (:meth:`Term.initial`, e.g. a ripple's spectral peak, a friction profile's knots),
    else the grid of its declared search space (:meth:`Term.space`), each completed
    from the model's coefficients (:meth:`Term.derive`) — what the search of
    ``motor-comp diagnose`` starts from, without its local refinement.
    """
    if name in spec.names:
        return [spec.of(name)]
    s = res.data.summary
    ctx = context(spec.with_(name, {}), res.data)
    starts = [dict(e) for e in t.initial(s, ctx, (res.x, res.r))]
    if not starts:
        space = t.space(s, ctx)
        bare = [p.name for p in space if not p.grid]
        if bare:
            return (f'{name} has no start for {", ".join(bare)} without a search '
                    f'(motor-comp diagnose searches it)')
        starts = [{p.name: tuple(v) if isinstance(v, tuple) else float(v)
                   for p, v in zip(space, combo)}
                  for combo in itertools.product(*[p.grid for p in space])]
    return [t.derive(e, res.values) for e in starts]


def _fit(cols: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, float]:
    """Return the least-squares coefficients of ``r`` on ``cols`` and the SSE left."""
    theta, *_ = np.linalg.lstsq(cols, r, rcond=None)
    d = r - cols @ theta
    return theta, float(d @ d)


def _screen(model: AxisModel, kin: Kinematics, base: _Residual) \
        -> tuple[Candidate | None, tuple[tuple[str, str], ...]]:
    """Return the candidate removing most of the model's residual, and the terms not screened.

    Every force term of the library is regressed, one at a time, on the residual of
    ``model`` over the rows of the processing the term is judged with
    (:func:`~motor_comp.workbench.library.processing_for`: pre-sliding's rows reach the
    stops) — the model's terms at their own nonlinear parameters (a *change*), the
    others at their declared starts (the best of them) — and so is the mass.  The
    score is the share of the residual energy removed minus a price per parameter
    (coefficients and chosen nonlinear parameters) of ``ln(n_eff)/n_eff``, BIC-like
    on the window's independent samples.

    Parameters
    ----------
    model : AxisModel
        The model under watch.
    kin : Kinematics
        The window's kinematics (for a term judged on other rows).
    base : _Residual
        The model's residual on the window's dataset (:func:`~.library.dataset_for`).

    Returns
    -------
    candidate : Candidate or None
        The best-scoring candidate (None when nothing removes any of the residual).
    skipped : tuple of (str, str)
        The library's terms the window cannot screen, with the reason.
    """
    spec = spec_of(model)
    data = base.data
    residuals: list[tuple[Processing, _Residual | str]] = [(data.processing, base)]
    skipped: list[tuple[str, str]] = []
    best: tuple[float, Candidate] | None = None

    #: each candidate's columns, residual and parameter count (for the nested check)
    kept: dict[int, tuple[_Residual, np.ndarray, int]] = {}

    def consider(name: str, res: _Residual, cols: np.ndarray, labels: list,
                 n_nonlinear: int) -> tuple[float, Candidate] | None:
        sse0 = float(res.r @ res.r)
        if sse0 <= 0 or len(res.r) < 10:
            return None
        theta, sse = _fit(cols, res.r)
        explained = 1.0 - sse / sse0
        score = explained - (len(labels) + n_nonlinear) * _price(res)
        present = name == MASS[0] or model.has(name)
        cand = Candidate(effect=name, status='changed' if present else 'missing',
                         explained=max(explained, 0.0),
                         change={k: float(v) for k, v in zip(labels, theta)})
        kept[id(cand)] = (res, cols, len(labels) + n_nonlinear)
        return score, cand

    def better(a: tuple[float, Candidate] | None, b: tuple[float, Candidate] | None) \
            -> tuple[float, Candidate] | None:
        return b if a is None or (b is not None and b[0] > a[0]) else a

    changed: list[tuple[float, Candidate]] = []
    view = base.design.view
    mass = consider(MASS[0], base, view.signal(Signal.ACCELERATION)[:, None], [MASS[1]], 0)
    best = better(best, mass)
    if mass is not None:
        changed.append(mass)
    for name, t in TERMS.items():
        why = _unscreenable(name, t, spec, data.summary)
        if why is not None:
            skipped.append((name, why))
            continue
        proc = processing_for(spec.with_(name, spec.of(name)))
        res = next((r for p, r in residuals if p == proc), None)
        if res is None:
            try:
                res = _residual(Dataset([kin], model, folds=2, processing=proc), spec, model)
            except MotorCompError as e:
                res = f'{name} is judged on other rows, too few in the window: {e}'
            residuals.append((proc, res))
        if isinstance(res, str):
            skipped.append((name, res))
            continue
        starts = _starts(name, t, spec, res)
        if isinstance(starts, str):
            skipped.append((name, starts))
            continue
        own = None
        for eta in starts:
            ctx = context(spec.with_(name, eta), res.data)
            cols = t.columns(eta, ctx)
            if not cols:
                continue
            X = np.column_stack(res.design.view.columns(cols, rests=res.design.ctx.rests))
            n_nl = 0 if name in spec.names else len(t.nonlinear(eta))
            own = better(own, consider(name, res, X, [c.label for c in cols], n_nl))
        if own is None and starts:
            skipped.append((name, f'{name} has no column at its start'))
        best = better(best, own)
        if own is not None and own[1].status == 'changed':
            changed.append(own)
    best = _prefer_change(best, changed, kept)
    cand = best[1] if best is not None and best[1].explained > 0 else None
    return cand, tuple(skipped)


def _price(res: _Residual) -> float:
    """Return the share of the residual one parameter must remove (BIC-like)."""
    n_eff = max(res.data.n_eff, 2.0)
    return math.log(n_eff) / n_eff


def _prefer_change(best: tuple[float, Candidate] | None,
                   changed: list[tuple[float, Candidate]], kept: dict) \
        -> tuple[float, Candidate] | None:
    """Name a change of the model's own term unless a new term explains more than it can.

    A level shift of friction is the Coulomb level changed, and also, nearly, a term
    the model lacks that contains a level (friction growing with the load while the
    load is steady, friction along a short stretch of travel): the screen's scores of
    the two are then within noise of each other.  The nested test decides: the new
    term is named only when, fitted together with the best change of the model's own
    terms on the same rows, it still removes more than its price per parameter.
    """
    if best is None or best[1].status != 'missing' or not changed:
        return best
    res_n, x_n, p_n = kept[id(best[1])]
    for score, cand in sorted(changed, key=lambda c: -c[0]):
        res_c, x_c, _ = kept[id(cand)]
        if res_c is not res_n:
            continue          # judged on other rows: no joint fit
        sse0 = float(res_n.r @ res_n.r)
        _, sse_c = _fit(x_c, res_n.r)
        _, sse_j = _fit(np.column_stack([x_c, x_n]), res_n.r)
        if (sse_c - sse_j) / sse0 < p_n * _price(res_n):
            return score, cand
        return best
    return best


def window_health(t: np.ndarray, position: np.ndarray, command: np.ndarray,
                  model: AxisModel, *, warn: float = 0.2, error: float = 0.5,
                  min_samples: int = 100, smoothing_s: float = 0.02) -> Health:
    """Judge ``model`` on one window of measured position [m] and drive input.

    Parameters
    ----------
    t : ndarray
        Sample times [s] (increasing; resampled to a uniform grid if irregular).
    position : ndarray
        Measured position [m] (or [rad]).
    command : ndarray
        Drive input in the model's input unit (V, A or N), held from each sample.
    model : AxisModel
        The model under watch.
    warn, error : float
        NRMSE thresholds of WARN and ERROR.
    min_samples : int
        Fewer sliding samples than this: STALE (the axis barely moved).
    smoothing_s : float
        Savitzky–Golay window of the derivatives [s] (the workbench's default).
    """
    check_thresholds(warn, error)
    t = np.asarray(t, dtype=float)
    duration = float(t[-1] - t[0]) if len(t) > 1 else 0.0
    stale = Health(Level.STALE, float('nan'), float('nan'), 0, duration, None,
                   'not enough motion in the window to judge the model')
    if len(t) < max(min_samples, 8 * max(int(round(smoothing_s / 1e-3)), 7)):
        return stale
    pos = np.asarray(position, dtype=float)
    steps = np.abs(np.diff(pos))
    quantum = float(np.min(steps[steps > 0])) if np.any(steps > 0) else 0.0
    if quantum == 0.0 or np.ptp(pos) < 20.0 * quantum:
        return stale   # at rest (or dithering by a few counts): friction holds, no model can
    run = Run(t=t - t[0], position=np.asarray(position, dtype=float),
              voltage=np.asarray(command, dtype=float), name='window')
    try:
        kin = kinematics(run, window_s=smoothing_s, hold=default_hold(model))
        data = dataset_for([kin], model, folds=2)
    except MotorCompError:
        return stale        # too short or too little motion for the processing
    n_fit = int(sum(np.count_nonzero(m) for m in data.masks))
    if n_fit < min_samples:
        return stale
    base = _residual(data, spec_of(model), model)
    r = base.r
    nrmse = math.sqrt(float(r @ r) / data.den) if data.den > 0 else float('inf')
    rms = float(np.sqrt(np.mean(r ** 2)))
    level = Level.OK if nrmse < warn else Level.WARN if nrmse < error else Level.ERROR
    unit = model.units.force
    cand, unscreened = _screen(model, kin, base) if level is not Level.OK else (None, ())
    text = f'force NRMSE {100 * nrmse:.1f} % (RMS residual {rms:.3g} {unit})'
    if level is Level.OK:
        msg = f'model explains the axis: {text}'
    else:
        msg = f'model no longer explains the axis: {text}'
        if cand is not None:
            msg += f'; candidate: {cand.sentence()}'
    return Health(level, nrmse, rms, n_fit, duration, cand, msg, unscreened)
