"""Sweeps on Dask: equal to the local sweep, killed workers, failing points, backpressure.

One loopback-only ``LocalCluster`` (2 single-threaded worker processes, no dashboard)
is shared by the module; every Dask call is bounded in time.
"""
from __future__ import annotations

import concurrent.futures
import csv
import json
import os
import signal
import subprocess
import sys
import time

import pytest

from motor_comp.cli import main as cli
from motor_comp.control.sweep import (PointResult, SweepStats, close_client, dask_client,
                                      expand_grid, iter_grid, iter_sweep, run_point, run_sweep)

distributed = pytest.importorskip('distributed')

pytestmark = pytest.mark.timeout(240)

BASE = {'plant': 'pmlm', 'controller': 'pid', 'duration': 0.4}


@pytest.fixture(scope='module')
def client():
    """A 2-worker LocalCluster on 127.0.0.1 (started once for the module)."""
    c = dask_client('local:2', timeout=60)
    try:
        c.wait_for_workers(2, timeout=60)
        yield c
    finally:
        close_client(c)


def _same(a: PointResult, b: PointResult) -> None:
    assert a.point == b.point and a.ok and b.ok
    assert a.metrics.keys() == b.metrics.keys()
    for k, v in a.metrics.items():
        assert v == pytest.approx(b.metrics[k], rel=1e-12, abs=1e-18), k


class RaiseFor:
    """Metrics callable that raises for one controller gain (picklable, module-level)."""

    def __init__(self, kp: float) -> None:
        self.kp = kp

    def __call__(self, result):
        """Raise for ``kp``, else the RMS error."""
        if result.metadata['settings'].get('kp') == self.kp:
            raise RuntimeError(f'planted failure at kp={self.kp:g}')
        e = result.error
        return {'rms_error': float((e * e).mean() ** 0.5)}


def test_dask_sweep_equals_local_point_for_point(client):
    points = expand_grid(BASE, {'kp': [2e4, 4.8e4], 'plant.coulomb.fc': [5.0, 15.0],
                                'seed': [0, 1]})
    stats = SweepStats()
    got = run_sweep(points, executor=client, batch_size=3, max_pending=2, stats=stats)
    local = [run_point(p, index=i) for i, p in enumerate(points)]
    assert [g.point for g in got] == points and [g.index for g in got] == list(range(8))
    for g, s in zip(got, local):
        _same(g, s)
    assert stats.tasks == 3 and stats.peak_pending <= 2
    # different true friction gives different errors: the comparison is not vacuous
    assert got[0].metrics['rms_error'] != got[2].metrics['rms_error']


def test_cli_scheduler_output_equals_local(client, capsys, monkeypatch, tmp_path):
    monkeypatch.setattr(cli, 'SUBCOMMANDS', ('sweep',))
    outs = {}
    for name, extra in (('dask', ['--scheduler', client.scheduler.address, '--progress']),
                        ('local', ['--workers', '1'])):
        table = tmp_path / f'{name}.csv'
        code = cli.main(['sweep', '--plant', 'pmlm', '--controller', 'pid', '--duration',
                         '0.4', '--grid', 'kp=2e4,4.8e4', '--grid', 'plant.coulomb.fc=5,15',
                         '--batch', '1', '--csv', str(table), '--json', *extra])
        out, err = capsys.readouterr()
        assert code == 0, err
        with open(table, newline='') as f:
            outs[name] = (json.loads(out), list(csv.reader(f)), err)
    (jd, cd, err), (jl, cl, _) = outs['dask'], outs['local']
    assert 'sweep: 4/4 points' in err and 'points/s' in err and 'ETA' in err
    assert len(jd['points']) == 4 and jd['failed'] == [] and jd['grid'] == jl['grid']
    for a, b in zip(jd['points'], jl['points']):
        a.pop('wall_s'), b.pop('wall_s')
        assert a.keys() == b.keys()
        for k in a:
            if isinstance(a[k], float):
                assert a[k] == pytest.approx(b[k], rel=1e-12, abs=1e-18), k
            else:
                assert a[k] == b[k], k
    wall = cd[0].index('wall_s')
    assert cd[0] == cl[0] and len(cd) == 5
    for rd, rl in zip(cd[1:], cl[1:]):
        assert rd[:wall] == rl[:wall]


def test_env_scheduler_address_is_used(client, capsys, monkeypatch):
    monkeypatch.setattr(cli, 'SUBCOMMANDS', ('sweep',))
    monkeypatch.setenv('DASK_SCHEDULER_ADDRESS', client.scheduler.address)
    before = client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.transition_counter)
    code = cli.main(['sweep', '--plant', 'pmlm', '--duration', '0.2', '--grid', 'kp=2e4,3e4',
                     '--json'])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert len(json.loads(out)['points']) == 2
    after = client.run_on_scheduler(lambda dask_scheduler: dask_scheduler.transition_counter)
    assert after > before          # the batches ran on the cluster, not in a local pool


def test_failing_point_is_reported_and_the_rest_complete(client):
    points = expand_grid(BASE, {'kp': [2e4, 3e4, 4.8e4]})
    got = run_sweep(points, executor=client, metrics=RaiseFor(3e4), batch_size=3)
    assert [g.ok for g in got] == [True, False, True]
    assert got[1].point['kp'] == 3e4 and 'RuntimeError: planted failure at kp=30000' \
        in got[1].error
    ref = run_point(points[2], RaiseFor(3e4))
    _same(got[2], ref)


