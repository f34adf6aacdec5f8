"""The inverse model: the force a model leaves unexplained along a measured run.

``r = S·F_in(u(t − τ)) − M·S·ẍ_m − Σ_k S·F_k(x_m, ẋ_m)`` (DESIGN.md §3 and §6), with the
one processing of :mod:`.processing` and each force the model's own term columns times
its coefficients (:mod:`.library`) — so the residual views, ``compare``, ``diagnose``,
``fit`` and ``monitor_node`` read the same numbers.  ``x_m`` is the measured (load)
position, or with ``backlash`` the motor position reconstructed from it.

The figures use every fitted sample; the force NRMSE (:attr:`Residual.force_nrmse`) is
the one every command reports: over the dataset's rows (every ``W/8``-th fitted
sample), ``RMS(r)/RMS(F_in − mean)``.  Samples where the axis is at rest are left out:
the friction of a stuck axis is whatever balances the drive.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np

from motor_comp.physics.axis import AxisModel
from motor_comp.physics.effects.identification import MASS, Signal
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.derivatives import Kinematics
from motor_comp.workbench.library import dataset_for, design, given_sse, processing_for, \
    spec_of, theta_of
from motor_comp.workbench.motion import motor_position, reversals
from motor_comp.workbench.processing import Processing, sliding_mask


@dataclasses.dataclass(frozen=True)
class Residual:
    """Force balance of a model along a run (all forces smoothed, [N]; NaN off the mask).

    Parameters
    ----------
    f_in : ndarray
        Smoothed drive force ``input_gain·(u − back_emf·ẋ) − damping·ẋ`` [N].
    inertia : ndarray
        ``M·ẍ_m`` [N].
    forces : dict[str, ndarray]
        Force of each effect [N].
    r : ndarray
        Residual force [N].
    x, v, a : ndarray
        Motor position, pointwise velocity and processed acceleration.
    mask : ndarray of bool
        The fitted samples (sliding, away from stops and the record's ends).
    force_nrmse : float
        The force NRMSE of the model on this run, as every command reports it.
    """

    f_in: np.ndarray
    inertia: np.ndarray
    forces: dict
    r: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    mask: np.ndarray
    force_nrmse: float = float('nan')

    def nrmse(self) -> float:
        """Return the force NRMSE (:attr:`force_nrmse`)."""
        return self.force_nrmse


def force_nrmse(r: np.ndarray, f_in: np.ndarray) -> float:
    """Return ``RMS(r)/RMS(F_in − mean(F_in))`` (DESIGN.md §6 ``force_nrmse``)."""
    den = float(np.sqrt(np.mean((f_in - np.mean(f_in)) ** 2)))
    num = float(np.sqrt(np.mean(r ** 2)))
    return num / den if den > 0 else float('inf')


def model_nrmse(data: Dataset, model: AxisModel) -> float:
    """Return the force NRMSE of ``model`` as given on ``data`` (no fitting)."""
    den = data.den
    return math.sqrt(given_sse(data, model) / den) if den > 0 else float('inf')


def residual(kin: Kinematics, model: AxisModel, *, data: Dataset | None = None) -> Residual:
    """Return the force residual of ``model`` along ``kin`` (see the module docstring).

    ``data`` is the run's dataset when the caller has one (its NRMSE is then not
    computed again).
    """
    spec = spec_of(model)
    data = data if data is not None else dataset_for([kin], model)
    full = Dataset([kin], model, processing=processing_for(spec, Processing(decimate=False)))
    d = design(full, spec, model)
    th = theta_of(model, spec, d.ctx)
    n = len(kin)
    rows = full.parts[0].rows

    def place(vals: np.ndarray) -> np.ndarray:
        out = np.full(n, np.nan)
        out[rows] = vals
        return out
    y = d.view.y()
    forces: dict[str, np.ndarray] = {}
    X = d.X
    for j, lab in enumerate(d.labels):
        if lab == MASS:
            continue
        forces[lab[0]] = forces.get(lab[0], 0.0) + X[:, j] * th[j]
    acc = d.view.signal(Signal.ACCELERATION)
    mass = float(th[d.labels.index(MASS)]) if MASS in d.labels else model.mass
    motion = d.view.motions[0]
    mask = np.zeros(n, dtype=bool)
    mask[rows] = True
    return Residual(f_in=place(y), inertia=place(mass * acc),
                    forces={k: place(v) for k, v in forces.items()},
                    r=place(d.y - X @ th), x=np.asarray(motion.x), v=np.asarray(motion.v),
                    a=place(acc), mask=mask, force_nrmse=model_nrmse(data, model))


__all__ = ['Residual', 'force_nrmse', 'model_nrmse', 'motor_position', 'residual',
           'reversals', 'sliding_mask']
