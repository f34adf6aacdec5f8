"""How well does a model explain a measured run?  In force and in position.

* Force: the inverse-model residual (:mod:`.residual`), as NRMSE and fit %
  (``100·(1 − NRMSE)``, the MATLAB ``compare`` convention).
* Position, k-step prediction: from the measured state at many origins, the model is
  simulated ``horizon`` seconds ahead with the *measured* input by the compiled plant
  kernel (:func:`motor_comp.physics.kernel.plant_advance`, the same law as the
  simulator), and the predicted position is compared with the measurement.  This works
  for closed-loop runs, where an open-loop simulation would drift away (an integrating
  plant with friction), and it shows the error in micrometres.  Fit % is computed on the
  displacement over the horizon (the position itself would give a meaningless ~100 %).
  Every history-dependent state starts each window from the measurement (DESIGN.md §6):
  the GMS element forces and phases from the element law run along the measured path
  up to the origin, the motor position across a backlash gap reconstructed from the
  load, the dead-time buffer from the commands before the origin — so a true
  hysteretic model predicts best (started with virgin elements, the ball-screw's own
  plant model predicted its default run worse than the same model without GMS).
* Position, closed-loop replay: when the run was produced by this project's
  simulator (its metadata names the plant, controller and trajectory), the same loop is
  re-run with the model as plant and the tracking errors are compared.
"""
from __future__ import annotations

import ast
import dataclasses
import math
from typing import Any, Mapping

import numpy as np

from motor_comp.errors import MotorCompError
from motor_comp.logs.run import Run
from motor_comp.physics.axis import AxisModel
from motor_comp.workbench.anchored import anchor, kstep
from motor_comp.workbench.floor import noise_floor
from motor_comp.workbench.library import dataset_for
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.residual import Residual, residual


@dataclasses.dataclass(frozen=True)
class Prediction:
    """k-step-ahead position prediction along a run.

    Parameters
    ----------
    horizon : float
        Prediction horizon [s].
    t : ndarray
        Times of the predicted samples [s].
    predicted, measured : ndarray
        Positions [m] at those times.
    rms_error, max_error : float
        Prediction error [m].
    fit_percent : float
        ``100·(1 − ‖y − ŷ‖/‖Δy − mean Δy‖)`` on the displacement over the horizon.
    """

    horizon: float
    t: np.ndarray
    predicted: np.ndarray
    measured: np.ndarray
    rms_error: float
    max_error: float
    fit_percent: float

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {'horizon': self.horizon, 'rms_error': self.rms_error,
                'max_error': self.max_error, 'fit_percent': self.fit_percent,
                'n_predictions': int(len(self.t))}


@dataclasses.dataclass(frozen=True)
class Replay:
    """Closed-loop replay of a simulated run with another plant model."""

    rms_difference: float     #: RMS(x_model − x_measured) [m]
    rms_error_measured: float  #: RMS tracking error of the run [m]
    rms_error_model: float    #: RMS tracking error of the replay [m]
    t: np.ndarray
    position: np.ndarray

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {'rms_difference': self.rms_difference,
                'rms_error_measured': self.rms_error_measured,
                'rms_error_model': self.rms_error_model}


