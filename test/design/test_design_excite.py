"""``excite`` (issue 24 item 2): designed identification runs and their predicted SEs.

Must-show: on three axes — a PMLM (mass, Coulomb, viscous, ripple), a ball-screw
(Coulomb, viscous, Stribeck, dead time) and a rotary arm with gravity — the standard
errors ``excite`` predicts are within 2× of those ``fit`` reports on recordings of the
designed excitation (the TRUE plant simulated along the table with its own noise seeds,
fitted from the start model with the true effect set).  The start models are 2–10 % off
the truth in every parameter (a data sheet, a previous fit).

A fit's reported SE is itself a statistic of one noisy run, so each prediction is
compared with three recordings (own noise seeds).  Where the fit reports a parameter's
SE steadily (these three and the prediction's own five draws within ×2.5 of each
other — three alone can agree by chance: the ball-screw's fc SE is 0.9–1.1 mN in one
draw and 4.5 mN in the next: every parameter of the PMLM and the
arm, the ball-screw's mass, viscous and dead time) the prediction is within 2× of their
median.  The ball-screw's Coulomb and Stribeck SEs are not steady: over eight designs
(``bench/excite_prediction.py``) three recordings of one table scatter up to ×5.4
(fc) and ×15 (vs) — fs from 0.04 to 0.86 N while the estimates themselves scatter by
0.16 N; each of the fit's SE components (cluster-robust, processing and re-measurement
spreads) moves by ×10.  No prediction can be within 2× of such a draw; there the test
asks that the recordings' median fall within the range of the prediction's own draws
(widened 2× each way).

Also: the designed table keeps every limit (travel, vmax, amax, the drive force under
the start model) and holds every regime (both directions, interleaved speeds from creep
to vmax, reversals of a few encoder counts, rests, two periods of travel); the pieces
(the D-optimal allocation, the regressor columns, the PID placement, the creep speed)
are checked on their own.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from motor_comp.control.excitation import ExcitationLimits, drive_along
from motor_comp.design.excite import check_periods, columns, creep_speed, d_optimal, \
    design, loop_for, pid_for, record
from motor_comp.errors import ParameterError
from motor_comp.physics.axis import AxisModel
from motor_comp.workbench.derivatives import kinematics
from motor_comp.workbench.fit import fit
from motor_comp.workbench.session import default_hold

PMLM = {'input_gain': 15.116279069767442, 'back_emf': 123.0}
SCREW = {'input_gain': 50.0, 'damping': 50.0}
ARM = {'axis': 'rotary', 'input': 'current', 'input_gain': 0.8}

CASES = {
    'pmlm': dict(
        true={**PMLM, 'mass': 5.4, 'effects': {
            'coulomb': {'fc': 10.0}, 'viscous': {'fv': 10.0},
            'ripple': {'period': 0.02, 'harmonics': [[8.5, 0.0]]}}},
        start={**PMLM, 'mass': 5.9, 'effects': {
            'coulomb': {'fc': 9.0}, 'viscous': {'fv': 11.0},
            'ripple': {'period': 0.0201, 'harmonics': [[7.7, 1.0]]}}},
        limits=ExcitationLimits(travel=(-0.05, 0.05), vmax=0.2, amax=3.0, bandwidth=5.0),
        loop={'plant': 'pmlm', 'noise_std': 2e-7},
        steady={('mass', 'mass'), ('coulomb', 'fc'), ('viscous', 'fv'),
                ('ripple', 'period'), ('ripple', 'amplitude_1')}),
    'ballscrew': dict(
        true={**SCREW, 'mass': 25.0, 'effects': {
            'coulomb': {'fc': 12.0}, 'viscous': {'fv': 200.0},
            'stribeck': {'fs': 18.0, 'vs': 0.001, 'delta': 1.0}, 'delay': {'tau': 0.00129}}},
        start={**SCREW, 'mass': 26.0, 'effects': {
            'coulomb': {'fc': 11.5}, 'viscous': {'fv': 190.0},
            'stribeck': {'fs': 17.3, 'vs': 0.00105, 'delta': 1.0},
            'delay': {'tau': 0.00125}}},
        limits=ExcitationLimits(travel=(-0.02, 0.02), vmax=0.05, amax=0.5, bandwidth=3.0),
        loop={'plant': 'ballscrew', 'noise_std': 2e-7},
        steady={('mass', 'mass'), ('delay', 'tau')}),
    'rotary': dict(
        true={**ARM, 'mass': 0.01, 'effects': {
            'coulomb': {'fc': 0.05}, 'viscous': {'fv': 0.01},
            'gravity': {'mgl': 1.5, 'q0': 0.3}}},
        start={**ARM, 'mass': 0.011, 'effects': {
            'coulomb': {'fc': 0.045}, 'viscous': {'fv': 0.011},
            'gravity': {'mgl': 1.4, 'q0': 0.25}}},
        limits=ExcitationLimits(travel=(-3.0, 3.0), vmax=5.0, amax=50.0, bandwidth=3.0),
        loop={'encoder': 1e-5, 'noise_std': 2e-6},
        steady={('mass', 'mass'), ('coulomb', 'fc'), ('viscous', 'fv'),
                ('gravity', 'mgl'), ('gravity', 'q0')}),
}


@pytest.mark.parametrize('name', list(CASES))
def test_predicted_se_within_2x_of_recorded(name):
    case = CASES[name]
    true, start = AxisModel.from_dict(case['true']), AxisModel.from_dict(case['start'])
    loop = loop_for(start, **case['loop'])
    d = design(start, case['limits'], duration=60.0, loop=loop, seed=0)
    recorded = []
    for seed in (1, 2, 3):      # the true plant along the table, its own noise seeds
        run = record(loop.with_model(true), d.table, seed=seed)
        recorded.append(fit(kinematics(run, hold=default_hold(start)), start).uncertainty)
    assert set(d.predicted_se) == set(recorded[0]) == {'mass'} | set(start.names)
    steady = set()
    for g, params in d.predicted_se.items():
        assert set(params) == set(recorded[0][g])
        for k, se in params.items():
            draws = np.array([r[g][k] for r in recorded])
            # the fit reports it steadily: over the prediction's own draws and these
            every = np.concatenate([draws, d.se_draws[g][k]])
            if every.max() / every.min() <= 2.5:
                steady.add((g, k))
                ratio = se / float(np.median(draws))
                assert 0.5 <= ratio <= 2.0, (name, g, k, se, draws)
            else:   # the recordings fall where the prediction's own draws do (±2×)
                own = np.asarray(d.se_draws[g][k])
                assert own.min() / 2 <= float(np.median(draws)) <= 2 * own.max(), \
                    (name, g, k, own, draws)
    assert steady >= case['steady'], (name, case['steady'] - steady)


def test_design_keeps_limits_and_holds_every_regime():
    start = AxisModel.from_dict(CASES['pmlm']['start'])
    # a drive limit that binds: the fastest passes need more than 28 N under the model
    lim = ExcitationLimits(travel=(-0.03, 0.05), vmax=0.2, amax=3.0, bandwidth=5.0, fmax=28.0)
    loop = loop_for(start, plant='pmlm', noise_std=2e-7)
    d = design(start, lim, duration=60.0, loop=loop, periods=(0.03,), seed=0)
    tab = d.table
    assert abs(tab.duration - 60.0) < 0.05 * 60.0
    # limits: travel, speed, acceleration, drive force under the start model
    assert lim.travel[0] <= tab.x.min() and tab.x.max() <= lim.travel[1]
    assert np.max(np.abs(tab.v)) <= lim.vmax * (1 + 1e-9)
    assert np.max(np.abs(tab.a)) <= lim.amax * (1 + 1e-9)
    f, _ = drive_along(start, tab.x, tab.v, tab.a, float(tab.t[1] - tab.t[0]))
    assert np.max(np.abs(f)) <= 28.0
    assert d.peaks.force == pytest.approx(np.max(np.abs(f)))
    # two periods of the longest position-dependent effect (the hint, 30 mm)
    assert tab.x.max() - tab.x.min() >= 2 * 0.03
    # speeds from creep to (nearly) vmax, in both directions, not rising in time
    speeds = d.speeds
    assert max(speeds) / min(speeds) > 20
    assert speeds != sorted(speeds) and speeds != sorted(speeds, reverse=True)
    assert np.sum(np.diff(speeds) > 0) >= 2 and np.sum(np.diff(speeds) < 0) >= 2
    top = max(speeds)
    assert np.any(tab.v > 0.99 * top) and np.any(tab.v < -0.99 * top)
    # small reversals: parts of ≤ 10 encoder counts that reverse several times
    small = [(t0, t1) for kind, lv, t0, t1 in d.order if kind == 'reversal' and lv <= 1e-5]
    assert small
    for t0, t1 in small:
        m = (tab.t >= t0) & (tab.t <= t1)
        assert np.ptp(tab.x[m]) <= 2.1e-5
        assert np.sum(np.diff(np.sign(tab.v[m][np.abs(tab.v[m]) > 0])) != 0) >= 4
    # rests: at least one per part, each ≥ 0.2 s at exactly zero speed
    still = np.abs(tab.v) == 0.0
    edges = np.flatnonzero(np.diff(still.astype(int)))
    runs = np.diff(np.concatenate(([0], edges + 1, [len(still)])))
    starts = np.concatenate(([0], edges + 1))
    rests = [r for r, s in zip(runs, starts) if still[s] and r >= 200]
    assert len(rests) >= len(d.order)
    # the D-optimal share went somewhere: some part more than once
    assert max(p['count'] for p in d.parts) > 1
    assert {p['kind'] for p in d.parts} == {'pass', 'reversal', 'sweep'}


def test_d_optimal_finds_the_known_design():
    """Quadratic regression on x ∈ {−1, 0, 1}: the D-optimal weights are 1/3 each."""
    infos = [np.outer(r, r) for r in ([1.0, -1.0, 1.0], [1.0, 0.0, 0.0], [1.0, 1.0, 1.0])]
    u = d_optimal(infos, np.zeros(3), 1.0)
    np.testing.assert_allclose(u, [1 / 3] * 3, atol=1e-3)
    # with one point already given twice its share, the free time goes to the others
    u = d_optimal(infos, np.array([0.0, 2.0, 0.0]), 1.0)
    assert u[1] < 0.05 and u[0] == pytest.approx(u[2], rel=1e-6)


def test_pid_places_the_poles():
    model = AxisModel.from_dict({'mass': 2.0, 'input_gain': 10.0, 'back_emf': 1.0,
                                 'damping': 4.0})
    g = pid_for(model, 10.0)
    w = 2 * math.pi * 10.0
    c = 4.0 + 10.0 * 1.0
    roots = np.roots([2.0, c + 10.0 * g['kd'], 10.0 * g['kp'], 10.0 * g['ki']])
    np.testing.assert_allclose(np.sort_complex(roots), [-w, -w, -w], rtol=1e-3, atol=1e-2)
    assert g['tf'] == pytest.approx(0.1 / w)


def test_regressor_columns_are_the_effects_laws():
    model = AxisModel.from_dict({'mass': 3.0, 'input_gain': 15.0, 'effects': {
        'coulomb': {'fc': 5.0}, 'viscous': {'fv': 2.0}, 'offset': {'f0': 1.0},
        'ripple': {'period': 0.02, 'harmonics': [[4.0, 1.0]]}, 'delay': {'tau': 1e-3}}})
    t = np.linspace(0, 2, 2001)
    x, v, a = 0.03 * np.sin(t), 0.03 * np.cos(t), -0.03 * np.sin(t)
    du = np.cos(3 * t)
    names, J = columns(model, x, v, a, du, 1e-3)
    col = dict(zip(names, J.T))
    np.testing.assert_allclose(col['mass'], -a, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(col['coulomb.fc'], -np.sign(v), atol=1e-6)
    np.testing.assert_allclose(col['viscous.fv'], -v, rtol=1e-6, atol=1e-9)
    np.testing.assert_allclose(col['offset.f0'], -1.0, rtol=1e-6)
    np.testing.assert_allclose(col['ripple.a1'], -np.sin(2 * np.pi * x / 0.02), atol=1e-6)
    np.testing.assert_allclose(col['ripple.b1'], -np.cos(2 * np.pi * x / 0.02), atol=1e-6)
    np.testing.assert_allclose(col['delay.tau'], -15.0 * du)
    # the period's column: the derivative of the ripple force with respect to it
    w = 2 * np.pi / 0.02
    d_period = -(4.0 * np.cos(w * x) - 1.0 * np.sin(w * x)) * (-w * x / 0.02)
    np.testing.assert_allclose(col['ripple.period'], d_period, rtol=1e-4,
                               atol=1e-4 * np.max(np.abs(d_period)))


def test_creep_speed_is_above_stick_slip():
    """Dry friction under PID-type feedback stick-slips at creep; a viscous axis does not."""
    start = AxisModel.from_dict(CASES['ballscrew']['true'])
    lim = CASES['ballscrew']['limits']
    loop = loop_for(start, plant='ballscrew', encoder=0.0)
    creep, stuck = creep_speed(start, lim, loop)
    assert stuck is not None and stuck < creep < 2e-3
    viscous = start.without('coulomb', 'stribeck')
    creep, stuck = creep_speed(viscous, lim, loop.with_model(viscous))
    assert stuck is None and creep == pytest.approx(lim.vmax / 300, rel=1e-6)


@pytest.mark.parametrize('model, travel, periods, needle', [
    ({'mass': 1.0, 'effects': {'ripple': {'period': 0.02}}}, (0.0, 0.03), (),
     "1.47 periods of the model's ripple period 0.02 m; at least 2"),
    ({'mass': 1.0}, (0.0, 0.03), (0.05,), 'periods of --period 0.05 m'),
    ({'axis': 'rotary', 'mass': 1.0, 'effects': {'gravity': {'mgl': 1.0}}}, (0.0, 2.0), (),
     'half a revolution'),
])
def test_travel_too_short(model, travel, periods, needle):
    m = AxisModel.from_dict(model)
    with pytest.raises(ParameterError, match=needle.replace('.', r'\.')):
        check_periods(m, ExcitationLimits(travel=travel, vmax=1.0, amax=1.0), periods)


def test_duration_and_drive_errors():
    start = AxisModel.from_dict(CASES['rotary']['start'])
    lim = CASES['rotary']['limits']
    with pytest.raises(ParameterError, match='too short: every part once takes'):
        design(start, lim, duration=5.0)
    with pytest.raises(ParameterError, match='at most 240 s'):
        design(start, lim, duration=1000.0)
    tight = ExcitationLimits(travel=lim.travel, vmax=lim.vmax, amax=lim.amax, fmax=1.0)
    with pytest.raises(ParameterError, match='leave no room'):
        design(start, tight, duration=60.0)
