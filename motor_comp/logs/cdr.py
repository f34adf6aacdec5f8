"""CDR encoding/decoding of the §5 messages in bulk with numpy.

Why hand-written: the general decoders (``mcap_ros2``, ``rosbags``) build one Python
object per message, several µs each; an hour at 1 kHz is 10⁷ messages.  Messages of one
topic almost always share one byte layout (same joint names, same array lengths, same
frame id): then the payloads of a chunk are rows of an ``(n, L)`` byte matrix (a
zero-copy strided view when the records repeat with a constant stride) and each field
is a column slice viewed as the right little-endian type.  The layout is taken from
the first payload (:func:`joint_state_layout`, a plain CDR walk: every primitive
aligned to its size relative to the body after the 4-byte encapsulation header) and
all the bytes that define it are verified equal in every row; otherwise the caller
uses the compiled per-message decoder of :mod:`motor_comp.logs.cdr_jit`, and the
general decoder for anything not little-endian CDR.
"""
from __future__ import annotations

import dataclasses
import struct

import numpy as np

#: per-message status codes of the decoders
OK = 0
SHORT = 1        # payload ends before the fields do (corrupt/truncated)
FOREIGN = 2      # not little-endian plain CDR: use the general decoder
NO_JOINT = 3     # JointState without the requested joint name (several joints)

#: ``present`` bits of the JointState decoders
HAS_POSITION = 1
HAS_VELOCITY = 2
HAS_EFFORT = 4

MESSAGE_OPCODE = 0x05
CDR_LE = b'\x00\x01'


@dataclasses.dataclass(frozen=True)
class JointStateLayout:
    """Byte layout of a one-layout JointState payload.

    Attributes
    ----------
    length : int
        Payload length [B].
    values : tuple of (int or None)
        Offsets of the selected joint's position, velocity, effort (None: empty array).
    variable : tuple of (int, int)
        Byte ranges that differ between messages (stamp, array contents); every other
        byte defines the layout and must match.
    """

    length: int
    values: tuple[int | None, int | None, int | None]
    variable: tuple[tuple[int, int], ...]

    def constant_mask(self) -> np.ndarray:
        """Boolean mask of the layout-defining bytes."""
        m = np.ones(self.length, bool)
        for a, b in self.variable:
            m[a:b] = False
        return m


def joint_state_layout(data: bytes, joint: bytes, strict: bool = False
                       ) -> JointStateLayout | int:
    """Layout of one JointState payload, or a status code (FOREIGN, SHORT, NO_JOINT).

    A message with one joint (or none named) is taken whatever its name unless
    ``strict`` (the user named the joint).
    """
    if len(data) < 4 or data[:2] != CDR_LE:
        return FOREIGN if len(data) >= 4 else SHORT
    body = memoryview(data)[4:]
    n = len(body)

    def align(p: int, a: int) -> int:
        return p + (-p) % a

    def u32(p: int) -> int:
        if p + 4 > n:
            raise IndexError
        return struct.unpack_from('<I', body, p)[0]
    try:
        p = 8 + 4 + u32(8)                      # stamp, frame_id
        p = align(p, 4)
        names = []
        count = u32(p)
        p += 4
        for _ in range(count):
            p = align(p, 4)
            ln = u32(p)
            if p + 4 + ln > n:
                raise IndexError
            names.append(bytes(body[p + 4:p + 4 + ln - 1]))
            p += 4 + ln
        if joint in names:
            j = names.index(joint)
        elif len(names) <= 1 and not strict:
            j = 0
        else:
            return NO_JOINT
        values: list[int | None] = []
        variable = [(4, 12)]
        for _ in range(3):
            p = align(p, 4)
            count = u32(p)
            p += 4
            if count:
                p = align(p, 8)
                if p + 8 * count > n or j >= count:
                    raise IndexError
                values.append(4 + p + 8 * j)
                variable.append((4 + p, 4 + p + 8 * count))
                p += 8 * count
            else:
                values.append(None)
    except IndexError:
        return SHORT
    return JointStateLayout(length=len(data), values=(values[0], values[1], values[2]),
                            variable=tuple(variable))


def payload_matrix(buf: np.ndarray, start: np.ndarray, length: int) -> np.ndarray:
    """Return the ``(n, length)`` bytes at ``start`` (a strided view when evenly spaced)."""
    n = start.shape[0]
    if n > 1:
        d = np.diff(start)
        if d[0] >= length and np.all(d == d[0]):
            return np.lib.stride_tricks.as_strided(
                buf[int(start[0]):], shape=(n, length), strides=(int(d[0]), 1),
                writeable=False)
    return buf[start[:, None] + np.arange(length)]


