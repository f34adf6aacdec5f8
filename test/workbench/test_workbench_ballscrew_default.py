"""The ball-screw's own default run, fitted from a bare model (issue 23, must-show).

The N-PID sine of the ball-screw plant (0–6 mm, speeds 1.4–9.4 mm/s) is the run whose
quadrant glitches the plant's 4-element GMS causes.  On a sine, friction knots along the
travel are also a function of the speed: a flexible ``position_friction`` once won the
second step here against the viscous slope and the Stribeck rise the run shows together,
and then absorbed the pre-sliding too.  From the bare nominal model (mass, input gain
and damping of the controller's nominal plant, no effects), on several noise seeds, the
fit must find the pre-sliding with its total stiffness, the Stribeck rise, and no
friction along the travel.
"""
from __future__ import annotations

import dataclasses

import pytest

from motor_comp.physics.axis import AxisModel
from motor_comp.physics.config import load_plant
from motor_comp.workbench import fit, kinematics
from motor_comp.workbench.session import default_hold

#: seeds of the position noise (the plant's own sensor is noise-free: seeds would not
#: differ without it)
SEEDS = (1, 2, 3)
#: position noise added before the encoder's 1 µm quantum [m]
NOISE_M = 2e-7


@pytest.fixture(scope='module')
def bare():
    cfg = load_plant('ballscrew')
    m = cfg.model
    return cfg, AxisModel.from_dict({'axis': 'linear', 'input': 'voltage',
                                     'input_gain': m.input_gain, 'back_emf': 0.0,
                                     'damping': m.damping, 'mass': 25.0, 'effects': {}})


def _default_run(cfg, start, seed: int):
    """Return the plant's default N-PID run (with position noise) as kinematics."""
    from motor_comp.control import simulator
    from motor_comp.control.controller import make_controller
    from motor_comp.control.nominal import derive_nominal
    from motor_comp.control.trajectories import default_trajectory
    cfg = dataclasses.replace(cfg, sensors=dataclasses.replace(cfg.sensors,
                                                               noise_std=NOISE_M))
    ctrl = make_controller('npid', plant=derive_nominal(cfg))
    res = simulator.simulate(cfg, ctrl, default_trajectory(cfg), duration=20.0, seed=seed)
    return kinematics(res.to_run(name=f'ballscrew default, seed {seed}'),
                      hold=default_hold(start)), cfg


@pytest.mark.parametrize('seed', SEEDS)
def test_presliding_found_on_the_default_run_from_a_bare_model(bare, seed):
    cfg, start = bare
    kin, cfg = _default_run(cfg, start, seed)
    result = fit(kin, start, auto=True)
    found = set(result.model.names)
    assert {'coulomb', 'stribeck', 'presliding'} <= found, found
    assert 'position_friction' not in found, found
    true_k = sum(cfg.model.get('presliding').k)
    k = sum(result.model.get('presliding').k)
    assert abs(k / true_k - 1.0) < 0.2, (k, true_k)
    fs = result.model.get('stribeck').fs
    assert abs(fs - cfg.model.get('stribeck').fs) < 2.5, fs


#: most simplex costs the fit of seed 1 may take: 71 measured with the searches stopped
#: at the data's resolution, 525 before (``varpro.RESOLUTION`` = 0 gives them again)
COSTS = 150


def test_the_searches_stop_at_the_data_resolution(bare, monkeypatch):
    """The fit's simplex searches end where their costs agree to the data's resolution.

    Before, the simplex went on contracting where no cost differed from another (four
    of the eight searches on the bench's run of this plant).  Counted, not timed.
    """
    from motor_comp.workbench import optim, varpro
    cfg, start = bare
    kin, _ = _default_run(cfg, start, 1)
    costs = []

    def counted(f, simplex, **options):
        out = optim.nelder_mead(f, simplex, **options)
        costs.append(out.nfev)
        return out
    monkeypatch.setattr(varpro, 'nelder_mead', counted)
    result = fit(kin, start, auto=True)
    assert 'presliding' in result.model.names
    assert costs and sum(costs) <= COSTS, costs


@pytest.mark.xfail(strict=True, reason=(
    'known, 2026-11-29: the search starts from element families (0.3, 1, 3)·d0 with d0 '
    'at the declared lower bound (3 encoder quanta), and an element at 0.3× stays there '
    'when no search moves it (the free search keeps its start unless it gains); the '
    "plant's own stiffest elements (0.68, 1.2, 1.8 um) lie below the bound too. With the "
    'starts inside the domain this run gives Coulomb + viscous + Stribeck + a 1.6 ms '
    'delay instead of pre-sliding; the independent pre-sliding list does not change'))
def test_the_fitted_presliding_distances_lie_in_the_declared_domain(bare):
    """Every fitted element distance lies in the domain the pre-sliding term declares.

    The selection holds a term to its declared domain (``../shared/IDENTIFICATION.md``,
    issue 22 item 2: distances from the sensor's resolution up); a value outside it is
    no value of the term.

    Tried 2026-11-29 the other way round: the bound lowered to one count (the grid
    still from three, every start and every trial of the family's common scale inside
    the domain — that scale step had moved the shortest element to 0.75 µm).  The
    bench's run of this plant then gives pre-sliding at its floor (one element at the
    bound, Σk 1.16e7 ± 3.5e5 N/m, 20 ms prediction 1.82 µm against 1.85), and this test
    passes; but on the independent generator, whose elements lie 2.7 µm or more out
    (counts of 0.5–2 µm), an element at one count stands in for the viscous slope and
    the mass (+384 % and +72 % on two ordinary pre-sliding sines), Σk rises 19–47 % on
    the complete list's four coulomb + viscous + pre-sliding fits and the suite falls
    to 307/312.  Three counts is what independent data support.
    """
    from motor_comp.physics.effects import TERMS
    from motor_comp.workbench.dataset import Dataset
    from motor_comp.workbench.library import Spec, context
    cfg, start = bare
    kin, _ = _default_run(cfg, start, 1)
    result = fit(kin, start, auto=True)
    gms = result.model.get('presliding')
    assert gms is not None
    data = Dataset([kin], start)
    d = next(p for p in TERMS['presliding'].space(data.summary, context(Spec((), {}), data))
             if p.name == 'd')
    fc = result.model.fc
    dists = [a * fc / k for a, k in zip(gms.alpha, gms.k)]
    assert min(dists) >= d.lo, (dists, d.lo)
