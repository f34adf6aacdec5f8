"""Fuzz the model-file loader with mutated YAML: a model or ModelFileError, nothing else."""
from __future__ import annotations

import os
import tempfile

import yaml
from hypothesis import HealthCheck, given, settings, strategies as st

from motor_comp.errors import ModelFileError
from motor_comp.physics.axis import AxisModel

VALID = """\
input: voltage
input_gain: 15.1
back_emf: 123.0
damping: 0.0
mass: 5.4
effects:
  coulomb: {fc: 10.0}
  viscous: {fv: 10.0}
  stribeck: {fs: 20.0, vs: 0.1, delta: 2.0}
  presliding: {alpha: [0.45, 0.3, 0.15, 0.1], k: [8.0e6, 3.0e6, 1.0e6, 3.0e5], c: 1000.0}
  ripple: {period: 0.02, harmonics: [[8.5, 0.0], [1.0, -0.5]]}
  offset: {f0: 1.0}
  spring: {k: 100.0, x0: 0.0}
  asymmetry: {dfc: 1.0, dfv: 2.0}
  delay: {tau: 0.001}
  backlash: {width: 1.0e-5}
"""

SCALARS = st.one_of(
    st.none(), st.booleans(), st.integers(-10**6, 10**6),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=8),
    st.lists(st.floats(allow_nan=True), max_size=3),
    st.dictionaries(st.text(max_size=5), st.integers(), max_size=2))


def _load_text(text: str):
    fd, path = tempfile.mkstemp(suffix='.yaml')
    try:
        with os.fdopen(fd, 'w', encoding='utf-8', errors='surrogatepass') as fh:
            fh.write(text)
        return AxisModel.load(path)
    finally:
        os.unlink(path)


def _check(text: str) -> None:
    try:
        model = _load_text(text)
    except ModelFileError as exc:
        msg = str(exc)
        assert '\n' not in msg and msg, msg
        return
    assert isinstance(model, AxisModel)
    assert model.mass > 0


def test_valid_file_loads():
    m = _load_text(VALID)
    assert len(m.effects) == 10


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(start=st.integers(0, len(VALID)), length=st.integers(0, 40),
       insert=st.text(alphabet=':{}[],-\n #"\'abcxyz019.eE', max_size=12))
def test_text_mutations(start, length, insert):
    _check(VALID[:start] + insert + VALID[start + length:])


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data())
def test_value_mutations(data):
    doc = yaml.safe_load(VALID)
    paths = [('mass',), ('input_gain',), ('back_emf',), ('damping',), ('input',),
             ('effects',)]
    for name, params in doc['effects'].items():
        paths.append(('effects', name))
        paths += [('effects', name, k) for k in params]
    path = data.draw(st.sampled_from(paths))
    node = doc
    for key in path[:-1]:
        node = node[key]
    if data.draw(st.booleans()):
        node[path[-1]] = data.draw(SCALARS)
    else:
        del node[path[-1]]
    _check(yaml.safe_dump(doc))


@settings(max_examples=60, deadline=None)
@given(top=st.one_of(SCALARS, st.lists(SCALARS, max_size=3)))
def test_non_mapping_documents(top):
    _check(yaml.safe_dump(top))
