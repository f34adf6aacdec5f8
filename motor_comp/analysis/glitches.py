"""Quadrant glitches: tracking-error peaks after reversals of the reference velocity.

DESIGN.md §6: the glitch of a reversal at ``t_r`` (sign change of the reference
velocity) is ``max |e(t)|`` for ``t ∈ [t_r, t_r + W]``.  At a reversal, friction
changes sign and the pre-sliding regime is crossed (Chiew et al., Fig. 9–11: the
"quadrant glitches" that GMS feedforward reduces most).

Reversal time: with ``k`` the first sample of the new sign, and ``j = k − 1``:
if the velocity passed straight through zero, ``t_r`` is the linearly interpolated zero
crossing between ``t_j`` and ``t_k``; if it rested at zero (a dwell), ``t_r = t_j``,
the last zero sample, i.e. when motion in the new direction starts.  Velocities with
``|v| ≤ zero_tol · max|v|`` count as zero (round-off of the reference generator).
"""
from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Glitch:
    """One quadrant glitch.

    Attributes
    ----------
    t : float
        Reversal time ``t_r`` [s].
    magnitude : float
        ``max |e|`` over ``[t_r, t_r + W]`` [m].
    t_peak : float
        Time of that maximum [s].
    direction : int
        +1 for a reversal from negative to positive velocity, −1 otherwise.
    """

    t: float
    magnitude: float
    t_peak: float
    direction: int

    def as_dict(self) -> dict[str, float | int]:
        """JSON form (DESIGN.md §6 keys ``t`` and ``magnitude`` plus extras)."""
        return dataclasses.asdict(self)


def reference_velocity(t: np.ndarray, reference: np.ndarray,
                       velocity: np.ndarray | None) -> np.ndarray:
    """Return the logged reference velocity, else the reference derivative [m/s]."""
    if velocity is not None:
        return np.asarray(velocity, dtype=float)
    if t.shape[0] < 2:
        return np.zeros_like(t)
    return np.gradient(np.asarray(reference, dtype=float), t)


def reversals(t: np.ndarray, v: np.ndarray, *, zero_tol: float = 1e-6
              ) -> tuple[np.ndarray, np.ndarray]:
    """Return times [s] and directions (+1/−1) of the sign changes of ``v``."""
    t = np.asarray(t, dtype=float)
    v = np.asarray(v, dtype=float)
    if v.size < 2:
        return np.empty(0), np.empty(0, dtype=int)
    vmax = float(np.max(np.abs(v)))
    if vmax == 0.0 or not np.isfinite(vmax):
        return np.empty(0), np.empty(0, dtype=int)
    s = np.where(np.abs(v) > zero_tol * vmax, np.sign(v), 0.0)
    nz = np.flatnonzero(s)
    if nz.size < 2:
        return np.empty(0), np.empty(0, dtype=int)
    change = np.flatnonzero(s[nz[1:]] != s[nz[:-1]])
    k = nz[change + 1]           # first sample of the new sign
    prev = nz[change]            # last sample of the old sign
    j = k - 1
    through = j == prev
    frac = np.zeros(k.size)
    vj, vk = v[j[through]], v[k[through]]
    frac[through] = vj / (vj - vk)
    tr = t[j] + frac * (t[k] - t[j])
    return tr, s[k].astype(int)


def find_glitches(t: np.ndarray, error: np.ndarray, ref_velocity: np.ndarray, *,
                  window: float = 0.2, zero_tol: float = 1e-6,
                  found: tuple[np.ndarray, np.ndarray] | None = None) -> tuple[Glitch, ...]:
    """Glitches of every reversal of ``ref_velocity`` (see the module docstring).

    Parameters
    ----------
    t : ndarray
        Sample times [s], increasing.
    error : ndarray
        Tracking error ``e = x_ref − x`` [m].
    ref_velocity : ndarray
        Reference velocity [m/s].
    window : float
        ``W`` [s] (``--glitch-window``).
    zero_tol : float
        Relative velocity below which the reference counts as at rest.
    found : (ndarray, ndarray), optional
        The result of :func:`reversals` if already computed.
    """
    if not window > 0:
        raise ValueError(f'glitch window must be > 0, got {window}')
    tr, direction = found if found is not None else reversals(t, ref_velocity,
                                                              zero_tol=zero_tol)
    error = np.asarray(error, dtype=float)
    i0 = np.searchsorted(t, tr, side='left')
    i1 = np.searchsorted(t, tr + window, side='right')
    out = []
    for a, b, r, d in zip(i0, i1, tr, direction):
        if b <= a:
            continue
        m = a + int(np.argmax(np.abs(error[a:b])))
        out.append(Glitch(t=float(r), magnitude=float(abs(error[m])), t_peak=float(t[m]),
                          direction=int(d)))
    return tuple(out)
