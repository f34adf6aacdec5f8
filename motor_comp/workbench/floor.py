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
the measurement, and the model's force NRMSE on it is the floor.

**Which rows.**  The reported floor is measured on the run's own rows where the twin is
a replica of the run: sliding, with its smoothed velocity within :data:`REPLICA` sliding
thresholds of the measured one, clear of each window's re-anchoring join, and of a
twin's stop that meets a stop of the run (the run's rows end half a smoother before it;
a twin that broke away a little later mixes its stuck force into rows the run keeps).
Where the twin departed from the run it says nothing about this run.  Rows near the
twin's other stops are kept while it follows the run: a quick reversal the axis passed
and the twin stuck at for a sample or two is where the processing leaves most, and
leaving those rows out (the rows both fit, as before) put the floor of complete models
2–10× under the true model's NRMSE on the independent generator's sine and sweep runs.
A twin that replicates less than :data:`REPLICA_SHARE` of the run's rows is not this run
(a model far from it): its floor is measured on the rows both fit.

**The logged input's own noise.**  The twin replays the logged input as applied, so a
*measured* input (a drive's current, :attr:`InputHold.SAMPLE`) brings its measurement
noise into the run's residual and not into the twin's.  That noise is white; what the
twin leaves is the sensor's and the processing's.  So the run's residual spectrum less
the twin's, over the smoother's passband (:data:`PASSBAND`), divided by the smoother's
response, is the input noise's density; its median over the band (robust to a line a
model error puts at one frequency) gives its σ, added to the twin's logged input — when
the excess is flat over the band (:data:`WHITE`), and at most what the logged input's own
second differences can hold (:func:`difference_bound`).  On the generator's current- and
force-input runs this recovers 0.85–1.04× the true σ where the noise matters to the
floor.  A logged *command* (ZOH) is what was applied: no noise is estimated for it.  The
estimate holds for a model near the truth (an error spread over the passband raises it),
so the floor's input part is reported on its own (:attr:`Floor.input_nrmse`).

On the generator's complete cases (seeds 21–24, ``bench/README.md``) the fit is within
1.5× this floor in 155 of 160 runs (132 with the floor of 8256e2d: the rows both fit, no
input noise).

**The selection's bar** (``bar=True``) is the floor on the rows both fit, without the
input's noise: a candidate is judged against the floor of a model still missing terms,
and both refinements answer to that model's error (:func:`noise_floor`).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np

from motor_comp.logs.run import Run
from motor_comp.physics.axis import AxisModel
from motor_comp.workbench.anchored import anchor, windows
from motor_comp.workbench.dataset import Dataset, model_signature
from motor_comp.workbench.derivatives import InputHold, Kinematics, kinematics
from motor_comp.workbench.library import given_residual, given_sse
from motor_comp.workbench.processing import kernel, rest_runs, sliding_mask, \
    sliding_threshold
from motor_comp.workbench.spectral import density, stretches

