"""Robots' bags: an MCAP file or a rosbag2 directory (MCAP or sqlite3 storage, split or not).

:func:`locate` finds the files of what the user named; :func:`feed_sqlite` hands the
messages of a sqlite3-storage bag to the MCAP reader's decoders.

Why rosbags for sqlite3: it is the well-kept pure-Python reader of both rosbag2
storages (metadata, split files, connections, message definitions).  Only its
iteration is used: the raw CDR payloads are gathered per topic into byte buffers and
decoded by our own batch decoders (:mod:`~motor_comp.logs.cdr`,
:mod:`~motor_comp.logs.cdr_jit`), which is where the time goes with the general
decoders (one Python object per message); ``bench/bag_read.py`` measures the ratio.
rosbag2 MCAP storage is read by our own MCAP reader, file after file, as before.
"""
from __future__ import annotations

import dataclasses
import re
import types
from pathlib import Path
from typing import Any

import numpy as np

from motor_comp.errors import InputFileError
from motor_comp.logs import schemas

#: messages gathered per topic before a batch is decoded (bounded memory, few calls)
BATCH = 1 << 16


@dataclasses.dataclass(frozen=True)
class Bag:
    """The files of one recording.

    Parameters
    ----------
    path : Path
        What the user named (a file, or a rosbag2 directory).
    storage : str
        ``mcap`` or ``sqlite3``.
    files : tuple of Path
        The storage files in recording order (split bags have several).
    """

    path: Path
    storage: str
    files: tuple[Path, ...]

    @property
    def size(self) -> int:
        """Total size of the storage files [bytes]."""
        return sum(f.stat().st_size for f in self.files)

    @property
    def name(self) -> str:
        """Short label: the file stem, or the bag directory's name."""
        return self.path.stem if self.path.is_file() else self.path.name


def _natural(p: Path) -> list:
    """Sort key: split files ``bag_2`` before ``bag_10``."""
    return [int(t) if t.isdigit() else t for t in re.split(r'(\d+)', p.name)]


def locate(path: str | Path) -> Bag:
    """Return the storage files of an MCAP file or a rosbag2 directory (one-line errors)."""
    path = Path(path)
    if not path.exists():
        raise InputFileError(f'{path}: no such file')
    if path.is_file() and path.suffix == '.db3':
        if (path.parent / 'metadata.yaml').is_file():
            return locate(path.parent)
        raise InputFileError(f'{path}: a sqlite3 bag file without its metadata.yaml; pass '
                             'the bag directory')
    if path.is_dir():
        return _directory(path)
    if not path.is_file():
        raise InputFileError(f'{path}: not a file')
    return Bag(path, 'mcap', (path,))


def _directory(path: Path) -> Bag:
    meta = path / 'metadata.yaml'
    if meta.is_file():
        import yaml
        try:
            with open(meta, encoding='utf-8') as f:
                info = (yaml.safe_load(f) or {})['rosbag2_bagfile_information']
            storage = str(info.get('storage_identifier', ''))
            rel = [str(r) for r in info.get('relative_file_paths') or ()]
        except (OSError, UnicodeDecodeError, yaml.YAMLError, KeyError, TypeError,
                AttributeError):
            raise InputFileError(f'{meta}: not a rosbag2 metadata file') from None
        if storage not in ('mcap', 'sqlite3'):
            raise InputFileError(f'{path}: rosbag2 storage {storage[:40]!r} is not read '
                                 '(mcap or sqlite3)')
        files = tuple(path / r for r in rel)
        missing = [f.name for f in files if not f.is_file()]
        if missing or not files:
            raise InputFileError(f'{path}: the bag lists {len(files)} files, '
                                 f'{len(missing)} missing ({", ".join(missing[:3])})')
        return Bag(path, storage, files)
    mcaps = sorted(path.glob('*.mcap'), key=_natural)
    if mcaps:
        return Bag(path, 'mcap', tuple(mcaps))
    if list(path.glob('*.db3')):
        raise InputFileError(f'{path}: sqlite3 bag files without metadata.yaml; a sqlite3 '
                             'bag is read through its metadata')
    raise InputFileError(f'{path}: a directory with no .mcap file and no rosbag2 '
                         'metadata.yaml')


def _schema(conn: Any, typestore: Any) -> Any:
    """A schema the general (mcap_ros2) decoder takes, from the bag or rosbags' store.

    Bags recorded before Iron carry no message definitions: the standard types are
    taken from rosbags' Jazzy type store; others cannot be decoded (None).
    """
    text = conn.msgdef.data if conn.msgdef is not None else ''
    if not text:
        try:
            text, _ = typestore.generate_msgdef(conn.msgtype, ros_version=2)
        except Exception:  # noqa: BLE001 - a type the store lacks: no general decoder
            return None
    return types.SimpleNamespace(id=conn.id, name=conn.msgtype, encoding='ros2msg',
                                 data=text.encode())


