"""Adaptive sliding controller (Tan 2002) on the PMLM: beats the PID, each law converges.

The controllers know only the nominal model (:mod:`motor_comp.control.nominal`): mass
+20 %, friction and ripple at 50 % of the truth (``half``) or zero (``zero``).
"""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from motor_comp.control import AdaptiveParams, default_trajectory, make_controller, simulate
from motor_comp.control.adaptive_sliding import ESTIMATES, estimates_in_units, \
    nominal_theta, projection_box
from motor_comp.control.controller import C_TH, Q_HI, Q_LO, Q_TH0
from motor_comp.control.nominal import derive_nominal
from motor_comp.physics import StepLoad, make_effect

DURATION = 16.0


@pytest.fixture(scope='module')
def pmlm_runs(pmlm):
    """PID baseline and adaptive sliding on the default p2p trajectory, from both starts."""
    traj = default_trajectory('pmlm')
    out = {}
    for start in ('half', 'zero'):
        nominal = derive_nominal(pmlm, start)
        for mode in ('pid', 'adaptive_sliding'):
            ctrl = make_controller(mode, plant=nominal)
            key = mode if start == 'half' else f'{mode}/zero'
            out[key] = (simulate(pmlm, ctrl, traj, duration=DURATION), ctrl)
    return out


def test_pid_baseline_is_the_adaptive_pid_part(pmlm):
    pid = make_controller('pid', plant=pmlm).params
    kp, ki, kd = AdaptiveParams().pid_gains
    assert (pid.kp, pid.ki, pid.kd, pid.tf) == (kp, ki, kd, AdaptiveParams().tf)


def test_pid_baseline_is_well_tuned(pmlm):
    """Not handicapped: exact sampled loop at 1 kHz, PM ≈ 50°, GM ≈ 8.4 dB, 120 Hz."""
    from motor_comp.control.npid import loop_margins, sampled_loop
    p = make_controller('pid', plant=pmlm).params
    w, L = sampled_loop(pmlm.model, p, delay=0.0, control_period=1e-3)
    m = loop_margins(L, w)
    assert m.phase_margin_deg == pytest.approx(49.9, abs=1.0)
    assert m.gain_margin_db == pytest.approx(8.4, abs=0.2) and m.crossover_hz > 110.0
    # the gain is near the most the sampled loop takes: 2.6× leaves no margin
    hot = p.replace(kp=p.kp * 2.6, ki=p.ki * 2.6, kd=p.kd * 2.6)
    w, L = sampled_loop(pmlm.model, hot, delay=0.0, control_period=1e-3)
    assert loop_margins(L, w).phase_margin_deg < 1.0


def test_adaptive_halves_pid_max_error(pmlm_runs):
    e_pid = np.max(np.abs(pmlm_runs['pid'][0].error))
    e_ad = np.max(np.abs(pmlm_runs['adaptive_sliding'][0].error))
    # Tan 2002 §IV: < 8 µm vs ≈ 15 µm (ratio ≈ 0.5).  Nominal at 50 %: measured 0.26
    # incl. the first moves, ≈ 0.07 in the last 4 s
    assert e_ad <= 0.35 * e_pid
    late = pmlm_runs['adaptive_sliding'][0].t > DURATION - 4.0
    assert np.max(np.abs(pmlm_runs['adaptive_sliding'][0].error[late])) <= 0.15 * e_pid


def test_adaptive_from_zero_knowledge(pmlm_runs, pmlm):
    """Tan's experiment: friction and ripple estimates start at zero; still <= 0.5× PID."""
    res, ctrl = pmlm_runs['adaptive_sliding/zero']
    e_pid = np.max(np.abs(pmlm_runs['pid/zero'][0].error))
    assert np.max(np.abs(res.error)) <= 0.5 * e_pid        # measured 0.42
    truth = make_controller('adaptive_sliding', plant=pmlm).nominal
    for name in ('fc', 'ripple_a'):
        est = res.estimate(name)
        assert est[0] == 0.0
        # measured after 16 s: fc 9.1 of 10 N, A1 7.6 of 8.5 N (nothing pulls them there:
        # the leakage target is the zero nominal)
        assert abs(est[-1] - truth[name]) <= 0.2 * truth[name], name


def test_adaptive_settles_within_encoder_counts(pmlm_runs):
    res = pmlm_runs['adaptive_sliding'][0]
    # end of each dwell (last 0.2 s of the 0.5 s rests) in the last 4 s
    tc = res.t % 2.0
    late = (((tc > 0.8) & (tc < 1.0)) | ((tc > 1.8) & (tc < 2.0))) & (res.t > DURATION - 4)
    assert np.max(np.abs(res.error[late])) <= 2e-6  # two counts of the 1 µm encoder


def test_no_chattering_beyond_boundary_layer(pmlm_runs):
    def hf_fraction(u):
        spec = np.abs(np.fft.rfft(u - u.mean())) ** 2
        f = np.fft.rfftfreq(u.size, 1e-3)
        return spec[f > 200.0].sum() / spec.sum()
    ad = hf_fraction(pmlm_runs['adaptive_sliding'][0].voltage)
    pid = hf_fraction(pmlm_runs['pid'][0].voltage)
    assert ad < 1e-3            # < 0.1 % of the command's power above 200 Hz
    assert ad < 5.0 * pid + 1e-4


