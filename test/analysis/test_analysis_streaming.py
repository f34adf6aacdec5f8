"""Streaming analysis equals the array path (``compute_metrics(read_run(...))``) to 1e-12.

The inputs are runs the streaming code did not produce: closed-loop simulations written
by the project's MCAP writer, a real HSM150 measurement, a real ODrive log with
irregular (host-polled) stamps, damaged and out-of-order files.  Blocks are made tiny
(a few hundred samples) so that every signal, glitch window, stroke and move crosses
many block borders.
"""
from __future__ import annotations

import math
import os
import shutil
import tracemalloc
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from motor_comp.analysis import streaming as S
from motor_comp.analysis.metrics import compute_metrics
from motor_comp.logs import Run, read_run, write_run

DATA = Path('/work/shared/data')
if not DATA.exists():
    DATA = Path(__file__).resolve().parents[3] / 'shared' / 'data'

SIGNALS = ('reference', 'reference_velocity', 'voltage')


@pytest.fixture
def small_blocks(monkeypatch):
    """Blocks of 257 samples, FFT rows of 64: many borders and a real four-step FFT."""
    monkeypatch.setattr(S, 'BLOCK', 257)
    monkeypatch.setattr(S, 'FFT_ROW', 64)


def _array_metrics(path, **kw):
    run = read_run(path, signals=SIGNALS, require=('reference',))
    return compute_metrics(run, **kw)


def _assert_same(a, b, where=''):
    """Recursive equality, floats to 1e-12 relative."""
    if isinstance(a, dict):
        assert a.keys() == b.keys(), where
        for k in a:
            _assert_same(a[k], b[k], f'{where}.{k}')
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), f'{where}: {len(a)} != {len(b)}'
        for i, (x, y) in enumerate(zip(a, b)):
            _assert_same(x, y, f'{where}[{i}]')
    elif isinstance(a, float) and isinstance(b, float):
        assert a == b or abs(a - b) <= 1e-12 * max(abs(a), abs(b)), f'{where}: {a} {b}'
    else:
        assert a == b, f'{where}: {a!r} != {b!r}'


def _check(path, **kw):
    ref = _array_metrics(path, **kw)
    got = S.stream_metrics(path, **kw)
    _assert_same(ref.as_dict(), got.as_dict())
    return ref


def _simulated(tmp_path, trajectory, duration, *, drop_velocity=False, name='sim',
               chunk_size=1024 * 1024):
    from motor_comp.control.scenario import Scenario
    res, _ = Scenario(plant='pmlm', controller='pid', duration=duration,
                      trajectory=trajectory, settings=(('sensors.noise_std', 2e-7),)).run()
    run = res.to_run()
    if drop_velocity:
        run = Run(t=run.t, position=run.position, reference=run.reference,
                  voltage=run.voltage, name=run.name)
    path = tmp_path / f'{name}.mcap'
    write_run(path, run, chunk_size=chunk_size)
    return path


def test_sine_tracking_run_equals_array_path(small_blocks, tmp_path):
    path = _simulated(tmp_path, 'sine', 6.0)
    ref = _check(path)
    # not vacuous: reversals, strokes and a spectrum to compare
    assert ref.glitch_count >= 4 and len(ref.segments) >= 5 and ref.chattering > 0


def test_point_to_point_moves_and_differentiated_reference(small_blocks, tmp_path):
    path = _simulated(tmp_path, 'p2p', 6.0, drop_velocity=True)
    ref = _check(path, settle_band=2e-6)
    assert len(ref.moves) >= 2
    assert any(m.settling_time is not None and m.settling_time > 0 for m in ref.moves)


def test_real_hsm150_measurement(small_blocks, tmp_path):
    from motor_comp.logs.importers import import_table
    src = DATA / 'hsm150' / 'idf_pos_0.06_1.mat'
    if not src.exists():
        pytest.skip('shared HSM150 data not present')
    run = import_table(src, time='data:0', input='data:4', position='data:2',
                       reference='data:1')
    path = tmp_path / 'hsm.mcap'
    write_run(path, run)
    ref = _check(path)
    assert ref.samples == 20000 and ref.max_error > 0


def test_real_odrive_log_with_irregular_stamps(small_blocks, tmp_path):
    from motor_comp.logs.importers import import_table
    src = DATA / 'odrive_cogging' / 'slow2' / 'nocomp_0.mat'
    if not src.exists():
        pytest.skip('shared ODrive data not present')
    run = import_table(src, time='data:0', input='data:2', position='data:1',
                       position_scale=2 * math.pi / 8192)
    t = run.t - run.t[0]
    # the velocity set-point of the log (0.1 rev/s) as the reference
    run = Run(t=t, position=run.position - run.position[0], reference=0.2 * math.pi * t,
              voltage=run.voltage, name='odrive')
    d = np.diff(run.t)
    assert d.max() > 1.01 * d.min()          # irregular: the resampled spectrum path
    path = tmp_path / 'odrive.mcap'
    write_run(path, run)
    ref = _check(path, chatter_cutoff=50.0)
    assert ref.chattering is not None and ref.chattering > 0


