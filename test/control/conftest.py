"""Shared fixtures of the control tests: the two packaged plants."""
from __future__ import annotations

import pytest

from motor_comp.physics import load_plant


@pytest.fixture(scope='session')
def pmlm():
    """Load the PMLM plant of config/pmlm.yaml."""
    return load_plant('pmlm')


@pytest.fixture(scope='session')
def ballscrew():
    """Load the ball-screw plant of config/ballscrew.yaml."""
    return load_plant('ballscrew')
