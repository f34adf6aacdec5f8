"""Speed bands: the residual's variance model by speed, and the row weights it gives.

On a run with many turns the rows near a turn carry residuals 10–50× those of the
sliding rows (how a turn is resolved between samples is modelled, but not exactly).
Least squares, and an information criterion on the plain sum of squares, then let
those few rows decide.  Feasible generalised least squares (Carroll & Ruppert,
*Transformation and Weighting in Regression*, 1988) models the variance as
constant within equal-count bands of the speed, estimates it from a first residual, and
weights each row by the inverse of its band's variance (:class:`SpeedBands`); the
weighted sum of squares is then, up to one common scale, the likelihood an information
criterion needs.  Used by the final reweighting (:mod:`.reweight`) and by the choice of
a structural order (:mod:`.varpro`).
"""
from __future__ import annotations

import dataclasses

import numpy as np

from motor_comp.errors import ParameterError
from motor_comp.physics.effects.identification import Evidence

#: speed bands of a residual's variance model (equal numbers of rows: :class:`SpeedBands`)
WEIGHT_BANDS = 20
#: rows are weighted only when the worst band's residual variance is this many times the
#: median band's (below it least squares is near enough to the likelihood)
WEIGHT_CONTRAST = 10.0
#: where a term's evidence lies that weights by speed band would suppress (a model with
#: such a term is not reweighted, such a term's order not chosen under weights)
PROTECTED = Evidence.SLOW | Evidence.TURNS | Evidence.STOPS


@dataclasses.dataclass(frozen=True)
class SpeedWeights:
    """Row weights by speed band: ``edges[i] ≤ |ẋ| < edges[i+1]`` gets ``w[i]`` (> 0)."""

    edges: tuple
    w: tuple

    def __post_init__(self) -> None:
        w = np.asarray(self.w, dtype=float)
        if len(w) != len(self.edges) or not np.all(np.isfinite(w)) or np.any(w <= 0):
            raise ParameterError('speed weights must be finite and positive, one per band')

    def at(self, speed: np.ndarray) -> np.ndarray:
        """Return each row's weight, its band's, at velocity or speed ``speed``."""
        band = _band(np.asarray(self.edges, dtype=float),
                     np.abs(np.asarray(speed, dtype=float)))
        return np.asarray(self.w, dtype=float)[band]


def _band(edges: np.ndarray, speed: np.ndarray) -> np.ndarray:
    """Return each speed's band: ``edges[i] ≤ speed < edges[i+1]`` is band ``i``."""
    return np.clip(np.searchsorted(edges, speed, side='right') - 1, 0, len(edges) - 1)


@dataclasses.dataclass(frozen=True)
class SpeedBands:
    """The residual variance of equal-count speed bands: feasible GLS's variance model.

    On a run with many turns the rows near a turn carry residuals 10–50× those of the
    sliding rows; least squares and an information criterion on the plain SSE then
    let those few rows decide.  ``edges[i]`` [m/s or rad/s] is the lowest speed of band
    ``i``, ``var[i]`` [N²] the mean squared residual of its rows.
    """

    edges: np.ndarray
    var: np.ndarray

    @classmethod
    def of(cls, speed: np.ndarray, e: np.ndarray, *, bands: int = WEIGHT_BANDS) \
            -> 'SpeedBands | None':
        """Return the bands of residual ``e`` over ``|speed|``, None when one is empty or 0.

        Also None with fewer than four rows a band.
        """
        speed = np.abs(np.asarray(speed, dtype=float))
        if len(speed) < 4 * bands:
            return None
        edges = np.quantile(speed, np.linspace(0.0, 1.0, bands + 1)[:-1])
        edges[0] = 0.0
        band = _band(edges, speed)
        count = np.bincount(band, minlength=bands)
        var = np.bincount(band, e * e, minlength=bands) / np.maximum(count, 1)
        if np.any(count == 0) or np.min(var) <= 0:
            return None
        return cls(edges, var)

    @property
    def contrast(self) -> float:
        """Return the largest band variance over the median one."""
        return float(np.max(self.var) / np.median(self.var))

    @property
    def weights(self) -> SpeedWeights:
        """Return the weights 1/variance, relative to the median band's."""
        return SpeedWeights(tuple(self.edges), tuple(float(np.median(self.var)) / self.var))

    def row_weights(self, speed: np.ndarray) -> np.ndarray:
        """Return each row's weight (its band's) at ``|speed|``."""
        return self.weights.at(speed)


__all__ = ['PROTECTED', 'SpeedBands', 'SpeedWeights', 'WEIGHT_BANDS', 'WEIGHT_CONTRAST']
