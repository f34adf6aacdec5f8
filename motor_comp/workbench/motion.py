"""The motor motion reconstructed from the measured load across a backlash gap.

Between reversals the motor pushes one edge of the gap; at a reversal of the load it
flies across the gap under the model's own dynamics (the compiled plant kernel, the one
implementation of the axis dynamics) until it takes the load along again
(:func:`motor_position`).  Also the reversals of a position record (a play operator on
the measurement, :func:`reversals`), which the reports use too.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from motor_comp.physics import aot
from motor_comp.physics import kernel as K
from motor_comp.physics.axis import AxisModel
from motor_comp.physics.plant import Sensors, initial_state, pack_params
from motor_comp.workbench.derivatives import InputHold, Kinematics


def _stationary_runs(pos: np.ndarray, k_ext: int, eps: float) -> tuple[int, int]:
    """Return the contiguous samples around ``k_ext`` whose position stays within ``eps``."""
    ref = pos[k_ext]
    i0 = k_ext
    while i0 > 0 and abs(pos[i0 - 1] - ref) <= eps:
        i0 -= 1
    i1 = k_ext
    while i1 < len(pos) - 1 and abs(pos[i1 + 1] - ref) <= eps:
        i1 += 1
    return i0, i1


def reversals(position: np.ndarray, hysteresis: float) -> list[tuple[int, int]]:
    """Find the direction reversals of a position record.

    A reversal is declared when the position has come back by more than ``hysteresis``
    [m] from its last extreme (a play operator on the measurement, so encoder flicker
    does not count).  Returns ``(index of the extreme, new direction ±1)`` pairs.
    """
    idx, dirs = _reversals_entry(np.ascontiguousarray(position, dtype=float), float(hysteresis))
    return [(int(i), int(d)) for i, d in zip(idx, dirs)]


@aot.ahead(aot.F8_1D, aot.F8)
@njit(cache=True)
def _reversals(position, hysteresis):
    # compiled: this runs inside the backlash width search, once per trial width
    out_i = []
    out_d = []
    direction = 0
    k_ext = 0
    k_max = 0
    k_min = 0
    for k in range(1, len(position)):
        p = position[k]
        if direction == 0:
            # first motion: whichever way the position first leaves its start band
            if p > position[k_max]:
                k_max = k
            if p < position[k_min]:
                k_min = k
            if position[k_max] - p > hysteresis:
                direction, k_ext = -1, k
            elif p - position[k_min] > hysteresis:
                direction, k_ext = 1, k
            continue
        if direction > 0:
            if p > position[k_ext]:
                k_ext = k
            elif position[k_ext] - p > hysteresis:
                out_i.append(k_ext)
                out_d.append(-1)
                direction, k_ext = -1, k
        else:
            if p < position[k_ext]:
                k_ext = k
            elif p - position[k_ext] > hysteresis:
                out_i.append(k_ext)
                out_d.append(1)
                direction, k_ext = 1, k
    return np.array(out_i, dtype=np.int64), np.array(out_d, dtype=np.int64)


def motor_position(kin: Kinematics, width: float, model: AxisModel,
                   u: np.ndarray, *, tau: float = 0.0) -> np.ndarray:
    """Motor position [m] reconstructed from the load position across a backlash gap.

    Between reversals the motor pushes one edge of the gap, ``x_m = x_load ± width/2``.
    The (massless, DESIGN.md §3 backlash) load stops at the instant the motor turns,
    so a reversal of the load starts where its position comes to rest before moving
    back — not at the extreme of a smoothed position, which a zero-phase filter moves
    towards the end of the pause (measured on the independent generator: the flight
    then started late, and the width search took the gap 40 % narrow to make up for
    it).  From that instant the motor flies from rest across the gap under the model's
    own dynamics, ``M·ẍ_m = F_in(u(t − τ), ẋ_m) − Σ F_k(x_m, ẋ_m)``, until it has
    travelled the width and takes the load along.  With the right width this flight
    ends when the measured load starts moving again; with a wrong one it ends early
    (the load appears stuck under a driving force) or late (the motor jumps when the
    load is seen moving), and the force residual grows — which is what the width
    search minimises.

    Any load reversal larger than the position noise is a gap crossing (the load only
    comes back when the motor has crossed the whole gap), so reversals are found on
    the raw position with a noise-sized hysteresis, whatever the trial width: a
    closed-loop overshoot that moves the load back by less than the gap is a crossing
    too.

    Parameters
    ----------
    kin : Kinematics
        The measured (load-side) run.
    width : float
        Gap [m].
    model : AxisModel
        Its forces drive the flight (its own ``backlash`` and ``delay`` are ignored).
    u : ndarray
        Logged input at each sample (not delayed), held or interpolated between the
        samples as ``kin.hold`` says.
    tau : float
        Input dead time [s], applied inside the flight at the integrator's sub-step (a
        shift by whole samples would move every flight by up to half a sample).
    """
    pos = kin.position
    if width <= 0:
        return pos.copy()
    rev, starts, stops, dirs, rest, side = _pauses(kin)
    xm = pos + 0.5 * width * side
    if not rev:
        return xm
    # free flight across each gap, integrated by the compiled plant kernel (the one
    # implementation of the axis dynamics, stiction included) for the model at hand
    ends = np.append(starts[1:], len(pos))
    horizon = np.maximum(np.minimum(ends - starts, 3 * (stops - starts) + 2 * kin.window + 5),
                         0).astype(np.int64)
    base = model.without('backlash', 'delay')
    # each flight starts at rest against the old edge (the load rests at ``rest``)
    x_start = rest - 0.5 * width * dirs
    if any(e.position_dependent for e in base.effects):
        _flights_entry(*_flight_setup(kin, base, u, tau), starts, x_start, dirs,
                       np.full(len(starts), float(width)), horizon, xm)
        return xm
    # no force reads the absolute position: each flight is the same path from rest
    # whatever the width (it ends where it has travelled the width), so the paths are
    # integrated once for the model and delay and each width takes its prefixes (a
    # width search tried ~10 widths a round, each integrating every flight)
    path = _flight_paths(kin, base, u, float(tau), starts, dirs, horizon)
    for j, k0 in enumerate(starts.tolist()):
        seg = path[k0:k0 + horizon[j]]
        past = np.flatnonzero(seg * dirs[j] >= width)
        n = int(past[0]) if past.size else len(seg)
        xm[k0:k0 + n] = x_start[j] + seg[:n]
    return xm


def _flight_setup(kin: Kinematics, model: AxisModel, u: np.ndarray, tau: float) -> tuple:
    """Return the kernel's leading arguments: packed model, state at rest, input, delay."""
    n_sub = 10
    P = pack_params(model, Sensors(encoder_resolution=0.0), kin.dt / n_sub)
    return (P, initial_state(P, 0.0), np.ascontiguousarray(u, dtype=float),
            float(tau) / kin.dt, kin.hold is InputHold.SAMPLE, n_sub)


