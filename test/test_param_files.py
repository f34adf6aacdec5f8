"""Files named by untrusted parameters (issue 24): where, what and how they are read.

The rules of :mod:`motor_comp.param_files` — a path outside the allowed directories is
refused without being opened, only a regular file under a size bound is read (a FIFO
never blocks, a device is never opened), and a rejection never quotes the file — are
checked here on the functions; ``test/nodes/test_nodes_param_files.py`` checks them
through the nodes' parameter services from another process.
"""
from __future__ import annotations

import os
import re
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

from motor_comp import param_files as pf
from motor_comp.errors import ParameterError
from motor_comp.physics.config import load_plant, plant_names

pytestmark = pytest.mark.timeout(120)   # a blocking open would hang: fail instead

SHADOW = ('_apt:*:20228:0:99999:7:::\n'
          'root:$6$Zq9Jx$SECRETHASHVALUE:20228:0:99999:7:::\n')


@pytest.fixture
def allowed(tmp_path: Path) -> Path:
    d = tmp_path / 'allowed'
    d.mkdir()
    return d


@pytest.fixture
def opened(monkeypatch) -> list[str]:
    """Every path ``os.open``/``os.stat`` is called on (wrapped, still working)."""
    calls: list[str] = []
    real_open, real_stat = os.open, os.stat

    def spy_open(path, *a, **k):
        calls.append(('open', str(path)))
        return real_open(path, *a, **k)

    def spy_stat(path, *a, **k):
        calls.append(('stat', str(path)))
        return real_stat(path, *a, **k)

    monkeypatch.setattr(pf.os, 'open', spy_open)
    monkeypatch.setattr(pf.os, 'stat', spy_stat)
    return calls


# ---- where -------------------------------------------------------------------------------
def test_outside_is_refused_without_being_opened(tmp_path, allowed, opened):
    secret = tmp_path / 'secret.yaml'
    secret.write_text(SHADOW)
    for path in (str(secret), str(allowed / '..' / 'secret.yaml'), '../secret.yaml'):
        with pytest.raises(ParameterError) as err:
            pf.read_text('model', path, [allowed])
        assert 'outside the allowed directories' in str(err.value)
        assert 'SECRET' not in str(err.value) and '_apt' not in str(err.value)
    assert opened == []          # neither stat'ed nor opened: only resolved


def test_a_link_inside_to_a_file_outside_is_outside(tmp_path, allowed, opened):
    secret = tmp_path / 'secret.yaml'
    secret.write_text(SHADOW)
    (allowed / 'm.yaml').symlink_to(secret)
    with pytest.raises(ParameterError, match='outside the allowed directories'):
        pf.read_text('model', 'm.yaml', [allowed])
    assert opened == []


def test_relative_paths_are_found_in_the_first_directory_that_holds_them(tmp_path):
    a, b = tmp_path / 'a', tmp_path / 'b'
    a.mkdir()
    b.mkdir()
    (b / 'm.yaml').write_text('mass: 1.0\n')
    real, text = pf.read_text('model', 'm.yaml', [a, b])
    assert real == (b / 'm.yaml').resolve() and text == 'mass: 1.0\n'
    with pytest.raises(ParameterError, match=r'a/x\.yaml: no such file'):
        pf.read_text('model', 'x.yaml', [a, b])   # in neither: named in the first


@pytest.mark.parametrize('path, needle', [('', 'empty path'), ('a\x00b', 'NUL')])
def test_empty_and_nul_paths(allowed, path, needle):
    with pytest.raises(ParameterError, match=needle):
        pf.read_text('model', path, [allowed])


def test_model_dir_parsing(tmp_path, monkeypatch):
    base = tmp_path.resolve()
    monkeypatch.chdir(base)
    assert pf.parse_dirs('') == (base, pf.package_config_dir())
    assert pf.parse_dirs(f'{base}/x{os.pathsep}rel') == (base / 'x', base / 'rel')


# ---- what --------------------------------------------------------------------------------
def test_a_fifo_is_refused_and_never_blocks(allowed, opened):
    fifo = allowed / 'model.yaml'
    os.mkfifo(fifo)
    with pytest.raises(ParameterError, match='is a FIFO; only regular files are read'):
        pf.read_text('model', str(fifo), [allowed])
    assert ('open', str(fifo)) not in opened       # refused on stat, before open


def test_a_fifo_swapped_in_after_the_check_does_not_block(allowed, monkeypatch):
    """Race: the path checks as a regular file, then is a FIFO when opened."""
    fifo = allowed / 'model.yaml'
    os.mkfifo(fifo)
    regular = os.stat(__file__)
    monkeypatch.setattr(pf.os, 'stat', lambda p, *a, **k: regular)
    with pytest.raises(ParameterError, match='is a FIFO'):
        pf.read_text('model', str(fifo), [allowed])   # O_NONBLOCK, then fstat


