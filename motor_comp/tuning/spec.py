"""What the node processes of ``motor-comp autotune`` are given, and what a run returns.

:class:`AxisSpec` holds the parameters of the session's nodes (no rclpy: the pure half);
the processes themselves and this process's ROS client are
:class:`motor_comp.cli.axis_session.AxisSession` (the ``motor-comp`` layer, beside
``motor-comp run``'s node machinery), which :mod:`motor_comp.tuning.autotune` is given
as a factory (:class:`Axis`), so the stages never import the CLI or rclpy.
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any, Protocol

from motor_comp.control.limits import Limits
from motor_comp.errors import MotorCompError

#: the controller's ``stale_timeout`` in lockstep [s] (see :meth:`AxisSpec.controller_params`)
LOCKSTEP_STALE_TIMEOUT = 30.0


class SessionError(MotorCompError):
    """The session's processes or the drive did not do what was asked (one line)."""


@dataclasses.dataclass(frozen=True)
class AxisSpec:
    """What the session's nodes are given (SI units).

    Attributes
    ----------
    plant : str or None
        The simulated axis for ``plant_node`` (``pmlm``, ``ballscrew``, a plant YAML);
        None: an external drive is the axis.
    nominal : str
        The controller's ``plant`` parameter: its nominal model and default gains.
    controller : str
        ``pid | adaptive_sliding | npid``.
    timing : str
        ``lockstep | realtime``.
    control_rate : float
        [Hz].
    limits : Limits
        Enforced by the controller (trip) and the trajectory (refusal).
    model_dirs : tuple of str
        Directories the nodes may read files from (``model_dir``).
    monitor : bool
        Start ``monitor_node`` with each run.
    namespace : str
        Topic namespace.
    seed : int
        Measurement-noise seed of a simulated plant.
    realtime_priority : int
        SCHED_FIFO priority of the loop processes in realtime (0: normal scheduling).
    """

    plant: str | None
    nominal: str
    controller: str
    timing: str = 'lockstep'
    control_rate: float = 1000.0
    limits: Limits = dataclasses.field(default_factory=Limits)
    model_dirs: tuple[str, ...] = ()
    monitor: bool = False
    namespace: str = 'axis'
    seed: int = 0
    realtime_priority: int = 0

    @property
    def external(self) -> bool:
        """Tell whether an external drive (not a ``plant_node`` of ours) is the axis."""
        return self.plant is None

    @property
    def lockstep(self) -> bool:
        """Tell whether the simulated plant owns sim time (lockstep timing)."""
        return self.timing == 'lockstep'

    def _files(self) -> dict[str, str]:
        return {'model_dir': os.pathsep.join(self.model_dirs)}

    def controller_params(self) -> dict[str, Any]:
        """Return the controller's parameters (fixed for the session)."""
        lim = self.limits
        return {'plant': self.nominal, 'mode': self.controller, 'feedforward': 'none',
                'timing': self.timing, 'control_rate': float(self.control_rate),
                'realtime_priority': int(self.realtime_priority), **self._files(),
                'autostart': False, 'compensation_model': '',
                # voltage readers: the plant (or the drive), the recorder, the monitor
                'expected_subscribers': 2 + int(self.monitor),
                'travel': [float(v) for v in lim.travel], 'vmax': lim.vmax,
                'amax': lim.amax, 'umax': lim.umax, 'max_error': lim.max_error,
                'exit_on_trip': True, 'diagnostics_readers': 1,
                # lockstep: the simulated plant waits for every command, so a reference
                # late by the node default (0.5 s of wall time, a trajectory process
                # descheduled on a loaded machine) must not be answered with 0 V: that
                # changed a ball-screw excitation mid-run (and this session watches the
                # trajectory's process itself); realtime keeps the node's default
                **({'stale_timeout': LOCKSTEP_STALE_TIMEOUT} if self.lockstep else {})}

    def run_params(self, table_file: Path, *, duration: float, x0: float, output: Path,
                   monitor_model: str = '') -> dict[str, dict[str, Any]]:
        """Return the parameters of one run's processes (not the controller's)."""
        common = {'timing': self.timing, 'control_rate': float(self.control_rate),
                  'realtime_priority': int(self.realtime_priority)}
        lim = self.limits
        nodes = ['trajectory_node', 'controller_node']
        params: dict[str, dict[str, Any]] = {
            'trajectory_node': {**common, **self._files(), 'trajectory': 'table',
                                'file': str(table_file), 'duration': float(duration),
                                'exit_at_end': not self.lockstep,
                                'travel': [float(v) for v in lim.travel],
                                'vmax': lim.vmax, 'amax': lim.amax},
            'recorder_node': {**self._files(), 'output': str(output),
                              'timing': self.timing},
        }
        if self.external:
            # a drive publishes joint_states for ever: the topics never go quiet, so the
            # recorder closes its file at once when stopped (the run ended well before:
            # the table's rest, then the controller's 0 V)
            params['recorder_node']['drain_time'] = 0.0
            # a drive measures from power-on: the trajectory's time starts only once the
            # controller answers (its first command), not with the first measurement
            params['trajectory_node']['wait_for_command'] = True
        if not self.external:
            nodes.insert(0, 'plant_node')
            params['plant_node'] = {
                **common, **self._files(), 'plant': self.plant, 'seed': int(self.seed),
                'x0': float(x0),
                # lockstep: the run ends with the plant; realtime: when the table does
                'duration': float(duration) if self.lockstep else 0.0,
                # joint_states readers: controller, recorder (+ the realtime trajectory,
                # which takes its time origin from it) (+ the monitor)
                'expected_subscribers': 2 + int(not self.lockstep) + int(self.monitor)}
        if self.monitor:
            nodes.append('monitor_node')
            params['monitor_node'] = {**self._files(), 'model': monitor_model,
                                      'timing': self.timing, 'diagnostics_readers': 1}
        params['recorder_node']['nodes'] = ','.join(nodes)
        return params


@dataclasses.dataclass(frozen=True)
class RunRecord:
    """One run of the session.

    Attributes
    ----------
    path : Path
        Its MCAP recording.
    seconds : float
        Wall time [s].
    logs : tuple of Path
        The node logs of the run.
    """

    path: Path
    seconds: float
    logs: tuple


class Axis(Protocol):
    """The axis as the stages use it: runs played by the nodes (a context manager)."""

    domain: str

    def position(self) -> float:
        """Return the measured position now (an external drive)."""

    def run(self, name: str, table_file: Path, *, duration: float, x0: float,
            output: Path, compensation: str = '', monitor_model: str = '') -> RunRecord:
        """Play a table through the nodes and record it."""

    def __enter__(self) -> 'Axis': ...

    def __exit__(self, *exc: Any) -> None: ...


__all__ = ['Axis', 'AxisSpec', 'LOCKSTEP_STALE_TIMEOUT', 'RunRecord', 'SessionError']
