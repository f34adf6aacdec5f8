"""The workbench's layout shows its design (issue 22 items 2, 3 and 7).

* every module of ``motor_comp/workbench/`` has under 600 lines, one concern each;
* the modules that select and estimate never name an effect: what an effect means for
  identification is its own term's (``motor_comp/physics/effects``);
* no fitter per effect is left (the old ``candidates`` module).
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

from motor_comp.physics.effects import TERMS, VOCABULARY

WORKBENCH = Path(__file__).resolve().parents[2] / 'motor_comp' / 'workbench'
#: the modules whose decisions must follow from the terms' declarations alone
GENERIC = ('selection.py', 'elimination.py', 'lookahead.py', 'varpro.py', 'library.py', 'lsq.py',
           'dataset.py', 'parts.py', 'repeats.py', 'reweight.py', 'uncertainty.py', 'result.py',
           'floor.py', 'bands.py', 'scan.py', 'heldout.py')


@pytest.mark.parametrize('path', sorted(WORKBENCH.glob('*.py')), ids=lambda p: p.name)
def test_modules_are_under_600_lines(path):
    n = len(path.read_text(encoding='utf-8').splitlines())
    assert n < 600, f'{path.name}: {n} lines'


def _code_names(path: Path) -> set[str]:
    """String constants and identifiers of the code, docstrings and comments left out."""
    tree = ast.parse(path.read_text(encoding='utf-8'))
    docs = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef,
                             ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                docs.add(id(first.value))
    out = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and id(node) not in docs:
            out.update(node.value.replace('.', ' ').replace('_', ' ').split()
                       + [node.value])
        elif isinstance(node, ast.Name):
            out.add(node.id)
        elif isinstance(node, ast.Attribute):
            out.add(node.attr)
    return out


@pytest.mark.parametrize('name', GENERIC)
def test_selection_and_estimation_name_no_effect(name):
    found = _code_names(WORKBENCH / name) & set(VOCABULARY)
    assert not found, f'{name} names {sorted(found)}'


def test_every_effect_owns_its_term_and_no_fitter_per_effect_is_left():
    assert not (WORKBENCH / 'candidates.py').exists()
    assert not (WORKBENCH / 'ident.py').exists()
    assert set(TERMS) == set(VOCABULARY)
    for path in WORKBENCH.glob('*.py'):
        tree = ast.parse(path.read_text(encoding='utf-8'))
        fitters = [n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)
                   and n.name.startswith('fit_') and n.name[4:] in VOCABULARY]
        assert not fitters, (path.name, fitters)


def test_the_commands_do_not_import_scipy_signal():
    # scipy.signal (and scipy.stats, which it imports) cost every command ~0.45 s of CPU,
    # more than a whole diagnosis of a 20 s run: the workbench computes its two uses
    # (Savitzky-Golay, Welch) itself, and this keeps a stray import from coming back
    import subprocess
    import sys
    code = ('import sys, motor_comp.workbench, motor_comp.cli.main; '
            'bad = sorted(m for m in ("scipy.signal", "scipy.stats") if m in sys.modules); '
            'print(",".join(bad))')
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                         check=True).stdout.strip()
    assert out == '', f'imported at start-up: {out}'
