"""Position-dependent dry friction: the level varies along the travel, ``fc + dfc(x)``.

Tight spots, wear and contamination of a guideway or a screw raise (or lower) the dry
friction over part of the travel (DESIGN.md §6, issue 23).  ``dfc(x)`` [N] is a cubic
spline through knots ``x_j`` [m] with values ``dfc_j`` [N], **clamped** with zero slope
at the end knots and constant beyond them; it shifts the Coulomb level and the
break-away (Stribeck) level alike, so the static curve becomes
``[fc + dfc(x) + (fs − fc)·e^{−|ẋ/vs|^δ}]·sgn(ẋ)`` and the Karnopp band at rest
``±(fs + dfc(x))``.  No paper is behind the shape: a tight spot is a local excess of the
friction level, and a smooth interpolation through a few measured levels is the least
one can assume about it.

Why this spline.  The identification fits ``dfc`` by least squares, so the law must be
linear in the knot values: ``dfc(x) = Σ_j dfc_j·b_j(x)`` with fixed basis functions
``b_j`` (:meth:`PositionFriction.basis`).  An interpolating cubic spline is (its
slopes solve a linear system in the values); the zero end slopes make the constant
continuation beyond the end knots continuous in slope too (C¹ on the whole line), where
a natural spline would leave a kink in the friction level at each end of the span.  The
spline is written in Hermite form — knot values and knot slopes, the slopes ``S·dfc``
from the clamped-spline system solved once (:func:`slope_matrix`) —
so it passes through every knot value exactly, and the compiled law
(:func:`spline_sum`) is a bisection and one cubic.  A law evaluated inside the plant's
RK4 stages cannot call scipy, which is why the evaluation is written here.

Bounds: 2..:data:`MAX_KNOTS` knots, strictly increasing by at least
:data:`MIN_SPACING`, within ±:data:`MAX_POSITION`; ``|dfc| <= MAX_LEVEL``.  The level
``fc + dfc(x)`` must not go below 0 anywhere: the model (:class:`AxisModel`) checks
``fc + min dfc(x) >= 0`` over the knots' span (the spline may dip below its lowest knot
value between knots: :attr:`PositionFriction.lowest` finds the true minimum).  What the
model cannot check — a direction-dependent level ``fc − |asymmetry.dfc|/2 + dfc(x)``
that goes negative, as an over-fitted asymmetry can — is handled as the kernel handles
asymmetry: a negative break-away level counts as zero at rest.

Units: x [m], dfc [N]; on a rotary axis read rad and N·m.
"""
from __future__ import annotations

import dataclasses
import functools
from typing import Any, Mapping

import numpy as np
from numba import njit

from motor_comp.errors import ParameterError, check_finite
from motor_comp.physics import aot
from motor_comp.physics.effects.base import Effect
from motor_comp.physics.effects.identification import Column, Context, LocalBasis, Shape, \
    Summary, Term

#: largest number of knots the compiled kernels carry
MAX_KNOTS = 32
#: knots lie within ±this [m or rad]: 1000 km of travel or 160 000 revolutions, beyond
#: any axis, and far enough from overflow for the spline's powers of the spacing
MAX_POSITION = 1e6
#: closest knot spacing [m or rad]: a friction profile finer than a nanometre (or
#: nanoradian) is below any encoder; it also keeps the slopes ``dfc/spacing`` finite
MIN_SPACING = 1e-9
#: largest |dfc| at a knot [N or N·m]
MAX_LEVEL = 1e9


