"""Rigs, drawn parameters and generated runs of the independent generator.

Part of the independent data generator (:mod:`independent_generator` is the public
face).  Never imports ``motor_comp.physics`` / ``motor_comp.control``; the only project
import is the run container (:class:`motor_comp.logs.run.Run`, the currency of every
offline tool).  The laws are in :mod:`indgen_laws`, the experiments in
:mod:`indgen_excitation`.

A case is drawn from a seed: a rig (drive, sensors, rates, sweep design), the TRUE model
as a model-file mapping (DESIGN.md §6; every effect of the library's vocabulary this
generator implements, incl. ``load_friction`` and ``position_friction``), and optionally
*extras* — effects no unit of the library models (:data:`EXTRA_NAMES`), kept out of the
model file (no model can hold them) and described by their ground truth instead
(:class:`Planted`: where they act, whether they flip with the direction of motion,
their share of the drive force).  The noise the generator adds is stated per run
(:class:`NoiseTruth`).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Any, Mapping, Sequence

import numpy as np

from indgen_excitation import chirp_reference, interleaved_reference, sine_reference, \
    sweep_reference
import indgen_laws as law
from indgen_laws import EXTRA_NAMES, hermite_tangents, MAX_KNOTS
from motor_comp.logs.run import Run

#: effect names of DESIGN.md §6 this generator implements (canonical order)
EFFECT_NAMES = ('coulomb', 'viscous', 'stribeck', 'presliding', 'ripple', 'offset', 'spring',
                'asymmetry', 'delay', 'backlash', 'gravity', 'load_friction',
                'position_friction')

#: effects a case needs alongside another for the law to be physical (Stribeck, GMS and
#: every dry-friction modifier act on a dry-friction level; asymmetry splits existing
#: Coulomb and viscous levels)
REQUIRES = {'stribeck': ('coulomb',), 'presliding': ('coulomb',),
            'asymmetry': ('coulomb', 'viscous'), 'load_friction': ('coulomb',),
            'position_friction': ('coulomb',), 'friction_drift': ('coulomb',),
            'speed_dip': ('coulomb',), 'reversal_transient': ('coulomb',)}

#: the experiments :func:`generate` can run
EXCITATIONS = ('sweep', 'interleaved', 'chirp', 'sine')

#: GMS element shapes (α, relative k) of this generator: 1 to 3 elements, none the
#: project's 4-element (0.45, 0.30, 0.15, 0.10) shape
GMS_SHAPES = (
    ((1.0,), (1.0,)),
    ((0.7, 0.3), (0.75, 0.25)),
    ((0.35, 0.65), (0.6, 0.4)),
    ((0.2, 0.5, 0.3), (0.55, 0.35, 0.10)),
)

#: knots of a drawn position_friction stretch (odd: the peak is a knot)
PF_KNOTS = 9


@dataclasses.dataclass(frozen=True)
class Rig:
    """The drive and sensor side of a generated axis (SI; rad on rotary axes).

    Parameters
    ----------
    axis : str
        ``linear`` or ``rotary``.
    input : str
        ``voltage`` (ZOH command logged), ``current`` or ``force`` (measured, sampled).
    input_gain : float
        N/V, N/A (force constant) or 1 [N per N]; N·m per unit on rotary axes.
    back_emf : float
        V·s/m (V·s/rad) for voltage drives, else 0.
    mass : float
        Moving mass [kg] or inertia [kg·m²].
    rate : float
        Log rate [Hz] (100 – 2000).
    control_rate : float
        Controller rate [Hz]; equals ``rate`` for voltage drives.
    encoder : float
        Encoder quantum [m] or [rad].
    noise : float
        Position noise std [m] or [rad] before quantisation.
    current_noise : float
        Std of the logged current/force relative to its RMS.
    current_lag : float
        Current-loop time constant [s] (current/force drives).
    u_max : float
        Command saturation (V, A or N).
    travel : float
        Usable stroke [m] or [rad].
    speeds : tuple
        Sweep speeds [m/s] or [rad/s], slow → fast.
    accel : float
        Sweep acceleration [m/s²] or [rad/s²].
    """

    axis: str = 'linear'
    input: str = 'voltage'
    input_gain: float = 20.0
    back_emf: float = 10.0
    mass: float = 4.0
    rate: float = 1000.0
    control_rate: float = 1000.0
    encoder: float = 1e-6
    noise: float = 3e-7
    current_noise: float = 0.003
    current_lag: float = 2e-4
    u_max: float = 1e9
    travel: float = 0.2
    speeds: tuple = (0.004, 0.01, 0.025, 0.06, 0.14, 0.3)
    accel: float = 3.0


def draw_rig(rng: np.random.Generator, *, axis: str = 'linear', input: str = 'voltage',
             rate: float = 1000.0) -> Rig:
    """Draw a plausible drive for ``axis``/``input``/``rate``."""
    if axis == 'linear':
        mass = float(rng.uniform(2.0, 12.0))
        kw: dict[str, Any] = dict(encoder=float(rng.choice([0.5e-6, 1e-6, 2e-6])),
                                  noise=float(rng.uniform(1e-7, 5e-7)), travel=0.2,
                                  speeds=(0.004, 0.01, 0.025, 0.06, 0.14, 0.3), accel=3.0)
        gains = {'voltage': float(rng.uniform(10.0, 40.0)), 'current':
                 float(rng.uniform(20.0, 90.0)), 'force': 1.0}
        bemf = float(rng.uniform(5.0, 25.0))
    else:
        mass = float(rng.uniform(0.005, 0.05))
        counts = int(rng.choice([2 ** 16, 2 ** 18, 2 ** 20]))
        kw = dict(encoder=2 * np.pi / counts, noise=float(rng.uniform(0.0, 1e-5)),
                  travel=3.6, speeds=(0.06, 0.15, 0.4, 1.0, 2.2, 4.5), accel=30.0)
        gains = {'voltage': float(rng.uniform(0.2, 1.0)), 'current':
                 float(rng.uniform(0.1, 0.8)), 'force': 1.0}
        bemf = float(rng.uniform(0.1, 0.6))
    # a voltage command is logged where it is computed; a current/force drive runs its
    # loop faster than the log (the logged value is a sample of the measured current)
    control = rate if input == 'voltage' else 4000.0
    return Rig(axis=axis, input=input, input_gain=gains[input],
               back_emf=bemf if input == 'voltage' else 0.0, mass=mass, rate=rate,
               control_rate=float(control), **kw)


def draw_effect(name: str, rng: np.random.Generator, rig: Rig,
                present: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """Draw the parameters of effect ``name`` from physical ranges (SI; rig's axis units).

    ``present`` holds the effects drawn so far (Stribeck needs the Coulomb level).
    Forces scale with the rig: linear ranges are in N, rotary ranges in N·m; lengths of
    the linear ranges are m, rotary ones rad (× 18: the rotary travel is 3.6 rad where
    the linear one is 0.2 m).
    """
    rot = rig.axis == 'rotary'
    fscale = 0.02 if rot else 1.0             # N·m per "N" of the linear ranges
    sign = 1.0 if rng.random() < 0.5 else -1.0
    if name == 'coulomb':
        return {'fc': fscale * float(rng.uniform(6.0, 30.0))}
    if name == 'viscous':
        if rot:
            return {'fv': float(rng.uniform(0.01, 0.06))}
        return {'fv': float(rng.uniform(25.0, 120.0))}
    if name == 'stribeck':
        fc = present['coulomb']['fc']
        vs = float(rng.uniform(0.2, 0.6)) if rot else float(rng.uniform(0.006, 0.02))
        return {'fs': fc * float(rng.uniform(1.5, 2.2)), 'vs': vs,
                'delta': float(rng.uniform(0.8, 2.0))}
    if name == 'presliding':
        alpha, kshape = GMS_SHAPES[int(rng.integers(len(GMS_SHAPES)))]
        ktot = float(rng.uniform(20.0, 120.0)) if rot else float(rng.uniform(1.5e5, 8e5))
        fc = present['coulomb']['fc']
        return {'alpha': list(alpha), 'k': [ktot * s for s in kshape],
                'C': fc * float(rng.uniform(300.0, 1500.0)), 'sigma': [0.0] * len(alpha)}
    if name == 'ripple':
        if rot:
            period = 2 * np.pi / int(rng.choice([6, 8, 12, 16]))
        else:
            period = float(rng.uniform(0.006, 0.03))
        nh = int(rng.integers(1, 4))
        a1 = fscale * float(rng.uniform(3.0, 9.0))
        harm = []
        for h in range(nh):
            amp = a1 * (1.0 if h == 0 else float(rng.uniform(0.25, 0.5)) ** h)
            ph = float(rng.uniform(0, 2 * np.pi))
            harm.append([amp * math.cos(ph), amp * math.sin(ph)])
        return {'period': period, 'harmonics': harm}
    if name == 'offset':
        return {'f0': sign * fscale * float(rng.uniform(4.0, 15.0))}
    if name == 'spring':
        if rot:
            return {'k': float(rng.uniform(0.05, 0.3)), 'x0': float(rng.uniform(-0.4, 0.4))}
        return {'k': float(rng.uniform(150.0, 600.0)), 'x0': float(rng.uniform(-0.03, 0.03))}
    if name == 'asymmetry':
        fc = present['coulomb']['fc']
        fv = present['viscous']['fv']
        return {'dfc': sign * fc * float(rng.uniform(0.25, 0.6)),
                'dfv': sign * fv * float(rng.uniform(0.3, 0.7))}
    if name == 'delay':
        return {'tau': float(rng.uniform(0.0005, 0.004))}
    if name == 'backlash':
        if rot:
            return {'width': float(rng.uniform(2e-3, 1e-2))}
        return {'width': float(rng.uniform(2e-5, 1.5e-4))}
    if name == 'gravity':
        if not rot:
            raise ValueError('gravity exists on rotary axes only (on a linear axis: offset)')
        return {'mgl': float(rng.uniform(0.1, 0.6)), 'q0': float(rng.uniform(-np.pi, np.pi))}
    if name == 'load_friction':
        # a screw or gear whose friction grows with the transmitted force: 3–10 % of the
        # drive force on top of fc
        return {'mu': float(rng.uniform(0.03, 0.1))}
    if name == 'position_friction':
        # a tight spot: +5–10 N over a stretch 10–20 mm wide at half height (a raised
        # cosine sampled at PF_KNOTS knots, zero at both ends), 5–25 mm off centre
        lscale = 18.0 if rot else 1.0
        centre = sign * lscale * float(rng.uniform(0.005, 0.025))
        half = lscale * float(rng.uniform(0.010, 0.020))
        height = fscale * float(rng.uniform(5.0, 10.0))
        x = centre + half * np.linspace(-1.0, 1.0, PF_KNOTS)
        dfc = height * 0.5 * (1.0 + np.cos(np.pi * (x - centre) / half))
        dfc[0] = dfc[-1] = 0.0
        return {'x': [float(v) for v in x], 'dfc': [float(v) for v in dfc]}
    raise KeyError(name)


def draw_extra(name: str, rng: np.random.Generator, rig: Rig,
               present: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """Draw the parameters of the out-of-library effect ``name`` (:data:`EXTRA_NAMES`), SI.

    Ranges are physical for the rig and large enough to stand clear of the noise (on
    the suite's rigs each raises the true in-library model's force NRMSE to about 2× or
    more): a lubricant that warms over a run (Δ 50–90 % of fc, time constant 4–10 s: the
    friction about halves from a cold start), a fan or pump at 5–18 Hz (3–8 N), drag of
    20–40 N at the top speed (a bellows cover pumping air through its vents; a fan or
    impeller on a rotary shaft), a cable snag of 10–20 N a few mm wide 5–20 mm off the
    travel's centre, a lubrication regime that lowers friction by 50–80 % of fc around
    one sweep speed, a lip seal that drags 60–120 % of fc more just after a reversal and
    settles over 0.5–1.5 mm.  Rotary ranges: forces × 0.02 (N·m), lengths × 18 (rad).
    """
    rot = rig.axis == 'rotary'
    fscale = 0.02 if rot else 1.0
    lscale = 18.0 if rot else 1.0
    sign = 1.0 if rng.random() < 0.5 else -1.0
    if name == 'friction_drift':
        fc = present['coulomb']['fc']
        falls = rng.random() < 0.7            # warm-up thins the grease: usually falls
        return {'delta': (1.0 if falls else -1.0) * fc * float(rng.uniform(0.5, 0.9)),
                'tau': float(rng.uniform(4.0, 10.0))}
    if name == 'disturbance':
        return {'amplitude': fscale * float(rng.uniform(3.0, 8.0)),
                'frequency': float(rng.uniform(5.0, min(18.0, 0.12 * rig.rate))),
                'phase': float(rng.uniform(0.0, 2 * np.pi))}
    if name == 'drag':
        top = rig.speeds[-1]
        return {'c': fscale * float(rng.uniform(20.0, 40.0)) / top ** 2}
    if name == 'bump':
        return {'amplitude': sign * fscale * float(rng.uniform(10.0, 20.0)),
                'x': (1.0 if rng.random() < 0.5 else -1.0) * lscale
                * float(rng.uniform(0.005, 0.02)),
                'width': lscale * float(rng.uniform(0.003, 0.006))}
    if name == 'speed_dip':
        fc = present['coulomb']['fc']
        vd = float(rig.speeds[int(rng.integers(2, 4))])
        return {'depth': fc * float(rng.uniform(0.5, 0.8)), 'speed': vd, 'width': 0.25 * vd}
    if name == 'reversal_transient':
        fc = present['coulomb']['fc']
        return {'height': fc * float(rng.uniform(0.6, 1.2)),
                'length': lscale * float(rng.uniform(0.5e-3, 1.5e-3))}
    raise KeyError(name)


def true_model(rig: Rig, effects: Mapping[str, Mapping[str, Any]]) -> dict[str, Any]:
    """Return the model-file mapping (DESIGN.md §6) of the generated axis."""
    out: dict[str, Any] = {}
    if rig.axis == 'rotary':
        out['axis'] = 'rotary'
    out.update({'input': rig.input, 'input_gain': float(rig.input_gain),
                'back_emf': float(rig.back_emf), 'mass': float(rig.mass),
                'effects': {n: dict(effects[n]) for n in EFFECT_NAMES if n in effects}})
    return out


def draw_scenario(names: Sequence[str], extra: Sequence[str] = (), *, seed: int,
                  axis: str = 'linear', input: str = 'voltage', rate: float = 1000.0) \
        -> tuple[Rig, dict[str, Any], dict[str, dict[str, Any]]]:
    """Draw a rig, the true model with effects ``names`` and the out-of-library ``extra``.

    What the effects require (:data:`REQUIRES`) is added to the model.  The draws come
    in a fixed order — rig, library effects in :data:`EFFECT_NAMES` order, extras in
    :data:`EXTRA_NAMES` order — so adding extras never changes the rest of a case.
    Returns ``(rig, truth, extras)`` with ``extras`` mapping name → parameters.
    """
    unknown = [n for n in names if n not in EFFECT_NAMES] + \
        [n for n in extra if n not in EXTRA_NAMES]
    if unknown:
        raise KeyError(f'unknown effect {unknown[0]!r}')
    rng = np.random.default_rng(seed)
    rig = draw_rig(rng, axis=axis, input=input, rate=rate)
    wanted: list[str] = []
    for n in list(names) + list(extra):
        for req in REQUIRES.get(n, ()):
            if req not in wanted:
                wanted.append(req)
        if n in EFFECT_NAMES and n not in wanted:
            wanted.append(n)
    effects: dict[str, dict[str, Any]] = {}
    for n in sorted(wanted, key=EFFECT_NAMES.index):
        effects[n] = draw_effect(n, rng, rig, effects)
    extras = {n: draw_extra(n, rng, rig, effects) for n in EXTRA_NAMES if n in extra}
    return rig, true_model(rig, effects), extras


def draw_case(names: Sequence[str], *, seed: int, axis: str = 'linear',
              input: str = 'voltage', rate: float = 1000.0) -> tuple[Rig, dict[str, Any]]:
    """Draw a rig and the true model with effects ``names`` (plus what they require)."""
    rig, truth, _ = draw_scenario(names, seed=seed, axis=axis, input=input, rate=rate)
    return rig, truth


def hermite(xq: np.ndarray, x: Sequence[float], d: Sequence[float]) -> np.ndarray:
    """Evaluate the generator's position_friction interpolation ``dfc(xq)`` [N] (numpy).

    Cubic Hermite through the knots ``(x, d)`` with :func:`indgen_laws.hermite_tangents`
    (Catmull–Rom, flat ends), constant beyond the end knots — the law the compiled
    kernel applies (:func:`indgen_laws.hermite_eval`).
    """
    x = np.asarray(x, dtype=float)
    d = np.asarray(d, dtype=float)
    m = hermite_tangents(x, d)
    xq = np.asarray(xq, dtype=float)
    j = np.clip(np.searchsorted(x, xq, side='right') - 1, 0, len(x) - 2)
    h = x[j + 1] - x[j]
    s = np.clip((xq - x[j]) / h, 0.0, 1.0)
    return ((2 * s ** 3 - 3 * s ** 2 + 1) * d[j] + (s ** 3 - 2 * s ** 2 + s) * h * m[j]
            + (-2 * s ** 3 + 3 * s ** 2) * d[j + 1] + (s ** 3 - s ** 2) * h * m[j + 1])


def position_friction_peak(params: Mapping[str, Any], *, points: int = 4001) \
        -> tuple[float, float]:
    """Find the peak ``(x [m], dfc [N])`` of a position_friction's knots under :func:`hermite`.

    Used for the truth (where it is the middle knot) and for a fitted model's knots
    (whose own interpolation may differ slightly between knots: the peak is searched on
    a fine grid over the knots' span).
    """
    x = np.asarray(params['x'], dtype=float)
    xq = np.linspace(x[0], x[-1], points)
    f = hermite(xq, x, params['dfc'])
    i = int(np.argmax(f))
    return float(xq[i]), float(f[i])


def drift_mean(tau: float, duration: float) -> float:
    """``ē = τ/T·(1 − e^{−T/τ})``: the mean of ``e^{−t/τ}`` over a run ``[0, T]``."""
    return tau / duration * (1.0 - math.exp(-duration / tau))


def pack(model: Mapping[str, Any], rig: Rig, extras: Mapping[str, Mapping[str, Any]]
         | None = None, *, duration: float = 1.0) -> np.ndarray:
    """Pack ``model`` + ``extras`` on ``rig`` (run ``duration``) for the kernel."""
    p = np.zeros(law.N_PAR)
    e = model.get('effects') or {}
    p[law.I_M] = model['mass']
    p[law.I_G] = model['input_gain']
    p[law.I_KE] = model.get('back_emf', 0.0)
    p[law.I_CURRENT] = 0.0 if model.get('input', 'voltage') == 'voltage' else 1.0
    p[law.I_TAU_I] = rig.current_lag
    fc = e.get('coulomb', {}).get('fc', 0.0)
    p[law.I_FC] = fc
    st = e.get('stribeck')
    p[law.I_FS] = st['fs'] if st else fc
    p[law.I_VS] = st['vs'] if st else 1.0
    p[law.I_DELTA] = st['delta'] if st else 1.0
    p[law.I_FV] = e.get('viscous', {}).get('fv', 0.0)
    asym = e.get('asymmetry', {})
    p[law.I_DFC] = asym.get('dfc', 0.0)
    p[law.I_DFV] = asym.get('dfv', 0.0)
    p[law.I_F0] = e.get('offset', {}).get('f0', 0.0)
    sp = e.get('spring', {})
    p[law.I_KSP] = sp.get('k', 0.0)
    p[law.I_X0] = sp.get('x0', 0.0)
    g = e.get('gravity', {})
    p[law.I_MGL] = g.get('mgl', 0.0)
    p[law.I_Q0] = g.get('q0', 0.0)
    p[law.I_TAU] = e.get('delay', {}).get('tau', 0.0)
    p[law.I_W] = e.get('backlash', {}).get('width', 0.0)
    rip = e.get('ripple')
    if rip:
        harm = rip['harmonics']
        p[law.I_PER] = rip['period']
        p[law.I_NH] = len(harm)
        for h, (a, b) in enumerate(harm):
            p[law.I_RA + h], p[law.I_RB + h] = a, b
    else:
        p[law.I_PER] = 1.0
    gms = e.get('presliding')
    if gms:
        n = len(gms['alpha'])
        p[law.I_GMS_N] = n
        p[law.I_GMS_C] = gms['C']
        p[law.I_ALPHA:law.I_ALPHA + n] = gms['alpha']
        p[law.I_K:law.I_K + n] = gms['k']
    p[law.I_MU] = e.get('load_friction', {}).get('mu', 0.0)
    pf = e.get('position_friction')
    if pf:
        x = np.asarray(pf['x'], dtype=float)
        d = np.asarray(pf['dfc'], dtype=float)
        if not 2 <= len(x) <= MAX_KNOTS or len(d) != len(x) or np.any(np.diff(x) <= 0):
            raise ValueError('position_friction needs 2–32 strictly increasing knots x '
                             'and as many values dfc')
        n = len(x)
        p[law.I_PF_N] = n
        p[law.I_PF_X:law.I_PF_X + n] = x
        p[law.I_PF_D:law.I_PF_D + n] = d
        p[law.I_PF_M:law.I_PF_M + n] = hermite_tangents(x, d)
    ex = extras or {}
    if 'friction_drift' in ex:
        q = ex['friction_drift']
        p[law.I_DR_D] = q['delta']
        p[law.I_DR_TAU] = q['tau']
        p[law.I_DR_MEAN] = drift_mean(q['tau'], duration)
    if 'disturbance' in ex:
        q = ex['disturbance']
        p[law.I_DI_A], p[law.I_DI_F], p[law.I_DI_PH] = q['amplitude'], q['frequency'], \
            q['phase']
    if 'drag' in ex:
        p[law.I_DG_C] = ex['drag']['c']
    if 'bump' in ex:
        q = ex['bump']
        p[law.I_BU_A], p[law.I_BU_X], p[law.I_BU_W] = q['amplitude'], q['x'], q['width']
    if 'speed_dip' in ex:
        q = ex['speed_dip']
        p[law.I_SD_D], p[law.I_SD_V], p[law.I_SD_W] = q['depth'], q['speed'], q['width']
    if 'reversal_transient' in ex:
        q = ex['reversal_transient']
        p[law.I_RT_R], p[law.I_RT_L] = q['height'], q['length']
    return p


# ---- ground truth beyond the model file ---------------------------------------------

@dataclasses.dataclass(frozen=True)
class Planted:
    """Where an out-of-library effect acts: the truth a residual feature is judged on.

    The fields mirror a workbench feature (DESIGN.md §6 ``unexplained.features``).

    Attributes
    ----------
    name : str
        The effect (:data:`EXTRA_NAMES`).
    against : str
        The scan variable it acts through: ``position``, ``velocity``, ``time``,
        ``reversal`` or ``frequency``.
    odd : bool
        Whether it flips with the direction of motion (friction-like).
    where : tuple of float
        ``(lo, hi)`` in SI units of ``against`` (:attr:`unit`): m, m/s (rad, rad/s on
        rotary axes), s, Hz; for an odd velocity effect the *speed* band ``|v|``; for
        ``reversal`` the distance since the reversal [m | rad].
    share : float
        The effect force's variance over the drive force's variance on the run (log
        stamps, each force averaged over its log interval).
    share_unabsorbed : float
        The same after a least-squares fit of an offset, a Coulomb (``sgn v``) and a
        viscous (``v``) term to the effect force: roughly what even a refitted
        in-library model cannot take up.
    params : dict
        The law's parameters (SI).
    text : str
        One line in words.
    unit : str
        Unit of :attr:`where`.
    where_time : tuple of float or None
        ``reversal`` only: the same window as a time since the reversal [s] (median over
        the run's reversals of the time to travel the distance).
    """

    name: str
    against: str
    odd: bool
    where: tuple
    share: float
    share_unabsorbed: float
    params: dict
    text: str
    unit: str
    where_time: tuple | None = None

    def as_dict(self) -> dict[str, Any]:
        """Return the plain form (YAML/JSON)."""
        d = dataclasses.asdict(self)
        d['where'] = [float(w) for w in self.where]
        if self.where_time is not None:
            d['where_time'] = [float(w) for w in self.where_time]
        return d


@dataclasses.dataclass(frozen=True)
class NoiseTruth:
    """The noise the generator added to a run (the truth for a noise-floor estimate).

    Attributes
    ----------
    encoder : float
        Encoder quantum [m | rad] (the logged position is rounded to it).
    quantisation_std : float
        Its rounding error's standard deviation ``q/√12`` [m | rad].
    position_noise : float
        Std of the white position noise added before quantisation [m | rad].
    position_std : float
        ``√(noise² + q²/12)``: the measured position's total error std [m | rad].
    input_noise : float
        Std of the white noise on the logged input, in its units (V, A or N; 0 for a
        voltage command, logged where it is computed).
    input_noise_force : float
        The same as a force, ``input_gain × input_noise`` [N | N·m].
    input : str
        The logged input kind.
    """

    encoder: float
    quantisation_std: float
    position_noise: float
    position_std: float
    input_noise: float
    input_noise_force: float
    input: str

    def as_dict(self) -> dict[str, Any]:
        """Return the plain form (YAML/JSON)."""
        return dataclasses.asdict(self)


@dataclasses.dataclass(frozen=True)
class Generated:
    """A generated run, its true model and what was hidden in it.

    Attributes
    ----------
    run : Run
        The logged signals (position, logged input, reference) at the log rate.
    truth : dict
        The true model-file mapping (library effects only).
    rig : Rig
        The drive and sensors.
    motor_position : ndarray
        Motor-side position at the log stamps (before backlash, noise, quantisation).
    applied : ndarray
        The input actually applied (current state or command) at the log stamps.
    planted : tuple of Planted
        The out-of-library effects and where they act.
    noise : NoiseTruth or None
        The noise added to the logged signals.
    signals : dict
        True signals at the log stamps: ``velocity`` (motor) [m/s | rad/s]; averaged
        over each log interval: ``drive_force`` ``F_in`` [N | N·m], ``friction`` (the
        dry-friction force applied, GMS elements included, viscous excluded) and one
        force per planted out-of-library effect, by name (a dry-friction one counted
        while sliding).
    meta : dict
        The experiment (``excitation`` and its parameters), ``braking_share`` (the
        share of moving samples where the drive force opposes the motion) and, with
        position_friction, its ``position_friction_peak`` ``[x, dfc]``.
    """

    run: Run
    truth: dict
    rig: Rig
    motor_position: np.ndarray
    applied: np.ndarray
    planted: tuple = ()
    noise: NoiseTruth | None = None
    signals: dict = dataclasses.field(default_factory=dict)
    meta: dict = dataclasses.field(default_factory=dict)

    def ground_truth(self) -> dict[str, Any]:
        """Return what the model file cannot hold, as plain data (``meta.yaml``)."""
        return {'noise': self.noise.as_dict() if self.noise else None,
                'planted': [p.as_dict() for p in self.planted], **self.meta}


def write(gen: Generated, directory: str, *, start: Mapping[str, Any] | None = None) -> None:
    """Write ``run.mcap``, ``truth.yaml``, ``meta.yaml`` and ``start.yaml`` to ``directory``.

    ``run.mcap`` by the project's MCAP writer; ``meta.yaml`` is
    :meth:`Generated.ground_truth` (noise, planted effects).
    """
    from pathlib import Path

    import yaml

    from motor_comp.logs import write_run
    out = Path(directory)
    out.mkdir(parents=True, exist_ok=True)
    write_run(out / 'run.mcap', gen.run)
    (out / 'truth.yaml').write_text(yaml.safe_dump(gen.truth, sort_keys=False),
                                    encoding='utf-8')
    (out / 'meta.yaml').write_text(yaml.safe_dump(gen.ground_truth(), sort_keys=False),
                                   encoding='utf-8')
    if start is not None:
        (out / 'start.yaml').write_text(yaml.safe_dump(dict(start), sort_keys=False),
                                        encoding='utf-8')


def chirp_end(rig: Rig) -> float:
    """Return the chirp's end frequency [Hz]: 3 Hz, or where its peak acceleration is the rig's.

    At the top speed ``v`` the chirp's acceleration amplitude is ``2π·f·v``; a rig whose
    acceleration was raised (an experiment that loads the drive, ``Case.accel``) is
    driven up to ``f = accel/(2π·v)``, where the inertia force dwarfs the friction and
    the drive brakes for about half of every cycle.  Every rig at its drawn
    acceleration stays at 3 Hz (linear 1.6 Hz, rotary 1.1 Hz by that formula).
    """
    return max(3.0, rig.accel / (2 * np.pi * rig.speeds[-1]))


def reference(excitation: str, rig: Rig, *, dt: float, duration: float, seed: int) \
        -> tuple[np.ndarray, dict[str, Any]]:
    """Build the reference ``(n, 3)`` of ``excitation`` on ``rig`` and its description.

    ``chirp``: 0.2 Hz to :func:`chirp_end`, the amplitude limited to the top sweep speed.
    ``sine``: frequency 0.5–2 Hz and a peak speed 25–60 % of the rig's top sweep speed
    (amplitude at most 40 % of the travel), drawn from ``seed`` on a stream of its own
    (the run's noise draws are not shifted).
    """
    if excitation == 'sweep':
        return sweep_reference(speeds=rig.speeds, stroke=rig.travel, accel=rig.accel, dt=dt,
                               duration=duration), {'excitation': 'sweep',
                                                    'speeds': list(rig.speeds)}
    if excitation == 'interleaved':
        return interleaved_reference(speeds=rig.speeds, stroke=rig.travel, accel=rig.accel,
                                     dt=dt, duration=duration), \
            {'excitation': 'interleaved', 'speeds': list(rig.speeds)}
    if excitation == 'chirp':
        f1 = chirp_end(rig)
        return chirp_reference(f0=0.2, f1=f1, amplitude=0.45 * rig.travel,
                               vmax=rig.speeds[-1], dt=dt, duration=duration), \
            {'excitation': 'chirp', 'f0': 0.2, 'f1': f1}
    if excitation == 'sine':
        srng = np.random.default_rng([seed, 51])
        f = float(srng.uniform(0.5, 2.0))
        vpk = float(srng.uniform(0.25, 0.6)) * rig.speeds[-1]
        amp = min(0.4 * rig.travel, vpk / (2 * np.pi * f))
        return sine_reference(frequency=f, amplitude=amp, dt=dt, duration=duration), \
            {'excitation': 'sine', 'frequency': f, 'amplitude': amp}
    raise ValueError(f'excitation must be one of {", ".join(EXCITATIONS)}, '
                     f'got {excitation!r}')


def _reversal_times(t: np.ndarray, x: np.ndarray, v: np.ndarray, dist: float) -> np.ndarray:
    """Per reversal of the motion: time [s] until ``dist`` is travelled (or the stroke ends)."""
    moving = np.flatnonzero(v != 0.0)
    if len(moving) == 0:
        return np.zeros(0)
    d = np.sign(v[moving])
    starts = moving[np.concatenate([[True], d[1:] != d[:-1]])]
    out = []
    for a, b in zip(starts, list(starts[1:]) + [len(t)]):
        x0 = x[max(a - 1, 0)]
        far = np.flatnonzero(np.abs(x[a:b] - x0) >= dist)
        end = a + far[0] if len(far) else b - 1
        out.append(t[end] - t[a])
    return np.asarray(out)


def _planted(name: str, q: Mapping[str, Any], sig: Mapping[str, np.ndarray],
             t: np.ndarray, x: np.ndarray, rig: Rig, duration: float) -> Planted:
    """Describe where extra ``name`` (parameters ``q``) acts on a generated run."""
    f = sig[name]
    v = sig['velocity']
    var_in = float(np.var(sig['drive_force']))
    cols = np.column_stack([np.ones_like(v), np.sign(v), v])
    coef, *_ = np.linalg.lstsq(cols, f, rcond=None)
    share = float(np.var(f)) / var_in
    unabsorbed = float(np.var(f - cols @ coef)) / var_in
    rot = rig.axis == 'rotary'
    lu, fu = ('rad', 'N·m') if rot else ('m', 'N')
    where_time = None
    if name == 'friction_drift':
        change = q['delta'] * (1.0 - math.exp(-duration / q['tau']))
        where, against, odd, unit = (0.0, min(duration, 2.0 * q['tau'])), 'time', True, 's'
        text = (f'friction {"falls" if change > 0 else "rises"} by {abs(change):.3g} {fu} '
                f'over the run (lubricant warm-up, time constant {q["tau"]:.3g} s), both '
                f'directions')
    elif name == 'disturbance':
        bw = max(0.25, 0.03 * q['frequency'])
        where = (q['frequency'] - bw, q['frequency'] + bw)
        against, odd, unit = 'frequency', False, 'Hz'
        text = (f'a {q["amplitude"]:.3g} {fu} force at {q["frequency"]:.3g} Hz (unbalanced '
                f'fan or pump), tied to neither position nor speed')
    elif name == 'drag':
        top = float(np.max(np.abs(v)))
        where, against, odd, unit = (0.5 * top, top), 'velocity', True, f'{lu}/s'
        text = (f'drag c·v·|v| with c {q["c"]:.3g}: {q["c"] * top * top:.3g} {fu} at '
                f'{top:.3g} {lu}/s')
    elif name == 'bump':
        where = (q['x'] - 2 * q['width'], q['x'] + 2 * q['width'])
        against, odd, unit = 'position', False, lu
        text = (f'a force of {q["amplitude"]:.3g} {fu} at {q["x"]:.4g} {lu} (width '
                f'{q["width"]:.2g} {lu}), the same in both directions (cable snag)')
    elif name == 'speed_dip':
        where = (max(0.0, q['speed'] - 2 * q['width']), q['speed'] + 2 * q['width'])
        against, odd, unit = 'velocity', True, f'{lu}/s'
        text = (f'friction lower by {q["depth"]:.3g} {fu} around {q["speed"]:.3g} {lu}/s '
                f'(a lubrication regime), both directions')
    elif name == 'reversal_transient':
        dist = 3.0 * q['length']
        where, against, odd, unit = (0.0, dist), 'reversal', True, lu
        times = _reversal_times(t, x, v, dist)
        where_time = (0.0, float(np.median(times)) if len(times) else 0.0)
        text = (f'friction higher by {q["height"]:.3g} {fu} just after each reversal, '
                f'settling over {q["length"]:.2g} {lu} (a lip seal flipping over)')
    else:
        raise KeyError(name)
    return Planted(name=name, against=against, odd=odd, where=tuple(float(w) for w in where),
                   share=share, share_unabsorbed=unabsorbed, params=dict(q), text=text,
                   unit=unit, where_time=where_time)


def generate(truth: Mapping[str, Any], rig: Rig, *, excitation: str = 'sweep',
             duration: float = 30.0, seed: int = 0, physics_dt: float = 2e-5,
             name: str = 'indgen', extras: Mapping[str, Mapping[str, Any]] | None = None) \
        -> Generated:
    """Simulate the closed loop of ``truth`` (+ ``extras``) on ``rig`` and log it.

    Parameters
    ----------
    truth : mapping
        Model-file mapping (:func:`true_model`), linear or rotary.
    rig : Rig
        Drive, sensors, rates and sweep design.
    excitation : str
        ``sweep`` (time-ordered back-and-forth speed sweep, the usual identification
        experiment), ``interleaved`` (the same strokes, speeds interleaved in time),
        ``chirp`` (0.2 → 3 Hz, peak speed the rig's top sweep speed) or ``sine`` (sine
        tracking); see :func:`reference`.
    duration : float
        Run length [s].
    seed : int
        Seed of the noise.
    physics_dt : float
        Plant step [s] (rounded so the control period is a whole number of steps).
    name : str
        Run label.
    extras : mapping, optional
        Out-of-library effects (:data:`EXTRA_NAMES`) → parameters (:func:`draw_extra`).

    Returns
    -------
    Generated
        The run, the truth, and the ground truth of the extras and the noise.
    """
    rng = np.random.default_rng(seed)
    T = 1.0 / rig.control_rate
    n_sub = max(1, int(round(T / physics_dt)))
    dt = T / n_sub
    log_every = max(1, int(round(rig.control_rate / rig.rate)))
    n_ctrl = int(round(duration / T))
    n_ctrl -= n_ctrl % log_every
    ref, info = reference(excitation, rig, dt=T, duration=n_ctrl * T, seed=seed)
    extras = dict(extras or {})
    p = pack(truth, rig, extras, duration=n_ctrl * T)
    # controller: a rough idea of the axis (±20 % mass), its own bandwidth choice; the
    # velocity estimate is low-passed at 3× the loop bandwidth (encoder-count noise)
    tau = p[law.I_TAU]
    wv = min(2 * np.pi * 40.0, 2 * np.pi * rig.control_rate / 25.0)
    if tau > 0:
        wv = min(wv, 0.35 / tau)
    m_est = rig.mass * float(rng.uniform(0.8, 1.2))
    c = np.array([wv / 4.0, wv, m_est * wv * wv / 6.0, m_est, rig.input_gain,
                  rig.back_emf, 1.0 - math.exp(-3.0 * wv * T)])
    n_log = n_ctrl // log_every
    noise_y = rng.normal(0.0, rig.noise, n_ctrl)
    out_y, out_u = np.zeros(n_ctrl), np.zeros(n_ctrl)
    out_i, out_x = np.zeros(n_ctrl), np.zeros(n_ctrl)
    out_v, out_fin, out_fric = np.zeros(n_ctrl), np.zeros(n_ctrl), np.zeros(n_ctrl)
    out_extra = np.zeros((n_ctrl, len(EXTRA_NAMES)))
    law.closed_loop(p, c, np.ascontiguousarray(ref), n_ctrl, n_sub, dt, noise_y, rig.encoder,
                    rig.u_max, out_y, out_u, out_i, out_x, out_v, out_fin, out_fric,
                    out_extra)
    pick = slice(0, n_ctrl, log_every)
    input_noise = 0.0
    if rig.input == 'voltage':
        logged = out_u[pick]
        applied = out_u[pick]
    else:
        # the drive reports its measured current averaged over a window centred on the
        # stamp (a zero-phase anti-alias filter), with measurement noise
        half = log_every // 2
        cs = np.concatenate([[0.0], np.cumsum(out_i)])
        k = np.arange(0, n_ctrl, log_every)
        lo = np.clip(k - half, 0, n_ctrl)
        hi = np.clip(k - half + log_every, 0, n_ctrl)
        applied = (cs[hi] - cs[lo]) / np.maximum(hi - lo, 1)
        input_noise = rig.current_noise * float(np.sqrt(np.mean(applied ** 2)))
        logged = applied + rng.normal(0.0, 1.0, n_log) * rig.current_noise \
            * float(np.sqrt(np.mean(applied ** 2)))
    t = np.arange(n_log) * (T * log_every)
    r = ref[::log_every][:n_log]
    run = Run(t=t, position=out_y[pick], reference=r[:, 0], reference_velocity=r[:, 1],
              voltage=logged, name=name,
              metadata={'generator': 'test/workbench/independent_generator.py',
                        'excitation': excitation, 'seed': str(seed)})

    def per_log(a: np.ndarray) -> np.ndarray:
        return a.reshape(n_log, log_every).mean(axis=1)
    signals = {'velocity': out_v[pick], 'drive_force': per_log(out_fin),
               'friction': per_log(out_fric)}
    for j, extra in enumerate(EXTRA_NAMES):
        if extra in extras:
            signals[extra] = per_log(out_extra[:, j])
    planted = tuple(_planted(n, extras[n], signals, t, out_x[pick], rig, n_ctrl * T)
                    for n in EXTRA_NAMES if n in extras)
    q = rig.encoder
    noise = NoiseTruth(encoder=float(q), quantisation_std=float(q / math.sqrt(12.0)),
                       position_noise=float(rig.noise),
                       position_std=float(math.sqrt(rig.noise ** 2 + q * q / 12.0)),
                       input_noise=float(input_noise),
                       input_noise_force=float(rig.input_gain * input_noise),
                       input=rig.input)
    meta: dict[str, Any] = dict(info)
    # where the drive brakes the motion (F_in against v): the samples that tell load
    # friction from a larger mass, Coulomb and viscous level
    v_log, f_log = signals['velocity'], signals['drive_force']
    moving = v_log != 0.0
    meta['braking_share'] = float(np.mean(f_log[moving] * v_log[moving] < 0.0)) \
        if np.any(moving) else 0.0
    pf = (truth.get('effects') or {}).get('position_friction')
    if pf:
        meta['position_friction_peak'] = list(position_friction_peak(pf))
    return Generated(run=run, truth=dict(truth), rig=rig, motor_position=out_x[pick],
                     applied=applied, planted=planted, noise=noise, signals=signals,
                     meta=meta)


def start_model(truth: Mapping[str, Any], *, mass_factor: float = 2.0,
                keep_effects: bool = False, changes: Mapping[str, Any] | None = None) \
        -> dict[str, Any]:
    """Return the model a user starts from: bare (``effects: {}``) with a wrong mass.

    ``keep_effects`` keeps the true effects (for wrong-parameter cases); ``changes``
    maps ``'input_gain'`` or ``'effect.param'`` (``'ripple.amplitude'`` scales every
    harmonic) to a factor applied to the true value.
    """
    m = {k: (dict(v) if isinstance(v, dict) else v) for k, v in truth.items()}
    m['effects'] = {n: dict(p) for n, p in truth['effects'].items()} if keep_effects else {}
    m['mass'] = truth['mass'] * mass_factor
    for key, factor in (changes or {}).items():
        if '.' not in key:
            m[key] = m[key] * factor
            continue
        eff, par = key.split('.')
        if eff == 'ripple' and par == 'amplitude':
            m['effects']['ripple']['harmonics'] = [
                [a * factor, b * factor] for a, b in truth['effects']['ripple']['harmonics']]
        else:
            m['effects'][eff][par] = m['effects'][eff][par] * factor
    return m
