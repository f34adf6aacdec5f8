"""Bad-input cases of every ``motor-comp`` command: the files, the argument lists, the outcome.

Shared by ``test_cli_bad_input.py`` (which asserts the outcomes) and, run as a script,
prints the Markdown table of ``docs/reliability.md`` from the real CLI's answers::

    python test/cli/cli_bad_input_cases.py > /tmp/table.md

Inputs are generated from one small, physically consistent run built with numpy (no
simulation, so no numba compilation): a 2 s, 1 kHz sine move of the example PMLM model
``docs/examples/model.yaml`` whose logged voltage is exactly the inverse model's.
"""
from __future__ import annotations

import contextlib
import dataclasses
import io
import os
import struct
import sys
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from motor_comp.logs import McapRecorder, Run, write_run
from motor_comp.logs import cdr, schemas

#: the example model of the tutorial (mass 5.4 kg, gain 130/8.6 N/V, back-EMF 123 V·s/m)
MASS, GAIN, KE, FC, FV = 5.4, 130.0 / 8.6, 123.0, 10.0, 10.0
MODEL_YAML = (f'input: voltage\ninput_gain: {GAIN!r}\nback_emf: {KE!r}\ndamping: 0.0\n'
              f'mass: {MASS!r}\neffects:\n  coulomb: {{fc: {FC!r}}}\n'
              f'  viscous: {{fv: {FV!r}}}\n')


def good_run(duration: float = 2.0, rate: float = 1000.0) -> Run:
    """Return a 5 mm, 1 Hz sine move and the voltage that drives it through the model exactly."""
    t = np.arange(int(duration * rate)) / rate
    w = 2 * np.pi
    ref = 5e-3 * np.sin(w * t)
    ref_v = 5e-3 * w * np.cos(w * t)
    x = ref - 2e-6 * np.sin(2 * w * t)        # a small tracking error
    v = 5e-3 * w * np.cos(w * t) - 4e-6 * w * np.cos(2 * w * t)
    a = -5e-3 * w**2 * np.sin(w * t) + 8e-6 * w**2 * np.sin(2 * w * t)
    force = MASS * a + FC * np.sign(v) + FV * v
    u = force / GAIN + KE * v
    return Run(t=t, position=x, velocity=v, reference=ref, reference_velocity=ref_v,
               voltage=u, metadata={'generator': 'cli_bad_input_cases'}, name='good')


def _write_unsorted(path: Path, run: Run, order: np.ndarray) -> None:
    """Write ``run``'s messages in the order ``order`` (stamps may repeat or go back)."""
    ns = np.round(run.t * 1e9).astype(np.int64)
    js = cdr.encode_joint_states(ns, run.position, run.velocity)
    rf = cdr.encode_joint_states(ns, run.reference, run.reference_velocity)
    vo = cdr.encode_float64(run.voltage)
    topics = schemas.topics('axis')
    with McapRecorder(path, flush_interval=0.0) as rec:
        for key, typ in (('reference', schemas.JOINT_STATE),
                         ('joint_states', schemas.JOINT_STATE), ('voltage', schemas.FLOAT64)):
            rec.add_channel(topics[key], typ)
        for k, i in enumerate(order.tolist()):
            log = int(ns[0] + k * 1_000_000)     # log times increase; the stamps do not
            rec.write_cdr(topics['reference'], rf[i].tobytes(), log)
            rec.write_cdr(topics['joint_states'], js[i].tobytes(), log)
            rec.write_cdr(topics['voltage'], vo[i].tobytes(), int(ns[i]))


def _chunk_offsets(data: bytes) -> list[int]:
    """Byte offsets of the chunk records of an MCAP file (walks the record headers)."""
    out, p = [], 8
    while p + 9 <= len(data):
        op, length = struct.unpack_from('<BQ', data, p)
        if op == 0x06:
            out.append(p)
        if op in (0x02, 0x0F):                  # footer, data end
            break
        p += 9 + length
    return out