def _column(rows: np.ndarray, offset: int, dtype: str) -> np.ndarray:
    size = np.dtype(dtype).itemsize
    return np.ascontiguousarray(rows[:, offset:offset + size]).view(dtype)[:, 0]


def decode_joint_states_fixed(rows: np.ndarray, layout: JointStateLayout
                              ) -> tuple[np.ndarray, ...] | None:
    """Decode payload rows of one layout: (stamp [ns], pos, vel, eff, present) or None.

    None when a layout-defining byte differs in some row (the layout varies).
    """
    mask = layout.constant_mask()
    # compare the layout-defining byte ranges of every row with the first row's
    edges = np.flatnonzero(np.diff(np.concatenate(([0], mask.view(np.int8), [0]))))
    n = rows.shape[0]
    for a, b in zip(edges[::2], edges[1::2]):
        if not np.array_equal(rows[:, a:b], np.broadcast_to(rows[0, a:b], (n, b - a))):
            return None
    sec = _column(rows, 4, '<i4').astype(np.int64)
    stamp = sec * 1_000_000_000 + _column(rows, 8, '<u4')
    out = []
    present = 0
    for bit, off in zip((HAS_POSITION, HAS_VELOCITY, HAS_EFFORT), layout.values):
        if off is None:
            out.append(None)
        else:
            out.append(_column(rows, off, '<f8'))
            present |= bit
    return stamp, out[0], out[1], out[2], np.full(n, present, np.uint8)


def decode_float64_fixed(rows: np.ndarray) -> np.ndarray | None:
    """Values of 12-byte little-endian ``std_msgs/Float64`` payload rows (None otherwise)."""
    if rows.shape[1] != 12 or not np.all(rows[:, :2] == np.frombuffer(CDR_LE, np.uint8)):
        return None
    return _column(rows, 4, '<f8')


# --------------------------------------------------------------------------- encoding

def _stamp_fields(stamp_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    sec = np.floor_divide(stamp_ns, 1_000_000_000)
    return sec.astype('<i4'), (stamp_ns - sec * 1_000_000_000).astype('<u4')


def encode_joint_states(stamp_ns: np.ndarray, position: np.ndarray,
                        velocity: np.ndarray | None = None,
                        effort: np.ndarray | None = None, *,
                        name: str = 'axis', frame_id: str = '') -> np.ndarray:
    """CDR payloads of one-joint ``JointState`` messages, as an ``(n, L)`` uint8 array.

    All messages share one layout (same name, same arrays present), so they are built
    in bulk as a numpy structured array instead of one serialisation call each.
    """
    n = stamp_ns.shape[0]
    fields: list[tuple[str, str]] = [('encap', '4u1'), ('sec', '<i4'), ('nsec', '<u4'),
                                     ('frame_len', '<u4')]
    frame = frame_id.encode() + b'\0'
    p = 12 + len(frame)
    fields.append(('frame', f'{len(frame)}u1'))
    pad = (-p) % 4
    if pad:
        fields.append(('pad0', f'{pad}u1'))
    p += pad
    nm = name.encode() + b'\0'
    fields += [('nnames', '<u4'), ('name_len', '<u4'), ('name', f'{len(nm)}u1')]
    p += 8 + len(nm)
    arrays = [('position', position), ('velocity', velocity), ('effort', effort)]
    for i, (key, arr) in enumerate(arrays):
        pad = (-p) % 4
        if pad:
            fields.append((f'pad{i}a', f'{pad}u1'))
        p += pad
        fields.append((f'{key}_count', '<u4'))
        p += 4
        if arr is not None:
            pad = (-p) % 8
            if pad:
                fields.append((f'pad{i}b', f'{pad}u1'))
            p += pad
            fields.append((key, '<f8'))
            p += 8
    dtype = np.dtype(fields)
    rec = np.zeros(n, dtype)
    rec['encap'] = (0, 1, 0, 0)
    rec['sec'], rec['nsec'] = _stamp_fields(stamp_ns)
    rec['frame_len'] = len(frame)
    rec['frame'] = np.frombuffer(frame, np.uint8)
    rec['nnames'] = 1
    rec['name_len'] = len(nm)
    rec['name'] = np.frombuffer(nm, np.uint8)
    for key, arr in arrays:
        if arr is not None:
            rec[f'{key}_count'] = 1
            rec[key] = arr
    return rec.view(np.uint8).reshape(n, dtype.itemsize)


def encode_float64(values: np.ndarray) -> np.ndarray:
    """CDR payloads of ``std_msgs/Float64`` messages, as an ``(n, 12)`` uint8 array."""
    values = np.asarray(values, dtype='<f8')
    out = np.zeros((values.shape[0], 12), np.uint8)
    out[:, 1] = 1
    out[:, 4:] = values.reshape(-1, 1).view(np.uint8)
    return out
