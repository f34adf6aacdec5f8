"""Parameters in words: error bars beyond their value, and when a common move is a gain."""
from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from motor_comp.physics.axis import AxisKind, AxisModel, Units
from motor_comp.workbench.wording import common_scale, fmt_param

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


def _moved(ratios: dict[tuple[str, str], tuple[float, float]]) -> SimpleNamespace:
    """A fit of the tutorial's start model whose parameters moved by ``ratio ± se``."""
    base = {('mass', 'mass'): 5.4, ('coulomb', 'fc'): 10.0, ('viscous', 'fv'): 10.0}
    scalars: dict = {}
    se: dict = {}
    for (g, k), v in base.items():
        q, s = ratios.get((g, k), (1.0, 0.0))
        scalars.setdefault(g, {})[k] = q * v
        se.setdefault(g, {})[k] = s * v
    return SimpleNamespace(scalars=scalars, se=se)


GIVEN = AxisModel.from_dict({'input': 'voltage', 'input_gain': 15.116, 'back_emf': 123.0,
                             'mass': 5.4, 'effects': {'coulomb': {'fc': 10.0},
                                                      'viscous': {'fv': 10.0}}})


def test_a_gain_error_moves_every_force_parameter_together() -> None:
    s = common_scale(GIVEN, _moved({('mass', 'mass'): (1.3, 0.01),
                                    ('coulomb', 'fc'): (1.31, 0.01),
                                    ('viscous', 'fv'): (1.28, 0.02)}))
    assert s == pytest.approx(1.3)


def test_one_move_and_wide_error_bars_are_not_a_gain_error() -> None:
    # the tutorial's run refitted without its ripple: the mass moved (2.2 SE), fc
    # barely (1.8 SE, 4 %), fv the other way within its wide error bar — each agrees
    # with a common ×1.042 only as well as with no move at all
    est = _moved({('mass', 'mass'): (1.1253, 0.0577), ('coulomb', 'fc'): (1.0418, 0.0233),
                  ('viscous', 'fv'): (0.8444, 0.1)})
    assert common_scale(GIVEN, est) is None
    # the same median with tight error bars on two of them is a common move
    est = _moved({('mass', 'mass'): (1.10, 0.01), ('coulomb', 'fc'): (1.10, 0.01),
                  ('viscous', 'fv'): (1.0, 0.1)})
    assert common_scale(GIVEN, est) == pytest.approx(1.10)
