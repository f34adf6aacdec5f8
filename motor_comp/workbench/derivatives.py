"""Zero-phase kinematics of a measured run: uniform resampling, smoothing, derivatives.

The inverse model ``r = F_in − M·ẍ − Σ F_k`` needs velocity and acceleration from a
quantized, noisy position.  We use a Savitzky–Golay filter (:mod:`motor_comp.workbench.savgol`:
a centred least-squares polynomial, hence zero phase) for the position, velocity and
acceleration, and apply the *same* smoothing to every force that enters the residual, so
the two sides of the balance have the same bandwidth (otherwise the unsmoothed command
alone would leave high-frequency noise in the residual).

Irregularly sampled logs (host-polled drives) are resampled onto a uniform grid at the
median step by linear interpolation of the position (and of the input: a sampled
measurement such as a current) or by sample-and-hold (a zero-order-hold command).
"""
from __future__ import annotations

import dataclasses
import enum
import functools

import numpy as np
from motor_comp.errors import InputFileError, ParameterError
from motor_comp.logs.run import Run
from motor_comp.workbench.savgol import savgol_filter

#: delayed inputs a :class:`Kinematics` keeps (each one array of the run's length)
INPUT_CACHE = 8


class InputHold(enum.Enum):
    """How the logged input relates to the motion between samples."""

    #: a command held from its stamp until the next one (a controller's voltage output)
    ZOH = 'zoh'
    #: an instantaneous measurement (e.g. a drive's measured current)
    SAMPLE = 'sample'


@dataclasses.dataclass(frozen=True)
class Kinematics:
    """A run on a uniform grid with zero-phase smoothed derivatives (SI units).

    Parameters
    ----------
    t : ndarray
        Uniform sample times [s].
    dt : float
        Sample step [s].
    position : ndarray
        Measured position on the grid [m] (unsmoothed).
    x, v, a : ndarray
        Smoothed position [m], velocity [m/s], acceleration [m/s²].
    u : ndarray
        Logged input on the grid (V, A or N, whatever ``input_gain`` converts).
    window : int
        Savitzky–Golay window [samples] (odd).
    polyorder : int
        Savitzky–Golay polynomial order.
    hold : InputHold
        Meaning of the input samples.
    resampled : bool
        Whether the log was irregularly sampled and had to be resampled.
    name : str
        Run label.
    """

    t: np.ndarray
    dt: float
    position: np.ndarray
    x: np.ndarray
    v: np.ndarray
    a: np.ndarray
    u: np.ndarray
    window: int
    polyorder: int
    hold: InputHold
    resampled: bool = False
    name: str = 'run'
    #: :meth:`input_at` by delay: the delay search and every view of one delay ask again
    _inputs: dict = dataclasses.field(default_factory=dict, init=False, repr=False,
                                      compare=False)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Length [s]."""
        return float(self.t[-1] - self.t[0])

    def smooth(self, y: np.ndarray) -> np.ndarray:
        """Apply the zero-phase smoothing of the position to ``y`` (any unit).

        Mirror padding at the ends rather than the polynomial end fit of the
        derivatives: it is several times faster inside the nonlinear searches, and the
        first and last windows are excluded from every fit and figure anyway.
        """
        return savgol_filter(np.asarray(y, dtype=float), self.window, self.polyorder,
                             axis=0, mode='mirror')

    def derivatives(self, position: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Smoothed (x [m], v [m/s], a [m/s²]) of another position signal on this grid."""
        x = savgol_filter(position, self.window, self.polyorder, mode='interp')
        v = savgol_filter(position, self.window, self.polyorder, deriv=1, delta=self.dt,
                          mode='interp')
        a = savgol_filter(position, self.window, self.polyorder, deriv=2, delta=self.dt,
                          mode='interp')
        return x, v, a

    def input_at(self, tau: float = 0.0) -> np.ndarray:
        """Input seen by the axis at each sample, delayed by ``tau`` [s].

        For a zero-order-hold command the value is the hold signal delayed by ``τ`` and
        averaged with the triangular weight over ``[t − dt, t + dt]``: exactly what the
        3-point second difference of the position at ``t`` responds to (the double
        integral of the force, differenced), so a correct model leaves no spurious
        half-sample delay in the residual — and no bias of a fractional delay either: a
        box average over one step, which equals this only at whole-sample delays,
        put the fitted τ 10–25 µs short of the truth at 1 kHz.  With ``τ = (n + f)·dt``
        the weights of ``u[k−n−2]``, ``u[k−n−1]``, ``u[k−n]`` are ``f²/2``,
        ``1 − f²/2 − (1 − f)²/2`` and ``(1 − f)²/2``.  A sampled input is interpolated.
        """
        hit = self._inputs.get(tau)
        if hit is None:
            if len(self._inputs) >= INPUT_CACHE:
                self._inputs.clear()
            hit = self._inputs[tau] = self._input_at(tau)
            hit.flags.writeable = False     # shared by every caller
        return hit

    def input_lags(self, tau: float) -> tuple[tuple[int, float], ...]:
        """Return ``(s, w)`` pairs with ``input_at(tau) = Σ w·u`` delayed by ``s`` samples.

        The samples are evenly spaced (an irregular log is resampled), so a delay is a
        whole-sample shift plus a fraction ``f`` of one: linear interpolation for a
        sampled input, the triangle weights of :meth:`input_at` for a held one.  A
        linear, time-invariant smoother of the delayed input is then the same weighted
        sum of the smoothed shifts, which a delay search can reuse from trial to trial.
        """
        q = float(tau) / self.dt
        n = int(np.floor(q))
        f = q - n
        if f > 1.0 - 1e-12:   # a whole sample, up to rounding
            n, f = n + 1, 0.0
        if self.hold is InputHold.SAMPLE:
            return ((n, 1.0 - f), (n + 1, f)) if f > 0.0 else ((n, 1.0),)
        lags = ((n + 1, 1.0 - 0.5 * f * f - 0.5 * (1.0 - f) ** 2), (n, 0.5 * (1.0 - f) ** 2))
        return lags + ((n + 2, 0.5 * f * f),) if f > 0.0 else lags

    def input_shifted(self, s: int) -> np.ndarray:
        """Return the input delayed by ``s`` whole samples (held at the record's ends)."""
        return _shifted(self.u, s)

    def _input_at(self, tau: float) -> np.ndarray:
        # before the first sample the command is held at u[0], after the last at u[-1]
        out = np.zeros(len(self.u))
        for s, w in self.input_lags(tau):
            out += w * _shifted(self.u, s)
        return out

    def quantum(self) -> float:
        """Smallest nonzero step of the measured position [m]: the encoder resolution.

        0 for a position that never moves.  (``np.min(..., initial=0)`` would return the
        ``initial`` value itself: it joins the minimum, it is not a default.)
        """
        return self._quantum

    @functools.cached_property
    def _quantum(self) -> float:
        steps = np.abs(np.diff(self.position))
        nz = steps[steps > 0]
        return float(nz.min()) if nz.size else 0.0

    def noise_std(self) -> float:
        """Robust estimate of the position measurement noise [m] (raw minus smoothed)."""
        return self._noise_std

    @functools.cached_property
    def _noise_std(self) -> float:
        # two medians over the whole run: computed once (the searches ask often)
        d = self.position - self.x
        return float(1.4826 * np.median(np.abs(d - np.median(d))))


