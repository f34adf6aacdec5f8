"""Fuzzing read_run: a damaged MCAP gives a Run or an InputFileError, nothing else."""
from __future__ import annotations

import tempfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from motor_comp.errors import InputFileError
from motor_comp.logs import Run, read_run, write_run

_TMP = tempfile.TemporaryDirectory(prefix='motor_comp_fuzz_')   # removed at exit
_DIR = Path(_TMP.name)


def _valid(compression: str) -> bytes:
    t = np.arange(400) * 1e-3
    ref = 0.01 * np.sin(2 * np.pi * t)
    run = Run(t=t, position=ref - 1e-6, velocity=np.cos(t), reference=ref,
              reference_velocity=np.cos(t), voltage=np.sin(t), metadata={'k': 'v'})
    path = _DIR / f'valid_{compression}.mcap'
    write_run(path, run, chunk_size=4096, compression=compression)
    return path.read_bytes()


VALID = {c: _valid(c) for c in ('zstd', 'none')}


def _check(data: bytes, tag: str) -> None:
    path = _DIR / f'fuzz_{tag}.mcap'
    path.write_bytes(data)
    try:
        run = read_run(path)
    except InputFileError:
        return
    assert isinstance(run, Run)
    assert len(run) >= 1 and np.all(np.diff(run.t) > 0)
    assert np.all(np.isfinite(run.position))


@pytest.mark.parametrize('compression', ['zstd', 'none'])
@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(frac=st.floats(0.0, 1.0))
def test_truncated_anywhere(compression: str, frac: float) -> None:
    data = VALID[compression]
    _check(data[:int(frac * len(data))], 'trunc')


@pytest.mark.parametrize('compression', ['zstd', 'none'])
@settings(max_examples=80, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(flips=st.lists(st.tuples(st.floats(0.0, 1.0, exclude_max=True),
                                st.integers(1, 255)), min_size=1, max_size=8))
def test_flipped_bytes(compression: str, flips: list[tuple[float, int]]) -> None:
    data = bytearray(VALID[compression])
    for where, mask in flips:
        data[int(where * len(data))] ^= mask
    _check(bytes(data), 'flip')