def _flight_paths(kin: Kinematics, model: AxisModel, u: np.ndarray, tau: float,
                  starts: np.ndarray, dirs: np.ndarray, horizon: np.ndarray) -> np.ndarray:
    """Return each flight's travel from rest over its whole horizon (0 elsewhere), cached.

    Kept on the run's :class:`Kinematics` by model and delay (the last few), for the
    input array it was integrated with.
    """
    cache = kin.__dict__.setdefault('_flight_paths', {})
    key = (model, tau)
    hit = cache.get(key)
    if hit is not None and hit[0] is u:
        return hit[1]
    path = np.zeros(len(kin.position))
    n = len(starts)
    _flights_entry(*_flight_setup(kin, model, u, tau), starts, np.zeros(n), dirs,
                   np.full(n, np.inf), horizon, path)
    if len(cache) > 8:
        cache.clear()
    cache[key] = (u, path)
    return path


def _pauses(kin: Kinematics) -> tuple:
    """Reversals of the load, its pause at each, the rest positions, the stroke sides.

    They depend on the measured position only, not on the gap: computed once per run
    (kept on the run's :class:`Kinematics`) for the many widths a search tries.
    Returns ``(rev, starts, stops, dirs, rest, side)``: ``side`` is ±1 per sample, the
    direction of the stroke each sample belongs to.
    """
    hit = kin.__dict__.get('_backlash_pauses')
    if hit is not None:
        return hit
    pos = kin.position
    eps = _position_tolerance(kin)
    rev = reversals(pos, 4.0 * eps + 1e-12)
    side = np.zeros(len(pos))
    if rev:
        # the first stroke runs against the first reversal's new direction (a start
        # transient of the velocity estimate can point the other way)
        d_prev = -float(rev[0][1])
    else:
        moving = np.abs(kin.v) > 0.05 * np.max(np.abs(kin.v))
        first = np.sign(kin.v[int(np.argmax(moving))])
        d_prev = first if first != 0 else 1.0
    starts = np.empty(len(rev), dtype=np.int64)
    stops = np.empty(len(rev), dtype=np.int64)
    rest = np.empty(len(rev))
    dirs = np.empty(len(rev))
    last = 0
    for j, (k_ext, d_new) in enumerate(rev):
        # the pause of the load around its extreme: where the motor turned
        i0, i1 = _stationary_runs(pos, k_ext, 2.0 * eps)
        i0 = max(i0, last)
        starts[j], stops[j], dirs[j] = i0, i1, d_new
        rest[j] = float(np.median(pos[i0:i1 + 1]))
        side[last:i0] = d_prev
        last = i0
        d_prev = d_new
    side[last:] = d_prev
    out = (rev, starts, stops, dirs, rest, side)
    # a frozen dataclass: the cache goes into the instance dict, like cached_property
    kin.__dict__['_backlash_pauses'] = out
    return out


