"""Real measurements as a robot records them (issue 25 item 4): the same model from the bag.

The HSM150 and ODrive runs of ``../shared/data`` are written into rosbag2 bags by rosbags
(the axis one joint among several, its effort = the logged torque or current, the
joints' order changing between messages in one of them), in both storages.  ``fit
--auto`` from a bare model on the bag, with ``--joint`` and ``--input effort``, must
give the model that ``motor-comp import`` of the same table gives, to 1e-9.
``fit --joint all`` fits each moving joint of one bag.
"""
from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from motor_comp.cli import main as cli
from motor_comp.logs import read_run
from motor_comp.logs.topics import RunTopics
from rosbag_writer import write_bag

REPO = Path(__file__).resolve().parents[2]
DATA = next((p for p in (Path('/work/shared/data'), REPO.parent / 'shared' / 'data')
             if (p / 'hsm150').is_dir() and (p / 'odrive_cogging').is_dir()), None)
pytestmark = pytest.mark.skipif(DATA is None, reason='real data sets not available')

HSM_RUNS = ('idf_pos_0.065_1', 'idf_neg_0.045_1')
#: 2023-11-14T22:13:20Z in ns: the ODrive bags carry wall-clock stamps
WALL_CLOCK_NS = 1_700_000_000_000_000_000
J0 = 1.2153e-4


def _close(a, b, path='model') -> None:
    """Recursively equal, numbers to 1e-9 relative."""
    if isinstance(a, dict):
        assert set(a) == set(b), (path, set(a) ^ set(b))
        for k in a:
            _close(a[k], b[k], f'{path}.{k}')
    elif isinstance(a, (list, tuple)):
        assert len(a) == len(b), path
        for i, (x, y) in enumerate(zip(a, b)):
            _close(x, y, f'{path}[{i}]')
    elif isinstance(a, float) or isinstance(b, float):
        assert math.isclose(a, b, rel_tol=1e-9, abs_tol=1e-300), (path, a, b)
    else:
        assert a == b, (path, a, b)


def _others(n: int, seed: int) -> dict[str, dict[str, np.ndarray]]:
    rng = np.random.default_rng(seed)
    return {name: {'position': np.cumsum(rng.normal(size=n)) * 1e-3,
                   'velocity': rng.normal(size=n), 'effort': rng.normal(size=n)}
            for name in ('base_joint', 'tool_joint')}


def _hsm150(name: str):
    from scipy.io import loadmat
    d = loadmat(DATA / 'hsm150' / f'{name}.mat')['data']
    return d[:, 0], d[:, 2], d[:, 3], d[:, 4]       # t, angle, speed, input torque


@pytest.fixture(scope='module')
def recorded(tmp_path_factory):
    """The imported runs (``motor-comp import``) and the same runs as bags, both storages."""
    root = tmp_path_factory.mktemp('real')
    runs: dict[str, dict[str, list[Path]]] = {'hsm150': {}, 'odrive': {}}
    assert cli.main(['import', str(DATA / 'odrive_cogging' / 'slow2' / 'nocomp_0.mat'),
                     '--time', '0', '--position', '1', '--input', '2',
                     '--position-scale', repr(2 * math.pi / 8192),
                     '-o', str(root / 'odrive.mcap')]) == 0
    odrive = read_run(root / 'odrive.mcap', topics=RunTopics.of())
    runs['odrive']['import'] = [root / 'odrive.mcap']
    # wall-clock stamps, as a robot's (as float seconds they would lose 0.24 µs)
    ns = np.round(odrive.t * 1e9).astype(np.int64) + WALL_CLOCK_NS
    for storage in ('sqlite3', 'mcap'):
        joints = {'odrive_axis': {'position': odrive.position, 'velocity': None,
                                  'effort': odrive.voltage}}
        joints = {'wheel_left': {'position': np.zeros(len(ns)), 'velocity': None,
                                 'effort': np.zeros(len(ns))}, **joints}
        runs['odrive'][storage] = [write_bag(root / f'odrive_{storage}', storage, ns, joints,
                                             shuffle_seed=3)]
    runs['hsm150'] = {'import': [], 'sqlite3': [], 'mcap': []}
    for k, name in enumerate(HSM_RUNS):
        path = root / f'{name}.mcap'
        assert cli.main(['import', str(DATA / 'hsm150' / f'{name}.mat'), '--time', '0',
                         '--position', '2', '--velocity', '3', '--input', '4',
                         '-o', str(path)]) == 0
        runs['hsm150']['import'].append(path)
        run = read_run(path)
        ns = np.round(run.t * 1e9).astype(np.int64)
        joints = {'hsm150': {'position': run.position, 'velocity': run.velocity,
                             'effort': run.voltage}, **_others(len(ns), k)}
        for storage in ('sqlite3', 'mcap'):
            runs['hsm150'][storage].append(write_bag(root / f'{name}_{storage}', storage, ns,
                                                     joints))
    models = {
        'hsm150': {'axis': 'rotary', 'input': 'force', 'input_gain': 1.0, 'mass': 2 * J0,
                   'effects': {}},
        'odrive': {'axis': 'rotary', 'input': 'current', 'input_gain': 1.0, 'mass': 0.01,
                   'effects': {}}}
    for axis, m in models.items():
        (root / f'{axis}.yaml').write_text(yaml.safe_dump(m))
    return root, runs