@njit(cache=True, inline='always', error_model='numpy')
def spline_sum(x, knots, ik, values, iv, slopes, im, n):
    """Friction-level change ``dfc(x)`` [N] at ``x`` [m] of a Hermite cubic through knots.

    The knots are ``knots[ik + j]`` (strictly increasing), the values
    ``values[iv + j]`` [N] and the slopes ``slopes[im + j]`` [N/m], ``j < n``, ``n >= 2``:
    packed vectors with offsets, as the plant kernel passes its parameter vector (no
    array views in its inner loop).  Constant beyond the end knots; exactly the knot
    value at a knot.  On a segment of length ``h`` with ``t = (x − x_j)/h``, ``s = 1 − t``
    (Hermite basis): ``(1 + 2t)·s²·y_j + t²·(3 − 2t)·y_{j+1} + h·t·s·(s·m_j − t·m_{j+1})``.

    Parameters
    ----------
    x : float
        Position [m].
    knots, values, slopes : ndarray
        Packed knot positions [m], values [N] and slopes [N/m].
    ik, iv, im : int
        Offsets of the first knot, value and slope.
    n : int
        Number of knots.
    """
    if x <= knots[ik]:
        return values[iv]
    if x >= knots[ik + n - 1]:
        return values[iv + n - 1]
    lo = 0
    hi = n - 1
    while hi - lo > 1:            # bisection: at most 5 halvings for 32 knots
        mid = (lo + hi) >> 1
        if knots[ik + mid] <= x:
            lo = mid
        else:
            hi = mid
    x0 = knots[ik + lo]
    h = knots[ik + hi] - x0
    t = (x - x0) / h
    s = 1.0 - t
    return ((1.0 + 2.0 * t) * s * s * values[iv + lo]
            + t * t * (3.0 - 2.0 * t) * values[iv + hi]
            + h * t * s * (s * slopes[im + lo] - t * slopes[im + hi]))


@aot.ahead(aot.F8_1D, aot.F8_1D, aot.F8_1D, aot.array(1, readonly=True))
@njit(cache=True, error_model='numpy')
def position_friction_dfc(x, knots, values, slopes):
    """Return ``dfc(x)`` [N] at each position of the array ``x`` [m] (see :func:`spline_sum`).

    Parameters
    ----------
    x : ndarray
        Positions [m].
    knots, values, slopes : ndarray
        Knot positions [m] (strictly increasing), values [N] and slopes [N/m].
    """
    out = np.empty(x.shape[0])
    n = knots.shape[0]
    for i in range(x.shape[0]):
        out[i] = spline_sum(x[i], knots, 0, values, 0, slopes, 0, n)
    return out


@aot.ahead(aot.F8_1D, aot.F8_1D, aot.I8_1D, aot.array(2, readonly=True), aot.F8_1D, aot.I8)
@njit(cache=True)
def _hermite_basis(t, h, lo, slopes, sign, first):
    """Columns of :meth:`PositionFriction.basis`, transposed: one row per knot from ``first``.

    Sample ``i`` lies in the interval ``lo[i]`` (length ``h[i]``, local coordinate
    ``t[i]``): the end values' weights at ``lo``/``lo + 1`` plus the slopes' weights
    through ``m = S·dfc``, each product in the order the array form took them; times
    ``sign[i]`` when ``sign`` is not empty.  Written knot by knot (each knot's samples
    contiguous), as the workbench's smoother reads a block of columns: transposing and
    multiplying an n × knots array afterwards cost more than the weights.
    """
    n, k = t.shape[0], slopes.shape[0]
    out = np.empty((k - first, n))
    w = np.empty(k)
    signed = sign.shape[0] > 0
    for i in range(n):
        ti = t[i]
        si = 1.0 - ti
        a = h[i] * ti * si * si
        b = h[i] * ti * ti * si
        j0 = lo[i]
        for j in range(k):
            # 0.0 + …: the array form added into zeros (a −0.0 product becomes +0.0)
            w[j] = 0.0 + (a * slopes[j0, j] - b * slopes[j0 + 1, j])
        # the end values' weights: the array form assigned them into zeros, then added
        w[j0] = (1.0 + 2.0 * ti) * si * si + w[j0]
        w[j0 + 1] = ti * ti * (3.0 - 2.0 * ti) + w[j0 + 1]
        if signed:
            for j in range(first, k):
                out[j - first, i] = w[j] * sign[i]
        else:
            for j in range(first, k):
                out[j - first, i] = w[j]
    return out


