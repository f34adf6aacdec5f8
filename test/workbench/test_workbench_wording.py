"""Parameters in words: an error bar that exceeds its value is said to be no error bar."""
from __future__ import annotations

import math

from motor_comp.physics.axis import AxisKind, Units
from motor_comp.workbench.wording import fmt_param

LIN = Units.of(AxisKind.LINEAR)


def test_a_resolved_parameter_shows_its_standard_error() -> None:
    assert fmt_param('coulomb', 'fc', 13.48, 0.013, LIN) == 'fc 13.48 ± 0.013 N'


def test_an_error_bar_beyond_the_value_is_said_unresolved() -> None:
    # the ball-screw's default run: the GMS attraction rate, jackknife SE 2e+15 1/s
    txt = fmt_param('presliding', 'c', 4.047e4, 2e15, LIN)
    assert txt == 'c 4.047e+04 1/s (not resolved by this run)'
    assert '±' not in txt
    txt = fmt_param('presliding', 'c', 4.047e4, math.inf, LIN)
    assert txt.endswith(' (not resolved by this run)')


def test_no_standard_error_says_nothing_about_resolution() -> None:
    assert fmt_param('coulomb', 'fc', 13.48, None, LIN) == 'fc 13.48 N'
    assert fmt_param('coulomb', 'fc', 13.48, math.nan, LIN) == 'fc 13.48 N'
