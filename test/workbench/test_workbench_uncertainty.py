"""The standard errors' Student factor (:func:`motor_comp.workbench.uncertainty.t_scale`).

Its table replaces ``scipy.special.stdtrit`` in every fit (the import cost 0.03 s); the
numbers must be scipy's to the bit, and beyond the table scipy answers.
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