@dataclasses.dataclass(frozen=True)
class Comparison:
    """Model against measurement: force residual, prediction, optional replay."""

    model: AxisModel
    kin: Kinematics
    residual: Residual
    force_nrmse: float
    prediction: Prediction
    replay: Replay | None
    replay_note: str
    rms_residual: float = float('nan')
    rms_drive: float = float('nan')
    noise_floor: float = float('nan')

    @property
    def force_fit_percent(self) -> float:
        """``100·(1 − force NRMSE)``."""
        return 100.0 * (1.0 - self.force_nrmse)

    def summary(self, *, rotary: bool = False) -> str:
        """Plain text for the terminal (``rotary``: positions are angles, shown in mrad)."""
        unit, k = ('mrad', 1e3) if rotary else ('µm', 1e6)
        p = self.prediction
        lines = [
            f'run {self.kin.name}: {len(self.kin)} samples at {1 / self.kin.dt:.0f} Hz'
            + (' (resampled from irregular stamps)' if self.kin.resampled else ''),
            f'force: NRMSE {100 * self.force_nrmse:.2f} % (fit {self.force_fit_percent:.1f} %; '
            f'noise floor {100 * self.noise_floor:.2f} %),'
            f' RMS residual {self.rms_residual:.3g} {self.model.units.force} of RMS drive '
            f'force {self.rms_drive:.3g} {self.model.units.force}',
            f'position, {1e3 * p.horizon:.0f} ms-ahead prediction: RMS error '
            f'{k * p.rms_error:.2f} {unit}, max {k * p.max_error:.2f} {unit} '
            f'(fit {p.fit_percent:.1f} % of the displacement)',
        ]
        if self.replay is not None:
            r = self.replay
            lines.append(f'closed-loop replay: RMS position difference '
                         f'{k * r.rms_difference:.2f} {unit}; tracking error RMS measured '
                         f'{k * r.rms_error_measured:.2f} {unit} vs model '
                         f'{k * r.rms_error_model:.2f} {unit}')
        else:
            lines.append(f'closed-loop replay: {self.replay_note}')
        return '\n'.join(lines)

    def as_dict(self) -> dict[str, Any]:
        """JSON form."""
        return {
            'run': self.kin.name,
            'force_nrmse': float(self.force_nrmse),
            'force_fit_percent': float(self.force_fit_percent),
            'noise_floor_nrmse': float(self.noise_floor),
            'rms_residual': float(self.rms_residual),
            'prediction': self.prediction.as_dict(),
            'replay': self.replay.as_dict() if self.replay is not None else None,
            'replay_note': self.replay_note,
            'model': self.model.to_dict(),
        }