#: window length of the anchored simulation, in smoother lengths: long enough that the
#: joins cost little of the run, short enough that the model stays near the measurement
WINDOW_SMOOTHERS = 12
#: a twin's sample stands for the run's while its smoothed velocity is within this many
#: sliding thresholds (:func:`~.processing.sliding_threshold`) of the measured one
REPLICA = 3.0
#: least share of the run's rows the twin must replicate for the floor to be measured on
#: them; a twin that replicates fewer is not this run, and the rows both fit are used
REPLICA_SHARE = 0.5
#: Welch segment of the input-noise estimate [rows]: the shortest stretches between
#: stops of a sweep still hold one
NOISE_NPER = 32
#: least |B(f)|² (the smoother's power response) of a frequency the input-noise
#: estimate uses: inside the passband the smoothed noise is not dwarfed by the division
PASSBAND = 0.5
#: most the input-noise density may rise over its median within the band and still be
#: white (the 1/f² a missing dry friction leaves rises 4× or more across the band)
WHITE = 3.0


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
    input_noise : float
        White noise σ of the logged input estimated from the run (its units: V, A or
        N; 0 for a command, which is what was applied).
    input_nrmse : float
        The part of :attr:`nrmse` the input's noise accounts for (in quadrature).
    data : Dataset or None
        The anchored runs measured like the run (the structure scan compares with them).
    """

    nrmse: float
    sensor_nrmse: float
    noise: float
    quantum: float
    rows: int
    input_noise: float = 0.0
    input_nrmse: float = 0.0
    data: Any = dataclasses.field(default=None, repr=False, compare=False)

    def as_dict(self) -> dict:
        """Return the JSON form."""
        return {'noise_floor_nrmse': self.nrmse, 'sensor_nrmse': self.sensor_nrmse,
                'noise': self.noise, 'quantum': self.quantum, 'rows': self.rows,
                'input_noise': self.input_noise, 'input_nrmse': self.input_nrmse}


def _sensor(kin: Kinematics) -> tuple[float, float]:
    """Return the white noise σ to add before quantising, and the quantum [m]."""
    q = kin.quantum()
    total = kin.noise_std()
    white = math.sqrt(max(total * total - q * q / 12.0, 0.0))
    return white, q


def _anchored(kin: Kinematics, model: AxisModel, length: int) -> np.ndarray:
    """Return the run of ``model`` in windows of ``length`` anchored to ``kin`` [m]."""
    a = anchor(kin, model)
    return windows(a, np.arange(0, len(kin), length, dtype=np.int64))


def _synthetic(kin: Kinematics, x: np.ndarray, rng: np.random.Generator,
               sensor: bool) -> Kinematics:
    """Return the anchored run ``x`` (:func:`_anchored`) measured like ``kin`` (or ideally)."""
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


def _replica(kin: Kinematics, twin: Kinematics, half: int) -> np.ndarray:
    """Return the samples where ``twin`` stands for ``kin`` (see the module docstring).

    It slides and its velocity follows the run's; and no stop of the twin that meets a
    stop of the run reaches it within ``half`` a smoother: there the run's own rows end
    a half smoother before its stop, and a twin that stuck a little longer mixes its
    stuck force into rows the run keeps (a break-away after a dwell).
    """
    m = sliding_mask(twin) & (np.abs(twin.v - kin.v) <= REPLICA * sliding_threshold(kin))
    run_stops = rest_runs(sliding_mask(kin))
    still = rest_runs(sliding_mask(twin)).astype(np.int8)
    d = np.diff(np.concatenate([[0], still, [0]]))
    for a, b in zip(np.flatnonzero(d == 1), np.flatnonzero(d == -1)):
        if run_stops[a:b].any():
            m[max(a - half, 0):b + half] = False
    return m


def input_noise(data: Dataset, twin: Dataset, model: AxisModel) -> float:
    """Return the logged input's white-noise σ [input units] (see the module docstring).

    ``twin`` is the floor's record of ``data`` (same processing), its input replayed
    without noise.  0 when no run's input is a measurement or no stretch between stops
    holds a spectral segment.
    """
    if not any(p.kin.hold is InputHold.SAMPLE for p in data.parts) or model.input_gain == 0:
        return 0.0
    r, rt = given_residual(data, model), given_residual(twin, model)
    g2 = float(model.input_gain) ** 2
    qs = []
    for i, (part, tpart) in enumerate(zip(data.parts, twin.parts)):
        if part.kin.hold is not InputHold.SAMPLE:
            continue
        # the longer segment where the stretches between stops hold most rows: twice
        # the frequency resolution, twice the bins over the band
        for nper in (2 * NOISE_NPER, NOISE_NPER):
            segs, fs = stretches(data, r, nper, part=i)
            if sum(len(s) for s in segs) >= 0.5 * len(part.rows) or nper == NOISE_NPER:
                break
        real = density(segs, fs, nper)
        rec = density(*stretches(twin, rt, nper, part=i), nper)
        if real is None or rec is None or len(real[0]) != len(rec[0]):
            continue
        f = real[0]
        dt = part.kin.dt
        b = kernel(part.W)
        B = np.abs(np.exp(-2j * np.pi * dt * np.outer(f, np.arange(len(b)))) @ b) ** 2
        band = (B >= PASSBAND) & (f > 0)
        # white noise σ² at the sample rate has the one-sided density 2σ²·dt; smoothed,
        # ×|B|²; the decimation keeps the band (B is negligible beyond its Nyquist)
        qs.append((real[1] - rec[1])[band] / (B[band] * 2.0 * dt * g2))
    if not qs:
        return 0.0
    q = np.concatenate(qs)
    med = float(np.median(q))
    # white noise is flat over the band; an excess that peaks (a ripple's line, the
    # 1/f² of a missing dry friction) is the model's error, not the input's noise
    if med <= 0 or float(np.max(q)) > WHITE * med:
        return 0.0
    # nor can the input hold more white noise than its own sample-to-sample changes
    # show: the band has a few bins only (≈ 3 at any rate: segment and smoother are
    # both counted in samples), and a disturbance inside it passes the flatness test;
    # the excess beyond that bound is the model's error
    return min(math.sqrt(med), max(difference_bound(p.kin.u) for p in data.parts
                                   if p.kin.hold is InputHold.SAMPLE))


def difference_bound(u: np.ndarray) -> float:
    """Return the most white-noise σ a logged input can hold [its units].

    White noise of σ gives second differences of variance 6σ²; the input's own
    changes only add to them, and the median of their magnitude (×1.4826, the normal
    MAD factor) ignores the steps and transients a few samples make.  So
    ``1.4826·median|Δ²u|/√6`` is σ (to its sampling error, ~1 % over 20 000 samples) or
    more on a smooth drive signal: 1.4–21× the generator's true σ on its 44 current-
    and force-input runs of the complete and out-of-library lists (seeds 21–22 and
    1–2), where the spectral estimate was 86× and 282× the truth on the two runs whose
    model missed a bump and a 7 Hz disturbance (and never above the bound where the
    model was complete).
    """
    d2 = np.diff(np.asarray(u, dtype=float), 2)
    if d2.size == 0:
        return 0.0
    return 1.4826 * float(np.median(np.abs(d2))) / math.sqrt(6.0)


def noise_floor(data: Dataset, model: AxisModel, *, seed: int = 0,
                sensor_share: bool = True, bar: bool = False,
                runs: dict | None = None) -> Floor:
    """Return the noise floor of ``model`` on ``data``'s runs (see the module docstring).

    ``sensor_share=False`` leaves out the noise-free twin that splits off the sensor's
    part (:attr:`Floor.sensor_nrmse` is then NaN).  ``bar=True`` returns the selection's
    bar instead of the reported floor: measured on the rows both the run and its twin
    fit, without the logged input's noise.  A candidate is judged against the floor of
    a model still missing terms, and both refinements answer to that model's error: a
    twin that diverges keeps its replica rows only where both are slow (at the turns,
    where the residual is largest: 10 % under a 9.7 % model that still lacked a ripple),
    and an error spread over the passband passes for the input's noise.  ``runs``: a
    cache of the anchored runs, shared by calls on the same runs (the bar and the
    reported floor of one model simulate the same run); keyed by run, model and window.
    """
    rng = np.random.default_rng(seed)
    kins, ideal, masks = [], [], []
    for part, mask in zip(data.parts, data.masks):
        kin = part.kin
        length = max(WINDOW_SMOOTHERS * part.W, 50)
        try:
            # one simulation for both records: they differ by the sensor alone
            key = (id(kin), model_signature(model), length)
            x = runs.get(key) if runs is not None else None
            if x is None:
                x = _anchored(kin, model, length)
                if runs is not None:
                    runs[key] = x
            syn = _synthetic(kin, x, rng, True)
            clean = _synthetic(kin, x, rng, False) if sensor_share else None
        except (FloatingPointError, ValueError):
            return Floor(float('nan'), float('nan'), kin.noise_std(), kin.quantum(), 0)
        # the rows both fit; for the report, the run's rows where the twin is its replica
        # (module docstring), unless the twin replicates less than REPLICA_SHARE of them
        m = mask & data.processing.rows(syn, part.W)
        if not bar:
            rep = mask & _replica(kin, syn, data.processing.stop_margin(part.W))
            if np.count_nonzero(rep) >= REPLICA_SHARE * np.count_nonzero(mask):
                m = rep
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
    sigma = 0.0 if bar else input_noise(data, d_syn, model)
    ms_quiet = ms = given_sse(d_syn, model) / max(d_syn.n, 1)
    if sigma > 0:
        # the twin's input logged as the drive logs it: with its measurement noise
        noisy = [dataclasses.replace(k, u=k.u + rng.normal(0.0, sigma, len(k)))
                 if p.kin.hold is InputHold.SAMPLE else k for k, p in zip(kins, data.parts)]
        d_syn = Dataset(noisy, model, folds=data.folds, processing=data.processing,
                        masks=masks)
        ms = given_sse(d_syn, model) / max(d_syn.n, 1)
    ms0 = given_sse(d_ideal, model) / max(d_ideal.n, 1) if d_ideal is not None else math.nan
    nrmse = math.sqrt(ms / per_row) if per_row > 0 else float('nan')
    sensor = math.sqrt(max(ms - ms0, 0.0) / per_row) if per_row > 0 and math.isfinite(ms0) \
        else float('nan')
    part_in = math.sqrt(max(ms - ms_quiet, 0.0) / per_row) if per_row > 0 else 0.0
    kin0 = data.kins[0]
    return Floor(nrmse=nrmse, sensor_nrmse=sensor, noise=kin0.noise_std(),
                 quantum=kin0.quantum(), rows=int(d_syn.n), input_noise=sigma,
                 input_nrmse=part_in, data=d_syn)


__all__ = ['Floor', 'NOISE_NPER', 'PASSBAND', 'REPLICA', 'REPLICA_SHARE', 'WHITE',
           'WINDOW_SMOOTHERS', 'difference_bound', 'input_noise', 'noise_floor']