def make_inputs(d: Path) -> Path:
    """Write every good and bad input file into ``d``; return ``d``."""
    run = good_run()
    write_run(d / 'good.mcap', run)
    (d / 'model.yaml').write_text(MODEL_YAML, encoding='utf-8')
    # several small chunks, so that a truncated or damaged copy has a readable prefix
    write_run(d / 'chunked.mcap', run, chunk_size=16 * 1024)
    data = (d / 'chunked.mcap').read_bytes()
    (d / 'truncated.mcap').write_bytes(data[:int(0.6 * len(data))])
    (d / 'truncated_head.mcap').write_bytes(data[:40])
    (d / 'empty.mcap').write_bytes(b'')
    (d / 'text.mcap').write_text('this is not an MCAP file\n' * 20, encoding='utf-8')
    (d / 'dir.mcap').mkdir()
    magic = bytearray(data)
    magic[1] ^= 0xFF
    (d / 'badmagic.mcap').write_bytes(bytes(magic))
    flipped = bytearray(data)
    at = _chunk_offsets(data)
    at = at[int(0.7 * len(at))] + 200           # inside a chunk's data, 70 % into the file
    for k in range(at, at + 64, 7):
        flipped[k] ^= 0x5A
    (d / 'flipped.mcap').write_bytes(bytes(flipped))
    write_run(d / 'novolt.mcap', dataclasses.replace(run, voltage=None))
    write_run(d / 'noref.mcap', dataclasses.replace(run, reference=None,
                                                    reference_velocity=None))
    pos = run.position.copy()
    pos[500:510] = np.nan
    pos[900] = np.inf
    write_run(d / 'nan.mcap', dataclasses.replace(run, position=pos))
    write_run(d / 'allnan.mcap', dataclasses.replace(run, position=np.full(len(run), np.nan)))
    volt = run.voltage.copy()
    volt[:] = np.nan
    write_run(d / 'nanvolt.mcap', dataclasses.replace(run, voltage=volt))
    n = len(run)
    order = np.arange(n)
    order[1000:1010] = order[1000:1010][::-1]                  # 10 stamps go back
    _write_unsorted(d / 'unsorted.mcap', run, order)
    _write_unsorted(d / 'duplicated.mcap', run, np.repeat(np.arange(n), 2)[:n + n // 4])
    # models
    (d / 'malformed.yaml').write_text('mass: [1, 2\neffects: {\n', encoding='utf-8')
    (d / 'negmass.yaml').write_text(MODEL_YAML.replace(f'mass: {MASS!r}', 'mass: -5.4'))
    (d / 'zeromass.yaml').write_text(MODEL_YAML.replace(f'mass: {MASS!r}', 'mass: 0'))
    (d / 'unknown_effect.yaml').write_text(MODEL_YAML + '  wobble: {a: 1.0}\n')
    (d / 'badparam.yaml').write_text(MODEL_YAML.replace('fc: 10.0', 'fc: -3.0'))
    (d / 'mixedkeys.yaml').write_text(MODEL_YAML.replace('fc: 10.0', 'fc: 10.0, 0.02: 1, foo: 2'))
    (d / 'empty.yaml').write_text('')
    (d / 'list.yaml').write_text('- 1\n- 2\n')
    # tables for import
    t, x, u = run.t.tolist(), run.position.tolist(), run.voltage.tolist()
    rows = '\n'.join(f'{a!r},{b!r},{c!r}' for a, b, c in zip(t, u, x))
    (d / 'good.csv').write_text('t,u,x\n' + rows + '\n')
    bad = rows.splitlines()
    bad[41] = bad[41].rsplit(',', 1)[0] + ',abc'
    (d / 'nonnumeric.csv').write_text('t,u,x\n' + '\n'.join(bad) + '\n')
    (d / 'header_only.csv').write_text('t,u,x\n')
    (d / 'empty.csv').write_text('')
    (d / 'binary.csv').write_bytes(bytes(range(256)) * 4)
    (d / 'table.xlsx').write_bytes(b'PK\x03\x04' + bytes(200))
    (d / 'table.json').write_text('{"t": [0, 1], "u": [0, 1], "x": [0, 1]}\n')
    (d / 'bad.mat').write_bytes(b'MATLAB 5.0 MAT-file' + bytes(50))
    neg = '\n'.join(f'{a - 1.0!r},{b!r},{c!r}' for a, b, c in zip(t, u, x))
    (d / 'negtime.csv').write_text('t,u,x\n' + neg + '\n')
    # files standing where directories are expected, and the reverse
    (d / 'afile').write_text('x')
    plant = (Path(__file__).resolve().parents[2] / 'motor_comp' / 'config' / 'pmlm.yaml')
    (d / 'plant_bad.yaml').write_text(plant.read_text(encoding='utf-8').replace(
        'mass_kg: 5.4', 'mass_kg: -5.4'))
    (d / 'plant_field.yaml').write_text('plant: pmlm\nmotr: {mass_kg: 5.4}\n')
    (d / 'grid_bad.yaml').write_text('grid: [1, 2]\n')
    _robot_bag(d / 'robot', run, effort=True)
    _robot_bag(d / 'robot_noeffort', run, effort=False)
    return d


def _robot_bag(path: Path, run: Run, *, effort: bool) -> None:
    """A robot's sqlite3 bag written by rosbags: /joint_states with shoulder and elbow."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore
    store = get_typestore(Stores.ROS2_JAZZY)
    js, hd = store.types['sensor_msgs/msg/JointState'], store.types['std_msgs/msg/Header']
    tm = store.types['builtin_interfaces/msg/Time']
    with Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as w:
        c = w.add_connection('/joint_states', js.__msgtype__, typestore=store)
        for k in range(0, len(run), 10):
            ns = int(round(run.t[k] * 1e9)) + 1_000_000_000
            e = np.array([0.0, run.voltage[k]]) if effort else np.empty(0)
            msg = js(header=hd(stamp=tm(sec=ns // 10**9, nanosec=ns % 10**9), frame_id=''),
                     name=['shoulder', 'elbow'], position=np.array([0.0, run.position[k]]),
                     velocity=np.empty(0), effort=e)
            w.write(c, ns, store.serialize_cdr(msg, js.__msgtype__))


@dataclasses.dataclass(frozen=True)
class Case:
    """One command with one bad input and the outcome the user must see.

    ``argv`` and ``names`` use ``{d}`` for the inputs' directory.  ``outcome`` is
    ``'error'`` (exit 2, one ``motor-comp: error:`` line naming each of ``names``) or
    ``'warn'`` (exit 0, a ``motor-comp: warning:`` line naming each of ``names``).
    """

    id: str
    command: str
    problem: str
    argv: tuple[str, ...]
    names: tuple[str, ...]
    outcome: str = 'error'
    subprocess: bool = False
    in_process: bool = True     # False: starts rclpy, so only as a subprocess
    #: a known defect outside the modules this matrix's author may change (strict xfail)
    known_defect: str = ''

    def args(self, d: Path) -> list[str]:
        """Return the argument list with ``{d}`` filled in."""
        return [a.format(d=d) for a in self.argv]

    def expected(self, d: Path) -> list[str]:
        """Return the strings the message must contain."""
        return [n.format(d=d) for n in self.names]


def _c(id_: str, command: str, problem: str, argv: str, names: Sequence[str] = (), **kw
       ) -> Case:
    return Case(id_, command, problem, tuple(argv.split()), tuple(names), **kw)


M = '--model {d}/model.yaml'
WB = ('compare', 'diagnose', 'fit')


def _run_file_cases() -> list[Case]:
    """Return the MCAP damage cases every reading command must answer."""
    files = [
        ('missing', 'missing file', 'nope.mcap', ['nope.mcap', 'no such file']),
        ('empty', 'zero-length file', 'empty.mcap', ['empty.mcap', 'empty']),
        ('directory', 'a directory named .mcap', 'dir.mcap', ['dir.mcap', 'directory']),
        ('text', 'a text file named .mcap', 'text.mcap', ['text.mcap', 'not an MCAP']),
        ('badmagic', 'corrupt magic bytes', 'badmagic.mcap', ['badmagic.mcap', 'magic']),
        ('trunc_head', 'truncated before any message', 'truncated_head.mcap',
         ['truncated_head.mcap', 'no messages']),
        ('allnan', 'only NaN positions', 'allnan.mcap',
         ['allnan.mcap', 'all 2000 /axis/joint_states position samples are NaN/Inf']),
    ]
    recoverable = [
        ('truncated', 'truncated at 60 %', 'truncated.mcap',
         ['truncated.mcap', 'recovered']),
        ('flipped', 'bytes flipped at 70 %', 'flipped.mcap', ['flipped.mcap', 'recovered']),
        ('nan', 'NaN/Inf position samples', 'nan.mcap',
         ['nan.mcap', 'position: dropped 11 non-finite']),
        ('unsorted', 'non-monotonic stamps', 'unsorted.mcap',
         ['unsorted.mcap', '9 out-of-order stamps sorted']),
        ('duplicated', 'duplicated stamps', 'duplicated.mcap',
         ['duplicated.mcap', '1250 duplicate stamps dropped']),
    ]
    out: list[Case] = []
    for cmd, extra in (('analyze', ''), ('compare', M), ('diagnose', M),
                       ('fit', M + ' --add ripple'), ('replay', '--startup-delay 0')):
        if cmd == 'replay':       # replays the recorded bytes: NaN is data, damage an error
            files = [f for f in files if f[0] != 'allnan']
            out.append(_c('replay-truncated', cmd, 'truncated at 60 %',
                          f'{cmd} {{d}}/truncated.mcap --rate 0 {extra}',
                          ['truncated.mcap', 'replaying the 3734 messages recovered'],
                          outcome='warn', subprocess=True, in_process=False))
        for key, problem, fname, names in files:
            out.append(_c(f'{cmd}-{key}', cmd, problem, f'{cmd} {{d}}/{fname} {extra}',
                          names, subprocess=(cmd == 'replay' and key == 'text')))
        if cmd == 'replay':
            continue
        for key, problem, fname, names in recoverable:
            out.append(_c(f'{cmd}-{key}', cmd, problem, f'{cmd} {{d}}/{fname} {extra}',
                          names, outcome='warn', subprocess=(key == 'truncated')))
    return out


CASES: list[Case] = _run_file_cases() + [
    # --- analyze
    _c('analyze-noref', 'analyze', 'run without /axis/reference', 'analyze {d}/noref.mcap',
       ['noref.mcap', 'reference']),
    _c('analyze-window-neg', 'analyze', '--glitch-window -1',
       'analyze {d}/good.mcap --glitch-window -1', ['--glitch-window', '-1']),
    _c('analyze-window-nan', 'analyze', '--glitch-window nan',
       'analyze {d}/good.mcap --glitch-window nan', ['--glitch-window', 'nan']),
    _c('analyze-report-file', 'analyze', '--report into a file path',
       'analyze {d}/good.mcap --report {d}/afile', ['{d}/afile']),
    _c('analyze-report-under-file', 'analyze', '--report below a file',
       'analyze {d}/good.mcap --report {d}/afile/rep', ['{d}/afile/rep']),
    _c('analyze-option', 'analyze', 'unknown option', 'analyze {d}/good.mcap --bogus',
       ['--bogus']),
    # --- workbench
    *[_c(f'{cmd}-novolt', cmd, 'run without /axis/voltage', f'{cmd} {{d}}/novolt.mcap {M}',
         ['novolt.mcap', '/axis/voltage']) for cmd in WB],
    *[_c(f'{cmd}-nanvolt', cmd, 'voltage all NaN', f'{cmd} {{d}}/nanvolt.mcap {M}',
         ['nanvolt.mcap', '/axis/voltage']) for cmd in WB],
    *[_c(f'{cmd}-csv', cmd, 'a CSV table instead of MCAP', f'{cmd} {{d}}/good.csv {M}',
         ['good.csv', 'motor-comp import']) for cmd in WB],
    *[_c(f'{cmd}-model-{key}', cmd, problem,
         f'{cmd} {{d}}/good.mcap --model {{d}}/{fname}', [fname, *extra])
      for cmd in WB for key, problem, fname, extra in (
          ('missing', 'missing model file', 'nomodel.yaml', []),
          ('malformed', 'malformed model YAML', 'malformed.yaml', []),
          ('negmass', 'negative mass', 'negmass.yaml', ['mass']),
          ('zeromass', 'zero mass', 'zeromass.yaml', ['mass']),
          ('unknown', 'unknown effect name', 'unknown_effect.yaml', ['wobble']),
          ('badparam', 'negative Coulomb level', 'badparam.yaml', ['fc']),
          ('emptyyaml', 'empty model file', 'empty.yaml', []),
          ('list', 'model file is a list', 'list.yaml', []),
          ('dir', 'model path is a directory', '', []))],
    *[_c(f'{cmd}-option', cmd, 'unknown option', f'{cmd} {{d}}/good.mcap {M} --bogus',
         ['--bogus'], subprocess=cmd == 'compare') for cmd in WB],
    *[_c(f'{cmd}-window-nan', cmd, '--window nan', f'{cmd} {{d}}/good.mcap {M} --window nan',
         ['--window', 'nan']) for cmd in WB],
    *[_c(f'{cmd}-report-file', cmd, '--report into a file path',
         f'{cmd} {{d}}/good.mcap {M} --report {{d}}/afile', ['{d}/afile'])
      for cmd in ('compare', 'diagnose')],
    _c('diagnose-report-under-file', 'diagnose', '--report below a file',
       f'diagnose {{d}}/good.mcap {M} --report {{d}}/afile/rep', ['{d}/afile/rep']),
    _c('compare-model-mixedkeys', 'compare', 'number and text as unknown parameter keys',
       'compare {d}/good.mcap --model {d}/mixedkeys.yaml', ['mixedkeys.yaml', 'coulomb']),
    _c('diagnose-min-gain', 'diagnose', '--min-gain 1.5',
       f'diagnose {{d}}/good.mcap {M} --min-gain 1.5', ['--min-gain']),
    _c('diagnose-folds', 'diagnose', '--folds 1', f'diagnose {{d}}/good.mcap {M} --folds 1',
       ['--folds']),
    _c('fit-add-unknown', 'fit', 'unknown effect for --add',
       f'fit {{d}}/good.mcap {M} --add wobble', ['--add', 'wobble']),
    _c('fit-add-present', 'fit', '--add an effect the model has',
       f'fit {{d}}/good.mcap {M} --add coulomb', ['coulomb']),
    _c('fit-output-missing-dir', 'fit', '-o in a non-existent directory',
       f'fit {{d}}/good.mcap {M} --add offset -o {{d}}/nonexistent/dir/new.yaml',
       ['{d}/nonexistent/dir/new.yaml']),
    _c('fit-output-dir', 'fit', '-o is a directory',
       f'fit {{d}}/good.mcap {M} --add offset -o {{d}}/dir.mcap', ['{d}/dir.mcap']),
    # --- import
    _c('import-missing', 'import', 'missing file',
       'import {d}/nope.csv --time t --input u --position x -o {d}/o.mcap', ['nope.csv'],
       subprocess=True),
    _c('import-column', 'import', 'missing column',
       'import {d}/good.csv --time t --input volts --position x -o {d}/o.mcap',
       ['good.csv', 'volts', '--input']),
    _c('import-index', 'import', 'column index out of range',
       'import {d}/good.csv --time 0 --input 1 --position 7 -o {d}/o.mcap',
       ['good.csv', '--position', '7']),
    _c('import-nonnumeric', 'import', 'non-numeric cell',
       'import {d}/nonnumeric.csv --time t --input u --position x -o {d}/o.mcap',
       ['nonnumeric.csv', 'line 43', "'abc'"]),
    _c('import-header-only', 'import', 'header but no rows',
       'import {d}/header_only.csv --time t --input u --position x -o {d}/o.mcap',
       ['header_only.csv', 'no data rows']),
    _c('import-empty', 'import', 'zero-length file',
       'import {d}/empty.csv --time t --input u --position x -o {d}/o.mcap',
       ['empty.csv', 'empty']),
    _c('import-binary', 'import', 'binary file named .csv',
       'import {d}/binary.csv --time t --input u --position x -o {d}/o.mcap',
       ['binary.csv']),
    _c('import-xlsx', 'import', 'unsupported extension .xlsx',
       'import {d}/table.xlsx --time t --input u --position x -o {d}/o.mcap',
       ['table.xlsx', '.xlsx']),
    _c('import-json', 'import', 'unsupported extension .json',
       'import {d}/table.json --time t --input u --position x -o {d}/o.mcap',
       ['table.json', '.json']),
    _c('import-mat', 'import', 'corrupt .mat file',
       'import {d}/bad.mat --time t --input u --position x -o {d}/o.mcap', ['bad.mat']),
    _c('import-negtime', 'import', 'negative time stamps',
       'import {d}/negtime.csv --time t --input u --position x -o {d}/o.mcap',
       ['negtime.csv', '--time-offset']),
    _c('import-out-missing-dir', 'import', '-o in a non-existent directory',
       'import {d}/good.csv --time t --input u --position x -o {d}/nonexistent/dir/x.mcap',
       ['{d}/nonexistent/dir/x.mcap']),
    _c('import-out-under-file', 'import', '-o below a file',
       'import {d}/good.csv --time t --input u --position x -o {d}/afile/x.mcap',
       ['{d}/afile/x.mcap']),
    _c('import-out-dir', 'import', '-o is a directory',
       'import {d}/good.csv --time t --input u --position x -o {d}/dir.mcap',
       ['{d}/dir.mcap']),
    _c('import-scale-nan', 'import', '--position-scale nan',
       'import {d}/good.csv --time t --input u --position x --position-scale nan -o '
       '{d}/o.mcap', ['--position-scale', 'nan']),
    _c('import-no-time', 'import', 'required option missing',
       'import {d}/good.csv --input u --position x -o {d}/o.mcap', ['--time']),
    # --- simulate (module owned by the lead; its bad-input behaviour is checked here)
    _c('simulate-duration-neg', 'simulate', '--duration -1', 'simulate --duration -1',
       ['--duration', '-1'], subprocess=True),
    _c('simulate-duration-nan', 'simulate', '--duration nan', 'simulate --duration nan',
       ['--duration', 'nan']),
    _c('simulate-plant-missing', 'simulate', 'nonexistent --plant file',
       'simulate --duration 0.1 --plant {d}/noplant.yaml', ['noplant.yaml']),
    _c('simulate-plant-bad', 'simulate', 'plant file with negative mass',
       'simulate --duration 0.1 --plant {d}/plant_bad.yaml', ['plant_bad.yaml', 'mass']),
    _c('simulate-plant-field', 'simulate', 'plant file with a misspelt section',
       'simulate --duration 0.1 --plant {d}/plant_field.yaml', ['plant_field.yaml', 'motr']),
    _c('simulate-set-unknown', 'simulate', '--set unknown parameter',
       'simulate --duration 0.1 --set wobble=3', ['wobble']),
    _c('simulate-set-bad', 'simulate', '--set bad value',
       'simulate --duration 0.1 --set kp=abc', ['kp']),
    _c('simulate-set-nan', 'simulate', '--set NaN value',
       'simulate --duration 0.1 --set kp=nan', ['kp']),
    _c('simulate-out-missing-dir', 'simulate', '-o in a non-existent directory',
       'simulate --duration 0.05 -o {d}/nonexistent/dir/x.mcap', ['{d}/nonexistent/dir/x.mcap']),
    _c('simulate-option', 'simulate', 'unknown option', 'simulate --bogus', ['--bogus']),
    # --- sweep
    _c('sweep-duration-neg', 'sweep', '--duration -1', 'sweep --duration -1 --grid kp=1,2',
       ['--duration', '-1'], subprocess=True),
    _c('sweep-no-grid', 'sweep', 'nothing to sweep', 'sweep --duration 0.1', ['--grid']),
    _c('sweep-grid-syntax', 'sweep', 'malformed --grid', 'sweep --duration 0.1 --grid kp',
       ['--grid', 'kp']),
    _c('sweep-grid-unknown', 'sweep', '--grid unknown parameter',
       'sweep --duration 0.1 --grid wobble=1,2', ['wobble']),
    _c('sweep-grid-bad-value', 'sweep', '--grid bad value',
       'sweep --duration 0.1 --grid kp=abc,2', ['kp']),
    _c('sweep-set-unknown', 'sweep', '--set unknown parameter',
       'sweep --duration 0.1 --grid kp=1,2 --set wobble=3', ['wobble']),
    _c('sweep-plant-missing', 'sweep', 'nonexistent --plant file',
       'sweep --duration 0.1 --grid kp=1,2 --plant {d}/noplant.yaml', ['noplant.yaml']),
    _c('sweep-grid-file-missing', 'sweep', 'missing --grid-file',
       'sweep --duration 0.1 --grid-file {d}/nogrid.yaml', ['nogrid.yaml']),
    _c('sweep-grid-file-bad', 'sweep', '--grid-file without a grid mapping',
       'sweep --duration 0.1 --grid-file {d}/grid_bad.yaml', ['grid_bad.yaml', 'grid']),
    _c('sweep-window-nan', 'sweep', '--glitch-window nan',
       'sweep --duration 0.1 --grid kp=1,2 --glitch-window nan', ['--glitch-window']),
    _c('sweep-workers', 'sweep', '--workers 0', 'sweep --duration 0.1 --grid kp=1,2 '
       '--workers 0', ['--workers']),
    _c('sweep-csv-missing-dir', 'sweep', '--csv in a non-existent directory',
       'sweep --duration 0.1 --grid kp=1,2 --csv {d}/nonexistent/dir/t.csv',
       ['{d}/nonexistent/dir/t.csv']),
    # --- run (checked before any node process starts)
    _c('run-duration-neg', 'run', '--duration -1', 'run --duration -1 -o {d}/r.mcap',
       ['--duration', '-1'], subprocess=True),
    _c('run-duration-nan', 'run', '--duration nan', 'run --duration nan -o {d}/r.mcap',
       ['--duration', 'nan']),
    _c('run-rate-neg', 'run', '--rate -5', 'run --rate -5 -o {d}/r.mcap', ['--rate', '-5']),
    _c('run-rate-nan', 'run', '--rate nan', 'run --rate nan -o {d}/r.mcap', ['--rate', 'nan']),
    _c('run-rate-text', 'run', '--rate abc', 'run --rate abc -o {d}/r.mcap', ['--rate', 'abc']),
    _c('run-timeout', 'run', '--timeout 0', 'run --timeout 0 -o {d}/r.mcap', ['--timeout']),
    _c('run-plant-missing', 'run', 'nonexistent --plant file',
       'run --plant {d}/noplant.yaml -o {d}/r.mcap', ['noplant.yaml']),
    _c('run-out-missing-dir', 'run', '-o in a non-existent directory',
       'run -o {d}/nonexistent/dir/x.mcap', ['{d}/nonexistent/dir']),
    _c('run-out-dir', 'run', '-o is a directory', 'run -o {d}/dir.mcap', ['{d}/dir.mcap']),
    _c('run-out-under-file', 'run', '-o below a file', 'run -o {d}/afile/x.mcap',
       ['{d}/afile/x.mcap']),
    _c('run-domain', 'run', '--domain-id 999', 'run --domain-id 999 -o {d}/r.mcap',
       ['--domain-id']),
    _c('run-no-output', 'run', 'required -o missing', 'run', ['-o']),
    _c('run-travel-order', 'run', '--travel MIN MAX with MIN > MAX',
       'run --travel 0.05 -0.05 -o {d}/r.mcap', ['--travel', 'MIN < MAX', '0.05 -0.05']),
    _c('run-travel-nan', 'run', '--travel nan 1', 'run --travel nan 1 -o {d}/r.mcap',
       ['--travel', 'nan']),
    _c('run-vmax-zero', 'run', '--vmax 0', 'run --vmax 0 -o {d}/r.mcap', ['--vmax']),
    _c('run-max-error-neg', 'run', '--max-error -1', 'run --max-error -1 -o {d}/r.mcap',
       ['--max-error']),
    _c('run-travel-reference', 'run', 'trajectory beyond --travel (p2p to 0.05 m)',
       'run --travel -0.01 0.03 -o {d}/r.mcap',
       ['trajectory refused', 'travel limit', 'reference position 0.03', '[-0.01, 0.03] m']),
    _c('run-vmax-reference', 'run', 'trajectory faster than --vmax',
       'run --vmax 0.01 -o {d}/r.mcap', ['trajectory refused', 'speed limit', '±0.01 m/s']),
    _c('run-monitor-missing', 'run', 'nonexistent --monitor model',
       'run --monitor {d}/nomodel.yaml -o {d}/r.mcap', ['nomodel.yaml']),
    # --- replay (checked before rclpy starts)
    _c('replay-rate-neg', 'replay', '--rate -1', 'replay {d}/good.mcap --rate -1',
       ['--rate', '-1']),
    _c('replay-rate-nan', 'replay', '--rate nan', 'replay {d}/good.mcap --rate nan',
       ['--rate', 'nan']),
    _c('replay-rate-text', 'replay', '--rate abc', 'replay {d}/good.mcap --rate abc',
       ['--rate', 'abc']),
    _c('replay-delay-nan', 'replay', '--startup-delay nan',
       'replay {d}/good.mcap --startup-delay nan', ['--startup-delay']),
    _c('replay-option', 'replay', 'unknown option', 'replay {d}/good.mcap --bogus',
       ['--bogus']),
    # --- demo (checked before any node process starts)
    _c('demo-duration-neg', 'demo', '--pmlm-duration -1',
       'demo --out {d}/demo --pmlm-duration -1', ['--pmlm-duration'], subprocess=True),
    _c('demo-duration-nan', 'demo', '--ballscrew-duration nan',
       'demo --out {d}/demo --ballscrew-duration nan', ['--ballscrew-duration']),
    _c('demo-out-file', 'demo', '--out is a file', 'demo --out {d}/afile', ['{d}/afile']),
    _c('demo-only-unknown', 'demo', '--only unknown run', 'demo --out {d}/demo --only nope',
       ['--only', 'nope']),
    # --- export-table, study (issue 12; their full bad-input tests: test_cli_compensation.py)
    _c('export-table-points', 'export_table', '--points 1',
       'export-table {d}/model.yaml --points 1 -o {d}/t.csv', ['--points'], subprocess=True),
    _c('study-duration-neg', 'study', '--duration -1', 'study compensate --duration -1',
       ['--duration', '-1'], subprocess=True),
    # --- excite and table trajectories (issue 24; their full bad-input tests:
    # test_cli_excite.py, test_control_table_trajectory.py)
    _c('excite-vmax-zero', 'excite', '--vmax 0',
       'excite --model {d}/model.yaml --travel -0.05 0.05 --vmax 0 -o {d}/e.csv', ['--vmax'],
       subprocess=True),
    _c('excite-travel-period', 'excite', 'travel shorter than two --period',
       'excite --model {d}/model.yaml --travel 0 0.01 --vmax 0.1 --period 0.02 -o {d}/e.csv',
       ['travel too short', '--period 0.02']),
    _c('excite-model-missing', 'excite', 'nonexistent --model',
       'excite --model {d}/nomodel.yaml --travel 0 0.1 --vmax 0.1 -o {d}/e.csv',
       ['nomodel.yaml', 'no such model file']),
    _c('simulate-table-missing', 'simulate', 'table trajectory file missing',
       'simulate --duration 0.1 --trajectory table --set traj.file={d}/notable.csv',
       ['notable.csv', 'no such file']),
    # --- autotune (issue 24; checked before any node process starts or anything moves)
    _c('autotune-no-axis', 'autotune', 'neither --plant nor --external-plant',
       'autotune --model {d}/model.yaml -o {d}/at', ['--plant', '--external-plant'],
       subprocess=True),
    _c('autotune-both-axes', 'autotune', '--plant and --external-plant',
       'autotune --plant pmlm --external-plant --model {d}/model.yaml -o {d}/at',
       ['--external-plant', 'not allowed with argument --plant']),
    _c('autotune-model-missing', 'autotune', 'nonexistent --model',
       'autotune --plant pmlm --model {d}/nomodel.yaml -o {d}/at',
       ['nomodel.yaml', 'no such model file']),
    _c('autotune-external-nominal', 'autotune', '--external-plant without --nominal',
       'autotune --external-plant --model {d}/model.yaml -o {d}/at',
       ['--external-plant needs --nominal']),
    _c('autotune-external-lockstep', 'autotune', '--external-plant --mode lockstep',
       'autotune --external-plant --nominal pmlm --mode lockstep --model {d}/model.yaml '
       '-o {d}/at', ['--external-plant runs in realtime', '--mode realtime']),
    _c('autotune-out-not-empty', 'autotune', '-o an existing non-empty directory',
       'autotune --plant pmlm --model {d}/model.yaml -o {d}',
       ['-o {d}', 'exists and is not empty']),
    _c('autotune-task-beyond-travel', 'autotune', 'the task beyond --travel (p2p to 0.05 m)',
       'autotune --plant pmlm --model {d}/model.yaml --travel -0.01 0.03 -o {d}/at',
       ['the task p2p', 'travel limit', '[-0.01, 0.03] m']),
    _c('autotune-vmax-zero', 'autotune', '--vmax 0',
       'autotune --plant pmlm --model {d}/model.yaml --vmax 0 -o {d}/at', ['--vmax']),
    _c('autotune-task-missing', 'autotune', 'nonexistent --task table',
       'autotune --plant pmlm --model {d}/model.yaml --task {d}/notask.csv -o {d}/at',
       ['--task', 'notask.csv', 'no such file']),
    # --- robots' bags (issue 25; full tests: test/logs/test_logs_bags*.py)
    *[_c(f'{cmd}-bag-joint-unknown', cmd, 'a joint the bag does not have',
         f'{cmd} {{d}}/robot {M} --joint wrist --input effort',
         ["joint 'wrist' not in /joint_states (has: shoulder, elbow)", '--joint NAME'])
      for cmd in WB],
    *[_c(f'{cmd}-bag-joint-unnamed', cmd, 'a multi-joint bag without --joint',
         f'{cmd} {{d}}/robot {M} --input effort',
         ["joint 'axis' not in /joint_states (has: shoulder, elbow)", '--joint NAME'])
      for cmd in WB],
    _c('fit-bag-topic-missing', 'fit', 'a JointState topic the bag does not have',
       f'fit {{d}}/robot {M} --topic /arm/joint_states --joint elbow --input effort',
       ['no /arm/joint_states messages', '/joint_states [sensor_msgs/msg/JointState]',
        '--topic T']),
    _c('fit-bag-no-effort', 'fit', '--input effort, the effort field empty',
       f'fit {{d}}/robot_noeffort {M} --joint elbow --input effort',
       ["joint 'elbow' of /joint_states has an empty effort field", '--input TOPIC']),
    _c('fit-bag-no-input', 'fit', 'a bag without the drive input topic',
       f'fit {{d}}/robot {M} --joint elbow', ['no /axis/voltage messages',
                                              '--input effort | TOPIC']),
    _c('analyze-bag-noref', 'analyze', 'a bag without a reference',
       'analyze {d}/robot --joint elbow', ['no /axis/reference messages',
                                           '--reference TOPIC[:JOINT]']),
    _c('fit-joint-all-no-out', 'fit', '--joint all without -o DIR/',
       f'fit {{d}}/robot {M} --joint all --input effort', ['--joint all', '-o DIR/']),
    _c('fit-abbreviated', 'fit', 'an abbreviated option (--inp for --input)',
       f'fit {{d}}/robot {M} --joint elbow --inp effort',
       ['unrecognized arguments: --inp effort']),
    _c('import-bag-table-option', 'import', 'a table column option given with a bag',
       'import {d}/robot --joint elbow --input effort --time 0 -o {d}/r.mcap',
       ['--time', 'column options of tables']),
    # --- the dispatcher
    _c('main-unknown-command', 'main', 'unknown command', 'frobnicate',
       ['frobnicate'], subprocess=True),
]


def _fix_dir_model(case: Case) -> Case:
    """Point --model of the 'model path is a directory' cases at ``dir.mcap``."""
    if case.id.endswith('-model-dir'):
        argv = tuple('{d}/dir.mcap' if a == '{d}/' else a for a in case.argv)
        return dataclasses.replace(case, argv=argv, names=('{d}/dir.mcap',))
    return case


CASES = [_fix_dir_model(c) for c in CASES]


@dataclasses.dataclass(frozen=True)
class Outcome:
    """What the user saw."""

    status: int
    stdout: str
    stderr: str


def run_in_process(argv: list[str]) -> Outcome:
    """Run ``motor-comp argv`` in this process (argparse exits become a status)."""
    from motor_comp.cli.main import main
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = main(argv)
        except SystemExit as exc:
            status = exc.code if isinstance(exc.code, int) else 1
    return Outcome(status, out.getvalue(), err.getvalue())


def run_subprocess(argv: list[str], env: dict[str, str] | None = None) -> Outcome:
    """Run ``python -m motor_comp.cli.main argv`` as a process."""
    import subprocess
    e = dict(os.environ if env is None else env)
    e.pop('MOTOR_COMP_DEBUG', None)
    # replay starts rclpy: DDS traffic stays on this machine, in a private domain
    from motor_comp.cli.run import private_domain_id
    e['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    e['ROS_DOMAIN_ID'] = str(private_domain_id())
    p = subprocess.run([sys.executable, '-m', 'motor_comp.cli.main', *argv],
                       capture_output=True, text=True, timeout=180, env=e,
                       stdin=subprocess.DEVNULL)
    return Outcome(p.returncode, p.stdout, p.stderr)


def markdown_table(d: Path, runner: Callable[[list[str]], Outcome] = run_in_process) -> str:
    """Return the table of ``docs/reliability.md``: command, bad input, message, exit status.

    Commands that answer a bad input with the same message (the MCAP reader is shared)
    are merged into one row.
    """
    rows: dict[tuple[str, str, int], list[str]] = {}
    for case in CASES:
        o = (runner if case.in_process else run_subprocess)(case.args(d))
        msg = [ln for ln in o.stderr.strip().splitlines() if ln.startswith('motor-comp:')]
        text = msg[0] if msg else '(nothing)'
        if len(msg) > 1:
            text += f' (+{len(msg) - 1} similar line{"s" if len(msg) > 2 else ""})'
        text = text.replace(str(d) + '/', '').replace(str(d), '.')
        if len(text) > 160:
            text = text[:157] + '…'
        cell = f'`{text}`'
        if case.known_defect:
            cell += f' — **known defect**: {case.known_defect}'
        key = (case.problem, cell.replace('|', '\\|'), o.status)
        rows.setdefault(key, []).append(case.command)
    lines = ['| command | bad input | what the user sees (stderr, abbreviated) | exit |',
             '|---|---|---|---|']
    for (problem, text, status), commands in rows.items():
        lines.append(f'| {", ".join(commands)} | {problem} | {text} | {status} |')
    return '\n'.join(lines)


if __name__ == '__main__':
    import tempfile
    with tempfile.TemporaryDirectory(prefix='mc_bad_') as tmp:
        print(markdown_table(make_inputs(Path(tmp))))