def test_cli_reports_failing_point_by_settings(client, capsys, monkeypatch):
    # 6e4 s at 1 kHz exceeds the simulator's step limit: the scenario builds (so the
    # up-front validation passes) but the simulation raises on the worker
    monkeypatch.setattr(cli, 'SUBCOMMANDS', ('sweep',))
    code = cli.main(['sweep', '--plant', 'pmlm', '--grid', 'duration=0.2,60000', '--json',
                     '--scheduler', client.scheduler.address])
    out, err = capsys.readouterr()
    data = json.loads(out)
    assert code == 1
    assert [p['duration'] for p in data['points']] == [0.2]
    assert len(data['failed']) == 1 and data['failed'][0]['duration'] == 60000.0
    line = [ln for ln in err.splitlines() if 'sweep point' in ln]
    assert len(line) == 1 and 'duration=60000.0' in line[0] and 'ParameterError' in line[0]
    assert 'Traceback' not in err


class SlowLogged:
    """Metrics that record each start as a file ``<kp>_<fc>_<pid>`` and take 0.3 s."""

    def __init__(self, log_dir: str) -> None:
        self.log_dir = log_dir

    def __call__(self, result):
        """Log the start, hold the worker busy, return the RMS error."""
        s = result.metadata['settings']
        name = f"{s['kp']:g}_{s['plant.coulomb.fc']:g}_{os.getpid()}"
        open(os.path.join(self.log_dir, name), 'w').close()
        time.sleep(0.3)      # keeps a task running when the worker is killed
        e = result.error
        return {'rms_error': float((e * e).mean() ** 0.5)}


def test_killed_worker_loses_no_point(client, tmp_path):
    grid = {'kp': [2e4, 3e4, 4e4, 4.8e4], 'plant.coulomb.fc': [5.0, 10.0, 15.0]}
    points = expand_grid(BASE, grid)
    metrics = SlowLogged(str(tmp_path))
    pids = client.run(os.getpid, nanny=False)
    assert len(pids) == 2
    victim = next(iter(pids.values()))
    done: dict[int, PointResult] = {}
    order: list[int] = []
    lost = None
    for r in iter_sweep(points, executor=client, metrics=metrics, batch_size=1,
                        max_pending=4):
        order.append(r.index)
        done[r.index] = r
        if len(order) == 2:
            # condition, not a fixed wait: the victim has started a point not yet returned
            deadline = time.monotonic() + 60
            while lost is None and time.monotonic() < deadline:
                for f in os.listdir(tmp_path):
                    kp, fc, pid = f.split('_')
                    i = next(j for j, p in enumerate(points)
                             if f"{p['kp']:g}" == kp and f"{p['plant.coulomb.fc']:g}" == fc)
                    if int(pid) == victim and i not in done:
                        lost = i
                time.sleep(0.01)
            assert lost is not None
            os.kill(victim, signal.SIGKILL)
    assert sorted(order) == list(range(len(points)))      # every point exactly once
    assert all(r.ok for r in done.values())
    p = points[lost]
    starts = [f for f in os.listdir(tmp_path)
              if f.startswith(f"{p['kp']:g}_{p['plant.coulomb.fc']:g}_")]
    assert len(starts) >= 2          # it was running on the victim, then ran again
    _same(done[lost], run_point(p, metrics, index=lost))
    client.wait_for_workers(2, timeout=60)                 # the nanny restarted it
    assert victim not in client.run(os.getpid, nanny=False).values()


class _InlineExecutor:
    """Executor returning finished futures without simulating (backpressure logic only)."""

    def __init__(self) -> None:
        self.submitted = 0

    def submit(self, fn, batch, metrics):
        self.submitted += 1
        f: concurrent.futures.Future = concurrent.futures.Future()
        f.set_result([PointResult(point=p, metrics={}, wall_s=0.0, index=i) for i, p in batch])
        return f


def test_backpressure_bounds_pending_futures_on_a_100k_grid():
    pulled = 0

    def points():
        nonlocal pulled
        grid = {'kp': list(range(1000)), 'seed': list(range(100))}
        for p in iter_grid({'plant': 'pmlm'}, grid):
            pulled += 1
            yield p

    stats = SweepStats()
    ex = _InlineExecutor()
    it = iter_sweep(points(), executor=ex, batch_size=16, max_pending=5, stats=stats)
    first = next(it)
    assert pulled <= 5 * 16      # the grid is consumed lazily, 5 batches at a time
    seen = [first.index] + [r.index for r in it]
    assert len(seen) == 100_000 and len(set(seen)) == 100_000
    assert stats.peak_pending == 5 and stats.tasks == ex.submitted == 6250


def test_missing_distributed_is_one_line_error():
    prog = ("import sys; sys.modules['distributed'] = None\n"
            "from motor_comp.cli import main as m\n"
            "import motor_comp.control.sweep\n"
            "sys.exit(m.main(sys.argv[1:]))")
    out = subprocess.run([sys.executable, '-c', prog, 'sweep', '--plant', 'pmlm',
                          '--duration', '0.2', '--grid', 'kp=2e4,3e4', '--scheduler',
                          'local:2'], capture_output=True, text=True, timeout=120)
    assert out.returncode == 2 and 'Traceback' not in out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1 and 'distributed' in lines[0] and "motor_comp[cluster]" in lines[0]


@pytest.mark.parametrize('spec', ['local:0', 'local:x', 'nonsense'])
def test_bad_scheduler_spec_is_one_line_error(capsys, monkeypatch, spec):
    monkeypatch.setattr(cli, 'SUBCOMMANDS', ('sweep',))
    code = cli.main(['sweep', '--plant', 'pmlm', '--grid', 'kp=2e4,3e4', '--scheduler', spec])
    _, err = capsys.readouterr()
    assert code == 2 and len(err.strip().splitlines()) == 1 and spec in err
