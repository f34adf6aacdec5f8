"""How well ``excite`` predicts the standard errors ``fit`` will report, over noise seeds.

For three axes (PMLM: mass, Coulomb, viscous, ripple; ball-screw: Coulomb, viscous,
Stribeck, dead time; rotary arm: Coulomb, viscous, gravity), each seed designs an
excitation from a start model 2–10 % off the truth (design seed ``10·s``), records the
TRUE plant along it three times (own noise seeds) and fits each recording from the
start model.  Per parameter the table gives the share of seeds whose predicted SE is
within 2× of the median recorded SE, within 2× of every single recording, and within
the recordings' range widened 2× (``min/2 ≤ predicted ≤ 2·max``), and the range of
predicted / median.  Also the spread of the recorded SEs themselves
(max / min over the three draws, worst seed): the fit's own scatter, which bounds how
closely any prediction can match one recording.

Usage: ``python bench/excite_prediction.py [--seeds N] [--duration S]``; prints Markdown.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from motor_comp.control.excitation import ExcitationLimits  # noqa: E402
from motor_comp.design.excite import design, loop_for, record  # noqa: E402
from motor_comp.physics.axis import AxisModel  # noqa: E402
from motor_comp.workbench.derivatives import kinematics  # noqa: E402
from motor_comp.workbench.fit import fit  # noqa: E402
from motor_comp.workbench.session import default_hold  # noqa: E402

PMLM = {'input_gain': 15.116279069767442, 'back_emf': 123.0}
SCREW = {'input_gain': 50.0, 'damping': 50.0}
ARM = {'axis': 'rotary', 'input': 'current', 'input_gain': 0.8}
#: (true model, start model, limits, loop options) — the cases of test_design_excite
CASES = {
    'pmlm': ({**PMLM, 'mass': 5.4, 'effects': {
        'coulomb': {'fc': 10.0}, 'viscous': {'fv': 10.0},
        'ripple': {'period': 0.02, 'harmonics': [[8.5, 0.0]]}}},
        {**PMLM, 'mass': 5.9, 'effects': {
            'coulomb': {'fc': 9.0}, 'viscous': {'fv': 11.0},
            'ripple': {'period': 0.0201, 'harmonics': [[7.7, 1.0]]}}},
        ExcitationLimits(travel=(-0.05, 0.05), vmax=0.2, amax=3.0, bandwidth=5.0),
        {'plant': 'pmlm', 'noise_std': 2e-7}),
    'ballscrew': ({**SCREW, 'mass': 25.0, 'effects': {
        'coulomb': {'fc': 12.0}, 'viscous': {'fv': 200.0},
        'stribeck': {'fs': 18.0, 'vs': 0.001, 'delta': 1.0}, 'delay': {'tau': 0.00129}}},
        {**SCREW, 'mass': 26.0, 'effects': {
            'coulomb': {'fc': 11.5}, 'viscous': {'fv': 190.0},
            'stribeck': {'fs': 17.3, 'vs': 0.00105, 'delta': 1.0},
            'delay': {'tau': 0.00125}}},
        ExcitationLimits(travel=(-0.02, 0.02), vmax=0.05, amax=0.5, bandwidth=3.0),
        {'plant': 'ballscrew', 'noise_std': 2e-7}),
    'rotary': ({**ARM, 'mass': 0.01, 'effects': {
        'coulomb': {'fc': 0.05}, 'viscous': {'fv': 0.01},
        'gravity': {'mgl': 1.5, 'q0': 0.3}}},
        {**ARM, 'mass': 0.011, 'effects': {
            'coulomb': {'fc': 0.045}, 'viscous': {'fv': 0.011},
            'gravity': {'mgl': 1.4, 'q0': 0.25}}},
        ExcitationLimits(travel=(-3.0, 3.0), vmax=5.0, amax=50.0, bandwidth=3.0),
        {'encoder': 1e-5, 'noise_std': 2e-6}),
}


def main() -> int:
    """Print the table; 0 always (a measurement, not a gate)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0], allow_abbrev=False)
    p.add_argument('--seeds', type=int, default=6, help='design seeds per axis (default 6)')
    p.add_argument('--duration', type=float, default=60.0, help='excitation length [s]')
    args = p.parse_args()
    print(f'command: python bench/excite_prediction.py --seeds {args.seeds} '
          f'--duration {args.duration:g}\n')
    print('| axis | parameter | within 2× of the median of 3 recordings | within 2× of '
          'each recording | within the recordings\' range ×/÷ 2 | predicted / median | '
          'recorded max/min (worst seed) |')
    print('|---|---|---|---|---|---|---|')
    t0 = time.monotonic()
    for name, (true_d, start_d, limits, loop_kw) in CASES.items():
        true, start = AxisModel.from_dict(true_d), AxisModel.from_dict(start_d)
        loop = loop_for(start, **loop_kw)
        med: dict[str, list[float]] = {}
        each: dict[str, list[bool]] = {}
        span: dict[str, list[bool]] = {}
        spread: dict[str, float] = {}
        for s in range(args.seeds):
            d = design(start, limits, duration=args.duration, loop=loop, seed=10 * s)
            recs = []
            for j in range(3):
                run = record(loop.with_model(true), d.table, seed=1000 + 3 * s + j)
                recs.append(fit(kinematics(run, hold=default_hold(start)), start).uncertainty)
            for g, dd in d.predicted_se.items():
                for k, se in dd.items():
                    key = f'{g}.{k}'
                    draws = np.array([r[g][k] for r in recs])
                    med.setdefault(key, []).append(se / float(np.median(draws)))
                    each.setdefault(key, []).append(bool(np.all((se / draws <= 2)
                                                                & (se / draws >= 0.5))))
                    span.setdefault(key, []).append(bool(draws.min() / 2 <= se
                                                         <= 2 * draws.max()))
                    spread[key] = max(spread.get(key, 0.0), float(draws.max() / draws.min()))
        for key, ratios in med.items():
            r = np.array(ratios)
            ok = np.mean((r >= 0.5) & (r <= 2.0))
            print(f'| {name} | {key} | {100 * ok:.0f} % | {100 * np.mean(each[key]):.0f} % | '
                  f'{100 * np.mean(span[key]):.0f} % | {r.min():.2f}–{r.max():.2f} | '
                  f'×{spread[key]:.1f} |', flush=True)
    print(f'\n- total wall time {time.monotonic() - t0:.0f} s')
    return 0


if __name__ == '__main__':
    sys.exit(main())
