"""A recorded or simulated run as time-aligned arrays (the currency of every offline tool).

Every array is sampled on the common time base ``t`` (the measurement stamps).  Topics
recorded at other rates or stamps are aligned onto it by the readers (sample-and-hold
of the latest value at or before each measurement, DESIGN.md §5 topics).
"""
from __future__ import annotations

import dataclasses
from typing import Any, Mapping

import numpy as np

from motor_comp.errors import InputFileError


@dataclasses.dataclass(frozen=True)
class Run:
    """Time-aligned signals of one run (SI units).

    Parameters
    ----------
    t : ndarray
        Sample times [s], strictly increasing, starting anywhere.
    position : ndarray
        Measured position [m] (``/axis/joint_states`` position).
    velocity : ndarray or None
        Measured velocity [m/s] when logged.
    reference : ndarray or None
        Desired position [m] (``/axis/reference`` position) at ``t``.
    reference_velocity : ndarray or None
        Desired velocity [m/s] at ``t``.
    voltage : ndarray or None
        Command applied to the plant (``/axis/voltage``) [V], or the input in the unit
        the model's ``input_gain`` converts (A for current-input drives, N for force).
    effort : ndarray or None
        Actuator force [N] when known (``joint_states`` effort).
    metadata : Mapping[str, str]
        Run parameters (MCAP metadata) and provenance.
    name : str
        Short label (file stem) for tables and plots.
    """

    t: np.ndarray
    position: np.ndarray
    velocity: np.ndarray | None = None
    reference: np.ndarray | None = None
    reference_velocity: np.ndarray | None = None
    voltage: np.ndarray | None = None
    effort: np.ndarray | None = None
    metadata: Mapping[str, Any] = dataclasses.field(default_factory=dict)
    name: str = 'run'

    SIGNALS = ('position', 'velocity', 'reference', 'reference_velocity', 'voltage',
               'effort')

    def __post_init__(self) -> None:
        t = np.asarray(self.t, dtype=float)
        object.__setattr__(self, 't', t)
        n = t.shape[0]
        for name in self.SIGNALS:
            v = getattr(self, name)
            if v is None:
                continue
            v = np.asarray(v, dtype=float)
            if v.shape != (n,):
                raise InputFileError(f'{self.name}: {name} has shape {v.shape}, '
                                     f'expected ({n},) like t')
            object.__setattr__(self, name, v)

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Length of the run [s]."""
        return float(self.t[-1] - self.t[0]) if len(self) > 1 else 0.0

    @property
    def error(self) -> np.ndarray:
        """Tracking error ``e = x_ref − x`` [m] (DESIGN.md §6)."""
        if self.reference is None:
            raise InputFileError(f'{self.name}: no reference (/axis/reference) in this run')
        return self.reference - self.position

    def require(self, *names: str) -> None:
        """Raise a one-line error naming the first missing signal among ``names``."""
        topic = {'position': '/axis/joint_states', 'velocity': '/axis/joint_states velocity',
                 'reference': '/axis/reference', 'reference_velocity': '/axis/reference',
                 'voltage': '/axis/voltage', 'effort': '/axis/joint_states effort'}
        for n in names:
            if getattr(self, n) is None:
                raise InputFileError(f'{self.name}: missing {n} ({topic.get(n, n)})')

    def slice(self, t0: float, t1: float) -> 'Run':
        """Return the samples with ``t0 <= t < t1``."""
        m = (self.t >= t0) & (self.t < t1)
        kw = {n: (None if getattr(self, n) is None else getattr(self, n)[m])
              for n in self.SIGNALS}
        return dataclasses.replace(self, t=self.t[m], **kw)
