"""The noise floor: the force NRMSE a *perfect* model would leave on this run.

A model is complete only near what the measurement itself leaves (DESIGN.md §6,
``../shared/IDENTIFICATION.md`` §8).  Propagating the encoder's quantisation and noise
through the differentiation gives part of it; what the processing leaves at the turns
(a stick resolved between samples, a reversal smoothed over) is the rest, and on a run
with strong dry friction it is most of it.  So the floor here is measured the honest way:
the fitted model is run with the run's own input in windows re-anchored to the measured
state (:mod:`.anchored`), which gives a record the model explains exactly and that visits
the run's regimes (speeds, turns, rests); the sensor is applied to it (the run's encoder
quantum and its noise, both estimated from the run itself), it is processed exactly like
the measurement, and the model's force NRMSE on it is the floor — over the same rows,
less a smoother width after each window's start, where the re-anchoring joins.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from motor_comp.logs.run import Run
from motor_comp.physics.axis import AxisModel
from motor_comp.workbench.anchored import anchor, windows
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.derivatives import Kinematics, kinematics
from motor_comp.workbench.library import given_sse

#: window length of the anchored simulation, in smoother lengths: long enough that the
#: joins cost little of the run, short enough that the model stays near the measurement
WINDOW_SMOOTHERS = 12


@dataclasses.dataclass(frozen=True)
class Floor:
    """The noise floor of one run (or experiment) under one model.

    Attributes
    ----------
    nrmse : float
        Force NRMSE the model leaves on its own anchored runs with the run's sensor.
    sensor_nrmse : float
        The part the sensor alone leaves (the same anchored runs unquantised, noise-free,
        subtracted in quadrature; 0 when the processing leaves more than the sensor).
    noise : float
        Position noise σ estimated from the run [m or rad].
    quantum : float
        Encoder resolution estimated from the run [m or rad].
    rows : int
        Samples the floor is measured on.
    data : Dataset or None
        The anchored runs measured like the run (the structure scan compares with them).
    """

    nrmse: float
    sensor_nrmse: float
    noise: float
    quantum: float
    rows: int
    data: Any = dataclasses.field(default=None, repr=False, compare=False)

    def as_dict(self) -> dict:
        """Return the JSON form."""
        return {'noise_floor_nrmse': self.nrmse, 'sensor_nrmse': self.sensor_nrmse,
                'noise': self.noise, 'quantum': self.quantum, 'rows': self.rows}


def _sensor(kin: Kinematics) -> tuple[float, float]:
    """Return the white noise σ to add before quantising, and the quantum [m]."""
    q = kin.quantum()
    total = kin.noise_std()
    white = math.sqrt(max(total * total - q * q / 12.0, 0.0))
    return white, q


def _synthetic(kin: Kinematics, model: AxisModel, length: int, rng: np.random.Generator,
               sensor: bool) -> Kinematics:
    """Return the anchored run of ``model`` measured like ``kin`` (or ideally)."""
    a = anchor(kin, model)
    origins = np.arange(0, len(kin), length, dtype=np.int64)
    x = windows(a, origins)
    if sensor:
        white, q = _sensor(kin)
        if white > 0:
            x = x + rng.normal(0.0, white, len(x))
        if q > 0:
            x = q * np.round(x / q)
    if not np.all(np.isfinite(x)):
        raise FloatingPointError('the model diverges on its own run')
    run = Run(t=kin.t.copy(), position=x, voltage=kin.u.copy(), name=f'{kin.name} (floor)')
    return kinematics(run, window_s=kin.window * kin.dt, polyorder=kin.polyorder,
                      hold=kin.hold)


def noise_floor(data: Dataset, model: AxisModel, *, seed: int = 0,
                sensor_share: bool = True) -> Floor:
    """Return the noise floor of ``model`` on ``data``'s runs (see the module docstring).

    ``sensor_share=False`` leaves out the noise-free twin that splits off the sensor's
    part (:attr:`Floor.sensor_nrmse` is then NaN): the selection needs the floor only.
    """
    rng = np.random.default_rng(seed)
    kins, ideal, masks = [], [], []
    for part, mask in zip(data.parts, data.masks):
        kin = part.kin
        length = max(WINDOW_SMOOTHERS * part.W, 50)
        try:
            syn = _synthetic(kin, model, length, rng, True)
            clean = _synthetic(kin, model, length, rng, False) if sensor_share else None
        except (FloatingPointError, ValueError):
            return Floor(float('nan'), float('nan'), kin.noise_std(), kin.quantum(), 0)
        # rows the processing fits on both the run and its twin: a wrong model's twin
        # does not stop where the axis stopped, and its rows next to its own stops are
        # what the processing leaves out (a Coulomb model's twin of a Stribeck axis
        # kept them: a 5.2 % floor under a 3.0 % model)
        m = mask & data.processing.rows(syn, part.W)
        if clean is not None:
            m &= data.processing.rows(clean, part.W)
        for k0 in range(0, len(kin), length):
            # the re-anchoring's step is smoothed over a smoother width after each join
            m[max(k0 - part.W, 0):k0 + part.W] = False
        kins.append(syn)
        ideal.append(clean)
        masks.append(m)
    try:
        d_syn = Dataset(kins, model, folds=data.folds, processing=data.processing,
                        masks=masks)
        d_ideal = Dataset(ideal, model, folds=data.folds, processing=data.processing,
                          masks=masks) if sensor_share else None
    except ValueError:
        return Floor(float('nan'), float('nan'), 0.0, 0.0, 0)
    per_row = data.den / max(data.n, 1)
    ms = given_sse(d_syn, model) / max(d_syn.n, 1)
    ms0 = given_sse(d_ideal, model) / max(d_ideal.n, 1) if d_ideal is not None else math.nan
    nrmse = math.sqrt(ms / per_row) if per_row > 0 else float('nan')
    sensor = math.sqrt(max(ms - ms0, 0.0) / per_row) if per_row > 0 and math.isfinite(ms0) \
        else float('nan')
    kin0 = data.kins[0]
    return Floor(nrmse=nrmse, sensor_nrmse=sensor, noise=kin0.noise_std(),
                 quantum=kin0.quantum(), rows=int(d_syn.n), data=d_syn)


__all__ = ['Floor', 'WINDOW_SMOOTHERS', 'noise_floor']
