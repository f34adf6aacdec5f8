"""Load what every workbench command needs: a run and a model, with one-line errors.

Runs are MCAP files or rosbag2 bags (DESIGN.md §5 topics, or a robot's topics and joint
given as :class:`~motor_comp.logs.topics.RunTopics`) read by
:func:`motor_comp.logs.read_run`; CSV/MAT tables are turned into MCAP by ``motor-comp
import`` first (that is where their column names and units are given).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING, Sequence

from motor_comp.errors import InputFileError
from motor_comp.logs.run import Run
from motor_comp.physics.axis import AxisKind, AxisModel, InputKind
from motor_comp.workbench.derivatives import InputHold, Kinematics, kinematics

if TYPE_CHECKING:
    from motor_comp.logs.topics import RunTopics


@dataclasses.dataclass(frozen=True)
class Session:
    """One or several runs (one experiment), their kinematics and a model.

    ``run``/``kin`` are the first run's (figures, position views); ``runs``/``kins``
    all of them (the identification uses every run).
    """

    run: Run
    kin: Kinematics
    model: AxisModel
    runs: tuple = ()
    kins: tuple = ()


#: why the workbench cannot work without the logged drive input
_NEEDS_INPUT = ('the workbench needs the command (or current/force) the model converts '
                'with input_gain')


def default_hold(model: AxisModel) -> InputHold:
    """Choose the input hold: a voltage command is held, a logged current/force sampled."""
    return InputHold.ZOH if model.input is InputKind.VOLTAGE else InputHold.SAMPLE


def load_run(path: str | Path, topics: RunTopics | None = None) -> Run:
    """Read a run from an MCAP file or bag (one-line :class:`InputFileError` on any problem)."""
    path = Path(path)
    if path.suffix.lower() in ('.csv', '.mat', '.txt'):
        raise InputFileError(f'{path}: tables are converted first: motor-comp import '
                             f'{path.name} --time COL --input COL --position COL -o RUN.mcap')
    from motor_comp.logs import read_run   # heavy (MCAP stack): load only when needed
    # exact_time: a robot's wall-clock stamps counted from the run's start, to the ns
    return read_run(path, require={'voltage': _NEEDS_INPUT}, topics=topics, exact_time=True)


def open_session(run_path: str | Path | Sequence[str | Path], model_path: str | Path, *,
                 window_s: float = 0.02, hold: str | None = None,
                 rotary: bool = False, topics: RunTopics | None = None) -> Session:
    """Load model and run(s), check each run has the drive input, compute kinematics.

    Several run paths are one experiment (DESIGN.md §6): every run is loaded and
    differentiated on its own grid; the workbench fits one model on all of them.
    ``rotary`` turns a model file without ``axis: rotary`` into a rotary one;
    ``topics`` says where the signals are in a robot's bag (default: the §5 topics).
    """
    model = AxisModel.load(model_path)
    if rotary and model.axis is not AxisKind.ROTARY:
        model = model.replace(axis=AxisKind.ROTARY)
    paths = [run_path] if isinstance(run_path, (str, Path)) else list(run_path)
    runs, kins = [], []
    for path in paths:
        run = load_run(path, topics)
        if run.voltage is None:    # a Run that did not come from read_run(require=...)
            raise InputFileError(f'{path}: no drive input (/axis/voltage) in this run; '
                                 f'{_NEEDS_INPUT}')
        runs.append(run)
        kins.append(kinematics(run, window_s=window_s,
                               hold=InputHold(hold) if hold else default_hold(model)))
    return Session(run=runs[0], kin=kins[0], model=model, runs=tuple(runs),
                   kins=tuple(kins))