def _uniform(t: np.ndarray) -> tuple[bool, float]:
    dts = np.diff(t)
    dt = float(np.median(dts))
    irregular = bool(np.max(np.abs(dts - dt)) > 1e-3 * dt)
    return irregular, dt


def _shifted(u: np.ndarray, s: int) -> np.ndarray:
    """Return ``u[clip(k − s, 0, len − 1)]`` for every ``k``: ``u`` delayed by ``s`` samples.

    Held at the first (last) value beyond the record: the same values as the gather
    through clipped indices, by slices (the delay search asks for many delays).
    """
    n = len(u)
    out = np.empty(n, dtype=u.dtype)
    if n == 0:
        return out
    if s >= n:
        out[:] = u[0]
    elif s >= 0:
        out[:s] = u[0]
        out[s:] = u[:n - s]
    elif -s >= n:
        out[:] = u[-1]
    else:
        out[:n + s] = u[-s:]
        out[n + s:] = u[-1]
    return out


def kinematics(run: Run, *, window_s: float = 0.02, polyorder: int = 3,
               hold: InputHold | str = InputHold.ZOH) -> Kinematics:
    """Resample (if needed), smooth and differentiate a run's position; align its input.

    Parameters
    ----------
    run : Run
        Must have ``voltage`` (the drive input) and ``position``.
    window_s : float
        Savitzky–Golay window length [s]; rounded to an odd number of samples >= 7.
    polyorder : int
        Polynomial order (3 keeps the acceleration unbiased on cubic motion).
    hold : InputHold or str
        Meaning of the input samples (``'zoh'`` command or ``'sample'`` measurement).

    Raises
    ------
    InputFileError
        Missing input, too few samples, non-finite values, non-increasing time.
    """
    hold = InputHold(hold) if not isinstance(hold, InputHold) else hold
    if not window_s > 0:
        raise ParameterError(f'window [s] must be > 0, got {window_s!r}')
    run.require('voltage')
    t = np.asarray(run.t, dtype=float)
    x = np.asarray(run.position, dtype=float)
    u = np.asarray(run.voltage, dtype=float)
    for name, arr in (('t', t), ('position', x), ('voltage', u)):
        if not np.all(np.isfinite(arr)):
            raise InputFileError(f'{run.name}: {name} contains NaN or inf')
    if len(t) < 50:
        raise InputFileError(f'{run.name}: only {len(t)} samples, need at least 50')
    if np.any(np.diff(t) <= 0):
        raise InputFileError(f'{run.name}: time stamps are not strictly increasing')
    irregular, dt = _uniform(t)
    if irregular:
        tu = t[0] + dt * np.arange(int(np.floor((t[-1] - t[0]) / dt)) + 1)
        xu = np.interp(tu, t, x)
        if hold is InputHold.ZOH:
            idx = np.clip(np.searchsorted(t, tu, side='right') - 1, 0, len(t) - 1)
            uu = u[idx]
        else:
            uu = np.interp(tu, t, u)
        t, x, u = tu, xu, uu
    else:
        t = t[0] + dt * np.arange(len(t))  # remove stamp jitter below 0.1 %
    window = max(7, int(round(window_s / dt)) | 1)
    polyorder = int(polyorder)
    if not 1 <= polyorder < window:
        raise ParameterError(f'polyorder must be in [1, {window - 1}], got {polyorder}')
    if window * 3 > len(t):
        raise InputFileError(f'{run.name}: run of {len(t)} samples is too short for a '
                             f'{window}-sample derivative window')
    kin = Kinematics(t=t, dt=dt, position=x, x=x, v=x, a=x, u=u, window=window,
                     polyorder=polyorder, hold=hold, resampled=irregular, name=run.name)
    xs, vs, as_ = kin.derivatives(x)
    return dataclasses.replace(kin, x=xs, v=vs, a=as_)
