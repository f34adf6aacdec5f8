"""The recorder asks a node for its parameters again until it answers.

A service request (or its response) sent before the other side's endpoint is discovered
is lost: DDS does not resend it.  Asked once, a node whose answer was lost was waited for
until the run timed out (or, with a 10 s cap, recorded without its parameters) — seen
under two CPU hogs.  Driven here through the recorder's own methods with stand-in
clients and clock, so the lost request is certain and nothing waits.
"""
from __future__ import annotations

import types

import pytest

rec = pytest.importorskip('motor_comp.nodes.recorder_node')


class _Client:
    """A parameter client whose services are up; it keeps every request's callback."""

    def __init__(self) -> None:
        self.lists: list = []
        self.gets: list = []

    def services_are_ready(self) -> bool:
        return True

    def list_parameters(self, callback):
        self.lists.append(callback)

    def get_parameters(self, names, callback):
        self.gets.append((names, callback))


def _future(result):
    return types.SimpleNamespace(result=lambda: result)


def test_a_lost_parameter_request_is_asked_again(monkeypatch):
    now = [100.0]
    monkeypatch.setattr(rec.time, 'monotonic', lambda: now[0])
    timer = types.SimpleNamespace(cancelled=False)
    timer.cancel = lambda: setattr(timer, 'cancelled', True)
    stored: list = []
    node = types.SimpleNamespace(
        _param_clients={'plant_node': _Client(), 'controller_node': _Client()},
        _raw_params={}, _asked={}, _param_timer=timer, _closed=False)
    node._on_list = lambda n, fut: rec.RecorderNode._on_list(node, n, fut)

    def store(n, names, fut):
        stored.append(n)
        node._raw_params[n] = dict(zip(names, fut.result().values))
    node._on_values = store
    plant, ctl = node._param_clients['plant_node'], node._param_clients['controller_node']
    tick = lambda: rec.RecorderNode._query_parameters(node)  # noqa: E731

    tick()
    assert len(plant.lists) == len(ctl.lists) == 1
    # the controller answers; the plant's request was lost
    ctl.lists[0](_future(types.SimpleNamespace(result=types.SimpleNamespace(names=['mode']))))
    names, cb = ctl.gets[0]
    cb(_future(types.SimpleNamespace(values=['npid'])))
    assert stored == ['controller_node']
    now[0] += 0.5 * rec.PARAM_RETRY_S
    tick()
    assert len(plant.lists) == 1          # not yet: its answer may still come
    now[0] += rec.PARAM_RETRY_S
    tick()
    assert len(plant.lists) == 2 and len(ctl.lists) == 1 and not timer.cancelled
    # the retry is answered ...
    plant.lists[1](_future(types.SimpleNamespace(result=types.SimpleNamespace(names=['plant']))))
    plant.gets[0][1](_future(types.SimpleNamespace(values=['ballscrew'])))
    assert stored == ['controller_node', 'plant_node']
    # ... and the lost one's late answer is a twin: nothing asked or stored twice
    plant.lists[0](_future(types.SimpleNamespace(result=types.SimpleNamespace(names=['plant']))))
    assert len(plant.gets) == 1
    tick()
    assert timer.cancelled and len(plant.lists) == 2