def feed_sqlite(bag: Bag, reader: Any) -> None:
    """Decode the wanted topics of a sqlite3-storage bag into an MCAP ``_Reader``.

    The reader's channel registration, batch decoders and topic accumulators are the
    ones its MCAP chunks go through, so both storages give the same arrays.
    """
    try:
        from rosbags.rosbag2 import Reader
        from rosbags.rosbag2.errors import ReaderError
        from rosbags.typesys import Stores, get_typestore
    except ImportError:   # pragma: no cover - rosbags is a dependency
        raise InputFileError(f'{bag.path}: reading sqlite3 bags needs the rosbags '
                             'package (pip install rosbags)') from None
    try:
        with Reader(bag.path) as b:
            store = get_typestore(Stores.ROS2_JAZZY)
            wanted = []
            for c in b.connections:
                fmt = getattr(c.ext, 'serialization_format', 'cdr')
                reader.add_channel(c.id, c.topic, schemas.normalise_type(c.msgtype), fmt,
                                   _schema(c, store) if c.topic in reader.wanted else None)
                if c.id in reader.channels:
                    wanted.append(c)
            pending: dict[int, tuple[list[int], list[bytes]]] = {}
            # (rosbags reads every connection when given none)
            for conn, stamp, raw in b.messages(connections=wanted) if wanted else ():
                logs, datas = pending.setdefault(conn.id, ([], []))
                logs.append(stamp)
                datas.append(raw)
                if len(datas) >= BATCH:
                    _decode(reader, conn.id, pending.pop(conn.id))
            for cid, batch in pending.items():
                _decode(reader, cid, batch)
    except ReaderError as exc:
        raise InputFileError(f'{bag.path}: cannot read the bag ({exc})') from None


def _decode(reader: Any, cid: int, batch: tuple[list[int], list[bytes]]) -> None:
    logs, datas = batch
    lengths = np.fromiter(map(len, datas), np.int64, len(datas))
    starts = np.zeros_like(lengths)
    np.cumsum(lengths[:-1], out=starts[1:])
    buf = np.frombuffer(b''.join(datas), np.uint8)
    log = np.asarray(logs, np.int64)
    reader.messages += int(log.size)
    reader.decode_batch(cid, buf, log, starts, lengths)


def joint_names(path: str | Path, candidates: tuple[str, ...], *, messages: int = 20
                ) -> tuple[str, list[str]]:
    """The JointState topic (first candidate present) and its joints, in first-seen order.

    Reads the first ``messages`` messages of the topic with the general decoders (a
    few messages: speed does not matter here); the joints may change order between
    messages, so their names are gathered, not taken from one message.
    """
    from mcap_ros2.decoder import DecoderFactory
    bag = locate(path)
    found: dict[str, Any] = {}
    if bag.storage == 'sqlite3':
        from rosbags.rosbag2 import Reader
        from rosbags.typesys import Stores, get_typestore
        with Reader(bag.path) as b:
            conns = {c.topic: c for c in b.connections}
            topic = next((t for t in candidates if t in conns), None)
            if topic is not None:
                conn = conns[topic]
                dec = DecoderFactory().decoder_for('cdr', _schema(
                    conn, get_typestore(Stores.ROS2_JAZZY)))
                for i, (_c, _t, raw) in enumerate(b.messages(connections=[conn])):
                    found.update(dict.fromkeys(dec(raw).name))
                    if i + 1 >= messages:
                        break
            listing = {c.topic: schemas.normalise_type(c.msgtype) for c in b.connections}
    else:
        from mcap.reader import make_reader
        topic, listing = None, {}
        for f in bag.files:
            with open(f, 'rb') as stream:
                try:
                    it = make_reader(stream, decoder_factories=[DecoderFactory()])
                    summary = it.get_summary()
                    chans = summary.channels.values() if summary is not None else ()
                    listing.update({c.topic: schemas.normalise_type(
                        summary.schemas[c.schema_id].name) for c in chans})
                    topic = next((t for t in candidates if t in listing), None)
                    if topic is None:
                        continue
                    n = 0
                    for _s, _c, _m, msg in it.iter_decoded_messages(topics=[topic]):
                        found.update(dict.fromkeys(msg.name))
                        n += 1
                        if n >= messages:
                            break
                except InputFileError:
                    raise
                except Exception as exc:  # noqa: BLE001 - a damaged file: one line
                    raise InputFileError(f'{f}: cannot list the joints ({type(exc).__name__})'
                                         ) from None
            if found:
                break
    if topic is None:
        has = ', '.join(f'{t} [{ty}]' for t, ty in sorted(listing.items())) or 'none'
        raise InputFileError(f'{bag.path}: no {" or ".join(candidates)} (topics: {has}); '
                             'pick the JointState topic with --topic T')
    return topic, list(found)
