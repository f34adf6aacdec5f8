"""Coverage of the reported standard errors (issue 11 item 3, IDENTIFICATION.md §5).

Over at least 30 seeded runs per effect from the independent generator, the true value
of each parameter lies within ±2 reported standard errors in at least 90 % of cases
(a 95 % interval, with room for a little non-normality).  Each run holds several
effects, so every run adds one sample to each of its effects: five run families (8 s
sweeps, 200 Hz – 1 kHz) cover all eleven effects of the vocabulary plus the mass.  The
fit is the user's path with the effect set known (``fit --add …`` from ``effects: {}``
and a mass off by 2×), so this measures the uncertainty of the estimates, not the
choice of effects (the independent suite judges that).  A parameter reported "at its
bound" has no standard error and counts as a miss.

Measured 2026-11-26 (idle machine, 18 s on two processes) after three changes to the
GMS: each element's distance a parameter of the Jacobian, the measurement spread
(``uncertainty.measurement_spread``), and a stiffer element grown back when it pays
(the vector search's growth, ``varpro``) — with the encoder quantum no longer lost to ``np.min``'s
``initial``: presliding.stiffness 29/30 (13/30 before), mass 139/150; and with the
gap's SE from its one-sided SSE profile (``uncertainty.profile_se``) backlash.width
30/30 (25/30 before: the fit sits 1–4 % wide of the truth on a flat-topped profile).
Every judged parameter now meets the bar.

Measured 2026-11-27 after the processing left touches out of the rows (a stroke
braked to a near stop the samples do not resolve, ``processing.touches``): the true
model's residual fell 2–6× on hard-braking runs, and with it the stretch jackknife's
SEs — to what a 7-degree-of-freedom jackknife gives, whose ±2 SE cover 91.5 %, not
95 %: gravity.q0 fell to 25/30, coulomb.fc to 139/150 and viscous.fv to 138/150 with
the estimates themselves unchanged.  With the jackknife's Student factor
(``uncertainty.t_scale``): mass 144/150, coulomb.fc 144/150, viscous.fv 140/150,
gravity.q0 28/30, presliding.stiffness 28/30, the rest 29–30/30 (the tree before both
changes, the same day: 143, 145, 144/150, q0 29/30, Σk 27/30).

Measured (2026-11-25, one process, ~3.5 min): with the stretch-jackknife SEs plus the
processing spread ``fit`` adds (``uncertainty.processing_spread``), the nonlinear parameters
re-searched after each ``--add``, the ripple columns matched to the acceleration
stencil, free GMS element distances, the held command and the velocity seen through the
stencil's own hat kernel (``Kinematics.input_at``, ``processing.stencil``) and the
generator at a 2 µs plant step: delay.tau 30/30, coulomb.fc 149/150, viscous.fv
145/150, mass 138/150, spring, gravity, offset, asymmetry, stribeck and ripple 29–30/30
each; short of the bar: backlash.width 24/30 (+1 % on average: a bias of the gap
reconstruction) and presliding.stiffness 13/30 (the stiffest element's break-away
distance is at the encoder's resolution; Σk is dominated by it).  Before the hat
velocity: delay.tau 26/30 (−6 … −9 SE on the runs with the largest back-EMF damping:
the central difference read as a dead time k·dt²/(12·M)); before the hat-weighted
command: 22/30; at the generator's default 20 µs step: mass 120/150, delay.tau 16/30.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent))

from independent_generator import Case, generate, main_params  # noqa: E402

#: many generate-and-fit jobs: allow more than pytest's default 300 s when the machine
#: is shared (the module's own fixture does all the work)
pytestmark = pytest.mark.timeout(1200)

#: the bar: truth within ±2 SE in at least this share of runs, per parameter
COVERAGE = 0.90
RUNS = 30
DURATION = 8.0
#: the generator's plant step [s]: 2 µs, not its 20 µs default — its semi-implicit
#: Euler step and the sub-step sampling of the delayed command make the delay the data
#: hold differ from the drawn τ by up to a step (−10 µs on average at 20 µs, the size
#: of the SEs judged here; at 2 µs the bias is ~1 µs)
PHYSICS_DT = 2e-6

#: run families: every effect of the vocabulary appears in one of them
FAMILIES = {
    'ripple+offset': Case(('coulomb', 'viscous', 'ripple', 'offset'), rate=500.0),
    'stribeck+spring': Case(('coulomb', 'viscous', 'stribeck', 'spring'), rate=500.0),
    'presliding': Case(('coulomb', 'viscous', 'presliding'), rate=1000.0),
    'asymmetry+delay+backlash': Case(('coulomb', 'viscous', 'asymmetry', 'delay', 'backlash'),
                                     rate=1000.0),
    'gravity': Case(('coulomb', 'viscous', 'gravity'), axis='rotary', input='current',
                    rate=200.0),
}

#: the parameters whose coverage is judged, per effect (names of the model file /
#: FitResult.uncertainty; ``stiffness`` = Σk, ``amplitude_1`` = |first harmonic|)
PARAMS = {
    'mass': ('mass',),
    'coulomb': ('fc',),
    'viscous': ('fv',),
    'stribeck': ('fs', 'vs'),
    'presliding': ('stiffness',),
    'ripple': ('period', 'amplitude_1'),
    'offset': ('f0',),
    'spring': ('k', 'x0'),
    'asymmetry': ('dfc', 'dfv'),
    'delay': ('tau',),
    'backlash': ('width',),
    'gravity': ('mgl', 'q0'),
}


def _se(unc: dict[str, dict[str, float]], name: str, key: str) -> float | None:
    """The reported SE of ``name.key``, None when not reported (NaN, 0, at a bound)."""
    se = (unc.get(name) or {}).get(key)
    if se is None or not math.isfinite(se) or se <= 0:
        return None
    return float(se)


def one_run(case: Case, seed: int) -> list[tuple[str, str, float, float, float | None]]:
    """``(effect, param, truth, estimate, se)`` for every judged parameter of one run."""
    from motor_comp.workbench import fit, kinematics
    from motor_comp.workbench.session import default_hold
    from test_workbench_independent import as_model
    rig, truth = case.draw(seed)
    gen = generate(truth, rig, excitation=case.excitation, duration=DURATION, seed=seed,
                   physics_dt=PHYSICS_DT)
    start = as_model(case.start(truth))
    kin = kinematics(gen.run, hold=default_hold(start))
    names = [n for n in truth['effects']]
    res = fit(kin, start, add=names)
    fitted = res.model.to_dict()
    out = []
    unc = res.uncertainty
    out.append(('mass', 'mass', truth['mass'], fitted['mass'], _se(unc, 'mass', 'mass')))
    for name in names:
        if name not in fitted['effects']:
            continue
        t = main_params(name, truth['effects'][name])
        f = main_params(name, fitted['effects'][name])
        for key in PARAMS.get(name, ()):
            out.append((name, key, t[key], f[key], _se(unc, name, key)))
    return out


def coverage(samples: list) -> dict[tuple[str, str], tuple[int, int]]:
    """Per (effect, param): (runs with |estimate − truth| ≤ 2·SE, runs)."""
    out: dict[tuple[str, str], list[int]] = {}
    for name, key, t, f, se in samples:
        err = f - t
        if name == 'gravity' and key == 'q0':
            err = math.remainder(err, 2 * math.pi)
        hit = se is not None and abs(err) <= 2.0 * se
        c = out.setdefault((name, key), [0, 0])
        c[0] += int(hit)
        c[1] += 1
    return {k: (v[0], v[1]) for k, v in out.items()}


@pytest.fixture(scope='module')
def samples():
    """Every family with RUNS seeds."""
    from test_workbench_independent import parallel_map
    runs = parallel_map(_one_job, [(case, seed) for case in FAMILIES.values()
                                   for seed in range(RUNS)])
    return [s for r in runs for s in r]


def _one_job(job: tuple) -> list:
    return one_run(*job)


def test_every_effect_has_at_least_30_runs(samples):
    """The design: ≥ 30 runs per effect of the vocabulary (and the mass)."""
    cov = coverage(samples)
    per_effect: dict[str, int] = {}
    for (name, _), (_, n) in cov.items():
        per_effect[name] = max(per_effect.get(name, 0), n)
    assert set(per_effect) == set(PARAMS), sorted(per_effect)
    assert min(per_effect.values()) >= RUNS, per_effect


def test_truth_within_two_standard_errors_in_90_percent(samples):
    """Reported SEs are honest: ≥ 90 % coverage of ±2 SE for every judged parameter.

    Measured 2026-11-27 (touches out, the jackknife's Student factor): mass 144/150,
    fc 144/150, fv 140/150, q0 28/30, Σk 28/30, the rest 29–30/30.  Measured
    2026-11-26: backlash.width 30/30 (25/30 with the jackknife and the spreads
    alone: ``uncertainty.profile_se``), presliding.stiffness 29/30, fc 149/150, fv
    145/150, mass 139/150, the rest 29–30 of 30.  Without the processing spread fc and
    fv fall to 81 % and 75 %; at the generator's 20 µs step the mass falls to 120/150;
    Σk without the measurement spread, the per-element distances in the Jacobian and
    the grown stiff element: 13/30.
    """
    cov = coverage(samples)
    bad = {f'{n}.{k}': f'{h}/{m}' for (n, k), (h, m) in cov.items() if h < COVERAGE * m}
    assert not bad, ', '.join(f'{n}.{k} {h}/{m}' for (n, k), (h, m) in cov.items())


def _fitted(family: str, seed: int) -> tuple:
    """``(truth, kinematics, FitResult)`` of one coverage run (``fit --add`` its effects)."""
    from motor_comp.workbench import fit, kinematics
    from motor_comp.workbench.session import default_hold
    from test_workbench_independent import as_model
    case = FAMILIES[family]
    rig, truth = case.draw(seed)
    gen = generate(truth, rig, excitation=case.excitation, duration=DURATION, seed=seed,
                   physics_dt=PHYSICS_DT)
    start = as_model(case.start(truth))
    kin = kinematics(gen.run, hold=default_hold(start))
    return truth, kin, fit(kin, start, add=list(truth['effects']))


def test_the_spreads_enter_the_reported_uncertainty():
    """``fit`` reports √(SE² + processing² + measurement²); each spread finite, ≥ 0."""
    from motor_comp.workbench.dataset import Dataset
    from motor_comp.workbench.library import spec_of
    from motor_comp.workbench.result import estimate
    from motor_comp.workbench.uncertainty import measurement_spread, processing_spread
    _, kin, res = _fitted('gravity', 0)
    D = Dataset([kin], res.model)
    spec = spec_of(res.model)
    est = estimate(D, spec, res.model)
    spread = processing_spread(D, spec, res.model)
    meas = measurement_spread(D, spec, res.model)
    for sp in (spread, meas):
        vals = [v for d in sp.values() for v in d.values()]
        assert vals and all(math.isfinite(v) and v >= 0 for v in vals)
        assert sp['coulomb']['fc'] > 0 and sp['mass']['mass'] > 0
    for g, d in est.se.items():
        for k, se in d.items():
            if math.isfinite(se) and k in spread.get(g, {}):
                want = math.hypot(se, spread[g][k], meas.get(g, {}).get(k, 0.0))
                assert res.uncertainty[g][k] == pytest.approx(want, rel=0.05), (g, k)


def test_the_gap_width_error_is_its_profile_interval():
    """Coverage seed 23: the width sits 2 % wide of a flat-topped SSE profile.

    The jackknife and the spreads once gave ±0.3 µm for a 2.5 µm error (z 8.7); the
    profile interval (``uncertainty.profile_se``) is a floor under what ``fit``
    reports, and alone it holds the truth.  (Today the processing spread is as wide
    as the gap itself: with a smoother twice as long this run is fitted as well by
    1.4 ms of delay and no gap — a choice of processing the run cannot decide.)
    """
    from motor_comp.workbench.library import dataset_for, spec_of
    from motor_comp.workbench.uncertainty import profile_se
    truth, kin, res = _fitted('asymmetry+delay+backlash', 23)
    w_true = truth['effects']['backlash']['width']
    w = res.model.get('backlash').width
    D = dataset_for([kin], res.model)     # the rows fit judged it on
    prof = profile_se(D, spec_of(res.model), res.model, 'backlash', 'width')
    se = res.uncertainty['backlash']['width']
    assert se >= prof * (1 - 1e-9)
    assert abs(w - w_true) <= 2 * se
    assert abs(w - w_true) <= 2 * prof        # the profile interval alone holds it
    assert abs(w - w_true) < 0.05 * w_true    # and the estimate is close


def test_a_stiff_gms_element_merged_into_a_softer_one_is_grown_back():
    """Coverage seed 13: three GMS elements, the free search alone kept two (Σk −36 %).

    The vector search tries a stiffer element and keeps it when the BIC improves: the
    three elements come back, Σk within 5 %, inside its ±2 SE.
    """
    truth, _, res = _fitted('presliding', 13)
    t, f = truth['effects']['presliding'], res.model.to_dict()['effects']['presliding']
    fc_t = truth['effects']['coulomb']['fc']
    fc_f = res.model.to_dict()['effects']['coulomb']['fc']
    d_t = sorted(a * fc_t / k for a, k in zip(t['alpha'], t['k']))
    d_f = sorted(a * fc_f / k for a, k in zip(f['alpha'], f['k']))
    assert len(d_f) == 3, d_f
    # the two softer within 10 %; the stiffest (14 µm, 20 % of fc) came back 34 % short
    # once the reversals were held to their ends (its share taken by the next one)
    assert all(abs(b / a - 1) < 0.1 for a, b in zip(d_t[1:], d_f[1:])), (d_t, d_f)
    assert abs(d_f[0] / d_t[0] - 1) < 0.4, (d_t, d_f)
    k_t, k_f = sum(t['k']), sum(f['k'])
    assert abs(k_f / k_t - 1) < 0.05, (k_t, k_f)
    assert abs(k_f - k_t) <= 2 * res.uncertainty['presliding']['stiffness']
