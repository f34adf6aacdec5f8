"""Standard errors: the Student factor, and a parameter the run never moved.

The Student factor (:func:`~motor_comp.workbench.uncertainty.t_scale`) is a table that
replaces ``scipy.special.stdtrit`` in every fit (the import cost 0.03 s): its numbers
must be scipy's to the bit, and beyond the table scipy answers.  A parameter no stretch
of the run moved has an infinite standard error (not resolved), not none.
"""
from __future__ import annotations

from scipy.special import stdtrit

from motor_comp.workbench.uncertainty import SE_CLUSTERS, T975, t_scale

Z975 = 1.959963984540054


def test_the_table_is_scipys_quantile_to_the_bit():
    assert len(T975) >= 8 * SE_CLUSTERS        # eight runs' stretches, less one
    for dof, t in enumerate(T975, start=1):
        assert t == float(stdtrit(dof, 0.975)), dof
        assert t_scale(dof) == float(stdtrit(dof, 0.975)) / Z975


def test_beyond_the_table_and_below_one_degree():
    for dof in (len(T975) + 1, 200, 5000):
        assert t_scale(dof) == float(stdtrit(dof, 0.975)) / Z975
    assert t_scale(0) == t_scale(1)
    # seven degrees of freedom (one run's eight stretches): ± 1.96 SE is the 95 % interval
    assert abs(t_scale(7) - 1.2065) < 1e-4
    assert 1.0 < t_scale(1000) < 1.002


def test_a_parameter_no_stretch_moved_is_not_resolved_not_exact():
    """Zero spread with a Jacobian column of zeros: no error bar, said so (∞, not NaN)."""
    import math

    import numpy as np

    from motor_comp.workbench.uncertainty import delta_se
    from motor_comp.workbench.wording import unresolved
    vals = {('presliding', 'c'): 8.9e4, ('coulomb', 'fc'): 12.0}
    idx = {('coulomb', 'fc'): 0, ('presliding', 'c'): 1}
    cov = np.array([[0.04, 0.0], [0.0, 0.0]])       # the run never moved c
    rate = delta_se(lambda v: v[('presliding', 'c')], vals, idx, cov)
    assert rate == math.inf and unresolved(8.9e4, rate)
    # and the reports say so (the text's flag, autotune's table)
    from motor_comp.tuning.report import _fmt_se
    from motor_comp.workbench.wording import LINEAR_UNITS, fmt_param
    assert fmt_param('presliding', 'c', 8.9e4, rate, LINEAR_UNITS).endswith(
        '(not resolved by this run)')
    assert _fmt_se(rate) == 'not resolved by this run' and _fmt_se(float('nan')) == '—'
    assert abs(delta_se(lambda v: v[('coulomb', 'fc')], vals, idx, cov) - 0.2) < 1e-9
    # a figure no fitted parameter moves (an element count) has no standard error
    assert math.isnan(delta_se(lambda v: 3.0, vals, idx, cov))
    # nor one read from a covariance that could not be computed
    assert math.isnan(delta_se(lambda v: v[('presliding', 'c')], vals, idx,
                               np.full((2, 2), np.nan)))


def _direct_jackknife(run_id, block, J, e, clusters):
    """The delete-a-stretch jackknife written from its definition, one mask per stretch."""
    import numpy as np
    cl = np.zeros(len(e), dtype=int)
    G = 0
    for i in np.unique(run_id):
        m = run_id == i
        b = block[m]
        nb = int(b.max() - b.min()) + 1
        g = min(clusters, nb)
        cl[m] = G + ((b - b.min()) * g) // nb
        G += g
    A = J.T @ J
    deltas = np.array([np.linalg.pinv(A - J[cl == c].T @ J[cl == c]) @ (J[cl == c].T @ e[cl == c])
                       for c in range(G)])
    deltas -= deltas.mean(axis=0)
    return (G - 1) / G * deltas.T @ deltas * t_scale(G - 1) ** 2


