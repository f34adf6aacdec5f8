"""Fixtures of the autotune tests: a private, localhost-only ROS domain; start models."""
from __future__ import annotations

from pathlib import Path
from typing import Callable

import pytest

#: the drives' own constants (DESIGN.md §3 / config/*.yaml), a rough mass, no effect
BARE = {
    'pmlm': ('# PMLM: k_f/R = 130/8.6 N/V, k_e = 123 V·s/m; the mass 11 % high\n'
             'input: voltage\ninput_gain: 15.116279069767442\nback_emf: 123.0\n'
             'mass: 6.0\neffects: {}\n'),
    'ballscrew': ('# ball-screw: k_f = 50 N/V, B·M = 50 N·s/m; the mass 12 % high\n'
                  'input: voltage\ninput_gain: 50.0\ndamping: 50.0\nmass: 28.0\n'
                  'effects: {}\n'),
}


@pytest.fixture
def domain(monkeypatch) -> int:
    """Reserve a ROS_DOMAIN_ID for the test (machine-unique); DDS on localhost only."""
    from motor_comp.cli.run import private_domain_id, release_domain_id
    dom = private_domain_id()
    monkeypatch.setenv('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    monkeypatch.setenv('ROS_DOMAIN_ID', str(dom))
    try:
        yield dom
    finally:
        release_domain_id(dom)


@pytest.fixture
def bare_model(tmp_path: Path) -> Callable[[str], Path]:
    """Write the bare start model of a plant; return its path."""
    def write(plant: str) -> Path:
        path = tmp_path / f'{plant}_bare.yaml'
        path.write_text(BARE[plant], encoding='utf-8')
        return path
    return write


@pytest.fixture
def autotune(capsys, domain) -> Callable[..., tuple[int, str, str]]:
    """Run ``motor-comp autotune ARGS --domain-id D`` here; (exit status, stdout, stderr)."""
    import motor_comp.cli.main as cli

    def run(*argv) -> tuple[int, str, str]:
        code = cli.main(['autotune', *[str(a) for a in argv], '--domain-id', str(domain)])
        out, err = capsys.readouterr()
        assert 'Traceback' not in err, err
        return code, out, err
    return run