def test_a_device_is_never_opened(opened):
    with pytest.raises(ParameterError, match='is a device; only regular files are read'):
        pf.read_text('model', '/dev/null', [Path('/dev')])
    assert ('open', '/dev/null') not in opened


def test_directory_size_bound_and_encoding(allowed):
    with pytest.raises(ParameterError, match='is a directory'):
        pf.read_text('model', str(allowed), [allowed])
    big = allowed / 'big.yaml'
    big.write_text('x' * 2000)
    with pytest.raises(ParameterError, match='2000 bytes, more than the 1000-byte bound'):
        pf.read_text('model', str(big), [allowed], max_bytes=1000)
    latin = allowed / 'latin.yaml'
    latin.write_bytes(b'mass: 5\n# \xe9t\xe9\n')
    with pytest.raises(ParameterError, match='not UTF-8 text'):
        pf.read_text('model', str(latin), [allowed])
    private = allowed / 'private.yaml'
    private.write_text('mass: 5\n')
    private.chmod(0)
    if os.access(private, os.R_OK):   # root reads anything
        pytest.skip('running as root: permissions are not enforced')
    with pytest.raises(ParameterError, match='permission denied'):
        pf.read_text('model', str(private), [allowed])


# ---- how: reasons ------------------------------------------------------------------------
def test_the_reported_shadow_case_names_no_line(allowed):
    f = allowed / 'shadow'
    f.write_text(SHADOW)
    with pytest.raises(ParameterError) as err:
        pf.load_model('model', str(f), [allowed])
    reason = str(err.value)
    assert reason == f'model: {f.resolve()}: not a valid model file (unknown field)'
    for line in SHADOW.splitlines():
        assert line not in reason


@pytest.mark.parametrize('text, detail', [
    ('mass: 5.4\neffects:\n  coulomb: {fc: -3}\n', 'coulomb.fc; must be >= 0'),
    ('mass: [1,\n  b: c: d\n', 'syntax error on line 2'),
    ('mass: SECRETVALUE\n', 'mass; must be a number'),
    ('mass: 1\neffects: {SECRETEFFECT: 1}\n', 'unknown effect'),
    ('mass: 1\neffects: {coulomb: {SECRETKEY: 3}}\n', 'coulomb; unknown parameter'),
])
def test_model_reasons_keep_field_names_and_drop_content(allowed, text, detail):
    f = allowed / 'bad.yaml'
    f.write_text(text)
    with pytest.raises(ParameterError) as err:
        pf.load_model('compensation_model', str(f), [allowed])
    assert str(err.value) == (f'compensation_model: {f.resolve()}: not a valid model '
                              f'file ({detail})')


def test_table_and_plant_reasons(allowed):
    t = allowed / 't.csv'
    t.write_text('position_m,force_N,command_V\n0,1,SECRET\n')
    with pytest.raises(ParameterError, match=r'not a valid compensation table '
                                             r'\(non-numeric value\)$'):
        pf.load_table('compensation_table', str(t), [allowed])
    t.write_text('position_m,force_N,command_V\n0,1,2\n1,SECRET\n')
    with pytest.raises(ParameterError, match=r'\(does not have 3 columns; row 3\)$'):
        pf.load_table('compensation_table', str(t), [allowed])
    p = allowed / 'plant.yaml'
    p.write_text('plant: SECRET\n')
    with pytest.raises(ParameterError, match=r'not a valid plant file \(plant; must be '
                                             r'one of\)$'):
        pf.load_plant('plant', str(p), [allowed])


def test_valid_files_parse_from_the_text_read(allowed):
    cfg = load_plant('pmlm')
    m = allowed / 'm.yaml'
    cfg.model.save(m)
    real, model = pf.load_model('model', 'm.yaml', [allowed])
    assert real == m.resolve() and model.to_dict() == cfg.model.to_dict()
    plant = pf.load_plant('plant', 'pmlm', [])      # packaged: no directory needed
    assert plant.model.to_dict() == cfg.model.to_dict()
    from motor_comp.control.compensation import position_table, write_table
    t = allowed / 't.csv'
    write_table(t, position_table(cfg.model, points=64))
    real, table = pf.load_table('compensation_table', str(t), [allowed])
    assert table.position.shape == (64,) and table.period == pytest.approx(0.02)


# ---- property: no rejection quotes the file ---------------------------------------------
MARK = 'Ж'    # in no path, parameter name or fixed phrase of a reason


def _vocabulary() -> frozenset[str]:
    return pf.model_vocabulary() | frozenset(plant_names()) | pf.TABLE_VOCABULARY


