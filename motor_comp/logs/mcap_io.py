"""MCAP runs: canonical writer, crash-tolerant recorder, fast chunk-by-chunk reader.

Files are MCAP with the ``ros2`` profile, ``ros2msg`` schemas (full definitions with
dependencies, as rosbag2 writes them), CDR messages, rosbag2-style channel metadata
(offered QoS, type hash) and the run parameters as an MCAP metadata record named
``motor_comp``.  Topics are those of DESIGN.md §5 (namespace ``axis`` by default).

Reading (:func:`read_run`) accepts any MCAP with those topics, whoever wrote it, and
needs no ROS install.  Policies (documented contract of the reader):

* **Time base.**  ``Run.t`` is the header stamp of ``/axis/joint_states`` [s]
  (log times if the publisher left the stamps at zero).  ``/axis/reference`` uses its
  header stamps; ``/axis/voltage`` (Float64, no header) its log time — shifted into the
  stamp clock by the median ``stamp − log time`` of the joint states when the two
  clocks are clearly different (> 1 s apart, e.g. sim-time stamps, wall-clock log).
* **Alignment.**  Other topics are sampled and held onto ``t``: the latest value
  stamped at or before each measurement.  Measurements before the first value of any
  present topic are dropped, so every returned array is complete.
* **Out-of-order or duplicate stamps** are sorted (stable) and de-duplicated keeping
  the last message of a stamp, with a warning on stderr giving the counts.
* **NaN/Inf samples** are dropped per signal with a warning giving the count; a topic
  without any finite sample is treated as absent.
* **Damage.**  Missing, empty, non-MCAP files raise :class:`InputFileError`.  A file
  that is truncated, unfinalised (no footer, e.g. recorder killed) or corrupt part-way
  is read record by record up to the damage; what was complete is returned, ending at
  the last stamp every topic reached (nothing is held over the lost part), with a
  warning stating where reading stopped and how many messages/what time span were
  recovered.  If nothing usable precedes the damage, :class:`InputFileError`.
* **Required signals.**  ``read_run(require=...)`` turns a missing or all-NaN signal
  the caller needs into one :class:`InputFileError` naming file, topic and reason; an
  optional signal without any finite sample is a warning and treated as absent.

Speed and memory: the file is read record by record (one chunk in memory at a time);
a chunk's message indexes give the offsets of its messages, whose payloads are decoded
as numpy byte matrices (:mod:`~motor_comp.logs.cdr`); chunks without usable indexes or
with varying layouts go through the compiled scanner (:mod:`~motor_comp.logs.cdr_jit`),
big-endian payloads through ``mcap_ros2``'s general decoder.  Only the decoded arrays
are kept.
"""
from __future__ import annotations

import dataclasses
import io
import json
import os
import struct
import time
import zlib
from pathlib import Path
from typing import Any, Callable, Collection, Iterator, Mapping

import numpy as np

from motor_comp.errors import InputFileError, ParameterError
from motor_comp.logs import bags, cdr, schemas
from motor_comp.logs.bags import Bag
from motor_comp.logs.progress import Progress, warn
from motor_comp.logs.run import Run
from motor_comp.logs.topics import RunTopics

MAGIC = b'\x89MCAP0\r\n'
_MAX_CHUNK = 1 << 30
#: stamps up to this [ns] (52 days) are held to the nanosecond as float seconds
EXACT_STAMP_NS = 2 ** 52
#: name of the metadata record holding the run parameters
METADATA_NAME = 'motor_comp'

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL = 0x01, 0x02, 0x03, 0x04
_OP_MESSAGE, _OP_CHUNK, _OP_MESSAGE_INDEX = 0x05, 0x06, 0x07
_OP_METADATA, _OP_DATA_END = 0x0C, 0x0F


def _library() -> str:
    from mcap.writer import LIBRARY_IDENTIFIER
    return f'motor_comp/0.1.0 {LIBRARY_IDENTIFIER}'


def _compression(name: str):
    from mcap.writer import CompressionType
    try:
        return {'zstd': CompressionType.ZSTD, 'lz4': CompressionType.LZ4,
                'none': CompressionType.NONE, '': CompressionType.NONE}[name]
    except KeyError:
        raise ParameterError(f'compression must be zstd, lz4 or none, got {name!r}') from None


class _Unbuffered:
    """Write-through file for the mcap writer.

    The mcap writer wraps raw files in a BufferedWriter; handing it this object (not a
    RawIOBase) makes every finished chunk reach the OS at once, so a recorder killed
    with SIGKILL leaves a file readable up to its last complete chunk.
    """

    def __init__(self, path: str | os.PathLike, *, exclusive: bool = False) -> None:
        # 'x': O_CREAT | O_EXCL, which also refuses a symbolic link at the path
        self._raw = open(path, 'xb' if exclusive else 'wb', buffering=0)

    def write(self, data: bytes) -> int:
        view = memoryview(data)
        while view:
            n = self._raw.write(view)
            view = view[n:]
        return len(data)

    def tell(self) -> int:
        return self._raw.tell()

    def flush(self) -> None:
        pass

    def close(self) -> None:
        self._raw.close()


class _PackedChunkIndex:
    """The mcap writer's chunk index, kept as serialized records in a temporary file.

    The writer keeps one ``ChunkIndex`` object (a dataclass and a dict of per-channel
    offsets, ≈ 0.6 KiB of Python heap) per chunk until it writes the summary: for a
    recorder closing a 256 KiB chunk every ≈ 0.7 s of 1 kHz lockstep, ≈ 3–5 MiB per
    hour of recording, growing with the run.  Here each index is serialized at once
    into the ≈ 120-byte record the summary will hold and appended to an unnamed
    temporary file (same bytes, in the same order), read back once when the summary is
    written: the recorder's memory no longer grows with the number of chunks.  Only
    ``append`` and iteration are used by ``mcap.writer.Writer``.
    """

    def __init__(self) -> None:
        import tempfile

        from mcap.data_stream import RecordBuilder
        self._builder = RecordBuilder()
        self._spill = tempfile.TemporaryFile(prefix='motor_comp_chunk_index_')
        self._count = 0

    def append(self, index: Any) -> None:
        """Serialize ``index`` (an ``mcap.records.ChunkIndex``); keep only its bytes, on disk."""
        index.write(self._builder)
        self._spill.write(self._builder.end())
        self._count += 1

    def __len__(self) -> int:
        return self._count

    def __iter__(self) -> Iterator[Any]:
        self._spill.seek(0)
        data = self._spill.read()
        self._spill.seek(0, os.SEEK_END)
        yield _RawRecords(data)

    def close(self) -> None:
        """Delete the temporary file."""
        self._spill.close()


class _RawRecords:
    """Already-serialized summary records, written as they are."""

    def __init__(self, data: bytes) -> None:
        self.data = data

    def write(self, stream: Any) -> None:
        """Append the records to the summary being built."""
        stream.write(self.data)