def _position_tolerance(kin: Kinematics) -> float:
    """Return the band [m] a position at rest stays in: 3σ of the noise, half a count."""
    return max(3.0 * kin.noise_std(), 0.5 * kin.quantum())


@njit(cache=True)
def _input_at(u, t, interpolate):
    """Input at time ``t`` [samples]: held from the last stamp, or interpolated."""
    n = u.shape[0]
    if t <= 0.0:
        return u[0]
    i = int(np.floor(t + 1e-9))
    if i >= n - 1:
        return u[n - 1]
    if interpolate:
        return u[i] + (t - i) * (u[i + 1] - u[i])
    return u[i]


@aot.ahead(aot.F8_1D, aot.F8_1D, aot.F8_1D, aot.F8, aot.BOOL, aot.I8, aot.I8_1D,
           aot.F8_1D, aot.F8_1D, aot.F8_1D, aot.I8_1D, aot.F8_1D)
@njit(cache=True)
def _flights(P, S0, u, shift, interpolate, n_sub, starts, x_start, dirs, reach, horizon, xm):
    # flight j starts at rest at ``x_start[j]`` and ends where it has travelled
    # ``reach[j]`` in ``dirs[j]`` (the far edge) or after ``horizon[j]`` samples; ``shift``
    # = τ/dt [samples]: the input of each sub-step is taken at its middle, τ earlier (a
    # whole-sample shift would move every flight by up to half a sample)
    for j in range(starts.shape[0]):
        k0 = starts[j]
        S = S0.copy()
        S[K.S_X] = x_start[j]
        S[K.S_XL] = x_start[j]
        S[K.S_V] = 0.0
        S[K.S_STUCK] = 1.0
        for step in range(horizon[j]):
            k = k0 + step
            # contact with the far edge: the load is taken along from here on
            if (S[K.S_X] - x_start[j]) * dirs[j] >= reach[j]:
                break
            xm[k] = S[K.S_X]
            # sub-steps that see the same input go in one call (a held command changes
            # once per sample at most)
            s = 0
            while s < n_sub:
                val = _input_at(u, k + (s + 0.5) / n_sub - shift, interpolate)
                e = s + 1
                while e < n_sub and _input_at(u, k + (e + 0.5) / n_sub - shift,
                                              interpolate) == val:
                    e += 1
                K.plant_advance(P, S, val, 0.0, e - s)
                s = e


__all__ = ['motor_position', 'reversals']


# Python calls the kernels above through their entries: compiled ahead of time where
# built (see motor_comp.physics.aot), else the JIT
_reversals_entry = aot.entry(_reversals)
_flights_entry = aot.entry(_flights)
