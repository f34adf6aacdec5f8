"""Reference trajectories of the independent generator: the experiments users run.

Part of the independent data generator (:mod:`independent_generator` is the public
face); numpy only.  Every reference is returned as an ``(n, 3)`` array of position,
velocity and acceleration at the controller's step ``dt`` (SI; rad on rotary axes):

* ``sweep`` — back-and-forth strokes at each speed in time order (slow → fast, then
  fast → slow), a dwell at every reversal: the usual identification experiment;
* ``interleaved`` — the same strokes, one pair per speed, the speed order changing every
  round along a balanced Latin square (Williams 1949), so that every speed is visited
  early and late in the run and time is not confounded with speed (a drift over time
  is then not a speed dependence);
* ``chirp`` — a linear chirp with the amplitude limited to a peak speed;
* ``sine`` — plain sine tracking at one frequency (the ordinary task of a servo axis,
  Chiew et al.'s slow sine with reversals), faded in over the first second.
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np


def _trapezoid(p0: float, p1: float, vmax: float, amax: float, dt: float) \
        -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sample (position, velocity, acceleration) of a trapezoidal move p0 → p1."""
    dist = abs(p1 - p0)
    sgn = 1.0 if p1 >= p0 else -1.0
    if dist == 0.0:
        return np.zeros(0), np.zeros(0), np.zeros(0)
    ta = vmax / amax
    if amax * ta * ta > dist:        # triangular profile
        ta = math.sqrt(dist / amax)
        vmax = amax * ta
    tc = (dist - amax * ta * ta) / vmax
    total = 2 * ta + tc
    t = np.arange(0.0, total, dt)
    s = np.where(t < ta, 0.5 * amax * t ** 2,
                 np.where(t < ta + tc, 0.5 * amax * ta ** 2 + vmax * (t - ta),
                          dist - 0.5 * amax * (total - t) ** 2))
    vel = np.where(t < ta, amax * t, np.where(t < ta + tc, vmax, amax * (total - t)))
    acc = np.where(t < ta, amax, np.where(t < ta + tc, 0.0, -amax))
    return p0 + sgn * s, sgn * vel, sgn * acc


def sweep_reference(*, speeds: Sequence[float], stroke: float, accel: float, dt: float,
                    duration: float, dwell: float = 0.1, min_time: float = 0.6,
                    cycles: int = 2, centre: float = 0.0) -> np.ndarray:
    """Build back-and-forth strokes at each speed in time order (slow → fast), repeated.

    Each speed runs ``cycles`` forward/backward pairs over a stroke of at most
    ``stroke`` (shorter at slow speeds so a stroke takes about ``min_time`` at full
    speed), centred on ``centre``, with a ``dwell`` [s] at rest at every reversal.  The
    pattern repeats (alternately fast → slow) until ``duration``.  Returns (n, 3):
    position, velocity, acceleration at step ``dt``.
    """
    n = int(round(duration / dt))

    def half_stroke(sp: float) -> float:
        return 0.5 * min(stroke, max(sp * min_time, 6 * sp * sp / accel))

    # a short run makes one cycle per speed, so that it still reaches the full travel
    one = sum(2 * (2 * half_stroke(sp) / sp + sp / accel + dwell) for sp in speeds)
    if cycles > 1 and cycles * one > duration:
        cycles = 1
    parts = []
    total = 0
    order = list(speeds)
    pos = centre
    while total < n:
        for sp in order:
            half = half_stroke(sp)
            for _ in range(cycles):
                for target in (centre + half, centre - half):
                    seg = _trapezoid(pos, target, sp, accel, dt)
                    pos = target
                    rest = int(round(dwell / dt))
                    block = np.stack(seg, axis=1)
                    still = np.tile([pos, 0.0, 0.0], (rest, 1))
                    parts += [block, still]
                    total += block.shape[0] + rest
        order = order[::-1]
    out = np.concatenate(parts)[:n]
    return out