def _str_metadata(data: Mapping[str, Any]) -> dict[str, str]:
    return {str(k): v if isinstance(v, str) else json.dumps(v, default=str)
            for k, v in data.items()}


class McapRecorder:
    """Context manager writing already-serialised CDR messages to an MCAP file.

    Used by the recorder node (which receives raw CDR bytes from rclpy).  Chunks are
    small (``chunk_size``, default 256 KiB) and are also closed every
    ``flush_interval`` seconds of wall time, and each chunk is written through to the
    OS: after a crash/SIGKILL the file can be read up to its last complete chunk by
    :func:`read_run`.

    Parameters
    ----------
    path : path-like
        Output file (overwritten, unless ``exclusive``).
    exclusive : bool
        Create the file only if nothing (no file, no symbolic link) is at ``path``; an
        existing one is an :class:`InputFileError` (the recorder node's rule: an output
        parameter cannot clobber a file).
    chunk_size : int
        Uncompressed bytes per chunk [B].
    compression : {'zstd', 'lz4', 'none'}
        Chunk compression.
    flush_interval : float
        Longest time a message waits in an open chunk [s] (wall clock); 0 disables.
    """

    def __init__(self, path: str | os.PathLike, *, chunk_size: int = 256 * 1024,
                 compression: str = 'zstd', flush_interval: float = 1.0,
                 exclusive: bool = False) -> None:
        from mcap.writer import Writer
        if chunk_size <= 0:
            raise ParameterError(f'chunk_size must be > 0, got {chunk_size}')
        self.path = Path(path)
        try:
            self._file = _Unbuffered(self.path, exclusive=exclusive)
        except FileExistsError:
            raise InputFileError(f'{self.path}: exists; refused (an output is always a new '
                                 'file, never overwritten)') from None
        except OSError as exc:
            raise InputFileError(f'{self.path}: cannot write ({exc.strerror})') from None
        self._writer = Writer(self._file, chunk_size=int(chunk_size),
                              compression=_compression(compression))
        # memory flat over long recordings (see _PackedChunkIndex); the attribute is the
        # writer's private list, so only where this mcap version has it
        if isinstance(getattr(self._writer, '_Writer__chunk_indices', None), list):
            self._writer._Writer__chunk_indices = _PackedChunkIndex()
        self._writer.start(profile='ros2', library=_library())
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._flush_interval = float(flush_interval)
        self._last_flush = time.monotonic()
        self._closed = False
        self.message_count = 0

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    def add_channel(self, topic: str, msgtype: str, *, definition: str | None = None,
                    qos_yaml: str | None = None) -> int:
        """Register ``topic`` of ROS type ``msgtype`` (e.g. ``sensor_msgs/msg/JointState``).

        ``definition`` is the full ros2msg text for types this module does not know;
        ``qos_yaml`` the offered QoS profiles in rosbag2's YAML layout.  Returns the
        channel id.  Registering a topic twice returns the existing channel.
        """
        if topic in self._channels:
            return self._channels[topic]
        msgtype = schemas.normalise_type(msgtype)
        text = definition if definition is not None else schemas.DEFINITIONS.get(msgtype)
        if text is None:
            raise ParameterError(f'{topic}: no message definition known for {msgtype}; '
                                 'pass definition=')
        if msgtype not in self._schemas:
            self._schemas[msgtype] = self._writer.register_schema(
                msgtype, 'ros2msg', text.encode())
        cid = self._writer.register_channel(
            topic, 'cdr', self._schemas[msgtype],
            metadata=schemas.channel_metadata(msgtype, qos_yaml=qos_yaml))
        self._channels[topic] = cid
        self._sequence[topic] = 0
        return cid

    def write_cdr(self, topic: str, data: bytes, log_time_ns: int,
                  publish_time_ns: int | None = None) -> None:
        """Append one serialised message of a registered topic (times in ns)."""
        try:
            cid = self._channels[topic]
        except KeyError:
            raise ParameterError(f'{topic}: add_channel() before write_cdr()') from None
        seq = self._sequence[topic]
        self._sequence[topic] = seq + 1
        log_time_ns = int(log_time_ns)
        self._writer.add_message(
            channel_id=cid, log_time=log_time_ns, data=bytes(data),
            publish_time=log_time_ns if publish_time_ns is None else int(publish_time_ns),
            sequence=seq & 0xFFFFFFFF)
        self.message_count += 1
        if self._flush_interval > 0:
            now = time.monotonic()
            if now - self._last_flush >= self._flush_interval:
                self._writer.flush()
                self._last_flush = now

    def add_metadata(self, name: str, data: Mapping[str, Any]) -> None:
        """Write an MCAP metadata record (values are stored as strings)."""
        self._writer.add_metadata(str(name), _str_metadata(data))

    def flush(self) -> None:
        """Close the open chunk and write it to the file."""
        self._writer.flush()
        self._last_flush = time.monotonic()

    def close(self) -> None:
        """Write the summary and footer and close the file (idempotent)."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.finish()
        finally:
            self._file.close()
            close_index = getattr(getattr(self._writer, '_Writer__chunk_indices', None),
                                  'close', None)
            if close_index is not None:   # the spilled chunk index (_PackedChunkIndex)
                close_index()


def write_run(path: str | os.PathLike, run: Run, *, metadata: Mapping[str, Any] | None = None,
              namespace: str = 'axis', chunk_size: int = 1024 * 1024,
              compression: str = 'zstd') -> None:
    """Write ``run`` as a canonical MCAP (DESIGN.md §5 topics).

    ``/axis/reference`` (if the run has a reference), ``/axis/joint_states`` and
    ``/axis/voltage`` (if any) are written at the stamps ``run.t`` [s] (header stamp,
    log and publish time), time-ordered; ``run.metadata`` updated by ``metadata`` goes
    into the ``motor_comp`` metadata record.  Times must be ≥ 0 (MCAP times are
    unsigned nanoseconds).
    """
    t = np.asarray(run.t, dtype=float)
    if t.size and (not np.all(np.isfinite(t)) or t[0] < 0):
        raise ParameterError(f'{run.name}: times must be finite and >= 0 to write MCAP')
    ns = np.round(t * 1e9).astype(np.int64)
    if ns.size > 1 and np.any(np.diff(ns) <= 0):
        raise ParameterError(f'{run.name}: times must be strictly increasing (at ns resolution)')
    names = schemas.topics(namespace)

    def sl(a: np.ndarray | None, b: slice) -> np.ndarray | None:
        return None if a is None else a[b]

    # (topic, type, encoder of a block of samples), in per-stamp publication order
    streams: list[tuple[str, str, Callable[[slice], np.ndarray]]] = []
    if run.reference is not None:
        streams.append((names['reference'], schemas.JOINT_STATE,
                        lambda b: cdr.encode_joint_states(
                            ns[b], run.reference[b], sl(run.reference_velocity, b))))
    streams.append((names['joint_states'], schemas.JOINT_STATE,
                    lambda b: cdr.encode_joint_states(ns[b], run.position[b],
                                                      sl(run.velocity, b), sl(run.effort, b))))
    if run.voltage is not None:
        streams.append((names['voltage'], schemas.FLOAT64,
                        lambda b: cdr.encode_float64(run.voltage[b])))
    meta = dict(run.metadata)
    meta.update(metadata or {})
    with McapRecorder(path, chunk_size=chunk_size, compression=compression,
                      flush_interval=0.0) as rec:
        if meta:
            rec.add_metadata(METADATA_NAME, meta)
        ids = [rec.add_channel(topic, typ) for topic, typ, _ in streams]
        add = rec._writer.add_message   # the per-message bookkeeping of write_cdr is not needed
        block = 8192                     # encode in blocks: memory stays bounded
        for b0 in range(0, ns.size, block):
            b = slice(b0, min(b0 + block, ns.size))
            payloads = [[row.tobytes() for row in enc(b)] for _, _, enc in streams]
            for k, tk in enumerate(ns[b].tolist()):
                for cid, pl in zip(ids, payloads):
                    add(channel_id=cid, log_time=tk, data=pl[k], publish_time=tk,
                        sequence=b0 + k)
        rec.message_count = ns.size * len(streams)


# ============================================================================ reading

class _Column:
    """A growing array (capacity doubles).

    Why not a list of per-chunk arrays: those are small heap blocks, and the heap they
    fragment is not returned to the OS after concatenation, doubling the peak memory of
    long runs.  Large buffers are mmap-backed and untouched capacity is not resident.
    Absent values (an int count) allocate nothing until real data arrives (then NaN).
    """

    def __init__(self) -> None:
        self.buf: np.ndarray | None = None
        self.n = 0

    def append(self, values: np.ndarray | int) -> None:
        if isinstance(values, int):
            if self.buf is not None:
                self._reserve(values)
                self.buf[self.n:self.n + values] = np.nan
            self.n += values
            return
        if self.buf is None:
            self.buf = np.empty(max(2 * (self.n + values.size), 4096), values.dtype)
            if self.n:
                self.buf[:self.n] = np.nan
        self._reserve(values.size)
        self.buf[self.n:self.n + values.size] = values
        self.n += values.size

    def _reserve(self, extra: int) -> None:
        assert self.buf is not None
        if self.n + extra > self.buf.size:
            grown = np.empty(max(2 * self.buf.size, self.n + extra), self.buf.dtype)
            grown[:self.n] = self.buf[:self.n]
            self.buf = grown

    def take(self) -> np.ndarray:
        if self.buf is None:
            return np.full(self.n, np.nan)
        out = self.buf[:self.n].copy() if self.buf.size > 1.25 * self.n else self.buf[:self.n]
        self.buf = None
        return out


@dataclasses.dataclass
class _Topic:
    """Decoded samples of one topic, accumulated chunk by chunk."""

    topic: str
    kind: str                     # 'joint', 'scalar' or 'ctrl' (a controller state)
    columns: dict[str, _Column] = dataclasses.field(default_factory=dict)
    drop: frozenset[str] = frozenset()      # decoded fields not to keep
    joint: str = 'axis'           # joint of a multi-joint message
    strict: bool = False          # the joint must be named in every message
    corrupt: int = 0
    messages: int = 0
    log_minus_stamp: list[np.ndarray] = dataclasses.field(default_factory=list)

    def add(self, **arrays: np.ndarray | int) -> None:
        """Append a chunk's arrays (an int ``n`` stands for ``n`` absent values)."""
        for k, v in arrays.items():
            col = self.columns.get(k)
            if col is None:
                col = self.columns[k] = _Column()
            col.append(v)

    def get(self, key: str) -> np.ndarray:
        """Return the samples of ``key`` and release them (call once per key)."""
        col = self.columns.pop(key, None)
        return np.empty(0) if col is None else col.take()

    def count(self) -> int:
        return self.messages


