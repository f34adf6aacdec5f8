"""Live model health: the force residual of a model over a sliding window of a run.

The core of ``monitor_node`` (no rclpy here): a window of measured position and drive
input goes through the workbench's own inverse model
(:func:`motor_comp.workbench.residual.residual` on
:func:`motor_comp.workbench.derivatives.kinematics`), giving the windowed force NRMSE
``RMS(r)/RMS(F_in − mean)`` (DESIGN.md §6) and the RMS residual [N] over the sliding
samples.  The level is OK / WARN / ERROR by two thresholds on the NRMSE.

When the residual is large, a cheap on-line version of ``diagnose`` names the effect
that would explain it: the residual is regressed, one candidate at a time, on the
effects' own regressor columns (:meth:`Effect.regressors`, smoothed like the residual)
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
from typing import Any

import numpy as np

from motor_comp.errors import ParameterError
from motor_comp.logs.run import Run
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects import Coulomb, Offset, Ripple, Spring, Stribeck, Viscous
from motor_comp.workbench.derivatives import kinematics
from motor_comp.workbench.residual import force_nrmse, residual
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


def _columns(model: AxisModel, res: Any, kin: Any) -> dict[str, tuple[np.ndarray, list]]:
    """Smoothed regressor columns of each candidate and the names of its parameters."""
    x, v = res.x, res.v
    out: dict[str, tuple[np.ndarray, list]] = {
        'coulomb': (kin.smooth(Coulomb().regressors(x, v)), ['fc']),
        'viscous': (kin.smooth(Viscous().regressors(x, v)), ['fv']),
        'offset': (Offset().regressors(x), ['f0']),
        'spring': (kin.smooth(Spring().regressors(x)[:, :1]), ['k']),
        'mass': (res.a[:, None], ['mass']),
    }
    st = model.get('stribeck')
    if st is not None:
        out['stribeck'] = (kin.smooth(st.regressors(x, v)), ['fs'])
    elif model.has('coulomb'):
        out['stribeck'] = (kin.smooth(Stribeck(vs=0.1 * max(np.max(np.abs(v)), 1e-6),
                                               delta=2.0).regressors(x, v)), ['fs'])
    rip = model.get('ripple')
    if rip is not None:
        cols = kin.smooth(Ripple(period=rip.period,
                                 harmonics=rip.harmonics).regressors(x, v))
        out['ripple'] = (cols, [f'{ab}{h + 1}' for h in range(cols.shape[1] // 2)
                                for ab in 'ab'])
    return out


def explain(model: AxisModel, res: Any, kin: Any) -> Candidate | None:
    """Return the candidate removing most of the residual after its parameter price."""
    m = res.mask
    r = res.r[m]
    sse0 = float(r @ r)
    n = int(m.sum())
    if sse0 <= 0 or n < 10:
        return None
    n_eff = max(n / max(kin.window, 1), 2.0)
    best: tuple[float, Candidate] | None = None
    for name, (cols, keys) in _columns(model, res, kin).items():
        a = cols[m]
        theta, *_ = np.linalg.lstsq(a, r, rcond=None)
        d = r - a @ theta
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
    kin = kinematics(run, window_s=smoothing_s, hold=default_hold(model))
    res = residual(kin, model)
    m = res.mask
    if int(m.sum()) < min_samples:
        return stale
    nrmse = force_nrmse(res.r[m], res.f_in[m])
    rms = float(np.sqrt(np.mean(res.r[m] ** 2)))
    level = Level.OK if nrmse < warn else Level.WARN if nrmse < error else Level.ERROR
    unit = model.units.force
    cand = explain(model, res, kin) if level is not Level.OK else None
    text = f'force NRMSE {100 * nrmse:.1f} % (RMS residual {rms:.3g} {unit})'
    if level is Level.OK:
        msg = f'model explains the axis: {text}'
    else:
        msg = f'model no longer explains the axis: {text}'
        if cand is not None:
            msg += f'; candidate: {cand.sentence()}'
    return Health(level, nrmse, rms, int(m.sum()), duration, cand, msg)
