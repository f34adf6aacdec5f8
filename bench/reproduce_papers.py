"""Reproduce the two papers' claims in simulation, with controllers that do not know the plant.

Every controller is built from a *nominal* model (:mod:`motor_comp.control.nominal`),
never from the simulated plant: PMLM mass +20 %, friction and ripple at 50 % of the
truth (Tan's simulation, ``half``) or zero (Tan's experiment, ``zero``); ball-screw with
its friction identified 20 % low and the GMS stiffness 30 % low (``identified``).  The
only exception is the labelled *oracle* row.

1. Tan, Huang & Lee 2002 (PMLM, ``config/pmlm.yaml``, p2p moves), both starts:

   * PID — the adaptive law's PID part (Tan Remark 3.1);
   * PID + nominal friction FF — Chiew's static friction model from the nominal;
   * PID + nominal model FF — the adaptive law *frozen* at the nominal model (all
     γ = 0, σ = 0): ``K·s + θ_nomᵀY``, the same feedforward structure without adaptation;
   * adaptive sliding — starts at the nominal, leakage and projection around it;
   * oracle — the same frozen law with the exact model (a reference, not a baseline).

   Tan's claim: adaptive/PID max error ≈ 0.5 (must be <= 0.5).  Then the estimates'
   convergence (Tan Fig. 4) from both starts, and ``--png`` draws it.
2. Chiew, Jamaludin et al. (ball-screw, ``config/ballscrew.yaml``): the PID designed
   on the loop as it runs (sampled, ZOH, τ = 1.29 ms) at several rates, its margins
   checked by python-control, and the Popov/Tsypkin and circle bounds of k(e);
3. the N-PID study: PID vs N-PID (this plant's k0, e_max and Chiew's), with the
   logged k(e) along the run;
4. Chiew's feedforward ordering none / static / GMS / static+GMS (Tables V–VI).

Metrics are :func:`motor_comp.analysis.metrics.compute_metrics` (DESIGN.md §6).

Usage: ``python bench/reproduce_papers.py [--pmlm-seconds 30] [--ballscrew-seconds 20]
[--png]``
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

OUT = Path(__file__).resolve().parent / 'out'

#: Chiew Tables V–VI: tracking error and quadrant glitch [mm], as recovered from the text
CHIEW_ERROR = {'none': 0.191, 'static': 0.12, 'gms': 0.188, 'static+gms': 0.1}
CHIEW_GLITCH = {'none': 0.5, 'static': 0.4, 'gms': 0.35, 'static+gms': 0.25}
#: adaptation off: the adaptive law reduces to ``K·s + θ̂ᵀY`` with θ̂ fixed
FROZEN = tuple((g, 0.0) for g in ('gamma_mass', 'gamma_back_emf', 'gamma_fc', 'gamma_fv',
                                  'gamma_ripple', 'gamma_k', 'sigma'))
NAMES = ('mass', 'back_emf', 'fc', 'fv', 'ripple_a', 'ripple_b')
TAU = 1.29e-3


def _pct(a: float, b: float) -> str:
    return f'{100.0 * (a / b - 1.0):+.0f} %'


def _run(plant: str, controller: str, seconds: float, *, feedforward: str = 'none',
         settings: tuple = ()) -> tuple:
    from motor_comp.control.scenario import Scenario
    return Scenario(plant=plant, controller=controller, feedforward=feedforward,
                    duration=seconds, settings=tuple(settings)).run()


# ---- 1. Tan ---------------------------------------------------------------------------
def pmlm_rows(seconds: float) -> tuple[list[str], dict, dict]:
    """Tan's table for both starts; returns rows, the adaptive runs and the claims."""
    from motor_comp.analysis.metrics import compute_metrics
    rows = ['| start | controller | max error [µm] | max, last 4 s [µm] | RMS [µm] | '
            'max / PID | max / (PID + nominal model FF) |', '|---|---|---|---|---|---|---|']
    runs, claims, windows = {}, {}, {}
    oracle = _run('pmlm', 'adaptive_sliding', seconds,
                  settings=(('nominal.start', 'exact'),) + FROZEN)[0]
    for start in ('half', 'zero'):
        nom = (('nominal.start', start),)
        cases = {'PID': ('pid', 'none', nom),
                 'PID + nominal friction FF': ('pid', 'static', nom),
                 'PID + nominal model FF': ('adaptive_sliding', 'none', nom + FROZEN),
                 'adaptive sliding': ('adaptive_sliding', 'none', nom)}
        res = {k: _run('pmlm', c, seconds, feedforward=f, settings=s)[0]
               for k, (c, f, s) in cases.items()}
        res['oracle: PID + exact model FF'] = oracle
        met = {k: compute_metrics(r.to_run(name=k)) for k, r in res.items()}
        pid, ff = met['PID'].max_error, met['PID + nominal model FF'].max_error
        for k, m in met.items():
            r = res[k]
            late = float(np.max(np.abs(r.error[r.t > seconds - 4.0])))
            rows.append(f'| {start} | {k} | {m.max_error * 1e6:.2f} | {late * 1e6:.2f} | '
                        f'{m.rms_error * 1e6:.2f} | {m.max_error / pid:.2f} | '
                        f'{m.max_error / ff:.2f} |')
        ad = met['adaptive sliding']
        claims[start] = (ad.max_error / pid, ad.max_error / ff, ad.rms_error
                         / met['PID + nominal model FF'].rms_error)
        runs[start] = res['adaptive sliding']
        windows[start] = {k: res[k] for k in ('PID + nominal model FF', 'adaptive sliding')}
    rows.append('')
    for start, (r_pid, r_ff, r_rms) in claims.items():
        rows.append(f'claim (Tan: adaptive/PID max ≈ 0.5, must be <= 0.5), start {start}: '
                    f'{r_pid:.2f} → {"holds" if r_pid <= 0.5 else "FAILS"}; adaptive / '
                    f'(PID + nominal model FF): max {r_ff:.2f}, RMS {r_rms:.2f}')
    rows += ['', 'max error [µm] per 5 s window (where each error is made):', '',
             '| start | controller | ' + ' | '.join(
                 f'{a:g}–{a + 5:g} s' for a in np.arange(0.0, seconds - 1e-9, 5.0)) + ' |',
             '|---|---|' + '---|' * len(np.arange(0.0, seconds - 1e-9, 5.0))]
    for start, by_ctrl in windows.items():
        for k, r in by_ctrl.items():
            e = np.abs(r.error)
            rows.append(f'| {start} | {k} | ' + ' | '.join(
                f'{e[(r.t >= a) & (r.t < a + 5.0)].max() * 1e6:.1f}'
                for a in np.arange(0.0, seconds - 1e-9, 5.0)) + ' |')
    reading = (
        "reading: Tan's claim holds from both starts.  A friction-only feedforward barely "
        "moves the PMLM's PID error (≈ ±2 %): that error is the back-EMF (k_e = 123 V·s/m) "
        "and inertia load, which only the model feedforward (ẍ_r, ẋ regressors) carries — "
        "hence the frozen-law baseline.  Against the same law frozen at the nominal model, "
        "adaptation costs peak error while the estimates move (half: one stiction breakaway "
        "at a move start, t ≈ 7 s; zero: the first moves, before fc is learnt) and wins once "
        "they have (half: ≈ 4 µm vs 7.6 µm from 10 s on).  From zero the fc estimate needs "
        "≈ 25 s, the leakage pulling it towards the zero nominal.  Mass and fv do not "
        "converge (mass drifts ≈ 30 % low, fv stays near its start): ẍ_r is excited only in "
        "the short accelerations and ẋ_d is nearly collinear with the back-EMF regressor, so "
        "these two absorb the Stribeck remainder instead (see the estimates table).")
    rows += ['', reading]
    return rows, runs, claims