@dataclasses.dataclass(frozen=True)
class Want:
    """What to decode from one topic.

    ``kind`` is ``joint`` (JointState), ``scalar`` (a ``data`` field), ``input`` (a
    JointState's effort or a scalar, by the topic's type) or ``reference`` (a JointState
    or a controller state, by the type); ``drop``: decoded fields not to keep.
    """

    kind: str
    drop: frozenset[str] = frozenset()
    joint: str = 'axis'
    strict: bool = False


@dataclasses.dataclass
class _Channel:
    topic: str
    schema_name: str
    encoding: str
    schema: Any


class _Damage(Exception):
    """Reading stopped at byte ``offset`` for ``reason``."""

    def __init__(self, offset: int, reason: str) -> None:
        super().__init__(reason)
        self.offset = offset
        self.reason = reason


def _gather_u64(buf: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Return the little-endian uint64 at each offset ``at`` of ``buf``."""
    return np.ascontiguousarray(cdr.payload_matrix(buf, at, 8)).view('<u8')[:, 0]


def _record_stream(data: bytes):
    from mcap.data_stream import ReadDataStream
    return ReadDataStream(io.BytesIO(data))


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    # Decompression with the codecs the mcap library itself uses (zstandard, lz4):
    # mcap's own helper wraps the result in a per-record parsing stream we do not want.
    if compression == '':
        return data
    if compression == 'zstd':
        import zstandard
        return zstandard.ZstdDecompressor().decompress(data, max_output_size=size)
    if compression == 'lz4':
        import lz4.frame
        return lz4.frame.decompress(data)
    raise ValueError(f'unsupported chunk compression {compression!r}')


class _Reader:
    """One pass over an MCAP file, decoding the wanted topics chunk by chunk."""

    def __init__(self, path: Path, wanted: Mapping[str, Want], progress: Progress) -> None:
        self.path = path
        self.wanted = wanted           # topic -> what to decode
        self.progress = progress
        self.done_bytes = 0            # bytes of the earlier files of a split bag
        self.schemas: dict[int, Any] = {}
        self.channels: dict[int, _Channel] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.topics: dict[str, _Topic] = {}
        self.all_topics: dict[str, str] = {}
        self.messages = 0
        self._decoders: dict[int, Callable[[bytes], Any]] = {}
        self._open: tuple[int, np.ndarray] | None = None
        self._index: dict[int, np.ndarray] = {}

    def next_file(self, path: Path) -> None:
        """Go on with the next file of a split bag: its own schemas and channel ids."""
        self.done_bytes += self.path.stat().st_size
        self.path = path
        self.schemas.clear()
        self.channels.clear()
        self._decoders.clear()
        self._open, self._index = None, {}

    # ---------------------------------------------------------------- records
    def _records(self, f: io.BufferedReader, size: int) -> Iterator[tuple[int, int, bytes]]:
        # Own top-level loop rather than mcap.StreamReader: that one makes a Python
        # object of every message-index entry (we read them as numpy arrays) and cannot
        # say at which byte a damaged file stops.
        pos = 8
        while True:
            head = f.read(9)
            if not head:
                raise _Damage(pos, 'file ends without footer (not finalised)')
            if len(head) < 9:
                raise _Damage(pos, 'truncated record header')
            op, length = struct.unpack('<BQ', head)
            if length > size - pos - 9:
                raise _Damage(pos, f'record of {length} bytes runs past the end of the file')
            if op in (_OP_SCHEMA, _OP_CHANNEL, _OP_CHUNK, _OP_METADATA, _OP_MESSAGE,
                      _OP_MESSAGE_INDEX, _OP_HEADER, _OP_FOOTER, _OP_DATA_END):
                body = f.read(length)
            else:                      # chunk indexes, attachments, statistics: unused
                f.seek(length, io.SEEK_CUR)
                body = b''
            yield pos, op, body
            pos += 9 + length
            self.progress.update(self.done_bytes + pos)
            if op in (_OP_DATA_END, _OP_FOOTER):
                return

    def read(self) -> tuple[bool, _Damage | None]:
        """Read the file; return (complete, damage)."""
        size = self.path.stat().st_size
        with open(self.path, 'rb') as f:
            if f.read(8) != MAGIC:
                raise InputFileError(f'{self.path}: not an MCAP file (bad magic bytes)')
            pending: list[tuple[int, int, int, bytes]] = []
            try:
                for pos, op, body in self._records(f, size):
                    try:
                        if op == _OP_MESSAGE_INDEX:
                            self._add_index(body)
                            continue
                        self._close_chunk()
                        if op == _OP_MESSAGE:
                            cid, _seq, log, pub = struct.unpack_from('<HIQQ', body)
                            pending.append((cid, log, pub, body[22:]))
                            if len(pending) >= 4096:
                                self._flush_pending(pending)
                            continue
                        if pending:
                            self._flush_pending(pending)
                        if op == _OP_CHUNK:
                            # decoded once its message indexes (the next records) are in
                            self._open = (pos, self._chunk_bytes(body))
                        else:
                            self._record(op, body)
                    except (InputFileError, _Damage):
                        raise
                    except Exception as exc:  # noqa: BLE001 - any parse failure is damage
                        raise _Damage(pos, f'{type(exc).__name__}: {exc}') from None
                self._close_chunk()
                if pending:
                    self._flush_pending(pending)
            except _Damage as dmg:
                self._index = {}          # the chunk is intact, its index may not be
                try:
                    self._close_chunk()
                except _Damage:
                    pass
                return False, dmg
        return True, None

    def _record(self, op: int, body: bytes) -> None:
        from mcap.records import Channel, Metadata, Schema
        if op == _OP_SCHEMA:
            s = Schema.read(_record_stream(body))
            self.schemas[s.id] = s
        elif op == _OP_CHANNEL:
            self._add_channel(Channel.read(_record_stream(body)))
        elif op == _OP_METADATA:
            m = Metadata.read(_record_stream(body))
            self.metadata.setdefault(m.name, {}).update(m.metadata)

    def _add_channel(self, ch: Any) -> None:
        schema = self.schemas.get(ch.schema_id)
        name = schemas.normalise_type(schema.name) if schema is not None else ''
        self.add_channel(ch.id, ch.topic, name, ch.message_encoding, schema)

    def add_channel(self, cid: int, topic: str, type_name: str, encoding: str,
                    schema: Any) -> None:
        """Register a channel (MCAP channel record, or a rosbag2 sqlite3 connection)."""
        self.all_topics[topic] = type_name
        if topic not in self.wanted:
            return
        want = self.wanted[topic]
        kind = _kind_of(self.path, topic, want.kind, type_name)
        if encoding != 'cdr':
            raise InputFileError(f'{self.path}: {topic} is {encoding!r}-encoded; '
                                 'only ROS 2 CDR is supported')
        self.channels[cid] = _Channel(topic, type_name, encoding, schema)
        self.topics.setdefault(topic, _Topic(topic, kind, drop=want.drop, joint=want.joint,
                                             strict=want.strict))

    def _chunk_bytes(self, body: bytes) -> np.ndarray:
        """Decompress and CRC-check a chunk record's records."""
        start, end, usize, crc = struct.unpack_from('<QQQI', body)
        (clen,) = struct.unpack_from('<I', body, 28)
        comp = body[32:32 + clen].decode()
        (dlen,) = struct.unpack_from('<Q', body, 32 + clen)
        data = body[40 + clen:40 + clen + dlen]
        if len(data) != dlen:
            raise ValueError('chunk shorter than its declared length')
        if usize > _MAX_CHUNK:       # a corrupt size must not trigger a huge allocation
            raise ValueError(f'chunk claims {usize} uncompressed bytes')
        raw = _decompress(comp, data, usize)
        if len(raw) != usize:
            raise ValueError(f'chunk decompressed to {len(raw)} bytes, expected {usize}')
        if crc and zlib.crc32(raw) != crc:
            raise ValueError('chunk CRC mismatch')
        return np.frombuffer(raw, np.uint8)

    def _add_index(self, body: bytes) -> None:
        """Collect a message index record of the open chunk (offsets of its messages)."""
        if self._open is None:
            return
        cid, nbytes = struct.unpack_from('<HI', body)
        if nbytes % 16 or 6 + nbytes > len(body):
            raise ValueError('malformed message index')
        pairs = np.frombuffer(body, '<u8', count=nbytes // 8, offset=6).reshape(-1, 2)
        self._index[cid] = pairs[:, 1].astype(np.int64)

    def _close_chunk(self) -> None:
        """Decode the open chunk: by its message indexes if they check out, else by scanning."""
        if self._open is None:
            return
        pos, buf = self._open
        index, self._open, self._index = self._index, None, {}
        try:
            if not (index and self._indexed_chunk(buf, index)):
                self._records_buffer(buf)
        except InputFileError:
            raise
        except Exception as exc:  # noqa: BLE001 - any parse failure is damage
            raise _Damage(pos, f'{type(exc).__name__}: {exc}') from None

    def _indexed_chunk(self, buf: np.ndarray, index: Mapping[int, np.ndarray]) -> bool:
        """Decode a chunk with numpy using its message indexes; False if they do not fit.

        The index must account for every message: the records between indexed messages
        are walked and must be schemas/channels only, else the scanner is used.
        """
        n = buf.shape[0]
        per: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        for cid, o in index.items():
            if o.size == 0:
                continue
            o = np.sort(o)             # the index is in log-time order; we want file order
            if o[0] < 0 or o[-1] > n - 31 or not np.all(buf[o] == _OP_MESSAGE):
                return False
            if not np.all((buf[o + 9] | (buf[o + 10].astype(np.int64) << 8)) == cid):
                return False
            # per channel the records usually repeat with one stride: strided reads
            per[cid] = (o, _gather_u64(buf, o + 1).astype(np.int64))
        if not per:
            return False
        offs = np.concatenate([o for o, _ in per.values()])
        ends = np.concatenate([o + 9 + ln for o, ln in per.values()])
        order = np.argsort(offs, kind='stable')
        offs, ends = offs[order], ends[order]
        if np.any(ends - offs < 31) or np.any(ends > n) or np.any(offs[1:] < ends[:-1]):
            return False
        starts = np.concatenate(([0], ends))
        stops = np.concatenate((offs, [n]))
        for g0, g1 in zip(starts[starts != stops], stops[starts != stops]):
            p = int(g0)
            while p < g1:
                if p + 9 > g1:
                    return False
                op, ln = struct.unpack_from('<BQ', buf, p)
                if op == _OP_MESSAGE or p + 9 + ln > g1:
                    return False
                if op in (_OP_SCHEMA, _OP_CHANNEL):
                    self._record(op, buf[p + 9:p + 9 + ln].tobytes())
                p += 9 + ln
        self.messages += int(offs.size)
        for cid, ch in self.channels.items():
            if cid not in per:
                continue
            o, lens = per[cid]
            self.decode_batch(cid, buf, _gather_u64(buf, o + 15).astype(np.int64), o + 31,
                              lens - 22)
        return True

    def decode_batch(self, cid: int, buf: np.ndarray, log: np.ndarray, ds: np.ndarray,
                     dl: np.ndarray) -> None:
        """Decode one channel's payloads at offsets ``ds`` (lengths ``dl``) of ``buf``.

        One payload layout (the usual case) goes through the numpy byte-matrix path,
        varying layouts through the compiled scanner.
        """
        ch = self.channels[cid]
        topic = self.topics[ch.topic]
        if not (np.all(dl == dl[0]) and self._fixed(ch, topic, buf, ds, int(dl[0]), log)):
            self._decode(ch, topic, buf, log, ds, dl)

    def _fixed(self, ch: _Channel, topic: _Topic, buf: np.ndarray, ds: np.ndarray,
               length: int, log: np.ndarray) -> bool:
        """Decode payloads of one length as a byte matrix; False if the layout varies."""
        rows = cdr.payload_matrix(buf, ds, length)
        if topic.kind == 'ctrl':
            return False
        if topic.kind == 'joint':
            layout = cdr.joint_state_layout(rows[0].tobytes(), topic.joint.encode(),
                                            topic.strict)
            if not isinstance(layout, cdr.JointStateLayout):
                return False
            res = cdr.decode_joint_states_fixed(rows, layout)
            if res is None:
                return False
            stamp, pos, vel, eff, present = res
            self._store_joint(topic, stamp, log, pos, vel, eff, present)
            return True
        if ch.schema_name != schemas.FLOAT64:
            return False
        val = cdr.decode_float64_fixed(rows)
        if val is None:
            return False
        topic.add(stamp=log, value=val)
        topic.messages += int(log.size)
        return True

    def _flush_pending(self, pending: list[tuple[int, int, int, bytes]]) -> None:
        # Top-level (unchunked) messages: rebuild them as one record buffer so the same
        # scanner/decoders handle them.
        parts = []
        for cid, log, pub, data in pending:
            parts.append(struct.pack('<BQHIQQ', _OP_MESSAGE, 22 + len(data), cid, 0, log, pub))
            parts.append(data)
        pending.clear()
        self._records_buffer(np.frombuffer(b''.join(parts), np.uint8))

    def _records_buffer(self, buf: np.ndarray) -> None:
        """Decode a buffer of records by scanning it (no message index to go by)."""
        from motor_comp.logs import cdr_jit
        op, start, length, chan, log, pub, ds, dl, end = cdr_jit.scan_records(buf)
        if end != buf.shape[0]:
            raise ValueError('chunk records are truncated or corrupt')
        is_msg = op == _OP_MESSAGE
        for i in np.flatnonzero(~is_msg):
            if op[i] in (_OP_SCHEMA, _OP_CHANNEL):
                self._record(int(op[i]), buf[start[i]:start[i] + length[i]].tobytes())
        self.messages += int(np.count_nonzero(is_msg))
        for cid, ch in self.channels.items():
            sel = np.flatnonzero(is_msg & (chan == cid))
            if sel.size:
                self._decode(ch, self.topics[ch.topic], buf, log[sel], ds[sel], dl[sel])

    # ---------------------------------------------------------------- decoding
    def _store_joint(self, topic: _Topic, stamp: np.ndarray, log: np.ndarray,
                     pos: np.ndarray | None, vel: np.ndarray | None, eff: np.ndarray | None,
                     present: np.ndarray) -> None:
        if stamp.size > 1 and not np.any(stamp):
            stamp = log                # the publisher does not stamp: use log times
        if sum(a.size for a in topic.log_minus_stamp) < 10_000:
            topic.log_minus_stamp.append(log - stamp)
        arrays: dict[str, np.ndarray | int] = {'stamp': stamp, 'present': present}
        # absent arrays (e.g. reference effort) are not stored: NaN-filled on assembly
        for key, bit, arr in (('position', cdr.HAS_POSITION, pos),
                              ('velocity', cdr.HAS_VELOCITY, vel),
                              ('effort', cdr.HAS_EFFORT, eff)):
            has = arr is not None and key not in topic.drop and np.any(present & bit)
            arrays[key] = arr if has else int(stamp.size)   # type: ignore[assignment]
        topic.add(**arrays)
        topic.messages += int(stamp.size)

    def _decode(self, ch: _Channel, topic: _Topic, buf: np.ndarray, log: np.ndarray,
                ds: np.ndarray, dl: np.ndarray) -> None:
        """Decode message by message (compiled), general decoder for foreign encodings."""
        from motor_comp.logs import cdr_jit
        if topic.kind in ('joint', 'ctrl'):
            if topic.kind == 'joint':
                stamp, pos, vel, eff, present, status = cdr_jit.decode_joint_states(
                    buf, ds, dl, np.frombuffer(topic.joint.encode(), np.uint8).copy(),
                    topic.strict)
            else:
                m = ds.shape[0]
                stamp, status = np.zeros(m, np.int64), np.full(m, cdr.FOREIGN, np.uint8)
                pos, vel, eff = np.full(m, np.nan), np.full(m, np.nan), np.full(m, np.nan)
                present = np.zeros(m, np.uint8)
            if np.any(status == cdr.NO_JOINT):
                i = int(np.flatnonzero(status == cdr.NO_JOINT)[0])
                msg = self._general(ch)(buf[ds[i]:ds[i] + dl[i]].tobytes())
                raise InputFileError(_no_joint(self.path, ch.topic, topic.joint,
                                               list(msg.name)))
            general = self._joint_general if topic.kind == 'joint' else self._ctrl_general
            for i in np.flatnonzero(status == cdr.FOREIGN):
                stamp[i], pos[i], vel[i], eff[i], present[i], status[i] = general(
                    ch, topic, buf[ds[i]:ds[i] + dl[i]].tobytes())
            ok = status == cdr.OK
            topic.corrupt += int(ok.size - np.count_nonzero(ok))
            self._store_joint(topic, stamp[ok], log[ok], pos[ok], vel[ok], eff[ok], present[ok])
        else:
            if ch.schema_name == schemas.FLOAT64:
                val, status = cdr_jit.decode_float64(buf, ds, dl)
            else:
                val = np.full(ds.shape[0], np.nan)
                status = np.full(ds.shape[0], cdr.FOREIGN, np.uint8)
            for i in np.flatnonzero(status == cdr.FOREIGN):
                val[i], status[i] = self._scalar_general(ch, buf[ds[i]:ds[i] + dl[i]].tobytes())
            ok = status == cdr.OK
            topic.corrupt += int(ok.size - np.count_nonzero(ok))
            topic.add(stamp=log[ok], value=val[ok])
            topic.messages += int(np.count_nonzero(ok))

    def _general(self, ch: _Channel) -> Callable[[bytes], Any]:
        from mcap_ros2.decoder import DecoderFactory
        key = id(ch)
        if key not in self._decoders:
            if ch.schema is None:
                raise InputFileError(f'{self.path}: {ch.topic} has no schema to decode it')
            dec = DecoderFactory().decoder_for('cdr', ch.schema)
            if dec is None:
                raise InputFileError(f'{self.path}: cannot decode {ch.topic} '
                                     f'(schema {ch.schema.encoding!r})')
            self._decoders[key] = dec
        return self._decoders[key]

    def _joint_general(self, ch: _Channel, topic: _Topic, data: bytes) -> tuple:
        """Decode with the general (mcap_ros2) decoder what the fast path does not handle."""
        try:
            m = self._general(ch)(data)
            return _joint_values(self.path, ch.topic, topic, _stamp(m), list(m.name),
                                 (m.position, m.velocity, m.effort))
        except InputFileError:
            raise
        except Exception:  # noqa: BLE001 - undecodable payload: counted as corrupt
            return (0, np.nan, np.nan, np.nan, 0, cdr.SHORT)

    def _ctrl_general(self, ch: _Channel, topic: _Topic, data: bytes) -> tuple:
        """A controller state's reference (``reference``, or ``desired`` before Iron)."""
        try:
            m = self._general(ch)(data)
            point = getattr(m, 'reference', None)
            if point is None or not (len(point.positions) or len(point.velocities)):
                point = getattr(m, 'desired', point)
            return _joint_values(self.path, ch.topic, topic, _stamp(m), list(m.joint_names),
                                 (point.positions, point.velocities, ()))
        except InputFileError:
            raise
        except Exception:  # noqa: BLE001 - undecodable payload: counted as corrupt
            return (0, np.nan, np.nan, np.nan, 0, cdr.SHORT)

    def _scalar_general(self, ch: _Channel, data: bytes) -> tuple[float, int]:
        try:
            return float(self._general(ch)(data).data), cdr.OK
        except InputFileError:
            raise
        except Exception:  # noqa: BLE001 - undecodable payload: counted as corrupt
            return np.nan, cdr.SHORT


#: types a reference topic may have: a JointState, or a ros2_control controller's state
CONTROLLER_STATES = ('control_msgs/msg/JointTrajectoryControllerState',
                     'control_msgs/msg/JointControllerState')


def _kind_of(path: Path, topic: str, kind: str, type_name: str) -> str:
    """Resolve what to decode from a wanted topic by its type; one-line error if unusable."""
    if kind == 'input':
        return 'joint' if type_name == schemas.JOINT_STATE else 'scalar'
    if kind == 'reference':
        if type_name == schemas.JOINT_STATE:
            return 'joint'
        if type_name == CONTROLLER_STATES[0]:
            return 'ctrl'
        raise InputFileError(f'{path}: {topic} has type {type_name or "(no schema)"}; a '
                             f'reference is a {schemas.JOINT_STATE} or a '
                             f'{CONTROLLER_STATES[0]}')
    if kind == 'joint' and type_name != schemas.JOINT_STATE:
        raise InputFileError(f'{path}: {topic} has type {type_name or "(no schema)"}, '
                             f'expected {schemas.JOINT_STATE}')
    return kind


def _no_joint(path: Path, topic: str, joint: str, names: list[str]) -> str:
    """The one-line error for a joint a message does not have, listing those it has."""
    has = ', '.join(names) if names else 'no named joints'
    return (f'{path}: joint {joint!r} not in {topic} (has: {has}); pick one with '
            '--joint NAME')


def _stamp(msg: Any) -> int:
    return int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)


def _joint_values(path: Path, topic_name: str, topic: _Topic, stamp: int, names: list[str],
                  arrays: tuple) -> tuple:
    """(stamp, position, velocity, effort, present bits, status) of the topic's joint."""
    if topic.joint in names:
        j = names.index(topic.joint)
    elif len(names) <= 1 and not topic.strict:
        j = 0
    else:
        raise InputFileError(_no_joint(path, topic_name, topic.joint, names))
    out, present = [], 0
    for bit, arr in zip((cdr.HAS_POSITION, cdr.HAS_VELOCITY, cdr.HAS_EFFORT), arrays):
        if len(arr) > j:
            out.append(float(arr[j]))
            present |= bit
        else:
            out.append(np.nan)
    return (stamp, *out, present, cdr.OK)


def _clean(path: Path, topic: str, field: str, t: np.ndarray, v: np.ndarray,
           unusable: dict[str, str] | None = None, signal: str = ''
           ) -> tuple[np.ndarray, np.ndarray] | None:
    """Sort, de-duplicate and drop non-finite samples of one signal (warning on stderr).

    A signal without any finite sample is returned as None and, instead of a warning,
    its reason goes into ``unusable[signal]``: the caller decides whether that is an
    error (a required signal) or a warning (an optional one).
    """
    if t.size == 0:
        return None
    finite = np.isfinite(v)
    bad = int(t.size - np.count_nonzero(finite))
    if bad == t.size and unusable is not None:
        unusable[signal] = f'all {bad} {topic} {field} samples are NaN/Inf'
        return None
    if bad:
        warn(f'{path.name}: {topic} {field}: dropped {bad} non-finite (NaN/Inf) samples')
        t, v = t[finite], v[finite]
        if t.size == 0:
            return None
    d = np.diff(t)
    if np.any(d <= 0):
        unsorted = int(np.count_nonzero(d < 0))
        order = np.argsort(t, kind='stable')
        t, v = t[order], v[order]
        keep = np.append(t[1:] != t[:-1], True)      # last message of each stamp
        dup = int(t.size - np.count_nonzero(keep))
        t, v = t[keep], v[keep]
        if field in ('position', 'value'):           # once per topic, not per field
            warn(f'{path.name}: {topic}: {unsorted} out-of-order stamps sorted, '
                 f'{dup} duplicate stamps dropped (kept the last)')
    return t, v


def _prepare(path: str | os.PathLike, namespace: str, signals: Collection[str] | None,
             require: Collection[str], topics: RunTopics | None = None
             ) -> tuple[Bag, int, dict[str, str | None], dict[str, Want], RunTopics]:
    """Check the files and the wanted signals.

    Returns the bag, its size, the topic of each signal (``joint_states`` is the first
    candidate until :func:`joint_states_of` has seen the messages; ``voltage`` None
    when the input is the joint's effort), what to decode per topic, and the selection.
    """
    topics = topics or RunTopics.of(namespace=namespace)
    bag = bags.locate(path)
    if bag.storage == 'mcap':
        for f in bag.files:
            size = f.stat().st_size
            if size == 0:
                raise InputFileError(f'{f}: empty file')
            if size < 8:
                raise InputFileError(f'{f}: not an MCAP file (only {size} bytes)')
    names: dict[str, str | None] = {'joint_states': topics.joint_states[0],
                                    'reference': topics.reference, 'voltage': topics.input}
    keep = set(Run.SIGNALS) if signals is None else set(signals) | {'position'}
    keep |= set(require)
    unknown = keep - set(Run.SIGNALS)
    if unknown:
        raise ParameterError(f'signals: unknown {sorted(unknown)}; choose from {Run.SIGNALS}')
    if topics.effort_input and 'voltage' in keep:
        keep.add('effort')
    states = Want('joint', frozenset(f for f in ('velocity', 'effort') if f not in keep),
                  topics.joint, topics.strict)
    wanted = {t: states for t in topics.joint_states}
    for option, topic, needed in (
            ('--reference', topics.reference, bool(keep & {'reference', 'reference_velocity'})),
            ('--input', topics.input, 'voltage' in keep)):
        if needed and topic in wanted:
            raise ParameterError(f'{option} {topic}: that is the measurement\'s topic; for '
                                 'the joint\'s own effort use --input effort')
    if keep & {'reference', 'reference_velocity'}:
        wanted[topics.reference] = Want('reference', frozenset(
            {'effort'} | ({'position'} if 'reference' not in keep else set())
            | ({'velocity'} if 'reference_velocity' not in keep else set())),
            topics.reference_joint, topics.reference_given)
    if 'voltage' in keep and topics.input is not None:
        wanted[topics.input] = Want('input', frozenset({'position', 'velocity'}),
                                    topics.input_joint, topics.strict)
    return bag, bag.size, names, wanted, topics


def joint_states_of(path: Path, reader: Any, names: dict[str, str | None], damage: Any,
                    topics: RunTopics) -> Any:
    """Warn about undecodable messages; return the joint-state topic or raise one line.

    The first candidate topic with messages is the measurement (``names`` is updated).
    Shared by :func:`read_run` and the streaming reader of
    :mod:`motor_comp.analysis.streaming` (same checks, same wording).
    """
    for tp in reader.topics.values():
        if tp.corrupt:
            warn(f'{path.name}: {tp.topic}: skipped {tp.corrupt} undecodable messages')
    for candidate in topics.joint_states:
        js = reader.topics.get(candidate)
        if js is not None and js.count():
            names['joint_states'] = candidate
            return js
    if damage is not None and reader.messages == 0:
        raise InputFileError(f'{path}: corrupt or truncated at byte {damage.offset} '
                             f'({damage.reason}); no messages could be read')
    raise InputFileError(f'{path}: no {" or ".join(topics.joint_states)} messages '
                         f'(topics: {_listing(reader.all_topics)}); '
                         'pick the JointState topic with --topic T')


def _listing(all_topics: Mapping[str, str]) -> str:
    """``/a [pkg/msg/T], /b [...]`` (what a bag holds, for one-line errors)."""
    if not all_topics:
        return 'none'
    return ', '.join(f'{t} [{ty}]' if ty else t for t, ty in sorted(all_topics.items()))


def _read(bag: Bag, reader: _Reader) -> _Damage | None:
    """Read every file of the bag into ``reader``; return the damage that stopped it."""
    try:
        if bag.storage == 'sqlite3':
            bags.feed_sqlite(bag, reader)
            return None
        for i, f in enumerate(bag.files):
            if i:
                reader.next_file(f)
            _complete, damage = reader.read()
            if damage is not None:
                if len(bag.files) > 1:
                    damage.reason = f'{f.name}: {damage.reason}'
                return damage
    except OSError as exc:
        raise InputFileError(f'{bag.path}: cannot read ({exc.strerror or exc})') from None
    return None


def read_run(path: str | os.PathLike, *, progress: bool = False, namespace: str = 'axis',
             signals: Collection[str] | None = None,
             require: Collection[str] | Mapping[str, str] = (),
             topics: RunTopics | None = None, exact_time: bool = False) -> Run:
    """Read an MCAP run into time-aligned arrays (see the module docstring for policies).

    Parameters
    ----------
    path : path-like
        MCAP file, or rosbag2 directory (MCAP or sqlite3 storage, split or not), with
        the joint states (required), reference and drive input (optional) of
        ``topics``.
    progress : bool
        Print a progress line on stderr while reading.
    namespace : str
        Topic namespace (DESIGN.md §5), ``axis`` by default (when ``topics`` is None).
    signals : collection of str, optional
        The :attr:`Run.SIGNALS` to return (``position`` always); the others are not
        kept, which saves memory on long runs.  Default: all.
    require : collection of str, or mapping of str to str
        Signals the caller cannot do without (e.g. ``voltage`` for the workbench):
        when one is absent or has no finite sample, one :class:`InputFileError` names
        the file, the topic and why, instead of a warning.  A mapping's values are
        appended to the message as a hint.
    topics : RunTopics, optional
        Which topics and joint the signals come from (a robot's bag: DESIGN.md §6);
        default: the §5 topics of ``namespace``, then ``/joint_states``.
    exact_time : bool
        Keep the stamps' nanoseconds: stamps beyond :data:`EXACT_STAMP_NS` (wall-clock
        time, e.g. a robot's bag) are counted from the first measurement (its stamp in
        ``metadata['time_origin_ns']``); as float seconds since 1970 they would be
        rounded to 0.24 µs, which the workbench's derivatives feel.  Stamps below
        (simulation time, imported tables) are kept as they are.

    Returns
    -------
    Run
        ``t`` [s] from the joint-state stamps; ``metadata`` holds the ``motor_comp``
        metadata record's keys, other records' keys as ``name/key``.

    Raises
    ------
    InputFileError
        Missing, empty, non-MCAP or unreadable file, no joint-state samples, or a
        required signal is absent.
    """
    bag, size, names, wanted, topics = _prepare(path, namespace, signals, require, topics)
    path = bag.path
    prog = Progress(bag.path.name, size, enabled=progress)
    reader = _Reader(bag.files[0], wanted, prog)
    try:
        damage = _read(bag, reader)
    finally:
        prog.finish()
    joint_states_of(path, reader, names, damage, topics)
    unusable: dict[str, str] = {}
    run = _assemble(path, reader, names, unusable, damaged=damage is not None,
                    effort_input=topics.effort_input, name=bag.name,
                    exact_time=exact_time)
    for field in require:
        if getattr(run, field) is None:
            raise InputFileError(_absent(path, reader, names, field, unusable, damage,
                                         hint=require.get(field, '')
                                         if isinstance(require, Mapping) else '',
                                         topics=topics))
    for field, why in unusable.items():
        warn(f'{path.name}: {why}; {field} treated as absent')
    if damage is not None:
        span = f'{run.t[0]:.6g}–{run.t[-1]:.6g} s' if len(run) else 'no samples'
        warn(f'{path.name}: {"unfinished" if "footer" in damage.reason else "damaged"} '
             f'file, reading stopped at byte {damage.offset} of {size} ({damage.reason}); '
             f'recovered {reader.messages} messages, {len(run)} samples, {span}')
    return run


def _absent(path: Path, reader: _Reader, names: Mapping[str, str | None], field: str,
            unusable: Mapping[str, str], damage: _Damage | None, hint: str,
            topics: RunTopics | None = None) -> str:
    """Return the one-line message for a required signal the file does not provide."""
    effort = field == 'voltage' and topics is not None and topics.effort_input
    topic = names[{'reference': 'reference', 'reference_velocity': 'reference',
                   'voltage': 'voltage'}.get(field, 'joint_states')] \
        if not effort else names['joint_states']
    if field in unusable:
        why = unusable[field]
    elif effort:
        why = (f'--input effort: joint {topics.joint!r} of {topic} has an empty effort '
               f'field; name the input topic with --input TOPIC (topics: '
               f'{_listing(reader.all_topics)})')
    elif topic not in reader.all_topics:
        why = f'no {topic} messages (topics: {_listing(reader.all_topics)})'
        if field == 'voltage':
            why += '; name the drive input with --input effort | TOPIC'
        elif field.startswith('reference'):
            why += '; name it with --reference TOPIC[:JOINT]'
    else:
        why = f'the {topic} messages carry no {field}'
    if damage is not None:
        why += f'; the file is damaged at byte {damage.offset}, only what precedes was read'
    return f'{path}: missing {field}: {why}' + (f'; {hint}' if hint else '')


def _masked(stamp: np.ndarray, values: np.ndarray, present: np.ndarray, bit: int
            ) -> tuple[np.ndarray, np.ndarray]:
    m = (present & bit) != 0
    if m.all():                    # the usual case: no copies
        return stamp, values
    return stamp[m], values[m]


def _assemble(path: Path, reader: _Reader, names: Mapping[str, str | None],
              unusable: dict[str, str], damaged: bool = False, effort_input: bool = False,
              name: str | None = None, exact_time: bool = False) -> Run:
    # Memory: each decoded array is concatenated once and released as soon as it has
    # been aligned, so the peak stays near the size of the decoded data.
    js = reader.topics[names['joint_states']]
    present = js.get('present').astype(np.uint8)
    stamp = js.get('stamp')
    series: dict[str, tuple[np.ndarray, np.ndarray] | None] = {}
    for field, bit in (('position', cdr.HAS_POSITION), ('velocity', cdr.HAS_VELOCITY),
                       ('effort', cdr.HAS_EFFORT)):
        if field not in js.drop:
            series[field] = _clean(path, js.topic, field,
                                   *_masked(stamp, js.get(field), present, bit),
                                   unusable, field)
    del stamp, present
    if series['position'] is None:
        why = unusable.get('position', f'{js.topic} carries no position samples')
        raise InputFileError(f'{path}: missing position: {why}')
    ref = reader.topics.get(names['reference'])
    if ref is not None and ref.count():
        rp = ref.get('present').astype(np.uint8)
        rs = ref.get('stamp')
        for field, key, bit in (('reference', 'position', cdr.HAS_POSITION),
                                ('reference_velocity', 'velocity', cdr.HAS_VELOCITY)):
            if key not in ref.drop:
                series[field] = _clean(path, ref.topic, key,
                                       *_masked(rs, ref.get(key), rp, bit), unusable, field)
        del rp, rs
    volt = reader.topics.get(names['voltage'] or '')
    if effort_input:
        series['voltage'] = series.get('effort')        # the same samples, same stamps
    elif volt is not None and volt.count() and volt.kind == 'joint':
        vp = volt.get('present').astype(np.uint8)
        series['voltage'] = _clean(path, volt.topic, 'effort',
                                   *_masked(volt.get('stamp'), volt.get('effort'), vp,
                                            cdr.HAS_EFFORT), unusable, 'voltage')
    elif volt is not None and volt.count():
        vt = volt.get('stamp').astype(np.int64)
        offset = -int(np.median(np.concatenate(js.log_minus_stamp)))
        if abs(offset) > 1_000_000_000:   # stamps and log times are different clocks
            vt = vt + offset
        series['voltage'] = _clean(path, volt.topic, 'value', vt, volt.get('value'),
                                   unusable, 'voltage')

    t_ns, position = series.pop('position')   # type: ignore[misc]
    present_series = {f: s for f, s in series.items() if s is not None}
    # the run starts at the first measurement at which every signal has a value
    start = max((int(s[0][0]) for s in present_series.values()), default=int(t_ns[0]))
    first = int(np.searchsorted(t_ns, start, side='left'))
    if first >= t_ns.size:
        late = max(present_series, key=lambda f: present_series[f][0][0])
        raise InputFileError(f'{path}: {late} starts after the last measurement '
                             '(topics do not overlap in time)')
    stop = t_ns.size
    if damaged and present_series:
        # A damaged file loses whole chunks, so a topic whose last messages were in the
        # lost part would be held over at the end of the run: stop at the last stamp
        # that every topic reached, so no returned sample is made up.
        end = min(int(s[0][-1]) for s in present_series.values())
        stop = max(int(np.searchsorted(t_ns, end, side='right')), first + 1)
    t_ns = t_ns[first:stop]
    aligned: dict[str, np.ndarray] = {}
    for field in list(present_series):
        ts, vs = present_series.pop(field)
        series[field] = None
        if ts.size == t_ns.size and np.array_equal(ts, t_ns):
            aligned[field] = vs                      # same stamps: nothing to align
        else:
            # sample and hold: the latest value stamped at or before each measurement
            aligned[field] = vs[np.searchsorted(ts, t_ns, side='right') - 1]
        del ts, vs
    meta: dict[str, Any] = {}
    for record, rec in reader.metadata.items():
        for k, v in rec.items():
            meta[k if record == METADATA_NAME else f'{record}/{k}'] = v
    t = t_ns / 1e9
    if exact_time and t_ns.size and abs(int(t_ns[0])) > EXACT_STAMP_NS:
        meta['time_origin_ns'] = int(t_ns[0])
        t = (t_ns - t_ns[0]) / 1e9
    return Run(t=t, position=position[first:stop], metadata=meta, name=name or path.stem,
               **aligned)
