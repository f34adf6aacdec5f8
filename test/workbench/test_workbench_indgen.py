"""The independent generator's own physics (issue 23 item 6): each new law with numbers.

No workbench and no project physics here: every check reads the generator's true
signals (motor position and velocity at the log stamps, drive force and dry friction
averaged over each log interval, :attr:`Generated.signals`) and compares them with the
law as the generator's docstrings state it.  Two exact tools:

* the **momentum balance** of the velocity-level time stepping: over a log interval
  ``M·Δv = T·(mean F_in − mean friction − mean Σ other forces) − fv·Δx`` holds to
  rounding, so what is left after the in-library forces is the planted force;
* **steady plateaus** of a speed sweep, where the drive force is the friction curve.

What the workbench makes of these runs is judged elsewhere (with the workbench work).
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import welch

sys.path.insert(0, str(Path(__file__).resolve().parent))

from independent_generator import Case, CASE_LISTS, COMPLETE_CASES, draw_case, \
    draw_scenario, drift_mean, EXTRA_NAMES, feature_matches, generate, hermite, main, \
    LOAD_FRICTION_SWEEP, matching_feature, NEW_EFFECT_CASES, ORDINARY_PRESLIDING_CASES, \
    OUT_OF_LIBRARY_CASES, parameter_errors, Planted, position_friction_peak, \
    williams_orders  # noqa: E402
import indgen_laws  # noqa: E402

#: the scan variables of DESIGN.md §6 ``unexplained.features``
AGAINST = ('position', 'velocity', 'force', 'time', 'reversal', 'frequency')
DURATION = 20.0


def steady(v: np.ndarray) -> np.ndarray:
    """Samples sliding in one direction with both neighbours sliding the same way."""
    d = np.sign(v)
    return (d != 0) & (np.roll(d, 1) == d) & (np.roll(d, -1) == d)


def balance_residual(gen) -> tuple[np.ndarray, np.ndarray]:
    """What the in-library forces leave of each log interval's momentum balance [N].

    ``mean F_in − M·Δv/T − mean friction − fv·Δx/T`` over interval ``k`` (the implicit
    viscous force acts on the step's end velocity, whose mean is ``Δx/T``) for a plant of
    Coulomb/Stribeck/viscous friction: the mean of every other force.  Returns the
    residual and the interval mid-positions.
    """
    s = gen.signals
    T = float(gen.run.t[1] - gen.run.t[0])
    fv = gen.truth['effects'].get('viscous', {}).get('fv', 0.0)
    x = gen.motor_position
    dv = np.diff(s['velocity'])
    dx = np.diff(x)
    r = s['drive_force'][:-1] - gen.truth['mass'] * dv / T - s['friction'][:-1] - fv * dx / T
    return r, 0.5 * (x[1:] + x[:-1])


def plateaus(gen, *, min_samples: int = 40) -> list[tuple[float, np.ndarray]]:
    """Constant-speed stretches of a sweep: ``(reference velocity, steady-sample mask)``."""
    vr = gen.run.reference_velocity
    v = gen.signals['velocity']
    out = []
    flat = np.abs(np.gradient(vr)) < 1e-12
    for sp in np.unique(np.round(np.abs(vr[flat & (vr != 0)]), 9)):
        for d in (1.0, -1.0):
            sel = flat & (np.abs(vr - d * sp) < 1e-9) & (np.abs(v - d * sp) < 0.01 * sp)
            if sel.sum() >= min_samples:
                out.append((d * sp, sel))
    return out


def starts_of_motion(v: np.ndarray) -> np.ndarray:
    """Indices where the motion starts in a new direction (every reversal, the first start)."""
    moving = np.flatnonzero(v != 0)
    d = np.sign(v[moving])
    return moving[np.concatenate([[True], d[1:] != d[:-1]])]


# ---------------------------------------------------------------------- draws, cases

def test_extras_and_controls_leave_the_rest_of_a_case_alone():
    """Extras draw after the library effects; a ``without`` control is the same axis.

    The suite's cases (:data:`CASES`, a regression floor) therefore draw what they drew
    before the issue-23 effects existed, and a matched run without pre-sliding differs
    from its pre-sliding case only by the GMS elements.
    """
    for names in (('coulomb', 'viscous'), ('coulomb', 'viscous', 'ripple', 'offset')):
        rig0, truth0 = draw_case(names, seed=77)
        rig1, truth1, extras = draw_scenario(names, EXTRA_NAMES, seed=77)
        assert rig1 == rig0 and truth1 == truth0
        assert set(extras) == set(EXTRA_NAMES)
    with_gms = ORDINARY_PRESLIDING_CASES[0]
    control = next(c for c in ORDINARY_PRESLIDING_CASES
                   if c.without and c.base_label == with_gms.base_label)
    rig_a, truth_a, _ = with_gms.scenario(4)
    rig_b, truth_b, _ = control.scenario(4)
    assert rig_a == rig_b
    assert 'presliding' in truth_a['effects'] and 'presliding' not in truth_b['effects']
    assert {n: p for n, p in truth_a['effects'].items() if n != 'presliding'} \
        == truth_b['effects']
    a, b = with_gms.make(4, duration=5.0), control.make(4, duration=5.0)
    np.testing.assert_array_equal(a.run.reference, b.run.reference)
    # the same noise draws: the encoder error differs only through the motion
    assert a.noise == b.noise


def test_case_lists_carry_their_truth():
    """Every list is labelled, every planted effect says where it acts, and stands out."""
    for name, cases in CASE_LISTS.items():
        labels = [c.label for c in cases]
        assert len(set(labels)) == len(labels), name
    assert all(c.kind == 'out_of_library' for c in OUT_OF_LIBRARY_CASES)
    assert all(c.kind == 'complete' and not c.extra for c in COMPLETE_CASES)
    assert {e for c in OUT_OF_LIBRARY_CASES for e in c.extra} == set(EXTRA_NAMES)
    assert {c.axis for c in OUT_OF_LIBRARY_CASES} == {'linear', 'rotary'}
    for effect in ('load_friction', 'position_friction'):
        mine = [c for c in NEW_EFFECT_CASES if effect in c.names]
        assert {c.axis for c in mine} == {'linear', 'rotary'}
        assert any(c.names == (effect,) for c in mine)                    # alone
        assert any('ripple' in c.names for c in mine)
    # load friction is identifiable only where the drive brakes: every case brakes for
    # a good share of the run on every axis drawn (20–43 % of the moving samples at
    # seeds 1–3; the mass- and friction-scaling is broken there), the control sweep
    # only in its short decelerations (1.2–1.4 %)
    for case in NEW_EFFECT_CASES:
        if 'load_friction' in case.names:
            for seed in (1, 2, 3):
                assert case.make(seed, duration=DURATION).meta['braking_share'] > 0.15, \
                    (case.label, seed)
    assert LOAD_FRICTION_SWEEP.make(1, duration=DURATION).meta['braking_share'] < 0.05
    half = len(ORDINARY_PRESLIDING_CASES) // 2
    assert all('presliding' in c.names and not c.without
               for c in ORDINARY_PRESLIDING_CASES[:half])
    assert all(c.without == ('presliding',) for c in ORDINARY_PRESLIDING_CASES[half:])
    assert {c.excitation for c in ORDINARY_PRESLIDING_CASES} == {'sine', 'sweep'}
    for case in OUT_OF_LIBRARY_CASES:
        for seed in (1, 2):
            gen = case.make(seed, duration=DURATION)
            (p,) = gen.planted
            assert p.name == case.extra[0] and p.against in AGAINST
            assert p.where[0] < p.where[1]
            # each stands clear of what offset + Coulomb + viscous can take up
            assert 0.0025 <= p.share_unabsorbed <= p.share + 1e-12 < 1.0, \
                (case.label, seed, p)
            assert not set(case.extra) & set(gen.truth['effects'])


def test_williams_orders_balance_the_speed_sequence():
    """Each speed follows each other speed exactly once; each takes every place once."""
    rows = williams_orders(6)
    assert all(sorted(r) == list(range(6)) for r in rows)
    assert all(sorted(col) == list(range(6)) for col in zip(*rows))
    pairs = [(r[i], r[i + 1]) for r in rows for i in range(5)]
    assert len(pairs) == len(set(pairs)) == 30


def test_interleaved_sweep_does_not_confound_time_with_speed():
    """Speed is nearly uncorrelated with time on interleaved strokes, not on a sweep."""
    interleaved = Case(('coulomb', 'viscous'), excitation='interleaved').make(2, duration=20.0)
    ordered = Case(('coulomb', 'viscous')).make(2, duration=20.0)

    def corr(gen):
        v = gen.signals['velocity']
        m = steady(v)
        return float(np.corrcoef(np.abs(v[m]), gen.run.t[m])[0, 1])
    assert abs(corr(interleaved)) < 0.15
    assert corr(ordered) > 0.5
    # every speed of the rig runs in both halves of the run
    for lo, hi in ((0.0, 10.0), (10.0, 20.0)):
        t = interleaved.run.t
        seen = {round(abs(v), 9) for v, sel in plateaus(interleaved, min_samples=5)
                if np.any(sel & (t >= lo) & (t < hi))}
        assert seen == {round(s, 9) for s in interleaved.rig.speeds}, (lo, seen)


# ---------------------------------------------------------------------- out of library

def test_friction_drift_level_at_start_and_end():
    """The Coulomb level falls with time as ``fc + Δ(e^{−t/τ} − ē)``; ``fc`` is its mean."""
    case = Case(('coulomb', 'viscous'), excitation='interleaved', extra=('friction_drift',))
    gen = case.make(2, duration=DURATION)
    q = gen.planted[0].params
    fc = gen.truth['effects']['coulomb']['fc']
    t, v = gen.run.t, gen.signals['velocity']
    span = len(t) * (t[1] - t[0])
    m = steady(v)
    level = gen.signals['friction'][m] * np.sign(v[m])
    law = fc + q['delta'] * (np.exp(-t[m] / q['tau']) - drift_mean(q['tau'], span))
    assert np.max(np.abs(level - law)) < 2e-3 * fc
    # start and end of the run: cold level Δ(1 − ē) above fc, warm level below it
    first, last = m & (t < t[m][0] + 1.0), m & (t > span - 1.0)
    start = np.mean(gen.signals['friction'][first] * np.sign(v[first]))
    end = np.mean(gen.signals['friction'][last] * np.sign(v[last]))
    ebar = drift_mean(q['tau'], span)
    assert start == pytest.approx(fc + q['delta'] * (math.exp(-np.mean(t[first]) / q['tau'])
                                                     - ebar), rel=2e-3)
    assert end == pytest.approx(fc + q['delta'] * (math.exp(-np.mean(t[last]) / q['tau'])
                                                   - ebar), rel=2e-3)
    assert (start - end) > 0.5 * abs(q['delta']) * (1 - math.exp(-span / q['tau'])) \
        if q['delta'] > 0 else (end - start) > 0
    # the drift's time average over the run is zero: fc is the average level
    tt = np.linspace(0.0, span, 200001)
    assert np.mean(np.exp(-tt / q['tau']) - ebar) == pytest.approx(0.0, abs=1e-5)
    assert gen.planted[0].where == (0.0, min(span, 2 * q['tau']))
    assert gen.planted[0].odd and gen.planted[0].against == 'time'


def test_disturbance_spectral_peak_at_its_frequency():
    """A fixed-frequency force: the balance leaves ``A·sin(2πft + φ)`` and nothing else."""
    for case in (Case(('coulomb', 'viscous'), extra=('disturbance',)),
                 Case(('coulomb', 'viscous'), axis='rotary', input='current', rate=200.0,
                      mass_factor=0.6, extra=('disturbance',))):
        gen = case.make(3, duration=DURATION)
        p = gen.planted[0]
        q = p.params
        r, _ = balance_residual(gen)
        T = float(gen.run.t[1] - gen.run.t[0])
        f, psd = welch(r, fs=1.0 / T, nperseg=min(4096, len(r) // 4))
        band = f > 1.0
        peak = float(f[band][np.argmax(psd[band])])
        assert abs(peak - q['frequency']) <= f[1] - f[0]
        assert p.where[0] <= peak <= p.where[1]
        # least squares at the frequency: the amplitude, and nothing left beside it
        tm = gen.run.t[:-1] + 0.5 * T
        w = 2 * np.pi * q['frequency']
        # a log interval's mean of the sine: amplitude × sinc(f·T) (the interval average)
        gain = np.sinc(q['frequency'] * T)
        cols = np.column_stack([np.sin(w * tm), np.cos(w * tm)])
        coef, *_ = np.linalg.lstsq(cols, r, rcond=None)
        assert math.hypot(*coef) == pytest.approx(q['amplitude'] * gain, rel=1e-3)
        assert np.std(r - cols @ coef) < 1e-3 * q['amplitude']
        assert not p.odd and p.against == 'frequency'


def test_drag_on_the_steady_friction_curve():
    """Steady drive force ``fc + fv·|v| + c·v²`` at every sweep speed, both directions."""
    case = Case(('coulomb', 'viscous'), extra=('drag',), mass_factor=0.6)
    gen = case.make(3, duration=30.0)
    e = gen.truth['effects']
    fc, fv, c = e['coulomb']['fc'], e['viscous']['fv'], gen.planted[0].params['c']
    rows, speeds = [], []
    for vr, sel in plateaus(gen):
        v = gen.signals['velocity'][sel]
        fin = float(np.mean(gen.signals['drive_force'][sel]))
        law = float(np.mean(np.sign(v) * (fc + fv * np.abs(v) + c * v * v)))
        assert fin * np.sign(vr) == pytest.approx(law * np.sign(vr), abs=0.5), vr
        rows.append(fin * np.sign(vr))
        speeds.append(abs(vr))
    assert len(speeds) >= 10
    s = np.array(speeds)
    coef, *_ = np.linalg.lstsq(np.column_stack([np.ones_like(s), s, s * s]), np.array(rows),
                               rcond=None)
    assert coef[2] == pytest.approx(c, rel=0.03)
    p = gen.planted[0]
    # a quadratic is mostly a line over the speeds: offset + Coulomb + viscous absorb
    # most of it, the curvature is left
    assert p.share_unabsorbed < 0.2 * p.share
    assert p.odd and p.against == 'velocity'


def test_bump_is_a_force_at_one_place_in_both_directions():
    """``A·exp(−½((x − x_b)/w)²)``, the same sign both ways, nothing away from it."""
    for case in (Case(('coulomb', 'viscous'), extra=('bump',)),
                 Case(('coulomb', 'viscous'), axis='rotary', extra=('bump',))):
        gen = case.make(2, duration=DURATION)
        q = gen.planted[0].params
        r, xm = balance_residual(gen)
        v = gen.signals['velocity'][:-1]
        for d in (1.0, -1.0):
            sel = np.sign(v) == d
            near = sel & (np.abs(xm - q['x']) < 3 * q['width'])
            assert near.sum() > 50
            law = q['amplitude'] * np.exp(-0.5 * ((xm[near] - q['x']) / q['width']) ** 2)
            assert np.max(np.abs(r[near] - law)) < 0.03 * abs(q['amplitude'])
            i = int(np.argmax(np.abs(r[near])))
            assert abs(xm[near][i] - q['x']) < 0.2 * q['width']
            assert np.sign(r[near][i]) == np.sign(q['amplitude'])        # not a friction
        far = np.abs(xm - q['x']) > 6 * q['width']
        assert np.max(np.abs(r[far])) < 1e-6 * abs(q['amplitude'])
        p = gen.planted[0]
        assert p.where[0] < q['x'] < p.where[1] and not p.odd and p.against == 'position'


def test_speed_dip_lowers_friction_at_one_speed():
    """Steady drive force ``fc − D·exp(−½((|v| − v_d)/w)²) + fv·|v|`` per plateau."""
    case = Case(('coulomb', 'viscous'), extra=('speed_dip',))
    gen = case.make(1, duration=30.0)
    e = gen.truth['effects']
    fc, fv = e['coulomb']['fc'], e['viscous']['fv']
    q = gen.planted[0].params
    dipped = 0
    for vr, sel in plateaus(gen):
        fin = float(np.mean(gen.signals['drive_force'][sel])) * np.sign(vr)
        level = fin - fv * abs(vr)
        dip = q['depth'] * math.exp(-0.5 * ((abs(vr) - q['speed']) / q['width']) ** 2)
        assert level == pytest.approx(fc - dip, abs=0.5), vr
        if math.isclose(abs(vr), q['speed']):
            dipped += 1
            assert fc - level == pytest.approx(q['depth'], rel=0.05)
        else:
            # the other sweep speeds lie outside the band: at most a tenth of the dip
            assert fc - level < 0.1 * q['depth'] + 0.5
    assert dipped == 2                                        # both directions
    p = gen.planted[0]
    assert p.where[0] < q['speed'] < p.where[1] and p.odd and p.against == 'velocity'


def test_reversal_transient_decays_with_distance():
    """``fc + R·exp(−s/λ)``: raised after each reversal, back to fc after a few λ."""
    case = Case(('coulomb', 'viscous'), rate=2000.0, extra=('reversal_transient',))
    gen = case.make(2, duration=DURATION)
    q = gen.planted[0].params
    fc = gen.truth['effects']['coulomb']['fc']
    v, x, fr = gen.signals['velocity'], gen.motor_position, gen.signals['friction']
    m = steady(v)
    dist, level = [], []
    starts = starts_of_motion(v)
    for a, b in zip(starts, list(starts[1:]) + [len(v)]):
        seg = np.arange(a, b)
        seg = seg[m[seg]]
        dist.append(np.abs(x[seg] - x[a - 1]))
        level.append(fr[seg] * np.sign(v[seg]))
    s, lv = np.concatenate(dist), np.concatenate(level)
    # fit the decay on the samples 0.3–3 λ after a reversal
    pick = (s > 0.3 * q['length']) & (s < 3 * q['length'])
    assert pick.sum() > 100
    slope, icpt = np.polyfit(s[pick], np.log(lv[pick] - fc), 1)
    assert -1.0 / slope == pytest.approx(q['length'], rel=0.05)
    assert math.exp(icpt) == pytest.approx(q['height'], rel=0.05)
    assert np.max(np.abs(lv[s > 8 * q['length']] - fc)) < 0.01 * fc
    p = gen.planted[0]
    assert p.where == (0.0, 3 * q['length']) and p.odd and p.against == 'reversal'
    assert 0.0 < p.where_time[1] < 1.0


# ---------------------------------------------------------------------- new library effects

def test_load_friction_grows_with_the_drive_force():
    """Dry level ``fc + mu·|F_in|``: steady ``|F_in| = (fc + fv·|v|)/(1 − mu)``."""
    for case in (Case(('coulomb', 'viscous', 'load_friction')),
                 Case(('coulomb', 'viscous', 'load_friction'), axis='rotary',
                      input='current')):
        gen = case.make(3, duration=30.0)
        e = gen.truth['effects']
        fc, fv, mu = e['coulomb']['fc'], e['viscous']['fv'], e['load_friction']['mu']
        rows, speeds = [], []
        for vr, sel in plateaus(gen):
            rows.append(float(np.mean(gen.signals['drive_force'][sel])) * np.sign(vr))
            speeds.append(abs(vr))
        s = np.array(speeds)
        (a, b), *_ = np.linalg.lstsq(np.column_stack([np.ones_like(s), s]), np.array(rows),
                                     rcond=None)
        assert 1.0 - fc / a == pytest.approx(mu, rel=0.1)
        assert b == pytest.approx(fv / (1.0 - mu), rel=0.03)
        # and sample by sample, accelerating or not
        v, fin = gen.signals['velocity'], gen.signals['drive_force']
        m = steady(v)
        level = gen.signals['friction'][m] * np.sign(v[m])
        assert np.quantile(np.abs(level - (fc + mu * np.abs(fin[m]))), 0.99) < 0.01 * fc
        assert np.ptp(level) > 0.5 * mu * np.ptp(np.abs(fin[m]))


def test_position_friction_interpolation():
    """The generator's own Hermite law: through the knots, C¹, flat beyond the ends."""
    rng = np.random.default_rng(3)
    x = np.linspace(-0.03, 0.03, 7) + rng.uniform(-0.002, 0.002, 7)     # uneven knots
    d = rng.uniform(0.0, 8.0, 7)
    np.testing.assert_allclose(hermite(x, x, d), d, atol=1e-12)
    assert hermite(np.array([x[0] - 0.01]), x, d)[0] == d[0]
    assert hermite(np.array([x[-1] + 0.01]), x, d)[0] == d[-1]
    # C¹: one-sided slopes agree at every knot (|d''| ≤ 6·8 N/(6 mm)² bounds the gap)
    h = 1e-8
    for k in range(7):
        left = (hermite(x[k] - h, x, d) - hermite(x[k] - 2 * h, x, d)) / h
        right = (hermite(x[k] + 2 * h, x, d) - hermite(x[k] + h, x, d)) / h
        assert left == pytest.approx(right, abs=0.05 + 1e-4 * abs(left))
    # and a kink would fail: the chord slopes either side of the middle knot differ
    chords = np.diff(d) / np.diff(x)
    assert abs(chords[3] - chords[2]) > 1.0
    # the compiled kernel's evaluation is the same law
    p = np.zeros(indgen_laws.N_PAR)
    p[indgen_laws.I_PF_X:indgen_laws.I_PF_X + 7] = x
    p[indgen_laws.I_PF_D:indgen_laws.I_PF_D + 7] = d
    p[indgen_laws.I_PF_M:indgen_laws.I_PF_M + 7] = indgen_laws.hermite_tangents(x, d)
    xq = np.linspace(-0.07, 0.07, 301)
    np.testing.assert_allclose([indgen_laws.hermite_eval(xx, 7, p) for xx in xq],
                               hermite(xq, x, d), rtol=1e-12, atol=1e-12)


def test_position_friction_raises_friction_over_a_stretch():
    """Sliding level ``fc + dfc(x)`` in both directions; the peak where the truth says."""
    for case in (Case(('coulomb', 'viscous', 'position_friction')),
                 Case(('coulomb', 'viscous', 'position_friction'), axis='rotary',
                      input='current')):
        gen = case.make(2, duration=DURATION)
        pf = gen.truth['effects']['position_friction']
        fc = gen.truth['effects']['coulomb']['fc']
        knots = np.array(pf['x'])
        peak, height = gen.meta['position_friction_peak']
        rot = case.axis == 'rotary'
        scale = 18.0 if rot else 1.0
        # the drawn stretch: 9 knots, zero at both ends, 5–10 N high, 10–20 mm wide at
        # half height, its peak (the middle knot) 5–25 mm off centre
        assert len(knots) == 9 and pf['dfc'][0] == pf['dfc'][-1] == 0.0
        assert peak == pytest.approx(knots[4], abs=1e-9)
        assert (0.1 if rot else 5.0) <= height <= (0.2 if rot else 10.0)
        assert 0.01 * scale <= 0.5 * (knots[-1] - knots[0]) <= 0.02 * scale
        assert 0.005 * scale <= abs(peak) <= 0.025 * scale
        v, x = gen.signals['velocity'], gen.motor_position
        m = steady(v)[:-1]
        xm = 0.5 * (x[1:] + x[:-1])
        level = gen.signals['friction'][:-1] * np.sign(v[:-1])
        for d in (1.0, -1.0):
            sel = m & (np.sign(v[:-1]) == d)
            law = fc + hermite(xm[sel], pf['x'], pf['dfc'])
            assert np.max(np.abs(level[sel] - law)) < 0.02 * height
            on = sel & (np.abs(xm - peak) < 0.1 * (knots[-1] - knots[0]))
            assert on.sum() > 20
            assert np.mean(level[on]) - fc == pytest.approx(height, rel=0.05)
        before = m & (np.maximum(x[1:], x[:-1]) < knots[0])
        assert np.max(np.abs(level[before] - fc)) < 1e-9 * fc


def test_new_effect_parameter_errors():
    """``mu`` relative within 20 %; the peak within 1 cm (0.18 rad rotary)."""
    rig, truth = draw_case(('coulomb', 'load_friction', 'position_friction'), seed=5)
    pf = truth['effects']['position_friction']
    fitted = {**truth, 'effects': {**truth['effects'],
                                   'load_friction': {'mu': truth['effects']['load_friction']
                                                     ['mu'] * 1.15},
                                   'position_friction': {'x': [v + 0.008 for v in pf['x']],
                                                         'dfc': pf['dfc']}}}
    rows = {(e, k): (err, ok) for e, k, _, _, err, ok in parameter_errors(truth, fitted)}
    assert rows[('load_friction', 'mu')][0] == pytest.approx(0.15)
    assert rows[('load_friction', 'mu')][1]
    assert rows[('position_friction', 'peak')][0] == pytest.approx(0.008, abs=1e-4)
    assert rows[('position_friction', 'peak')][1]
    fitted['effects']['load_friction']['mu'] *= 1.1
    fitted['effects']['position_friction']['x'] = [v + 0.015 for v in pf['x']]
    rows = {(e, k): ok for e, k, *_, ok in parameter_errors(truth, fitted)}
    assert not rows[('load_friction', 'mu')] and not rows[('position_friction', 'peak')]
    assert position_friction_peak(pf)[0] == pytest.approx(pf['x'][4], abs=1e-9)


# ---------------------------------------------------------------------- pre-sliding, noise

def test_presliding_on_sine_tracking_and_its_control():
    """Sine tracking at its reversal rate; GMS spreads each turn over µm, the control not."""
    with_gms = next(c for c in ORDINARY_PRESLIDING_CASES
                    if c.label.startswith('coulomb+presliding [') and c.excitation == 'sine')
    control = next(c for c in ORDINARY_PRESLIDING_CASES
                   if c.without and c.base_label == with_gms.base_label)
    reach = {}
    for case in (with_gms, control):
        gen = case.make(3, duration=DURATION)
        f = gen.meta['frequency']
        assert 0.5 <= f <= 2.0 and gen.meta['excitation'] == 'sine'
        vr = gen.run.reference_velocity
        turns = int(np.sum(np.diff(np.sign(vr[np.abs(vr) > 0])) != 0))
        assert abs(turns - 2 * f * DURATION) <= 2
        assert np.max(np.abs(vr)) == pytest.approx(2 * np.pi * f * gen.meta['amplitude'],
                                                   rel=1e-3)
        fc = gen.truth['effects']['coulomb']['fc']
        v, x, fr = gen.signals['velocity'], gen.motor_position, gen.signals['friction']
        starts = starts_of_motion(v)
        dist = []
        for a, b in zip(starts[1:], list(starts[2:]) + [len(v)]):
            d = np.sign(v[a])
            seg = np.arange(a - 1, b)
            hit = np.flatnonzero(fr[seg] * d >= 0.9 * fc)
            if len(hit):
                dist.append(abs(x[seg[hit[0]]] - x[a - 1]))
        assert len(dist) >= 2 * f * DURATION - 3
        reach[case.without] = (float(np.median(dist)), gen)
    d_gms, gen = reach[()]
    k = sum(gen.truth['effects']['presliding']['k'])
    fc = gen.truth['effects']['coulomb']['fc']
    assert d_gms > 0.3 * fc / k
    d_ctrl, gen = reach[('presliding',)]
    step = np.max(np.abs(np.diff(gen.motor_position)))
    assert d_ctrl <= step


@pytest.mark.parametrize('inp,rate', [('voltage', 1000.0), ('current', 500.0),
                                      ('force', 2000.0)])
def test_noise_truth_is_the_noise_on_the_log(inp, rate):
    """The stated position and input noise are what the logged signals carry."""
    gen = Case(('coulomb', 'viscous'), input=inp, rate=rate).make(2, duration=DURATION)
    n = gen.noise
    assert n.quantisation_std == pytest.approx(n.encoder / math.sqrt(12))
    err = gen.run.position - gen.motor_position
    assert np.std(err) == pytest.approx(n.position_std, rel=0.15)
    assert np.allclose(gen.run.position / n.encoder, np.round(gen.run.position / n.encoder),
                       atol=1e-6)
    if inp == 'voltage':
        assert n.input_noise == 0.0
        np.testing.assert_array_equal(gen.run.voltage, gen.applied)
    else:
        assert np.std(gen.run.voltage - gen.applied) == pytest.approx(n.input_noise, rel=0.05)
        assert n.input_noise_force == pytest.approx(gen.rig.input_gain * n.input_noise)


# ---------------------------------------------------------------------- judging helpers

def test_feature_matches_against_odd_and_where():
    """Same scan variable, same parity, overlapping band; speeds folded; reversal s or m."""
    dip = Planted('speed_dip', 'velocity', True, (0.04, 0.08), 0.02, 0.01, {}, '', 'm/s')
    ok = {'against': 'velocity', 'odd': True, 'where': [0.07, 0.1], 'share': 0.3}
    assert feature_matches(ok, dip)
    assert feature_matches({**ok, 'where': [-0.1, -0.06]}, dip)          # signed, folded
    assert not feature_matches({**ok, 'where': [0.1, 0.2]}, dip)
    assert not feature_matches({**ok, 'odd': False}, dip)
    assert not feature_matches({**ok, 'against': 'position'}, dip)
    assert not feature_matches({**ok, 'where': None}, dip)
    bump = Planted('bump', 'position', False, (0.01, 0.02), 0.02, 0.02, {}, '', 'm')
    assert not feature_matches({'against': 'position', 'odd': False,
                                'where': [-0.02, -0.01]}, bump)          # not folded
    rev = Planted('reversal_transient', 'reversal', True, (0.0, 0.002), 0.01, 0.01, {}, '',
                  'm', where_time=(0.0, 0.05))
    assert feature_matches({'against': 'reversal', 'odd': True, 'where': [0.03, 0.2]}, rev)
    assert not feature_matches({'against': 'reversal', 'odd': True, 'where': [0.1, 0.2]},
                               rev)
    feats = [{'against': 'time', 'odd': True, 'where': [0, 1]}, ok]
    assert matching_feature(feats, dip) == 1
    assert matching_feature([], dip) is None and matching_feature(None, dip) is None


def test_generator_writes_a_case_with_its_ground_truth(tmp_path, capsys):
    """``independent_generator.py LABEL -o DIR``: run, truth, meta (noise, planted), start."""
    import yaml
    label = OUT_OF_LIBRARY_CASES[0].label
    assert main([label, '--seed', '2', '--duration', '3', '-o', str(tmp_path)]) == 0
    meta = yaml.safe_load((tmp_path / 'meta.yaml').read_text(encoding='utf-8'))
    truth = yaml.safe_load((tmp_path / 'truth.yaml').read_text(encoding='utf-8'))
    start = yaml.safe_load((tmp_path / 'start.yaml').read_text(encoding='utf-8'))
    assert (tmp_path / 'run.mcap').stat().st_size > 0
    (planted,) = meta['planted']
    assert planted['name'] == 'friction_drift' and planted['against'] == 'time'
    assert meta['noise']['encoder'] > 0 and meta['excitation'] == 'interleaved'
    assert 'friction_drift' not in truth['effects'] and start['effects'] == {}
    with pytest.raises(SystemExit) as exc:
        main(['no such case', '-o', str(tmp_path)])
    assert exc.value.code == 2
    assert 'no case label starts with' in capsys.readouterr().err


def test_generate_rejects_an_unknown_experiment():
    """A misspelt excitation is an error naming the known ones, not a silent default."""
    rig, truth = draw_case(('coulomb',), seed=1)
    with pytest.raises(ValueError, match='sweep, interleaved, chirp, sine'):
        generate(truth, rig, excitation='sinus', duration=1.0)