@aot.ahead(aot.F8_1D, aot.F8_1D, aot.I8_1D, aot.F8_1D, aot.I8)
@njit(cache=True)
def _hermite_local(t, h, lo, sign, k):
    """Local form of :func:`_hermite_basis`: each sample's four nonzero weights.

    Sample ``i`` in interval ``j = lo[i]`` weighs the values of knots ``j``, ``j + 1``
    (functions ``j``, ``j + 1``) and their slopes (functions ``k + j``, ``k + j + 1``),
    times ``sign[i]`` when ``sign`` is not empty; returns the ``(n, 4)`` indices and
    values.
    """
    n = t.shape[0]
    index = np.empty((n, 4), np.int64)
    value = np.empty((n, 4))
    signed = sign.shape[0] > 0
    for i in range(n):
        ti = t[i]
        si = 1.0 - ti
        g = sign[i] if signed else 1.0
        j = lo[i]
        index[i, 0] = j
        index[i, 1] = j + 1
        index[i, 2] = k + j
        index[i, 3] = k + j + 1
        value[i, 0] = (1.0 + 2.0 * ti) * si * si * g
        value[i, 1] = ti * ti * (3.0 - 2.0 * ti) * g
        value[i, 2] = h[i] * ti * si * si * g
        value[i, 3] = -h[i] * ti * ti * si * g
    return index, value


#: no sign: :func:`_hermite_basis` returns the weights themselves
_NO_SIGN = np.zeros(0)


def slope_matrix(knots: np.ndarray) -> np.ndarray:
    """Return ``S`` (n × n) with the knot slopes of the clamped spline ``m = S·dfc`` [1/m].

    Column ``j`` holds the slopes of the spline through the unit values ``e_j``
    (the clamped spline: zero end slopes; the same numbers as
    :class:`scipy.interpolate.CubicSpline` with ``bc_type='clamped'``).
    A read-only array, cached per knot tuple: the workbench's search builds the
    columns of the same knots hundreds of times (0.45 s of a 3.6 s fit built splines).
    """
    return _slope_matrix(tuple(float(k) for k in np.asarray(knots, dtype=float)))


@functools.lru_cache(maxsize=256)
def _mix(knots: tuple, first: int) -> np.ndarray:
    # the map of PositionFriction.local_basis: the values' identity over the slopes' S
    n = len(knots)
    M = np.vstack([np.eye(n), slope_matrix(np.array(knots))])[:, first:]
    M = np.ascontiguousarray(M)
    M.setflags(write=False)
    return M


@functools.lru_cache(maxsize=256)
def _slope_matrix(knots: tuple) -> np.ndarray:
    # The clamped spline's continuity of curvature at each inner knot, in slope form
    # (de Boor, A Practical Guide to Splines, ch. IV):
    #   h_i·m_{i−1} + 2(h_{i−1} + h_i)·m_i + h_{i−1}·m_{i+1} = 3(h_i·δ_{i−1} + h_{i−1}·δ_i),
    # h_i = x_{i+1} − x_i, δ_i = (y_{i+1} − y_i)/h_i, m_0 = m_{n−1} = 0; solved with
    # numpy for the unit values (scipy.interpolate's import cost ~0.15 s of CPU a fit
    # for this small system; the tests compare against its CubicSpline).
    k = np.array(knots)
    n = k.shape[0]
    S = np.zeros((n, n))
    if n > 2:
        h = np.diff(k)
        A = np.zeros((n - 2, n - 2))
        B = np.zeros((n - 2, n))
        for r in range(n - 2):
            i = r + 1
            A[r, r] = 2.0 * (h[i - 1] + h[i])
            if r > 0:
                A[r, r - 1] = h[i]
            if r < n - 3:
                A[r, r + 1] = h[i - 1]
            B[r, i - 1] = -3.0 * h[i] / h[i - 1]
            B[r, i] = 3.0 * h[i] / h[i - 1] - 3.0 * h[i - 1] / h[i]
            B[r, i + 1] = 3.0 * h[i - 1] / h[i]
        S[1:-1] = np.linalg.solve(A, B)
    S.setflags(write=False)
    return S