def chirp_reference(*, f0: float, f1: float, amplitude: float, vmax: float, dt: float,
                    duration: float, centre: float = 0.0) -> np.ndarray:
    """Build a linear chirp ``f0 → f1`` [Hz], its amplitude limited to peak speed ``vmax``.

    The amplitude fades in and out over 1 s (no step in velocity).  Returns (n, 3).
    """
    n = int(round(duration / dt))
    t = np.arange(n) * dt
    rate = (f1 - f0) / duration
    phase = 2 * np.pi * (f0 * t + 0.5 * rate * t ** 2)
    f = f0 + rate * t
    amp = np.minimum(amplitude, vmax / (2 * np.pi * f))
    ramp = np.clip(np.minimum(t, duration - t) / 1.0, 0.0, 1.0)
    env = amp * 0.5 * (1 - np.cos(np.pi * ramp))
    x = centre + env * np.sin(phase)
    v = np.gradient(x, dt)
    a = np.gradient(v, dt)
    return np.stack([x, v, a], axis=1)


def williams_orders(n: int) -> list[list[int]]:
    """Return the rows of a balanced Latin square of order ``n`` (Williams 1949).

    Row ``r`` is ``(w_j + r) mod n`` with the first row ``0, 1, n−1, 2, n−2, …``; for even
    ``n`` every index follows every other exactly once over the rows, and every index
    takes every place in the order once.
    """
    first = [0]
    lo, hi = 1, n - 1
    while len(first) < n:
        first.append(lo)
        lo += 1
        if len(first) < n:
            first.append(hi)
            hi -= 1
    return [[(w + r) % n for w in first] for r in range(n)]


def interleaved_reference(*, speeds: Sequence[float], stroke: float, accel: float,
                          dt: float, duration: float, dwell: float = 0.1,
                          min_time: float = 0.3, centre: float = 0.0) -> np.ndarray:
    """Build strokes, one pair per speed, the speed order changing every round.

    The rounds follow :func:`williams_orders` of the speeds (then repeat), so a round
    takes a few seconds and every speed recurs through the run.  Strokes as in
    :func:`sweep_reference` (at most ``stroke``, about ``min_time`` [s] at full speed),
    centred on ``centre``, with a ``dwell`` [s] at rest at every reversal.  Returns
    (n, 3): position, velocity, acceleration at step ``dt``.
    """
    n = int(round(duration / dt))
    orders = williams_orders(len(speeds))
    parts = []
    total = 0
    pos = centre
    rnd = 0
    while total < n:
        for i in orders[rnd % len(orders)]:
            sp = speeds[i]
            half = 0.5 * min(stroke, max(sp * min_time, 6 * sp * sp / accel))
            for target in (centre + half, centre - half):
                seg = _trapezoid(pos, target, sp, accel, dt)
                pos = target
                rest = int(round(dwell / dt))
                block = np.stack(seg, axis=1)
                parts += [block, np.tile([pos, 0.0, 0.0], (rest, 1))]
                total += block.shape[0] + rest
        rnd += 1
    return np.concatenate(parts)[:n]


def sine_reference(*, frequency: float, amplitude: float, dt: float, duration: float,
                   centre: float = 0.0, fade: float = 1.0) -> np.ndarray:
    """Build sine tracking ``centre + E(t)·A·sin(2πft)`` with an analytic fade-in ``E``.

    ``E(t) = ½(1 − cos(πt/fade))`` over the first ``fade`` [s], then 1: velocity and
    acceleration start at zero.  Velocity and acceleration are the exact derivatives.
    Returns (n, 3).
    """
    n = int(round(duration / dt))
    t = np.arange(n) * dt
    w = 2 * np.pi * frequency
    k = np.pi / fade
    inside = t < fade
    env = np.where(inside, 0.5 * (1 - np.cos(k * t)), 1.0)
    d_env = np.where(inside, 0.5 * k * np.sin(k * t), 0.0)
    dd_env = np.where(inside, 0.5 * k * k * np.cos(k * t), 0.0)
    s, c = np.sin(w * t), np.cos(w * t)
    x = centre + amplitude * env * s
    v = amplitude * (d_env * s + env * w * c)
    a = amplitude * (dd_env * s + 2 * d_env * w * c - env * w * w * s)
    return np.stack([x, v, a], axis=1)