def test_the_sandwiches_are_their_definitions():
    """Stretches and blocks taken as slices of the rows give the masks' covariances."""
    import types

    import numpy as np

    from motor_comp.workbench.uncertainty import block_sandwich, sandwich
    rng = np.random.default_rng(7)
    for trial in range(40):
        runs = rng.integers(1, 4)
        sizes = [rng.integers(1, 7, rng.integers(3, 40)) for _ in range(runs)]
        first = np.cumsum([0] + [len(s) for s in sizes])
        block = np.concatenate([np.repeat(np.arange(len(s)), s) + first[k]
                                for k, s in enumerate(sizes)])
        run_id = np.concatenate([np.full(int(s.sum()), k) for k, s in enumerate(sizes)])
        p = int(rng.integers(1, 5))
        J = rng.normal(size=(len(block), p))
        e = rng.normal(size=len(block))
        if len(e) <= p + 2:
            continue
        data = types.SimpleNamespace(run_id=run_id, block=block)
        want = _direct_jackknife(run_id, block, J, e, SE_CLUSTERS)
        np.testing.assert_allclose(sandwich(data, J, e), want, rtol=1e-8,
                                   atol=1e-12 * np.max(np.abs(want)))
        nb = int(block.max()) + 1
        S = np.array([(J[block == b] * e[block == b, None]).sum(axis=0) for b in range(nb)])
        c = nb / max(nb - 1, 1) * (len(e) - 1) / max(len(e) - p, 1)
        Gi = np.linalg.pinv(J.T @ J)
        np.testing.assert_allclose(block_sandwich(data, J, e), c * Gi @ (S.T @ S) @ Gi,
                                   rtol=1e-8, atol=1e-12)


def test_a_fit_at_huge_values_gives_no_correlation_and_no_warning():
    """Columns that overflow the sandwich (a fit at its declared bounds) read as NaN, quietly."""
    import types
    import warnings

    import numpy as np

    from motor_comp.workbench.uncertainty import block_sandwich, correlations
    rng = np.random.default_rng(3)
    block = np.repeat(np.arange(12), 5)
    data = types.SimpleNamespace(run_id=np.zeros(len(block), int), block=block)
    J = rng.normal(size=(len(block), 3))
    J[:, 2] *= 1e100
    e = rng.normal(size=len(block)) * 1e60
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        cov = block_sandwich(data, J, e)
        assert np.all(np.isnan(cov))
        assert correlations(cov, [('a', 'x'), ('b', 'y'), ('c', 'z')]) == []


def test_standard_errors_read_late_are_those_computed_at_once():
    """An estimate computes its SEs when first read: the same numbers, not before."""
    import numpy as np

    from motor_comp.workbench import kinematics
    from motor_comp.workbench.dataset import Dataset
    from motor_comp.workbench.library import spec_of
    from motor_comp.workbench.result import estimate
    from motor_comp.workbench.synthetic import scenario
    from motor_comp.workbench.uncertainty import block_sandwich, correlations, jacobian, \
        sandwich, scalars_of, standard_errors
    sc = scenario(('stribeck',), seed=2)
    kin = kinematics(sc.run(duration=6.0, seed=2))
    D = Dataset([kin], sc.plant)
    spec = spec_of(sc.plant)
    est = estimate(D, spec, sc.plant)
    assert not est.details._done                 # nothing read yet: nothing computed
    jac = jacobian(D, spec, sc.plant)
    scalars = scalars_of(spec, dict(jac.values), D)
    se = standard_errors(spec, dict(jac.values), jac.labels, sandwich(D, jac.J, jac.e), D)
    assert est.scalars == scalars
    assert est.se == se                              # computed now, to the bit
    assert est.details._done
    assert est.correlations == correlations(block_sandwich(D, jac.J, jac.e), jac.labels)
    assert se['coulomb']['fc'] > 0 and np.isfinite(se['coulomb']['fc'])
