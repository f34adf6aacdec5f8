"""What the residual still holds: a structure scan against the noise floor (DESIGN.md §6).

A model that fits is not a model that is complete.  The final model's *held-out*
residual (each fold's samples predicted by the parameters fitted on the others) is
regressed on a smooth function of one variable at a time — position, speed, the
magnitude of the drive force (the load), time since the start, time since the last
reversal — both as a force and as a friction (the residual times the direction of
motion, which a friction flips with), and its time spectrum is searched for a peak
(Welch).  The smooth function is a step function over equal-count bins, its bin count
chosen by held-out share (4–32 bins); the share is the held-out fraction of the
residual's energy it removes.

The same scan is run on the residual the model leaves on its own anchored runs measured
like this one (the noise floor's record, :mod:`.floor`): what the processing and the
sensor alone leave — a stick resolved between samples shows against the time since a
reversal even for a perfect model.  A structure is a **feature** when the energy it
holds exceeds what it holds on the floor's record by a real share of the residual
(:data:`FEATURE_SHARE`).  Each feature says where it acts, in plain words, and whether
an effect of the library has its shape; the model is said to be complete only when its
NRMSE is near the floor and no feature stands.
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping

import numpy as np

from motor_comp.physics.axis import Units
from motor_comp.physics.effects import TERMS
from motor_comp.workbench.dataset import Dataset
from motor_comp.workbench.library import Spec, design, given_residual, spec_of
from motor_comp.workbench.lsq import solve_gram
from motor_comp.workbench.optim import brent_bounded, next_fast_len
from motor_comp.workbench.spectral import density, stretches

#: least share of the residual's energy, beyond what the floor's record shows, that a
#: structure must hold to be reported as a feature
FEATURE_SHARE = 0.05
#: a model is near its floor when its NRMSE is within this factor of it
NEAR_FLOOR = 1.5
#: bin counts tried for the step functions
BINS = (4, 8, 16, 32)


def shape_of(against: str, odd: bool, trend: int = 0, level: bool = False) -> str:
    """Return the library effect whose declared shape a feature has ('' when none).

    The terms declare their own (:class:`~motor_comp.physics.effects.identification.
    Shape`): a feature against a variable with this parity, and rising (+1), falling
    (−1) or neither (0) along it, or a constant level.  A rise of friction with speed
    is a viscous slope's shape, a fall from the lowest speeds a Stribeck excess's —
    told apart by the trend, where one map of (variable, parity) said "Stribeck" for
    both (a missing viscous slope, 27 N at 171–300 mm/s, was hinted as ``fit --add
    stribeck`` while the candidates ranked viscous first at 97 %).
    """
    for name, t in TERMS.items():
        if t.shape is not None and t.shape.matches(against, odd, trend, level):
            return name
    return ''


@dataclasses.dataclass(frozen=True)
class Feature:
    """A structure of the residual beyond the noise floor.

    Attributes
    ----------
    against : str
        ``position | velocity | force | time | reversal | frequency``.
    odd : bool
        It flips with the direction of motion (a friction).
    where : tuple of float
        ``[lo, hi]`` in SI units of ``against`` (Hz for frequency; s since the last
        reversal for reversal).
    share : float
        Held-out share of the residual's energy it holds beyond the floor's record.
    amplitude : float
        Its size [N or N·m]: the largest step of its mean.
    text : str
        Plain words.
    shape_of : str
        A library effect with this shape that the model lacks ('' when none).
    level : float
        Its level [N or N·m] when it is mostly one (the median of its mean over the
        bins, holding more of its energy than the departures from it): a friction
        level when odd, a force of one sign when not; 0 otherwise and for a tone.
    trend : int
        +1 when its largest departure is a rise towards the top of what it is seen
        against (speed, the drive force's magnitude, position…), −1 a fall from the
        bottom (higher at the lowest speeds), 0 when the departure touches neither end
        or both.
    """

    against: str
    odd: bool
    where: tuple
    share: float
    amplitude: float
    text: str
    shape_of: str = ''
    level: float = 0.0
    trend: int = 0

    def as_dict(self) -> dict[str, Any]:
        """Return the JSON form (DESIGN.md §6 ``features`` entry)."""
        return {'against': self.against, 'odd': bool(self.odd),
                'where': [float(self.where[0]), float(self.where[1])],
                'share': float(self.share), 'amplitude': float(self.amplitude),
                'text': self.text, 'shape_of': self.shape_of or None,
                'level': float(self.level), 'trend': int(self.trend)}


@dataclasses.dataclass(frozen=True)
class Unexplained:
    """What the final model leaves: its NRMSE, the noise floor, the features.

    ``input_noise_force`` is the logged input's own white noise as a force [N or N·m]
    (estimated for a measured input, 0 for a command) and ``input_noise_nrmse`` the
    part of the floor it accounts for (:mod:`.floor`).
    """

    force_nrmse: float
    noise_floor_nrmse: float
    features: tuple
    complete: bool
    summary: str
    scans: tuple = ()
    input_noise_force: float = 0.0
    input_noise_nrmse: float = 0.0

    def as_dict(self) -> dict[str, Any]:
        """Return the JSON form of DESIGN.md §6 ``unexplained``."""
        return {'force_nrmse': float(self.force_nrmse),
                'noise_floor_nrmse': float(self.noise_floor_nrmse),
                'input_noise_force': float(self.input_noise_force),
                'input_noise_nrmse': float(self.input_noise_nrmse),
                'features': [f.as_dict() for f in self.features],
                'complete': bool(self.complete), 'summary': self.summary}


@dataclasses.dataclass(frozen=True)
class Profile:
    """The step function of one scan: bin edges and means, real and floor shares."""

    against: str
    odd: bool
    edges: np.ndarray
    means: np.ndarray
    share: float
    floor_share: float


def heldout_residual(data: Dataset, spec: Spec, model: Any) -> np.ndarray:
    """Return the residual at the rows, each fold's rows from the others' fit [N]."""
    d = design(data, spec, model)
    X, y = d.X, d.y
    P = data.part_grams(np.column_stack([X, y]))
    out = np.empty(data.n)
    part_of_row = np.repeat(np.arange(len(data.starts)), np.diff(np.append(data.starts, data.n)))
    for tr, te in zip(data.train_parts, data.test_parts):
        th, _ = solve_gram(P[tr].sum(axis=0), d.bounds)
        rows = te[part_of_row]
        out[rows] = y[rows] - X[rows] @ th
    return out


def variables(data: Dataset, spec: Spec, model: Any, r: np.ndarray) -> dict[str, np.ndarray]:
    """Return the scan variables at the rows: x, v, F, t, time since a reversal.

    The load is the drive force the model explains (the measured one less the residual
    ``r``): the measured force holds the residual itself, so any structure in time
    would show against it.
    """
    from motor_comp.workbench.library import view_for
    view = view_for(data, spec, model)
    x = view.gather(lambda p, mo: mo.x)
    v = view.gather(lambda p, mo: mo.v)
    t = view.gather(lambda p, mo: p.kin.t - p.kin.t[0])

    def since(p: Any, mo: Any) -> np.ndarray:
        s = np.sign(mo.v)
        flips = np.flatnonzero((s[1:] != s[:-1]) & (s[1:] != 0)) + 1
        last = np.zeros(len(s))
        idx = np.searchsorted(flips, np.arange(len(s)), side='right') - 1
        ok = idx >= 0
        last[ok] = (np.arange(len(s))[ok] - flips[idx[ok]]) * p.kin.dt
        last[~ok] = np.inf
        return last
    rev = view.gather(since)
    d = design(data, spec, model)
    return {'position': x, 'velocity': v, 'force': d.y - r, 'time': t, 'reversal': rev,
            'speed_sign': np.sign(v)}


class _Bins:
    """The bins of one scanned variable ``z`` and its rows' folds, shared by its scans.

    A variable is scanned against the residual and its direction-signed twin, at each
    bin count of :data:`BINS`: its quantile edges, the bin of each row and the rows
    of each (fold, bin) are found once per bin count.  Rows where ``z`` is not finite
    (no reversal yet) are in no bin.
    """

    def __init__(self, z: np.ndarray, fold: np.ndarray, folds: int) -> None:
        self.ok = np.isfinite(z)
        self.zs = z[self.ok]
        self.fold = fold[self.ok]
        self.folds = folds
        self._by: dict = {}

    def at(self, bins: int) -> tuple | None:
        """Return edges, bins, (fold, bin) keys and counts at ``bins`` bins (None: too few)."""
        if bins not in self._by:
            got = None
            if len(self.zs) >= 4 * bins:
                edges = np.unique(np.quantile(self.zs, np.linspace(0.0, 1.0, bins + 1)))
                if len(edges) >= 3:
                    nb = len(edges) - 1
                    idx = np.clip(np.searchsorted(edges, self.zs, side='right') - 1, 0,
                                  nb - 1)
                    key = self.fold * nb + idx
                    count = np.bincount(key, minlength=self.folds * nb)
                    got = (edges, idx, key, count.reshape(self.folds, nb))
            self._by[bins] = got
        return self._by[bins]


def _cv_share(zb: _Bins, r: np.ndarray, bins: int) -> tuple[float, np.ndarray, np.ndarray]:
    """Held-out energy share of ``r`` a step function of ``z`` removes, and its bins.

    Each fold's held-out rows are predicted by the bin means of the other folds' rows:
    the sums per (fold, bin) in one pass, a fold's training sums all rows' less its own.
    """
    got = zb.at(bins)
    if got is None:
        return 0.0, np.zeros(0), np.zeros(0)
    edges, idx, key, count = got
    rk = r[zb.ok]
    sums = np.bincount(key, weights=rk, minlength=count.size).reshape(count.shape)
    s, cnt = sums.sum(axis=0), count.sum(axis=0)
    tr_s, tr_cnt = s - sums, cnt - count
    mean = np.where(tr_cnt > 0, tr_s / np.maximum(tr_cnt, 1), 0.0)
    d = rk - mean[zb.fold, idx]
    total = float(rk @ rk)
    removed = total - float(d @ d)
    return (removed / total if total > 0 else 0.0), edges, np.where(cnt > 0, s / np.maximum(
        cnt, 1), 0.0)


def _best(zb: _Bins, r: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
    best = (0.0, np.zeros(0), np.zeros(0))
    for b in BINS:
        got = _cv_share(zb, r, b)
        if got[0] > best[0]:
            best = got
    return best


def _scanned(name: str, z: np.ndarray) -> np.ndarray:
    """Return what a variable is scanned against: speed and load by their magnitude.

    For both parts, the residual as a force the same both ways (even) and as a
    friction (odd): against the signed velocity the "even" scan held any function of
    it, a Coulomb step too, and won over the friction scan it contains (bench60's bare
    model: "force lower by 18.1 N at velocities −486 to −47.5 mm/s, the same sign both
    ways" for a missing Coulomb level).
    """
    return np.abs(z) if name in ('velocity', 'force') else z


def _scans(vars_: dict, r: np.ndarray, fold: np.ndarray, folds: int) -> dict:
    out = {}
    sgn = vars_['speed_sign']
    for name in ('position', 'velocity', 'force', 'time', 'reversal'):
        zb = _Bins(_scanned(name, vars_[name]), fold, folds)
        for odd in (False, True):
            rr = r * sgn if odd else r
            out[(name, odd)] = _best(zb, rr)
    return out


def _tone(data: Dataset, r: np.ndarray, t: np.ndarray) \
        -> tuple[float, float, float, np.ndarray]:
    """Return the residual's strongest tone: frequency [Hz], half-width [Hz], share, fit.

    The peak of the Welch spectrum of the contiguous stretches of rows (gaps are stops),
    refined to the sinusoid at that frequency that removes the most energy (least
    squares over the rows' own times); its share is the energy it removes.
    """
    dt = data.kins[0].dt
    segs, fs = stretches(data, r, 64)
    none = (0.0, 0.0, 0.0, np.zeros_like(r))
    if not segs:
        return none
    nper = int(min(256, min(len(s) for s in segs)))
    got = density(segs, fs, nper)
    if got is None:
        return none
    f, psd = got
    if len(psd) < 4 or psd[1:].sum() <= 0:
        return none
    k = int(np.argmax(psd[1:])) + 1
    df = float(f[1] - f[0])
    e0 = float(r @ r)
    if e0 <= 0:
        return none

    def fit_at(fr: float) -> tuple[float, np.ndarray]:
        A = np.column_stack([np.sin(2 * np.pi * fr * t), np.cos(2 * np.pi * fr * t)])
        th, *_ = np.linalg.lstsq(A, r, rcond=None)
        fit = A @ th
        return 1.0 - float((r - fit) @ (r - fit)) / e0, fit
    # a tone keeps its phase over the run: the frequency must be resolved to a small
    # part of 1/T, far finer than the Welch bins.  The periodogram of the rows on
    # their sample grid (gaps as zeros, padded 4×: a step of 1/(4T), the main lobe is
    # ±1/T wide) locates the peak in O(n log n) — a least-squares fit per trial
    # frequency grew as T² (12.6 s on a 120 s run) — and a bounded least-squares search
    # refines it
    span = float(np.ptp(t)) or 1.0
    h = dt           # the samples' own grid: the decimated rows do not share a phase
    idx = np.round((t - t.min()) / h).astype(np.int64)
    z = np.zeros(int(idx.max()) + 1)
    np.add.at(z, idx, r)
    nfft = next_fast_len(4 * len(z))
    power = np.abs(np.fft.rfft(z, nfft)) ** 2
    freqs = np.fft.rfftfreq(nfft, d=h)
    band = np.flatnonzero((freqs >= max(f[k] - df, df)) & (freqs <= f[k] + df))
    if len(band) == 0:
        return none
    j = int(band[np.argmax(power[band])])
    step_f = float(freqs[1] - freqs[0])
    opt = brent_bounded(lambda fr: -fit_at(fr)[0], max(freqs[j] - 2 * step_f, 0.5 * step_f),
                        freqs[j] + 2 * step_f, xatol=1e-4 / span)
    share, fit = fit_at(float(opt.x))
    return float(opt.x), 0.5 / span, share, fit


def _level(means: np.ndarray, counts: np.ndarray) -> float:
    """Return a step function's typical level when it holds most of the function's energy.

    A structure is described by its larger part: a residual that is mostly one level
    (the friction of a model without Coulomb friction, on every bin of whatever it is
    seen against) is that level, with its departures besides; 0 when the departures
    hold more (a bump, a ripple, a rise at low speed).
    """
    if len(means) == 0 or counts.sum() <= 0:
        return 0.0
    base = float(np.median(means))
    dep = float(counts @ (means - base) ** 2)
    return base if base * base * float(counts.sum()) >= dep else 0.0


def _where(edges: np.ndarray, means: np.ndarray) -> tuple[float, float, float, int]:
    """Return the span where a step function departs most from its typical level.

    Also its trend (:attr:`Feature.trend`): a departure that reaches the last bin and
    not the first rises towards the top when it is higher (+1), one that reaches the
    first and not the last falls from the bottom when it is higher (−1).
    """
    if len(means) == 0:
        return 0.0, 0.0, 0.0, 0
    base = float(np.median(means))
    dev = means - base
    k = int(np.argmax(np.abs(dev)))
    sign = np.sign(dev[k])
    lo = hi = k
    while lo > 0 and sign * dev[lo - 1] > 0.5 * abs(dev[k]):
        lo -= 1
    while hi < len(dev) - 1 and sign * dev[hi + 1] > 0.5 * abs(dev[k]):
        hi += 1
    first, last = lo == 0, hi == len(dev) - 1
    trend = int(sign) if last and not first else -int(sign) if first and not last else 0
    return float(edges[lo]), float(edges[hi + 1]), float(dev[k]), trend


def _rank(verdicts: Mapping[str, Any] | None, name: str) -> tuple:
    """Return how the candidates rank ``name``: paying (by share explained), not, unjudged.

    A term the candidates did not score is one this run cannot judge (or one the model
    holds); with no verdicts at all every term ranks alike.
    """
    if not name:
        return (-1, 0.0)
    v = (verdicts or {}).get(name)
    if v is None:
        return (0, 0.0)
    return (2 if v.supported else 1, float(v.explained))


def _text(against: str, odd: bool, lo: float, hi: float, amp: float, share: float,
          units: Units, shape: str, refused: str = '', inside: str = '',
          level: float = 0.0, alike: str = '') -> str:
    kind = 'friction' if odd else 'force'
    way = 'higher' if amp > 0 else 'lower'
    # a bin edge at zero comes out of the quantiles as a rounding (2e-16 mm/s): it is 0
    tiny = 1e-9 * max(abs(lo), abs(hi))
    lo, hi = (0.0 if abs(lo) <= tiny else lo), (0.0 if abs(hi) <= tiny else hi)
    if against == 'position':
        k, u = (1e3, 'mm') if not units.rotary else (1.0, 'rad')
        span = f'over {k * lo:.4g}–{k * hi:.4g} {u} of the travel'
    elif against == 'velocity':
        k, u = (1e3, 'mm/s') if not units.rotary else (1.0, 'rad/s')
        span = f'at speeds {k * lo:.4g}–{k * hi:.4g} {u}'
    elif against == 'force':
        span = f'at drive forces |F| {lo:.4g}–{hi:.4g} {units.force}'
    elif against == 'time':
        span = f'from {lo:.3g} s to {hi:.3g} s of the run (it changes over time)'
    elif against == 'reversal':
        span = f'{1e3 * lo:.3g}–{1e3 * hi:.3g} ms after a reversal'
    else:
        span = f'at {lo:.3g}–{hi:.3g} Hz'
    body = f'{kind} {way} by {abs(amp):.3g} {units.force} {span}'
    if not odd and against != 'frequency':
        body += ', the same sign both ways'
    if level:
        # mostly one level: that first, its largest departure besides
        if alike:
            # one way only: a friction level and a constant force are the same level
            head = f'a constant level of {level:.3g} {units.force}'
        elif not odd:
            head = f'a constant force of {level:.3g} {units.force}'
        elif level > 0:
            head = f'a friction level of {level:.3g} {units.force}'
        else:
            head = f'friction lower by {-level:.3g} {units.force} all along'
        body = head + (f', {way} by {abs(amp):.3g} {units.force} {span}'
                       if abs(amp) >= 0.1 * abs(level) else '')
    also = f', as has {alike} on this run, which moves one way only' if alike else ''
    if shape and refused:
        # the candidates' verdict on this model stands over the scan's shape hint
        tail = (f'; the library\'s {shape} has this shape{also}, but does not pay here: '
                f'{refused}')
    elif shape:
        tail = f'; the library\'s {shape} has this shape{also} (motor-comp fit --add {shape})'
    elif inside:
        # the model's own term of this shape leaves it: its law does not follow what is
        # here, and what it fitted may stand in for part of it
        tail = (f'; the model\'s {inside} has this shape{also} and leaves this: as fitted it '
                f'does not follow it, or it stands in for something else of this shape')
    else:
        tail = '; no effect in the library has this shape'
    return f'{body} — {100 * share:.0f} % of the residual beyond the noise floor{tail}'


def scan(data: Dataset, est: Any, floor: Any, *, units: Units,
         nrmse: float | None = None, verdicts: Mapping[str, Any] | None = None) \
        -> Unexplained:
    """Return what ``est``'s model leaves on ``data`` (see the module docstring).

    ``nrmse``: the model's held-out force NRMSE as its fit reported it (a speed-band
    weighted fit is scored by its own weighted folds); one figure for one model in
    every line.  Default: that of the scan's own held-out residual.  ``verdicts``: the
    candidates scored on this same model, by effect; a feature whose shape is an
    effect that did not pay there says so instead of suggesting ``fit --add``.
    """
    spec = est.spec
    model = est.model
    r = heldout_residual(data, spec, model)
    den = data.den
    if nrmse is None:
        nrmse = math.sqrt(float(r @ r) / den) if den > 0 else float('nan')
    fnr = float(getattr(floor, 'nrmse', float('nan')))
    vars_ = variables(data, spec, model, r)
    real = _scans(vars_, r, data.fold, data.folds)
    e_real = float(r @ r)
    fdata = getattr(floor, 'data', None)
    if fdata is not None and fdata.n > 0:
        rf = given_residual(fdata, model)
        fvars = variables(fdata, spec_of(model), model, rf)
        fl = _scans(fvars, rf, fdata.fold, fdata.folds)
        # the floor's energy per row, on this run's row count
        e_floor_rows = float(rf @ rf) / max(fdata.n, 1) * data.n
        f_tone = _tone(fdata, rf, fvars['time'])[2]
    else:
        fl, e_floor_rows, f_tone = {}, 0.0, 0.0
    feats: list[Feature] = []
    profiles = [Profile(k[0], k[1], e, m, sh, fl.get(k, (0.0,))[0])
                for k, (sh, e, m) in real.items()]
    # one structure at a time, each judged on what the ones found before leave (a
    # structure against position shows against time and force too in a sweep)
    cur = r.copy()
    used: set = set()
    tvar = vars_['time']
    direction = int(data.summary.direction)     # 0: the runs move both ways
    for _ in range(4):
        best = None
        scans = _scans(vars_, cur, data.fold, data.folds) if feats else real
        for key, (share, edges, means) in scans.items():
            if key[0] in used or len(means) == 0:
                continue
            fshare = fl.get(key, (0.0,))[0]
            beyond = (share * float(cur @ cur) - fshare * e_floor_rows) / e_real \
                if e_real > 0 else 0.0
            if best is None or beyond > best[0]:
                best = (beyond, key, edges, means)
        if 'frequency' not in used:
            f0, hw, tshare, tfit = _tone(data, cur, tvar)
            beyond = (tshare * float(cur @ cur) - f_tone * e_floor_rows) / e_real \
                if e_real > 0 else 0.0
            if f0 > 0 and (best is None or beyond > best[0]):
                best = (beyond, ('frequency', False), (f0, hw), tfit)
        if best is None or best[0] < FEATURE_SHARE:
            break
        beyond, key, edges, means = best
        against, odd = key
        used.add(against)
        if against == 'frequency':
            f0, hw = edges
            amp = float(np.sqrt(2.0 * np.mean(means ** 2)))
            feats.append(Feature('frequency', False, (f0 - hw, f0 + hw), beyond, amp,
                                 f'a disturbance of about {amp:.3g} {units.force} at '
                                 f'{f0:.3g} Hz, not tied to position or speed — '
                                 f'{100 * beyond:.0f} % of the residual beyond the noise '
                                 'floor; no effect in the library has this shape'))
            cur = cur - means
            continue
        lo, hi, amp, trend = _where(edges, means)
        z = _scanned(against, vars_[against])
        idx = np.clip(np.searchsorted(edges, z, side='right') - 1, 0, len(means) - 1)
        level = _level(means, np.bincount(idx[np.isfinite(z)], minlength=len(means)))
        shape = shape_of(against, odd, trend, bool(level))
        # on a run that moves one way a force and a friction of the same profile are
        # one column: the term of the other parity has the shape as much (its step
        # function the direction times this one: the trend too), and the candidates'
        # ranking (what pays, then what explains more) says which to name
        alike = shape_of(against, not odd, trend * direction, bool(level)) \
            if direction else ''
        if alike and _rank(verdicts, alike) > _rank(verdicts, shape):
            shape, alike = alike, shape
        inside = shape if shape in spec.names else ''
        if inside:
            shape = ''
        verdict = (verdicts or {}).get(shape) if shape else None
        refused = '' if verdict is None or verdict.supported else (
            verdict.why_not or 'it does not pay for its parameters on held-out data')
        feats.append(Feature(against, odd, (lo, hi), beyond, abs(amp),
                             _text(against, odd, lo, hi, amp, beyond, units, shape, refused,
                                   inside, level, alike), shape, level, trend))
        step = means[idx] * (vars_['speed_sign'] if odd else 1.0)
        cur = cur - np.where(np.isfinite(step), step, 0.0)
    near = math.isfinite(fnr) and nrmse <= NEAR_FLOOR * fnr
    complete = near and not feats
    sig = float(getattr(floor, 'input_noise', 0.0)) * float(model.input_gain)
    part_in = float(getattr(floor, 'input_nrmse', 0.0))
    of_it = (f' (the logged input\'s own noise, σ ≈ {sig:.3g} {units.force} as a force, '
             f'accounts for {100 * part_in:.2f} %)' if part_in > 0 else '')
    # the floor is what the model leaves on its own run (the twin): far above what it
    # leaves, held out, on this one, it overstates what this measurement leaves
    over = (f'; the noise floor, measured on the model\'s own run, is {fnr / nrmse:.1f}× '
            'what the model leaves on this one: it overstates what this measurement leaves'
            if nrmse > 0 and math.isfinite(fnr) and fnr > NEAR_FLOOR * nrmse else '')
    if complete:
        summary = (f'complete as far as this run shows: force NRMSE {100 * nrmse:.2f} % at the '
                   f'noise floor {100 * fnr:.2f} %{of_it}, and no structure left in the '
                   'residual')
    elif feats:
        summary = (f'not complete: force NRMSE {100 * nrmse:.2f} % against a noise floor of '
                   f'{100 * fnr:.2f} %{of_it}; the residual still holds: '
                   + '; '.join(f.text for f in feats[:3]))
    else:
        summary = (f'force NRMSE {100 * nrmse:.2f} % against a noise floor of {100 * fnr:.2f} %'
                   f'{of_it}: more is left than the measurement explains, but no structure '
                   'against position, velocity, load, time, reversals or frequency stands out')
    return Unexplained(force_nrmse=nrmse, noise_floor_nrmse=fnr, features=tuple(feats),
                       complete=complete, summary=summary + over, scans=tuple(profiles),
                       input_noise_force=sig, input_noise_nrmse=part_in)


__all__ = ['FEATURE_SHARE', 'Feature', 'NEAR_FLOOR', 'Profile', 'Unexplained',
           'heldout_residual', 'scan', 'shape_of']
