"""Bad model files through the command line: one line naming the problem, exit status 2.

Issue 11 must-show (bad input): gravity on a linear axis, an unknown axis kind, and an old
GMS slip rate that cannot be converted, as a user meets them through ``motor-comp``.
"""
from __future__ import annotations

import pytest

from motor_comp.cli.main import main

BAD = {
    'gravity_linear': ('axis: linear\nmass: 1.0\neffects:\n  gravity: {mgl: 1.0, q0: 0.0}\n',
                       ("effect 'gravity'", 'linear axis', 'offset')),
    'gravity_default_axis': ('mass: 1.0\neffects:\n  gravity: {mgl: 2.0}\n',
                             ("effect 'gravity'", 'linear axis')),
    'unknown_axis': ('axis: cylindrical\nmass: 1.0\n', ('axis must be one of', 'cylindrical')),
    'old_gms_without_coulomb': (
        'mass: 1.0\neffects:\n  presliding: {alpha: [1.0], k: [1.0e6], c: 1000.0}\n',
        ("'c' [1/s]", "'C' [N/s]", 'C = c·fc')),
}


@pytest.mark.parametrize('command', ['compare', 'diagnose', 'fit'])
@pytest.mark.parametrize('case', sorted(BAD))
def test_bad_model_file_is_one_line_and_exit_2(tmp_path, capsys, command, case):
    text, needles = BAD[case]
    path = tmp_path / f'{case}.yaml'
    path.write_text(text)
    rc = main([command, str(tmp_path / 'run.mcap'), '--model', str(path)])
    out, err = capsys.readouterr()
    assert rc == 2
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f'motor-comp: error: {path}: '), err
    assert 'Traceback' not in err and out == ''
    for needle in needles:
        assert needle in lines[0]