def test_damaged_file_reads_the_same_part(small_blocks, tmp_path, capsys):
    path = _simulated(tmp_path, 'sine', 4.0, chunk_size=32 * 1024)
    cut = tmp_path / 'cut.mcap'
    data = path.read_bytes()
    cut.write_bytes(data[:int(len(data) * 0.6)])
    ref = _check(cut)
    err = capsys.readouterr().err
    assert err.count('reading stopped at byte') == 2       # same warning, both paths
    assert 0 < ref.samples < 4000


def test_out_of_order_file_falls_back_to_the_array_path(tmp_path):
    from motor_comp.logs import cdr, schemas
    from motor_comp.logs.mcap_io import McapRecorder
    n = 2000
    ns = np.arange(1, n + 1, dtype=np.int64) * 1_000_000
    stamps = ns.copy()
    stamps[[700, 701]] = stamps[[701, 700]]           # two measurements swapped
    x = 0.01 * np.sin(ns / 1e9)
    names = schemas.topics('axis')
    path = tmp_path / 'ooo.mcap'
    with McapRecorder(path, chunk_size=32 * 1024, flush_interval=0) as rec:
        rec.add_channel(names['reference'], schemas.JOINT_STATE)
        rec.add_channel(names['joint_states'], schemas.JOINT_STATE)
        refs = cdr.encode_joint_states(ns, x + 1e-6, None)
        meas = cdr.encode_joint_states(stamps, x, None)
        for k in range(n):
            rec.write_cdr(names['reference'], refs[k].tobytes(), int(ns[k]))
            rec.write_cdr(names['joint_states'], meas[k].tobytes(), int(ns[k]))
    got = S.open_stream(path, signals=SIGNALS)
    assert isinstance(got, Run) and len(got) == n     # sorted by read_run
    _check(path)


def test_last_stroke_keeps_the_last_sample_late_in_a_long_run(small_blocks, tmp_path):
    # at t ≈ 10 h, 1e-12 s is below the float spacing of t: the last stroke must still
    # end with the last sample (it holds the largest error here), in both paths
    t = 36_000.0 + np.arange(3000) * 1e-3
    ref = 0.01 * np.sin(2 * np.pi * 1.0 * t)
    x = ref.copy()
    x[-1] += 5e-6
    run = Run(t=t, position=x, reference=ref, voltage=np.sin(t), name='late')
    path = tmp_path / 'late.mcap'
    write_run(path, run)
    ref_m = _check(path)
    assert ref_m.segments[-1].max_error == pytest.approx(5e-6, rel=1e-6)


def test_spill_files_are_removed(tmp_path):
    path = _simulated(tmp_path, 'sine', 1.0)
    spill = tmp_path / 'spill'
    spill.mkdir()
    S.stream_metrics(path, spill_dir=str(spill))
    assert list(spill.iterdir()) == []


def test_traced_memory_does_not_grow_with_length(tmp_path, monkeypatch):
    """Peak of numpy/Python allocations for a 4x longer run: within 1.2x (+ its glitches)."""
    monkeypatch.setattr(S, 'BLOCK', 2048)
    monkeypatch.setattr(S, 'FFT_ROW', 1024)
    peaks = []
    for seconds in (4, 16):
        t = np.arange(seconds * 1000) * 1e-3
        ref = 0.01 * np.sin(2 * np.pi * 0.05 * t)       # few reversals: flat output size
        rng = np.random.default_rng(seconds)
        run = Run(t=t, position=ref - 1e-6 * rng.standard_normal(t.size), reference=ref,
                  voltage=np.sin(t) + 0.01 * rng.standard_normal(t.size), name=f'r{seconds}')
        path = tmp_path / f'r{seconds}.mcap'
        write_run(path, run, chunk_size=64 * 1024)
        tracemalloc.start()
        S.stream_metrics(path)
        peaks.append(tracemalloc.get_traced_memory()[1])
        tracemalloc.stop()
    assert peaks[1] < 1.2 * peaks[0], peaks


@settings(max_examples=8, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(n=st.integers(40, 700), block=st.integers(7, 90), seed=st.integers(0, 10_000),
       jitter=st.booleans(), period=st.floats(0.05, 0.5))
def test_property_random_runs_and_blocks(tmp_path_factory, monkeypatch, n, block, seed,
                                         jitter, period):
    monkeypatch.setattr(S, 'BLOCK', block)
    monkeypatch.setattr(S, 'FFT_ROW', 16)
    rng = np.random.default_rng(seed)
    dt = 1e-3 * (1 + (0.5 * rng.random(n) if jitter else np.zeros(n)))
    t = np.cumsum(dt)
    ref = 0.01 * np.sin(2 * np.pi * t / period)
    ref[rng.random(n) < 0.1] = ref[0]                    # dwells and flat stretches
    run = Run(t=t, position=ref + 1e-5 * rng.standard_normal(n), reference=ref,
              voltage=rng.standard_normal(n), name='prop')
    d = tmp_path_factory.mktemp('prop')
    path = d / 'p.mcap'
    write_run(path, run)
    _check(path, glitch_window=0.01, min_dwell=0.002)
    shutil.rmtree(d)
    assert os.path.exists(str(d)) is False