def test_estimates_stay_in_projection_box(pmlm_runs, pmlm):
    res, ctrl = pmlm_runs['adaptive_sliding']
    nominal = derive_nominal(pmlm)
    theta, _ = nominal_theta(nominal.model)        # the box is built around the nominal
    lo, hi = projection_box(theta, AdaptiveParams().bound_factor)
    # what the kernel uses: leakage target θ0 and box from the nominal, not the truth
    np.testing.assert_allclose(ctrl.packed[Q_TH0:Q_TH0 + 7], theta, rtol=1e-12)
    np.testing.assert_allclose(ctrl.packed[Q_LO:Q_LO + 7], lo, rtol=1e-12)
    np.testing.assert_allclose(ctrl.packed[Q_HI:Q_HI + 7], hi, rtol=1e-12)
    true_theta, _ = nominal_theta(pmlm.model)
    assert theta[2] == pytest.approx(0.5 * true_theta[2])     # fc/g at 50 %
    assert theta[0] == pytest.approx(1.2 * true_theta[0])     # mass +20 %
    lo_u = estimates_in_units(lo, pmlm.model.input_gain)
    hi_u = estimates_in_units(hi, pmlm.model.input_gain)
    for i, name in enumerate(ESTIMATES):
        assert np.all(res.estimates[:, i] >= lo_u[name] - 1e-12)
        assert np.all(res.estimates[:, i] <= hi_u[name] + 1e-12)
    # nominal fc = 5 N (50 %) is below the floor 0.5 V = 7.6 N: box [0, 3·7.6 N] ∋ 10 N
    assert lo_u['fc'] == 0.0 and hi_u['fc'] == pytest.approx(1.5 * pmlm.model.input_gain)
    assert hi_u['fc'] > pmlm.model.fc


GAMMAS = {'mass': 'gamma_mass', 'back_emf': 'gamma_back_emf', 'fc': 'gamma_fc',
          'fv': 'gamma_fv', 'ripple_a': 'gamma_ripple', 'ripple_b': 'gamma_ripple'}


def _single_effect_plant(pmlm, name):
    base = pmlm.model.without('coulomb', 'stribeck', 'viscous', 'ripple')
    extra = {'fc': make_effect('coulomb', {'fc': 10.0}),
             'fv': make_effect('viscous', {'fv': 30.0}),
             'ripple_a': make_effect('ripple', {'period': 0.02, 'harmonics': [[6.0, 4.0]]}),
             'ripple_b': make_effect('ripple', {'period': 0.02, 'harmonics': [[6.0, 4.0]]})}
    model = base.with_effect(extra[name]) if name in extra else base
    return dataclasses.replace(pmlm, model=model)


@pytest.mark.parametrize('name', list(GAMMAS))
def test_each_update_law_moves_its_estimate_to_truth(pmlm, name):
    plant = _single_effect_plant(pmlm, name)
    gammas = {g: 0.0 for g in set(GAMMAS.values()) | {'gamma_k'}}
    gammas[GAMMAS[name]] = getattr(AdaptiveParams(), GAMMAS[name])
    # σ = 0: the nominal here is the truth, and leakage towards it would help the law
    ctrl = make_controller('adaptive_sliding', plant=plant, initial_fraction=1.0, sigma=0.0,
                           **gammas)
    idx = ESTIMATES.index(name)
    for j in ((4, 5) if name.startswith('ripple') else (idx,)):
        ctrl.state[C_TH + j] *= 0.5           # only the law under test starts at 50 %
    truth = ctrl.nominal[name]
    res = simulate(plant, ctrl, default_trajectory('pmlm'), duration=10.0)
    est = res.estimate(name)
    assert est[0] == pytest.approx(0.5 * truth, rel=1e-3)
    # the gap to the truth closes by ≥ 75 % in 10 s (measured: back-EMF 99 %, fc 91 %,
    # fv 82 %, A1 99 %, B1 82 %); the mass law only by ≥ 55 % (measured 60 %): its
    # regressor ẍ_r is excited only during the short accelerations of the moves
    closed = 1.0 - abs(est[-1] - truth) / abs(0.5 * truth)
    assert closed >= (0.55 if name == 'mass' else 0.75)


def test_robust_gain_grows_with_unmodelled_load(pmlm):
    plant = _single_effect_plant(pmlm, 'mass')
    ctrl = make_controller('adaptive_sliding', plant=plant, initial_fraction=1.0,
                           gamma_mass=0.0, gamma_back_emf=0.0, gamma_fc=0.0, gamma_fv=0.0,
                           gamma_ripple=0.0)
    traj = default_trajectory('pmlm')
    res = simulate(plant, ctrl, traj, duration=4.0, load=StepLoad(force=15.0, t_start=1.0))
    k = res.estimate('robust_gain')
    ctrl.reset()
    k_free = simulate(plant, ctrl, traj, duration=4.0).estimate('robust_gain')
    assert k[-1] > 1.0 and k[-1] > 5.0 * k[999]   # the load makes |s_Δ| > 0: k̂ grows
    assert k[-1] > 3.0 * k_free[-1]
    assert np.all(np.diff(k) >= 0.0)           # k̂ never decreases: dk̂/dt = γ|s_Δ|


@pytest.mark.parametrize('mode', ['pid', 'adaptive_sliding', 'npid'])
def test_step_load_is_rejected(pmlm, mode):
    """A 60 N load step at rest (3× the breakaway force) is rejected by every mode."""
    from motor_comp.control.trajectories import PointToPoint
    traj = PointToPoint(distance=0.01, move_time=0.5, dwell=10.0)
    ctrl = make_controller(mode, plant=derive_nominal(pmlm))
    res = simulate(pmlm, ctrl, traj, duration=3.0, load=StepLoad(force=60.0, t_start=1.5))
    after = res.t > 2.5
    peak = np.max(np.abs(res.error[(res.t > 1.5) & (res.t < 2.0)]))
    assert peak > 2e-6                          # the step is felt …
    assert np.max(np.abs(res.error[after])) <= 2e-6   # … and rejected within 1 s
