"""The residual's variance by speed band, the weights it gives, and the order it chooses.

:class:`~motor_comp.workbench.bands.SpeedBands` must recover a planted band variance
(equal-count bands, the median band's weight 1), refuse what it cannot estimate, and
give each row its band's weight exactly as a weighted view does.  The order of a term
(ripple harmonics) is then chosen on the weighted sum of squares when the residual is
heteroscedastic: rows at the turns with a position-locked error must not buy harmonics
the sliding rows do not show, and harmonics the sliding rows do show are kept.
"""
from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from motor_comp.workbench.bands import WEIGHT_BANDS, SpeedBands


@settings(max_examples=40, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), ratio=st.floats(2.0, 400.0),
       slow=st.floats(0.05, 0.3))
def test_a_planted_band_variance_is_recovered(seed, ratio, slow):
    rng = np.random.default_rng(seed)
    n = 20_000
    speed = rng.uniform(0.0, 1.0, n)
    slow_rows = speed < slow
    sigma = np.where(slow_rows, math.sqrt(ratio), 1.0)
    b = SpeedBands.of(speed, rng.normal(size=n) * sigma)
    assert b is not None and len(b.var) == WEIGHT_BANDS
    # equal-count bands: the band edges are the speed's quantiles
    assert np.allclose(b.edges[1:], np.quantile(speed, np.arange(1, WEIGHT_BANDS) / WEIGHT_BANDS))
    fast = b.edges >= slow + 1.0 / WEIGHT_BANDS
    low = np.append(b.edges[1:], 1.0) <= slow
    # 1000 rows a band: each variance within ~5 sigma of its sampling error (4.5 %)
    assert np.allclose(b.var[fast], 1.0, rtol=0.25)
    assert np.allclose(b.var[low], ratio, rtol=0.25)
    assert b.contrast == pytest.approx(ratio, rel=0.3)
    w = b.weights.w
    assert np.allclose(np.asarray(w)[fast], 1.0, rtol=0.25)
    assert np.allclose(np.asarray(w)[low], 1.0 / ratio, rtol=0.3)
    # each row's weight is its band's
    rw = b.row_weights(speed)
    band = np.searchsorted(b.edges, speed, side='right') - 1
    assert np.array_equal(rw, np.asarray(w)[band])


def test_homoscedastic_rows_have_no_contrast_to_speak_of():
    rng = np.random.default_rng(3)
    b = SpeedBands.of(rng.uniform(-2.0, 2.0, 40_000), rng.normal(size=40_000))
    # 20 bands of 2000 rows: the largest over the median is sampling error alone
    assert 1.0 < b.contrast < 1.2


def test_what_cannot_be_estimated_is_refused():
    rng = np.random.default_rng(0)
    # fewer than four rows a band
    assert SpeedBands.of(rng.uniform(size=4 * WEIGHT_BANDS - 1),
                         rng.normal(size=4 * WEIGHT_BANDS - 1)) is None
    # a band with no residual at all has no variance to weight by
    speed = rng.uniform(size=4000)
    e = rng.normal(size=4000)
    e[speed < 0.2] = 0.0
    assert SpeedBands.of(speed, e) is None


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_turn_rows_do_not_buy_ripple_harmonics(seed):
    """The bench run (one planted harmonic) keeps one harmonic from a bare model.

    Its residual at the turns is 100× or more the median band's variance, and recurs at
    the same positions: on the plain sum of squares the harmonic count went to 5–6 (five
    amplitudes of a few mN, within their errors of zero once weighted).
    """
    from motor_comp.physics.axis import AxisModel
    from motor_comp.physics.effects.identification import Signal
    from motor_comp.workbench import fit, kinematics
    from motor_comp.workbench.dataset import Dataset
    from motor_comp.workbench.library import design, spec_of
    from motor_comp.workbench.lsq import solve_gram
    from motor_comp.workbench.synthetic import scenario
    sc = scenario('ripple', seed=seed)
    kin = kinematics(sc.run(duration=15.0, seed=seed))
    p = sc.plant
    bare = AxisModel(mass=2 * p.mass, input_gain=p.input_gain, back_emf=p.back_emf,
                     input=p.input)
    r = fit(kin, bare, auto=True)
    assert set(r.model.names) == {'coulomb', 'viscous', 'ripple'}
    assert len(r.model.get('ripple').harmonics) == len(p.get('ripple').harmonics) == 1
    # the case is one the weights decide: the fitted model's residual by speed band
    D = Dataset([kin], r.model)
    d = design(D, spec_of(r.model), r.model)
    th, _ = solve_gram(d.gram(), d.bounds)
    b = SpeedBands.of(D.at().signal(Signal.VELOCITY), d.y - d.X @ th)
    assert b is not None and b.contrast > 10.0