VOCAB = sorted(_vocabulary())
_secret = st.text(alphabet='abcdefghijklmnopqrstuvwxyz0123456789_-+.:,[]{}\'" ',
                  min_size=1, max_size=12)
_marked = st.builds(lambda s: f'{MARK}{s}{MARK}', _secret)
_scalar = st.one_of(_marked, st.floats(allow_nan=True, allow_infinity=True),
                    st.integers(-10, 10))
_line = st.one_of(
    st.builds(lambda k, v: f'{k}: {v}', st.sampled_from(VOCAB), _marked),
    st.builds(lambda k, s: f'  {k}: {{fc: {s}}}', st.sampled_from(VOCAB), _marked),
    st.builds(lambda a, b: f'{a},{b},{MARK}x', _marked, _marked),
    st.builds(lambda t: f'{t}{MARK}', st.text(max_size=30)),
)
_yaml_doc = st.builds(lambda d: yaml.safe_dump(d), st.dictionaries(
    st.sampled_from(VOCAB), st.one_of(_scalar, st.dictionaries(
        st.sampled_from(VOCAB), st.one_of(_scalar, st.lists(_scalar, max_size=3)),
        max_size=3)), max_size=4))


def _effect_params(name: str):
    import dataclasses

    from motor_comp.physics.effects import EFFECTS
    fields = [f.name for f in dataclasses.fields(EFFECTS[name])]
    return st.dictionaries(st.sampled_from(fields), _scalar, max_size=3)


def _effects():
    from motor_comp.physics.effects import EFFECTS
    return st.sampled_from(sorted(EFFECTS)).flatmap(
        lambda n: st.builds(lambda p: {n: p}, _effect_params(n)))


# the model layout with content in the values: deeper than "unknown field"
_model_doc = st.builds(lambda m, e: yaml.safe_dump({'mass': m, 'effects': e}), _scalar,
                       _effects())
_files = st.one_of(st.builds(lambda ls: '\n'.join(ls) + '\n', st.lists(_line, min_size=1,
                                                                       max_size=6)),
                   _yaml_doc, _model_doc)

_PART = re.compile('|'.join([r'syntax error on line \d+', r'row \d+',
                             *(re.escape(p) for p in pf.PROBLEMS),
                             r'[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*']))


def _content_free(reason: str, param: str, real: Path, what: str) -> bool:
    """The reason is ``<param>: <path>: not a valid <what>`` + schema names/phrases only."""
    head = f'{param}: {real}: not a valid {what}'
    if reason == head:
        return True
    if not (reason.startswith(head + ' (') and reason.endswith(')')):
        return False
    for part in reason[len(head) + 2:-1].split('; '):
        if not _PART.fullmatch(part):
            return False
        if part[0].isalpha() and ' ' not in part and part not in pf.PROBLEMS and \
                not all(w in VOCAB for w in part.split('.')):
            return False
    return True


@settings(max_examples=300, deadline=None,
          suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(text=_files, loader=st.sampled_from(['model', 'table', 'plant']))
def test_no_rejection_contains_any_line_of_the_file(tmp_path_factory, text, loader):
    """Whatever the file holds, a rejection holds no line of it and no marked content."""
    d = tmp_path_factory.getbasetemp() / 'property'
    d.mkdir(exist_ok=True)
    f = d / ('f.csv' if loader == 'table' else 'f.yaml')
    f.write_text(text, encoding='utf-8')
    load, param, what = {'model': (pf.load_model, 'model', 'model file'),
                         'table': (pf.load_table, 'compensation_table',
                                   'compensation table'),
                         'plant': (pf.load_plant, 'plant', 'plant file')}[loader]
    try:
        load(param, str(f), [d])
    except ParameterError as exc:
        reason = str(exc)
    else:
        return   # a valid file: nothing to reject
    assert MARK not in reason, reason
    for line in text.splitlines():
        if MARK in line:
            assert line not in reason and line.strip() not in reason, (line, reason)
    assert _content_free(reason, param, f.resolve(), what), reason


def test_the_property_would_catch_a_quoting_parser(allowed):
    """The check above is not vacuous: a parser that quotes its input is caught."""
    f = allowed / 'f.yaml'
    f.write_text(f'mass: {MARK}x{MARK}\n')

    def quoting(text: str):
        raise ValueError(f'bad value in {text.strip()}')
    with pytest.raises(ParameterError) as err:
        pf.load('model', str(f), [allowed], quoting, what='model file',
                vocabulary=pf.model_vocabulary())
    assert MARK not in str(err.value)      # parse_untrusted dropped it ...
    leaky = f'model: {f.resolve()}: not a valid model file (mass: {MARK}x{MARK})'
    assert not _content_free(leaky, 'model', f.resolve(), 'model file')   # ... and if not
