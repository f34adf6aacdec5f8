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