def _fit(capsys, root: Path, axis: str, paths: list[Path], *extra: str) -> dict:
    argv = ['fit', *map(str, paths), '--model', str(root / f'{axis}.yaml'), '--auto',
            '--json', *extra]
    assert cli.main(argv) == 0, capsys.readouterr().err
    return json.loads(capsys.readouterr().out)


@pytest.mark.parametrize('axis, storage, joint', [('hsm150', 'sqlite3', 'hsm150'),
                                                  ('odrive', 'mcap', 'odrive_axis')])
def test_the_bag_gives_the_imported_model(recorded, capsys, monkeypatch, axis, storage,
                                          joint) -> None:
    """``fit BAG --joint J --input effort`` = ``fit IMPORTED.mcap``, every number to 1e-9."""
    monkeypatch.setattr(cli, 'SUBCOMMANDS', ('fit',))
    root, runs = recorded
    imported = _fit(capsys, root, axis, runs[axis]['import'])
    bag = _fit(capsys, root, axis, runs[axis][storage], '--joint', joint, '--input', 'effort')
    _close(imported['model'], bag['model'])
    _close([s['force_nrmse'] for s in imported['steps']],
           [s['force_nrmse'] for s in bag['steps']])
    _close(imported['unexplained']['noise_floor_nrmse'],
           bag['unexplained']['noise_floor_nrmse'])
    # one figure for the final model in every line (a speed-band weighted fit included)
    assert bag['unexplained']['force_nrmse'] == bag['steps'][-1]['force_nrmse']
    # and it is the physics the real-data tests assert (test_workbench_realdata)
    effects = bag['model']['effects']
    if axis == 'hsm150':
        assert 'asymmetry' in effects and abs(bag['model']['mass'] / J0 - 1) < 0.25
    else:
        assert abs(2 * math.pi / effects['ripple']['period'] - 7.0) < 0.1


@pytest.mark.parametrize('axis, storage, joint', [('hsm150', 'mcap', 'hsm150'),
                                                  ('odrive', 'sqlite3', 'odrive_axis')])
def test_the_other_storage_gives_the_same_run(recorded, axis, storage, joint) -> None:
    """The other storage of each: the very same arrays as the import (so the same model)."""
    _, runs = recorded
    sel = RunTopics.of(joint=joint, input='effort')
    for imp, bag in zip(runs[axis]['import'], runs[axis][storage]):
        a, b = read_run(imp), read_run(bag, topics=sel, exact_time=True)
        if axis == 'odrive':      # wall-clock stamps: counted from the first, to the ns
            assert b.metadata['time_origin_ns'] == round(a.t[0] * 1e9) + WALL_CLOCK_NS
            np.testing.assert_allclose(b.t, a.t - a.t[0], rtol=0, atol=1e-12)
            b = dataclasses.replace(b, t=a.t)
        for sig in ('t', 'position', 'velocity', 'voltage'):
            x, y = getattr(a, sig), getattr(b, sig)
            assert (x is None and y is None) or np.array_equal(x, y), sig


def test_every_moving_joint_gets_its_model(recorded, capsys, monkeypatch, tmp_path) -> None:
    """``fit BAG --joint all -o DIR/``: the ODrive joint fitted, the still wheel skipped."""
    monkeypatch.setattr(cli, 'SUBCOMMANDS', ('fit',))
    root, runs = recorded
    out = tmp_path / 'joints'
    data = _fit(capsys, root, 'odrive', runs['odrive']['sqlite3'], '--joint', 'all',
                '--input', 'effort', '-o', f'{out}/')
    rows = {r['joint']: r for r in data['joints']}
    assert set(rows) == {'wheel_left', 'odrive_axis'}
    assert rows['wheel_left']['status'] == 'skipped'
    assert rows['wheel_left']['reason'] == 'does not move'
    assert rows['odrive_axis']['status'] == 'fitted'
    saved = yaml.safe_load((out / 'odrive_axis.yaml').read_text())
    single = _fit(capsys, root, 'odrive', runs['odrive']['sqlite3'], '--joint', 'odrive_axis',
                  '--input', 'effort')
    _close(single['model'], saved)
    table = (out / 'joints.csv').read_text().splitlines()
    assert table[0].startswith('joint,status') and len(table) == 3
    # without -o DIR: one line naming what is missing
    argv = ['fit', str(runs['odrive']['sqlite3'][0]), '--model', str(root / 'odrive.yaml'),
            '--joint', 'all', '--input', 'effort']
    assert cli.main(argv) == 2
    assert capsys.readouterr().err.strip() == ('motor-comp: error: --joint all fits every '
                                               'moving joint: give -o DIR/ for their model '
                                               'files')