@dataclasses.dataclass(frozen=True)
class PositionFriction(Effect):
    """Dry friction whose level varies along the travel (tight spots, wear).

    Parameters
    ----------
    x : tuple of float
        Knot positions [m], strictly increasing, 2..32 of them.
    dfc : tuple of float
        Change of the dry-friction level at each knot [N] (added to ``coulomb.fc`` and
        ``stribeck.fs``), one per knot.  Between knots a clamped cubic spline, beyond
        the end knots the end value.
    """

    name = 'position_friction'
    position_dependent = True
    title = 'position-dependent friction'
    x: tuple
    dfc: tuple

    def __post_init__(self) -> None:
        knots = _numbers('position_friction.x', 'm', self.x)
        values = _numbers('position_friction.dfc', 'N', self.dfc)
        if not 2 <= len(knots) <= MAX_KNOTS:
            raise ParameterError(f'position_friction.x [m] must have 2..{MAX_KNOTS} knots, '
                                 f'got {len(knots)}')
        if len(values) != len(knots):
            raise ParameterError(f'position_friction.dfc has {len(values)} values but x has '
                                 f'{len(knots)} knots')
        for i in range(1, len(knots)):
            if not knots[i] > knots[i - 1]:
                raise ParameterError(
                    f'position_friction.x [m] must be strictly increasing, but x[{i}] = '
                    f'{knots[i]:g} <= x[{i - 1}] = {knots[i - 1]:g}')
            if not knots[i] - knots[i - 1] >= MIN_SPACING:
                raise ParameterError(
                    f'position_friction.x [m]: knots x[{i - 1}] and x[{i}] are closer than '
                    f'{MIN_SPACING:g} m')
        for i, xk in enumerate(knots):
            if abs(xk) > MAX_POSITION:
                raise ParameterError(f'position_friction.x[{i}] [m] must lie within '
                                     f'±{MAX_POSITION:g}, got {xk:g}')
        for i, yk in enumerate(values):
            if abs(yk) > MAX_LEVEL:
                raise ParameterError(f'position_friction.dfc[{i}] [N] must lie within '
                                     f'±{MAX_LEVEL:g}, got {yk:g}')
        object.__setattr__(self, 'x', knots)
        object.__setattr__(self, 'dfc', values)
        try:
            slopes = slope_matrix(np.array(knots)) @ np.array(values)
        except (ValueError, FloatingPointError, np.linalg.LinAlgError):
            slopes = np.array([np.nan])
        if not np.all(np.isfinite(slopes)):   # not reached within the bounds above
            raise ParameterError('position_friction: no finite spline through these knots')
        slopes.setflags(write=False)
        # derived, not a field: equality, the model file and replace() see x and dfc only
        object.__setattr__(self, '_slopes', slopes)

    @property
    def knots(self) -> np.ndarray:
        """Knot positions [m]."""
        return np.array(self.x)

    @property
    def values(self) -> np.ndarray:
        """Level change at the knots [N]."""
        return np.array(self.dfc)

    @property
    def slopes(self) -> np.ndarray:
        """Slope of ``dfc`` at each knot [N/m] (zero at both end knots)."""
        return self._slopes  # type: ignore[attr-defined]

    @property
    def span(self) -> tuple[float, float]:
        """First and last knot [m]."""
        return self.x[0], self.x[-1]

    def level(self, x: np.ndarray) -> np.ndarray:
        """Change of the dry-friction level ``dfc(x)`` [N] at positions ``x`` [m]."""
        x = np.ascontiguousarray(np.atleast_1d(np.asarray(x, dtype=float)))
        return position_friction_dfc_entry(x, self.knots, self.values, self.slopes)

    def force(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Extra friction force ``dfc(x)·sgn(v)`` [N] at positions [m] and velocities [m/s]."""
        x = np.asarray(x, dtype=float)
        v = np.asarray(v, dtype=float)
        return self.level(x.ravel()).reshape(np.shape(x)) * np.sign(v)

    def basis(self, x: np.ndarray, sign: np.ndarray | None = None, *,
              first: int = 0) -> np.ndarray:
        """Return the spline's basis functions ``b_j`` at ``x``: ``dfc(x) = B @ dfc``.

        ``B`` has one row per position and one column per knot (n × n_knots).
        Column ``j`` is the spline through the unit values ``e_j`` (same knots, same
        clamped ends, constant beyond them): the identification's columns for the
        knot values.  The columns sum to 1 at every ``x`` (a constant ``dfc`` is a
        Coulomb level).  Column-major (each column's samples contiguous).

        Parameters
        ----------
        x : ndarray
            Positions [m], any shape (flattened).
        sign : ndarray, optional
            A factor per position (the direction of motion): ``B`` times it, row by row.
        first : int
            The first knot whose column is returned (the columns before it are left out).
        """
        x = np.asarray(x, dtype=float).ravel()
        knots = self.knots
        n = knots.shape[0]
        slopes = slope_matrix(knots)
        xc = np.clip(x, knots[0], knots[-1])
        lo = np.clip(np.searchsorted(knots, xc, side='right') - 1, 0, n - 2)
        hi = lo + 1
        h = knots[hi] - knots[lo]
        t = (xc - knots[lo]) / h
        # the Hermite weights of spline_sum: the values at lo/hi and, through the
        # slopes m = S·dfc, every knot value (compiled: one pass over the n × knots
        # output instead of eight array passes, 0.3 s of a 60 s run's fit)
        sign = _NO_SIGN if sign is None else np.ascontiguousarray(sign, dtype=float)
        return _hermite_basis_entry(t, h, lo, np.ascontiguousarray(slopes), sign,
                                    int(first)).T

    def local_basis(self, x: np.ndarray, sign: np.ndarray | None = None, *,
                    first: int = 0) -> LocalBasis:
        """Return :meth:`basis` as a basis local in the samples and a map: ``B = L·mix``.

        The Hermite form ``b_j(x) = h00(t)·[j = lo] + h01(t)·[j = lo + 1] + h·(a(t)·S[lo, j]
        − b(t)·S[lo + 1, j])`` is local in the knot values and slopes of the interval
        each position lies in (four functions of ``2·n_knots``), and global only through
        the slope matrix ``S``: ``L`` holds those four weights (times ``sign``), ``mix``
        stacks the identity over ``S`` (columns from ``first``).  The workbench smooths
        ``L`` and maps it (:class:`~.identification.LocalBasis`): the same block as
        :meth:`basis`, to rounding.
        """
        x = np.asarray(x, dtype=float).ravel()
        knots = self.knots
        n = knots.shape[0]
        xc = np.clip(x, knots[0], knots[-1])
        lo = np.clip(np.searchsorted(knots, xc, side='right') - 1, 0, n - 2)
        h = knots[lo + 1] - knots[lo]
        t = (xc - knots[lo]) / h
        sign = _NO_SIGN if sign is None else np.ascontiguousarray(sign, dtype=float)
        index, value = _hermite_local_entry(t, h, lo, sign, n)
        return LocalBasis(index, value, _mix(tuple(float(k) for k in knots), int(first)))

    def regressors(self, x: np.ndarray, v: np.ndarray) -> np.ndarray:
        """Columns ``b_j(x)·sgn(v)``; coefficients ``dfc_j`` [N]."""
        return self.basis(x, np.sign(np.asarray(v, dtype=float).ravel()))

    @property
    def lowest(self) -> tuple[float, float]:
        """Return ``(x, dfc(x))`` at the minimum of ``dfc`` over the knots' span [m, N].

        The candidates are the knots and the interior stationary points of each cubic
        (the roots of its derivative, a quadratic in the Hermite form); the values
        there come from this module's own law.
        """
        k, y, m = self.knots, self.values, self.slopes
        crit = []
        for i in range(len(k) - 1):
            h = k[i + 1] - k[i]
            # d/dt of the Hermite cubic on t ∈ [0, 1]: a·t² + b·t + c
            a = 6.0 * (y[i] - y[i + 1]) + 3.0 * h * (m[i] + m[i + 1])
            b = 6.0 * (y[i + 1] - y[i]) - h * (4.0 * m[i] + 2.0 * m[i + 1])
            c = h * m[i]
            roots = np.roots([a, b, c]) if a or b else np.zeros(0)
            crit += [k[i] + float(t.real) * h for t in roots
                     if abs(t.imag) <= 1e-12 and 0.0 < t.real < 1.0]
        cand = np.concatenate([self.knots, np.array(crit, dtype=float)])
        vals = self.level(cand)
        i = int(np.argmin(vals))
        return float(cand[i]), float(vals[i])

    def params(self) -> dict[str, Any]:
        """Parameters in model-file form: ``{x: [m...], dfc: [N...]}``."""
        return {'x': [float(v) for v in self.x], 'dfc': [float(v) for v in self.dfc]}


def _numbers(key: str, unit: str, seq: Any) -> tuple[float, ...]:
    """Return ``seq`` as a tuple of finite floats or raise a one-line ParameterError."""
    if isinstance(seq, (str, bytes)) or not hasattr(seq, '__iter__'):
        raise ParameterError(f'{key} [{unit}] must be a list of numbers')
    return tuple(check_finite(f'{key}[{i}] [{unit}]', v) for i, v in enumerate(seq))


#: knot counts the identification chooses among (by an information criterion), up to
#: what the kernels carry: a tight spot narrower than the knot spacing is drawn coarse.
#: On the generator's runs with one (5 cases × seeds 1–3, bench/workbench_independent.py
#: --list new-effects), a cap of 24 left a feature of it in 13 of 15 fits (14–81 % of
#: the residual; NRMSE over the true model's p50 1.64, max 7.4); at 32, in 11 of 15
#: (14–73 %; p50 1.18, max 3.7)
FIT_KNOTS = (4, MAX_KNOTS)
#: least share of the travel crossed in both directions for the run to judge the term
MIN_SHARED = 0.5


def uniform_knots(lo: float, hi: float, n: int) -> tuple[float, ...]:
    """Return ``n`` knots spread evenly over ``[lo, hi]`` [m]."""
    return tuple(float(v) for v in np.linspace(lo, hi, int(n)))


class PositionFrictionTerm(Term):
    """Identification of friction that varies along the travel: knot values on splines.

    With the knots held (spread evenly over the travel seen), ``dfc(x) = Σ_j dfc_j·b_j(x)``
    is linear in the knot values, so each knot's column is its basis function times the
    signed share of sliding (a friction flips with the motion).  The basis functions sum
    to 1, so a constant ``dfc`` is the Coulomb level: the first knot's value is held at 0
    (the friction along the travel is told relative to the travel's start) and the level
    there is ``fc``.  The knot count is the term's order, chosen by an information
    criterion (4–32 knots).  Inside the estimator the level stays a friction at every
    knot, ``fc + dfc_j ≥ 0``.
    """

    name = 'position_friction'
    #: in a residual's scan: a friction that varies along the travel
    shape = Shape('position', odd=True)
    effect = PositionFriction
    requires = ('coulomb',)
    dry_friction = True

    def orders(self, s: Summary, eta: Mapping) -> tuple[int, int]:
        """Return the knot counts allowed."""
        return FIT_KNOTS

    def order_of(self, eta: Mapping) -> int:
        """Return the knot count."""
        return len(eta.get('x', ()))

    def with_order(self, eta: Mapping, order: int) -> dict:
        """Return ``eta`` with ``order`` knots over the same span."""
        x = eta['x']
        return dict(eta, x=uniform_knots(x[0], x[-1], order))

    def applicable(self, s: Summary) -> str | None:
        """Refuse a run that crosses too little of its travel in both directions.

        A friction is told from a force along the travel only by its sign flipping with
        the motion at the same positions: where each direction covers its own stretch
        (one-way runs over different ranges) the knot values fit any force there, and a
        direction dependence (on HSM150's four one-way runs the term stood in for it).
        """
        why = super().applicable(s)
        if why:
            return why
        lo, hi = s.shared_span if s.shared_span else (0.0, 0.0)
        if hi - lo < MIN_SHARED * s.travel:
            return (f'{self.name} is told from a force along the travel only by motion both '
                    f'ways over the same positions: the runs cross '
                    f'{100 * max(hi - lo, 0.0) / max(s.travel, 1e-300):.0f} % of their travel '
                    f'both ways (at least {100 * MIN_SHARED:.0f} % needed)')
        return None

    def initial(self, s: Summary, ctx: Context, profile: Any) -> list[dict]:
        """Return eight knots over the travel crossed both ways."""
        lo, hi = s.shared_span if s.shared_span else s.span
        return [{'x': uniform_knots(lo, hi, 8)}]

    def columns(self, eta: Mapping, ctx: Context) -> list[Column]:
        """Return one column per knot but the first."""
        knots = tuple(eta['x'])
        pf = PositionFriction(x=knots, dfc=(0.0,) * len(knots))

        def block(p: Any) -> np.ndarray:
            return pf.basis(p.x, p.fwd - p.bwd, first=1)

        # the same block on the spline's local basis, which the workbench smooths in its
        # place: the knot-count search smoothed up to 31 dense columns a count, 0.12 of
        # the 0.59 s it took on the 60 s bench run, and built them in 0.15 s more
        def local(p: Any) -> LocalBasis:
            return pf.local_basis(p.x, p.fwd - p.bwd, first=1)
        # its levels held inside the estimator to a quarter of what the effect holds, so
        # that the lift of a spline's dip (:meth:`encode`; the spline through levels
        # within ±L on the term's uniform knots stays within ±1.5 L) keeps them inside:
        # knots over a stretch the run barely crosses leave near-collinear columns, and
        # levels of 3e26 N reached the effect's own check as an input error (a search
        # trial on the generator's GMS sine run, seed 4)
        return [Column(f'dfc{j}', ('position_friction', knots, j), block,
                       width=len(knots) - 1, index=j - 1, local=local,
                       lo=-0.25 * MAX_LEVEL, hi=0.25 * MAX_LEVEL)
                for j in range(1, len(knots))]

    def constraints(self, ctx: Context) -> list:
        """Keep the level a friction at every knot, ``fc + dfc_j ≥ 0``."""
        if 'coulomb' not in ctx.present or 'presliding' in ctx.present:
            return []
        knots = ctx.eta.get(self.name, {}).get('x', ())
        return [({('coulomb', 'fc'): 1.0, (self.name, f'dfc{j}'): 1.0}, 0.0)
                for j in range(1, len(knots))]

    def _dfc(self, values: Mapping, n: int) -> tuple[float, ...]:
        return (0.0,) + tuple(float(values.get((self.name, f'dfc{j}'), 0.0))
                              for j in range(1, n))

    def encode(self, values: Mapping, eta: Mapping, ctx: Context) -> list[Effect]:
        """Return the fitted friction along the travel."""
        knots = tuple(eta['x'])
        dfc = self._dfc(values, len(knots))
        pf = PositionFriction(x=knots, dfc=dfc)
        fc = float(values.get(('coulomb', 'fc'), 0.0))
        low = pf.lowest[1]
        if fc + low < 0.0:        # a dip of the spline between knots below zero friction
            pf = PositionFriction(x=knots, dfc=tuple(d - (fc + low) for d in dfc))
        return [pf]

    def decode(self, model: Any) -> tuple[dict, dict]:
        """Return the knot values relative to the first (its value goes to ``fc``)."""
        e = model.get(self.name)
        d0 = e.dfc[0]
        coef: dict = {f'dfc{j}': v - d0 for j, v in enumerate(e.dfc) if j}
        if d0:
            coef[('coulomb', 'fc')] = d0
        return coef, {'x': tuple(e.x)}

    def scalars(self, eta: Mapping, ctx: Context) -> dict:
        """Report the rise [N] along the travel and where it peaks [m]."""
        knots = tuple(eta['x'])
        grid = np.linspace(knots[0], knots[-1], 400)
        basis = PositionFriction(x=knots, dfc=(0.0,) * len(knots)).basis(grid)

        def curve(v: Mapping) -> np.ndarray:
            return basis @ np.array(self._dfc(v, len(knots)))
        return {(self.name, 'rise'): lambda v: float(np.ptp(curve(v))),
                (self.name, 'x_peak'): lambda v: float(grid[int(np.argmax(curve(v)))])}


TERM = PositionFrictionTerm()


# Python calls the kernels above through their entries: compiled ahead of time where
# built (see motor_comp.physics.aot), else the JIT
_hermite_basis_entry = aot.entry(_hermite_basis)
_hermite_local_entry = aot.entry(_hermite_local)
position_friction_dfc_entry = aot.entry(position_friction_dfc)