def predict(kin: Kinematics, model: AxisModel, res: Any = None, *,
            horizon: float = 0.02, n_sub: int = 10, max_origins: int = 2000) -> Prediction:
    """Return the k-step-ahead position prediction (see the module docstring).

    Parameters
    ----------
    horizon : float
        Prediction horizon [s] (rounded to whole samples, at least one).
    n_sub : int
        Physics steps per sample.
    max_origins : int
        Upper bound on the number of prediction origins (evenly spread).  2000 windows
        of 20 ms cover a 20 s run twice over; more only repeat overlapping windows
        and cost every ``fit`` and ``compare`` their largest single item of CPU.
    """
    h = max(1, int(round(horizon / kin.dt)))
    n = len(kin)
    lo, hi = kin.window, n - h - kin.window
    if hi <= lo:
        raise MotorCompError(f'{kin.name}: run too short for a {horizon:g} s prediction')
    step = max(1, -(-(hi - lo) // max_origins))
    origins = np.arange(lo, hi, step, dtype=np.int64)
    pred = kstep(anchor(kin, model, n_sub=n_sub), origins, h)
    meas = kin.position[origins + h]
    err = meas - pred
    if not np.all(np.isfinite(err)):
        # an unstable model (e.g. a negative stiffness) diverges: report it, do not crash
        err = np.full_like(err, np.nan)
    disp = meas - kin.position[origins]
    den = float(np.linalg.norm(disp - disp.mean()))
    fit = 100.0 * (1.0 - float(np.linalg.norm(err)) / den) if den > 0 else float('nan')
    return Prediction(horizon=h * kin.dt, t=kin.t[origins + h], predicted=pred, measured=meas,
                      rms_error=float(np.sqrt(np.mean(err ** 2))),
                      max_error=float(np.max(np.abs(err))),
                      fit_percent=fit if np.isfinite(fit) else float('nan'))


def _literal(text: Any) -> Any:
    if not isinstance(text, str):
        return text
    try:
        return ast.literal_eval(text)
    except (ValueError, SyntaxError):
        return text


def _nominal_spec(text: Any) -> Any:
    """Factors of a recorded ``nominal of … (mass_factor=1.2, …)`` tag; None = default."""
    if not isinstance(text, str) or '(' not in text:
        return None
    from motor_comp.control.nominal import NominalSpec
    factors = {}
    for item in text[text.rfind('(') + 1:].rstrip(')').split(','):
        key, _, value = item.strip().partition('=')
        factors[key] = value
    try:
        return NominalSpec.preset('exact').replace(**factors)
    except MotorCompError:
        return None


def replay(run: Run, model: AxisModel) -> tuple[Replay | None, str]:
    """Re-run the closed loop recorded in ``run``'s metadata with ``model`` as the plant.

    Returns ``(None, reason)`` when the run does not say how it was produced.
    """
    meta: Mapping[str, Any] = run.metadata or {}
    needed = ('plant', 'controller', 'trajectory')
    missing = [k for k in needed if k not in meta]
    if missing:
        return None, f'not available (run metadata lacks {", ".join(missing)})'
    try:
        from motor_comp.control import simulator as sim_mod
        from motor_comp.control.controller import default_params, make_controller, \
            ControlMode
        from motor_comp.control.nominal import derive_nominal
        from motor_comp.control.trajectories import trajectory_from_dict
        from motor_comp.physics.config import load_plant
    except ImportError as exc:
        return None, f'not available (control package: {exc})'
    try:
        recorded = load_plant(str(meta['plant']))
        cfg = recorded.with_model(model)
        # the controller knew the recorded run's nominal model, not the candidate model
        nominal = derive_nominal(recorded, _nominal_spec(meta.get('nominal')))
        mode = ControlMode.parse(str(meta['controller']))
        names = set(default_params(mode, nominal).as_dict())
        params = {k: _literal(meta[k]) for k in names if k in meta}
        ff = str(meta.get('feedforward', 'none'))
        ctrl = make_controller(mode, plant=nominal, feedforward=ff, **params)
        traj = trajectory_from_dict(dict(_literal(meta['trajectory'])))
        duration = len(run) / float(_literal(meta.get('control_rate_hz', 1.0 / np.median(
            np.diff(run.t)))))
        out = sim_mod.simulate(cfg, ctrl, traj, duration=duration,
                               seed=int(_literal(meta.get('seed', 0))))
    except (MotorCompError, ValueError, TypeError, KeyError) as exc:
        return None, f'not available ({exc})'
    n = min(len(out.t), len(run))
    x_meas = run.position[:n]
    x_mod = out.position[:n]
    ref = run.reference[:n] if run.reference is not None else out.reference[:n]
    rep = Replay(rms_difference=float(np.sqrt(np.mean((x_mod - x_meas) ** 2))),
                 rms_error_measured=float(np.sqrt(np.mean((ref - x_meas) ** 2))),
                 rms_error_model=float(np.sqrt(np.mean((out.reference[:n] - x_mod) ** 2))),
                 t=run.t[:n], position=x_mod)
    return rep, 'ok'


def compare(run: Run, kin: Kinematics, model: AxisModel, *, horizon: float = 0.02,
            closed_loop: bool = True) -> Comparison:
    """Compare ``model`` with the run in force and position (see module docstring)."""
    data = dataset_for([kin], model)
    res = residual(kin, model, data=data)
    pred = predict(kin, model, horizon=horizon)
    rep, note = replay(run, model) if closed_loop else (None, 'not requested')
    return Comparison(model=model, kin=kin, residual=res, force_nrmse=res.force_nrmse,
                      prediction=pred, replay=rep, replay_note=note,
                      rms_residual=res.force_nrmse * math.sqrt(data.den / data.n),
                      rms_drive=math.sqrt(data.den / data.n),
                      noise_floor=noise_floor(data, model).nrmse)
