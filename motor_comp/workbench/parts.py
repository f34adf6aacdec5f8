"""A run's fitted samples, the pointwise signals along one motion, and a term's view of them.

:class:`RunPart` is one processed run of a :class:`~.dataset.Dataset`; :class:`Motion`
the signals along one motor motion (the measured one, or the motor's across a backlash
gap), each computed once when first asked for; :class:`PathView` what a term's columns
read (:class:`~motor_comp.physics.effects.identification.Path`).
"""
from __future__ import annotations

import dataclasses
from typing import Any, Callable

import numpy as np

from motor_comp.workbench import processing as proc
from motor_comp.workbench.derivatives import InputHold, Kinematics
from motor_comp.workbench.turns import REVERSAL_HALF, reversal_shares


@dataclasses.dataclass(frozen=True)
class RunPart:
    """One processed run: its kinematics, fitted rows and smoother length."""

    kin: Kinematics
    rows: np.ndarray
    W: int
    gms_scale: float = 1.0


class Motion:
    """The pointwise signals of one run along one motor motion (lazily computed once)."""

    def __init__(self, part: RunPart, position: np.ndarray, measured: bool) -> None:
        self.part = part
        self.position = position
        self._measured = measured
        self._cache: dict[str, Any] = {}

    def _get(self, name: str) -> Any:
        hit = self._cache.get(name)
        if hit is None:
            kin = self.part.kin
            if name == 'x':
                hit = kin.x if self._measured else proc.point_position(kin, self.position)
            elif name == 'v':
                hit = proc.point_velocity(kin, self.position)
            elif name == 'xg':
                hit = proc.gms_position(kin, self.position, self.part.gms_scale)
            elif name == 'xs':
                hit = proc.smooth_full(self.position, self.part.W)
            elif name == 'shares':
                half = max(3, int(round(REVERSAL_HALF * kin.window)))
                eps = max(kin.quantum(), kin.noise_std())
                fwd, bwd, stuck = reversal_shares(
                    np.asarray(self.position, dtype=float), self._get('v'), half, eps,
                    spread=kin.hold is not InputHold.SAMPLE)
                # an axis at rest (outside a fitted turn): its friction balances every
                # other force, whatever the sign of its dither
                rest = proc.rest_runs(proc.held_ends(kin, proc.sliding_mask(
                    kin, None if self._measured else self.position)))
                rest &= (stuck == 0.0) & ((fwd == 0.0) | (fwd == 1.0)) & \
                    ((bwd == 0.0) | (bwd == 1.0))
                fwd, bwd = np.where(rest, 0.0, fwd), np.where(rest, 0.0, bwd)
                hit = (fwd, bwd, stuck, rest.astype(float))
            self._cache[name] = hit
        return hit

    @property
    def x(self) -> np.ndarray:
        """Pointwise position [m or rad]."""
        return self._get('x')

    @property
    def v(self) -> np.ndarray:
        """Pointwise velocity [m/s or rad/s]."""
        return self._get('v')

    @property
    def xg(self) -> np.ndarray:
        """Position the GMS elements are driven by."""
        return self._get('xg')

    smoothed = property(lambda self: self._get('xs'))   # S·position: both stencils' input

    @property
    def shares(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Forward, backward, stuck (at a turn) and at-rest shares of each sample."""
        return self._get('shares')


class PathView:
    """A run's signals as a term's columns see them (:class:`~…identification.Path`)."""

    def __init__(self, motion: Motion, f_in: Any, direction: int) -> None:
        self._m = motion
        self._f_in = f_in
        self.position = motion.position
        self.dt = motion.part.kin.dt
        self.direction = direction

    x = property(lambda self: self._m.x)
    v = property(lambda self: self._m.v)
    xg = property(lambda self: self._m.xg)
    fwd = property(lambda self: self._m.shares[0])
    bwd = property(lambda self: self._m.shares[1])
    stuck = property(lambda self: self._m.shares[2])
    rest = property(lambda self: self._m.shares[3])
    f_in = property(lambda self: self._f_in(self._m))

    def memo(self, key: tuple, make: Callable[[], Any]) -> Any:
        """Return ``make()`` computed once per motion and ``key`` (shared derived signals)."""
        cache = self._m._cache
        k = ('memo',) + tuple(key)
        if k not in cache:
            cache[k] = make()
        return cache[k]


__all__ = ['Motion', 'PathView', 'RunPart']
