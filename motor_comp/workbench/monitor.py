"""Live model health: the force residual of a model over a sliding window of a run.

The core of ``monitor_node`` (no rclpy here): a window of measured position and drive
input goes through the workbench's one processing and inverse model
(:mod:`motor_comp.workbench.dataset`, :mod:`motor_comp.workbench.library`), giving the
windowed force NRMSE ``RMS(r)/RMS(F_in − mean)`` (DESIGN.md §6) — the figure
``compare`` and ``diagnose`` report for the same data — and the RMS residual [N].
The level is OK / WARN / ERROR by two thresholds on the NRMSE.

When the residual is large, a cheap on-line version of ``diagnose`` names the effect
that would explain it: the residual is regressed, one candidate at a time, on the
effects' own term columns (the same processing as the residual)
— Coulomb, viscous, Stribeck (with the model's shape), offset, spring, ripple (at the
model's period), mass — and the candidate removing the largest share of the residual,
after a price per parameter (BIC-like, on the window's independent samples), is named.
An effect the model already has is reported as *changed* (with the change of its
level, e.g. ``fc +9.8 N``), an absent one as *missing*.  It is a screening, not a fit:
no nonlinear search (period, Stribeck velocity, delay…), which ``motor-comp diagnose``
does offline.
"""
from __future__ import annotations

import dataclasses
import enum
import math

import numpy as np

from motor_comp.errors import MotorCompError, ParameterError
from motor_comp.logs.run import Run
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import TERMS, EffectKind
from motor_comp.physics.effects.identification import Signal
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.derivatives import kinematics
from motor_comp.workbench.library import context, dataset_for, design, spec_of, theta_of
from motor_comp.workbench.session import default_hold


class Level(enum.IntEnum):
    """Health level (the values of ``diagnostic_msgs/DiagnosticStatus``)."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


TITLES = {'coulomb': 'Coulomb friction', 'viscous': 'viscous friction',
          'stribeck': 'Stribeck friction', 'offset': 'constant force offset',
          'spring': 'spring (position-proportional force)', 'ripple': 'force ripple',
          'mass': 'mass/inertia'}


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
        return TITLES.get(self.effect, self.effect)

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
    """

    level: Level
    nrmse: float
    rms_residual: float
    samples: int
    duration: float
    candidate: Candidate | None
    message: str


def check_thresholds(warn: float, error: float) -> None:
    """Raise :class:`ParameterError` unless ``0 < warn < error``."""
    if not (math.isfinite(warn) and math.isfinite(error) and 0 < warn < error):
        raise ParameterError(f'NRMSE thresholds must satisfy 0 < warn_nrmse < error_nrmse, '
                             f'got warn {warn:g}, error {error:g}')


def _columns(model: AxisModel, data: Dataset) -> dict[str, tuple[np.ndarray, list]]:
    """Return each screened candidate's columns at the rows (the one processing) and names.

    The terms without nonlinear parameters, the model's own nonlinear terms at their
    parameters, a Stribeck curve at a tenth of the peak speed when the model has none,
    and the mass.
    """
    view = data.at()
    out: dict[str, tuple[np.ndarray, list]] = {
        'mass': (view.signal(Signal.ACCELERATION)[:, None], ['mass'])}
    base = spec_of(model)
    for name, t in TERMS.items():
        if t.kind is not EffectKind.FORCE or t.applicable(data.summary) is not None:
            continue
        if t.params and name not in model.names:
            if name != 'stribeck' or not model.has('coulomb'):
                continue
            eta = {'vs': 0.1 * max(data.summary.speeds[95], 1e-6), 'delta': 2.0}
        else:
            eta = base.of(name)
        spec = base.with_(name, eta)
        cols = [c for c in t.columns(eta, context(spec, data))]
        if not cols:
            continue
        out[name] = (np.column_stack(view.columns(cols)), [c.label for c in cols])
    return out


def explain(model: AxisModel, data: Dataset, r: np.ndarray) -> Candidate | None:
    """Return the candidate removing most of the residual ``r`` after its parameter price."""
    sse0 = float(r @ r)
    n = len(r)
    if sse0 <= 0 or n < 10:
        return None
    n_eff = max(data.n_eff, 2.0)
    best: tuple[float, Candidate] | None = None
    for name, (cols, keys) in _columns(model, data).items():
        theta, *_ = np.linalg.lstsq(cols, r, rcond=None)
        d = r - cols @ theta
        explained = 1.0 - float(d @ d) / sse0
        score = explained - len(keys) * math.log(n_eff) / n_eff
        present = model.has(name) or (name == 'mass')
        cand = Candidate(effect=name, status='changed' if present else 'missing',
                         explained=max(explained, 0.0),
                         change={k: float(t) for k, t in zip(keys, theta)})
        if best is None or score > best[0]:
            best = (score, cand)
    return best[1] if best is not None and best[1].explained > 0 else None


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
    spec = spec_of(model)
    d = design(data, spec, model)
    r = d.y - d.X @ theta_of(model, spec, d.ctx)
    nrmse = math.sqrt(float(r @ r) / data.den) if data.den > 0 else float('inf')
    rms = float(np.sqrt(np.mean(r ** 2)))
    level = Level.OK if nrmse < warn else Level.WARN if nrmse < error else Level.ERROR
    unit = model.units.force
    cand = explain(model, data, r) if level is not Level.OK else None
    text = f'force NRMSE {100 * nrmse:.1f} % (RMS residual {rms:.3g} {unit})'
    if level is Level.OK:
        msg = f'model explains the axis: {text}'
    else:
        msg = f'model no longer explains the axis: {text}'
        if cand is not None:
            msg += f'; candidate: {cand.sentence()}'
    return Health(level, nrmse, rms, n_fit, duration, cand, msg)