def convergence_rows(runs: dict, truth: dict, seconds: float) -> list[str]:
    """Tan Fig. 4 as a table: each estimate at a few instants, and the gap closed."""
    times = [t for t in (0.0, 2.0, 5.0, 10.0, 20.0, 30.0, 60.0) if t <= seconds]
    rows = ['| start | estimate | truth | ' + ' | '.join(f't = {t:g} s' for t in times)
            + ' | gap closed |', '|---|---|---|' + '---|' * len(times) + '---|']
    for start, res in runs.items():
        for n in NAMES:
            est = res.estimate(n)
            vals = [est[min(int(round(t * 1000)), est.size - 1)] for t in times]
            gap0 = abs(vals[0] - truth[n])
            closed = (f'{100 * (1 - abs(est[-1] - truth[n]) / gap0):.0f} %' if gap0 > 1e-9
                      else '—')
            rows.append(f'| {start} | {n} | {truth[n]:.4g} | '
                        + ' | '.join(f'{v:.4g}' for v in vals) + f' | {closed} |')
    return rows


def plot_convergence(runs: dict, truth: dict, path: Path) -> None:
    """Tan Fig. 4 analogue: the estimates from both starts against the truth."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(2, 3, figsize=(13, 7))
    for ax, n in zip(axes.flat, NAMES):
        for i, (start, res) in enumerate(runs.items()):
            ax.plot(res.t, res.estimate(n), color=f'C{i}', lw=1, label=f'start {start}')
        ax.axhline(truth[n], color='k', ls='--', lw=0.8, label='truth')
        ax.set_title(n)
        ax.set_xlabel('t [s]')
    axes.flat[0].legend(fontsize=8)
    fig.suptitle('Adaptive sliding (Tan 2002): estimates from the nominal model '
                 '(half: 50 % of truth, zero: nothing known)', fontsize=11)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


# ---- 2. the ball-screw loop ---------------------------------------------------------
def loop_rows() -> list[str]:
    """The sampled-loop design at several rates, python-control margins, k(e) bounds."""
    import control as ct

    from motor_comp.control.controller import make_controller
    from motor_comp.control.npid import NPIDParams, design_pid, discrete_pid_response, \
        loop_margins, popov_limit, sampled_loop, sampled_plant
    from motor_comp.control.nominal import derive_nominal
    from motor_comp.physics import load_plant
    nominal = derive_nominal(load_plant('ballscrew'))
    model = nominal.model
    rows = ['| design | rate [kHz] | Kp [V/m] | Ki [V/(m·s)] | Kd [V·s/m] | T_f [ms] | '
            'GM [dB] | PM [°] | crossover [Hz] | bandwidth [Hz] | Popov/Tsypkin k_max | '
            'circle k_max |', '|---|---|---|---|---|---|---|---|---|---|---|---|']

    def row(label: str, rate: float, p: NPIDParams, m, kpop: float, kcirc: float) -> str:
        return (f'| {label} | {rate:g} | {p.kp:.1f} | {p.ki:.4g} | {p.kd:.2f} | '
                f'{p.tf * 1e3:.3f} | {m.gain_margin_db:.2f} | {m.phase_margin_deg:.1f} | '
                f'{m.crossover_hz:.1f} | {m.bandwidth_hz:.1f} | {kpop:.2f} | {kcirc:.2f} |')

    cont = design_pid(model, delay=TAU)
    rows.append(row('Chiew, continuous (paper targets)', math.inf, cont.params, cont.margins,
                    cont.popov_limit, float('nan')))
    w, L = sampled_loop(model, cont.params, delay=TAU, control_period=1e-3)
    rows.append(row('same gains, run at 1 kHz', 1.0, cont.params, loop_margins(L, w),
                    popov_limit(L, w, control_period=1e-3), float('nan')))
    for rate in (1.0, 2.0, 5.0, 10.0, 100.0):
        T = 1e-3 / rate
        d = design_pid(model, delay=TAU, control_period=T)
        w, L = sampled_loop(model, d.params, delay=TAU, control_period=T)
        rows.append(row('sampled design', rate, d.params, d.margins, d.popov_limit,
                        _circle(L, w)))
    # the defaults, as python-control sees the sampled loop (dt system, exact ZOH + delay)
    p = NPIDParams()
    T = 1e-3
    sp = sampled_plant(model, delay=TAU, control_period=T).to_control()
    a = T / (T + p.tf)
    z = ct.tf([1.0, 0.0], [1.0], T)
    pid = p.kp + p.ki * T * z / (z - 1) + p.kd * a / T * (z - 1) / (z - (1 - a))
    gm, pm, _, wpc, wgc, _ = ct.stability_margins(pid * sp)
    w = np.array([2 * math.pi * 10.0])
    ours = discrete_pid_response(p.kp, p.ki, p.kd, p.tf, w, control_period=T)
    theirs = complex(np.squeeze(pid(np.exp(1j * w[0] * T))))
    ctrl = make_controller('npid', plant=nominal)
    rows += ['', f'defaults (PIDParams) at 1 kHz, python-control `stability_margins` of the '
             f'dt loop: GM {20 * math.log10(gm):.2f} dB at {wpc / (2 * math.pi):.1f} Hz, PM '
             f'{pm:.1f}° at {wgc / (2 * math.pi):.1f} Hz (Chiew Table IV: 9.9 dB, 54.2°, '
             f'bandwidth 38.5 Hz); discrete PID agrees with python-control to '
             f'{abs(ours[0] - theirs) / abs(theirs):.1e}; N-PID k_max used = '
             f'{ctrl.packed[9]:.2f}.',
             'bandwidth: GM and PM are met at every rate; 38.5 Hz is not reached at any '
             'rate with GM 9.9 dB and PM 54° held and a derivative filter >= T/2 — the '
             '1.29 ms dead time plus the hold leave a PID too little phase lead; the '
             'bandwidth saturates near 34 Hz as T → 0 (100 kHz row).  Chiew\'s continuous '
             'design reaches 38.9 Hz only at GM 9.3 dB with T_f = 10 µs (no filtering) on '
             'the bare delay; the same gains at 1 kHz have the margins of the second row '
             '(the loop this project ran before).']
    return rows


def _circle(L: np.ndarray, w: np.ndarray) -> float:
    """Circle-criterion bound ``1/max(−Re L)`` above the gain crossover (q = 0)."""
    mag = np.abs(L)
    gc = np.nonzero((mag[:-1] >= 1.0) & (mag[1:] < 1.0))[0]
    worst = float(np.max(-L.real[int(gc[-1]) if gc.size else 0:]))
    return 1.0 / worst if worst > 0 else math.inf


# ---- 3. N-PID where k(e) works ------------------------------------------------------
def npid_rows(seconds: float) -> list[str]:
    """PID vs N-PID on the ball-screw study, with the logged k(e)."""
    from motor_comp.control.npid import npid_gain
    rows = ['| feedforward | controller | k0 [1/mm] | e_max [µm] | peak error [µm] | '
            'RMS [µm] | peak / PID | k(e): median | 95th pct | max | time at >= 90 % of '
            'k(e_max) |', '|---|---|---|---|---|---|---|---|---|---|---|']
    for ff in ('none', 'static+gms'):
        pid, _ = _run('ballscrew', 'pid', seconds, feedforward=ff)
        steady = pid.t > 1.0
        p_peak = float(np.max(np.abs(pid.error[steady])))
        rows.append(f'| {ff} | pid | | | {p_peak * 1e6:.1f} | '
                    f'{np.sqrt(np.mean(pid.error[steady] ** 2)) * 1e6:.2f} | 1.00 | 1 | 1 | '
                    f'1 | |')
        for label, extra in (('npid (defaults)', ()),
                             ('npid (Chiew k0, e_max)', (('k0', 15000.0), ('e_max', 1e-4)))):
            r, ctrl = _run('ballscrew', 'npid', seconds, feedforward=ff, settings=extra)
            q = ctrl.packed
            e = r.error[steady]
            k = np.array([npid_gain(x, q[7], q[8], q[9]) for x in e])
            k_top = npid_gain(q[8], q[7], q[8], q[9])
            peak = float(np.max(np.abs(e)))
            rows.append(f'| {ff} | {label} | {q[7] / 1e3:g} | {q[8] * 1e6:g} | '
                        f'{peak * 1e6:.1f} | {np.sqrt(np.mean(e ** 2)) * 1e6:.2f} | '
                        f'{peak / p_peak:.2f} | {np.median(k):.2f} | '
                        f'{np.percentile(k, 95):.2f} | {k.max():.2f} | '
                        f'{100 * np.mean(k >= 0.9 * k_top):.0f} % |')
    return rows


# ---- 4. Chiew's ordering ------------------------------------------------------------
#: nominal friction the feedforward is built from: the default (identified 20 % low), a
#: good identification (5 % low) and the exact levels (isolates the feedforward structure)
ORDERING_NOMINALS = (('identified (default): levels −20 %, GMS stiffness −30 %', ()),
                     ('identified: levels −5 %, GMS stiffness −30 %',
                      (('nominal.friction_factor', 0.95),)),
                     ('exact friction (structure only, oracle)', (('nominal.start', 'exact'),)))


def ordering_rows(seconds: float) -> list[str]:
    """N-PID with each feedforward (Chiew Tables V–VI) and the ordering claims."""
    from motor_comp.analysis.metrics import compute_metrics
    rows = ['| nominal friction | feedforward | RMS error [µm] | Δ vs none | paper Δ | '
            'max glitch [µm] | mean glitch [µm] | Δ vs none (mean) | paper Δ |',
            '|---|---|---|---|---|---|---|---|---|']
    claims = []
    for label, settings in ORDERING_NOMINALS:
        met = {}
        for ff in ('none', 'static', 'gms', 'static+gms'):
            r, _ = _run('ballscrew', 'npid', seconds, feedforward=ff, settings=settings)
            met[ff] = compute_metrics(r.to_run(name=ff).slice(1.0, seconds + 1))
        n = met['none']
        for ff, m in met.items():
            rows.append(
                f'| {label} | {ff} | {m.rms_error * 1e6:.2f} | '
                f'{_pct(m.rms_error, n.rms_error)} | '
                f'{_pct(CHIEW_ERROR[ff], CHIEW_ERROR["none"])} | {m.max_glitch * 1e6:.2f} | '
                f'{m.mean_glitch * 1e6:.2f} | {_pct(m.mean_glitch, n.mean_glitch)} | '
                f'{_pct(CHIEW_GLITCH[ff], CHIEW_GLITCH["none"])} |')
        st, gms, both = met['static'], met['gms'], met['static+gms']
        claims.append(
            f'- {label}: static better than GMS on error: {st.rms_error < gms.rms_error} '
            f'({st.rms_error * 1e6:.2f} vs {gms.rms_error * 1e6:.2f} µm); GMS better than '
            f'static on glitches: {gms.mean_glitch < st.mean_glitch} '
            f'({gms.mean_glitch * 1e6:.2f} vs {st.mean_glitch * 1e6:.2f} µm); static+GMS '
            f'best on error: {both.rms_error <= min(st.rms_error, gms.rms_error)}, on '
            f'glitches: {both.mean_glitch <= min(st.mean_glitch, gms.mean_glitch)}')
    rows += ['', 'Chiew ordering (static best on error, GMS best on glitches, static+GMS best '
             'on both):', ''] + claims
    rows += ['', 'reading: the ordering is a property of the feedforward *structure*, and it '
             'holds in full when the nominal friction levels are right (last block).  With '
             'the levels 20 % low (the default nominal) the missing ≈ 2.4 N of Coulomb '
             'friction dominates: after every reversal the integrator must rebuild it, '
             'whichever model shapes the transition, so static, GMS and static+GMS all cut '
             'the error and the glitches by ≈ 75 % and differ by 1–3 % (static+GMS still '
             'best on both; static vs GMS no longer ordered).  At 5 % level error the '
             'ordering is back, with small gaps.']
    return rows


def main() -> int:
    """Print the tables (and with ``--png`` the convergence figure)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    ap.add_argument('--pmlm-seconds', type=float, default=30.0)
    ap.add_argument('--ballscrew-seconds', type=float, default=20.0)
    ap.add_argument('--png', action='store_true', help='write bench/out/adaptive_estimates.png')
    args = ap.parse_args()
    from motor_comp.control.scenario import Scenario
    truth_ctrl = Scenario(plant='pmlm', controller='adaptive_sliding',
                          settings=(('nominal.start', 'exact'),)).build()[2]
    truth = truth_ctrl.nominal
    print('### Tan 2002 — PMLM, p2p, nominal ≠ plant\n')
    rows, runs, _ = pmlm_rows(args.pmlm_seconds)
    print('\n'.join(rows))
    print('\n### Estimates from both starts (Tan Fig. 4)\n')
    print('\n'.join(convergence_rows(runs, truth, args.pmlm_seconds)))
    if args.png:
        png = OUT / 'adaptive_estimates.png'
        plot_convergence(runs, truth, png)
        print(f'\nfigure: {png}')
    print('\n### Chiew — ball-screw PID designed for the sampled loop\n')
    print('\n'.join(loop_rows()))
    print('\n### N-PID where k(e) works (k(e) from the logged error)\n')
    print('\n'.join(npid_rows(args.ballscrew_seconds)))
    print('\n### Chiew Tables V–VI — N-PID with each feedforward\n')
    print('\n'.join(ordering_rows(args.ballscrew_seconds)))
    return 0


if __name__ == '__main__':
    sys.exit(main())
