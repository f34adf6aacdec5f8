"""``/diagnostics`` of a recorded run: the monitor's verdicts and the controller's limits.

The recorder writes ``diagnostic_msgs/DiagnosticArray`` messages with their ``ros2msg``
schema (:mod:`motor_comp.logs.schemas`); this module reads them back as plain records,
one per ``DiagnosticStatus``, with the general ``mcap_ros2`` decoder (a run holds a few
verdicts per second, so the hand-written bulk decoders of the loop's topics are not
needed here).  Core module: no rclpy.
"""
from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import BinaryIO, Mapping

from motor_comp.errors import InputFileError
from motor_comp.logs import schemas

#: the ROS standard topic
TOPIC = '/diagnostics'

#: ``DiagnosticStatus.level`` names
LEVELS = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}


@dataclasses.dataclass(frozen=True)
class DiagnosticRecord:
    """One recorded ``DiagnosticStatus``.

    Attributes
    ----------
    t : float
        The array's header stamp [s] (sim time in a lockstep run).
    name, message, hardware_id : str
        As published.
    level : str
        ``OK``, ``WARN``, ``ERROR`` or ``STALE``.
    values : Mapping[str, str]
        The key-values.
    """

    t: float
    name: str
    level: str
    message: str
    hardware_id: str
    values: Mapping[str, str]


def read_diagnostics(path: str | os.PathLike, *, topic: str = TOPIC) -> list[DiagnosticRecord]:
    """Return the ``DiagnosticStatus`` records of ``topic`` in an MCAP file, in log order.

    A file without the topic gives an empty list; a rosbag2 directory's MCAP files are
    read in order (a sqlite3 bag gives an empty list).  The file's index is used to read
    only the chunks that hold the topic; a file whose index is damaged or missing (a
    recording cut short) is read from its start up to the damage.  Damage is not
    reported again here: the reader of the loop's topics
    (:func:`motor_comp.logs.read_run`) already says so.

    Raises
    ------
    InputFileError
        The file cannot be opened.
    """
    from motor_comp.logs.bags import locate
    bag = locate(Path(path))
    files = bag.files if bag.storage == 'mcap' else ()   # sqlite3: not read here
    out: list[DiagnosticRecord] = []
    for f in files:
        try:
            fh = open(f, 'rb')
        except OSError as exc:
            raise InputFileError(f'{f}: cannot read ({exc.strerror})') from None
        with fh:
            found: list[DiagnosticRecord] = []
            try:
                _read(fh, topic, found, seeking=True)
            except Exception:   # noqa: BLE001 - a damaged index: read in order instead
                found.clear()
                fh.seek(0)
                try:
                    _read(fh, topic, found, seeking=False)
                except Exception:   # noqa: BLE001 - keep what precedes the damage
                    pass
            out.extend(found)
    return out


def _read(fh: BinaryIO, topic: str, out: list[DiagnosticRecord], *, seeking: bool) -> None:
    """Append the records of ``topic`` in ``fh`` to ``out`` (raises on damage)."""
    from mcap.reader import NonSeekingReader, SeekingReader
    from mcap_ros2.decoder import DecoderFactory

    cls = SeekingReader if seeking else NonSeekingReader
    reader = cls(fh, decoder_factories=[DecoderFactory()])
    # in file order: sorting by log time would first read the whole (damaged) file
    for schema, _, _, msg in reader.iter_decoded_messages(topics=[topic],
                                                          log_time_order=seeking):
        if schema is None or schemas.normalise_type(schema.name) != schemas.DIAGNOSTIC_ARRAY:
            continue
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        for st in msg.status:
            level = st.level if isinstance(st.level, int) else \
                int.from_bytes(bytes(st.level), 'little')
            out.append(DiagnosticRecord(
                t=t, name=st.name, level=LEVELS.get(level, str(level)), message=st.message,
                hardware_id=st.hardware_id, values={kv.key: kv.value for kv in st.values}))


__all__ = ['LEVELS', 'TOPIC', 'DiagnosticRecord', 'read_diagnostics']
