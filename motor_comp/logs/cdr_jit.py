"""Compiled fallback: MCAP record scanning and CDR decoding of any message layout.

Why hand-written: the general decoders (``mcap_ros2``, ``rosbags``) build one Python
object per message, ≈ 7 µs each; a 1 kHz hour-long run has 10⁷ messages.  Here the
records of a decompressed MCAP chunk are walked by a compiled loop and the fields of
``sensor_msgs/JointState`` and ``std_msgs/Float64`` are read straight from the bytes
(little-endian CDR with the alignment rules of OMG CDR: each primitive aligned to its
size relative to the start of the body, after the 4-byte encapsulation header).
Anything unusual (big-endian, unknown encapsulation) is flagged so the caller falls
back to the general decoder.  Every read is bounds-checked: corrupt bytes give a status
code, never an out-of-bounds access.

The numpy path of :mod:`motor_comp.logs.cdr` handles the common case (chunks with
message indexes, one payload layout per topic) without compiling anything; this module
is imported only when a chunk needs it (no message index, layouts that vary), because
loading numba and its cached machine code costs about a second of start-up.
"""
from __future__ import annotations

import numpy as np
from numba import njit

from motor_comp.logs.cdr import (FOREIGN, HAS_EFFORT, HAS_POSITION, HAS_VELOCITY,
                                 MESSAGE_OPCODE, NO_JOINT, SHORT)

_MSG_HEADER = 2 + 4 + 8 + 8   # channel id, sequence, log time, publish time


@njit(cache=True)
def _u64(buf, p):
    v = np.uint64(0)
    for i in range(8):
        v |= np.uint64(buf[p + i]) << np.uint64(8 * i)
    return v


@njit(cache=True)
def _u32(buf, p):
    return (np.uint32(buf[p]) | (np.uint32(buf[p + 1]) << np.uint32(8))
            | (np.uint32(buf[p + 2]) << np.uint32(16)) | (np.uint32(buf[p + 3]) << np.uint32(24)))


@njit(cache=True)
def scan_records(buf):
    """Walk the records of a decompressed chunk (or of a run of top-level records).

    Parameters
    ----------
    buf : ndarray of uint8
        Concatenated MCAP records (opcode u8, length u64, body).

    Returns
    -------
    opcode, start, length, channel, log_time, publish_time, data_start, data_length, end
        Per record: opcode, offset of the body and its length; for message records
        (opcode 5) the channel id, log/publish time [ns] and the payload's offset and
        length (-1 elsewhere).  ``end`` is the offset where parsing stopped
        (``len(buf)`` when every record was complete).
    """
    n = buf.shape[0]
    cap = n // 9 + 1
    opcode = np.empty(cap, np.uint8)
    start = np.empty(cap, np.int64)
    length = np.empty(cap, np.int64)
    channel = np.empty(cap, np.int64)
    log_time = np.empty(cap, np.int64)
    pub_time = np.empty(cap, np.int64)
    data_start = np.empty(cap, np.int64)
    data_length = np.empty(cap, np.int64)
    k = 0
    p = 0
    while p + 9 <= n:
        op = buf[p]
        ln = _u64(buf, p + 1)
        if ln > np.uint64(n - p - 9):
            break
        body = p + 9
        ln_i = np.int64(ln)
        opcode[k] = op
        start[k] = body
        length[k] = ln_i
        if op == MESSAGE_OPCODE and ln_i >= _MSG_HEADER:
            channel[k] = np.int64(buf[body]) | (np.int64(buf[body + 1]) << 8)
            log_time[k] = np.int64(_u64(buf, body + 6))
            pub_time[k] = np.int64(_u64(buf, body + 14))
            data_start[k] = body + _MSG_HEADER
            data_length[k] = ln_i - _MSG_HEADER
        else:
            channel[k] = -1
            log_time[k] = -1
            pub_time[k] = -1
            data_start[k] = -1
            data_length[k] = -1
        k += 1
        p = body + ln_i
    return (opcode[:k], start[:k], length[:k], channel[:k], log_time[:k], pub_time[:k],
            data_start[:k], data_length[:k], p)


@njit(cache=True)
def _align(p, a):
    r = p % a
    return p if r == 0 else p + (a - r)


@njit(cache=True)
def _double_array(buf, base, end, p, index, bits, fview):
    """Read a ``float64[]``: returns (new p, value, present, ok)."""
    p = _align(p, 4)
    if base + p + 4 > end:
        return p, np.nan, False, False
    count = np.int64(_u32(buf, base + p))
    p += 4
    if count == 0:
        return p, np.nan, False, True
    p = _align(p, 8)
    if count < 0 or base + p + 8 * count > end or index >= count:
        return p, np.nan, False, False
    bits[0] = _u64(buf, base + p + 8 * index)
    return p + 8 * count, fview[0], True, True


@njit(cache=True)
def decode_joint_states(buf, data_start, data_length, joint, strict=False):
    """Decode ``sensor_msgs/JointState`` payloads (little-endian CDR).

    Parameters
    ----------
    buf : ndarray of uint8
        Buffer holding the payloads.
    data_start, data_length : ndarray of int64
        Offset and length of each payload in ``buf``.
    joint : ndarray of uint8
        Name of the joint to extract (UTF-8, no terminator).  A message with one joint
        (or no names) is taken whatever its name, unless ``strict``.
    strict : bool
        The joint must be named in every message (the user chose it).

    Returns
    -------
    stamp, position, velocity, effort, present, status
        Header stamp [ns], the joint's position, velocity and effort (NaN when the
        array is empty), ``present`` bits and a status code per message.
    """
    m = data_start.shape[0]
    stamp = np.zeros(m, np.int64)
    pos = np.full(m, np.nan)
    vel = np.full(m, np.nan)
    eff = np.full(m, np.nan)
    present = np.zeros(m, np.uint8)
    status = np.zeros(m, np.uint8)
    bits = np.zeros(1, np.uint64)
    fview = bits.view(np.float64)
    jl = joint.shape[0]
    for i in range(m):
        s = data_start[i]
        end = s + data_length[i]
        if data_length[i] < 4 or end > buf.shape[0]:
            status[i] = SHORT
            continue
        if buf[s] != 0 or buf[s + 1] != 1:
            status[i] = FOREIGN
            continue
        base = s + 4
        if base + 12 > end:
            status[i] = SHORT
            continue
        sec = np.int64(np.int32(_u32(buf, base)))
        nsec = np.int64(_u32(buf, base + 4))
        stamp[i] = sec * 1_000_000_000 + nsec
        strlen = np.int64(_u32(buf, base + 8))
        p = 12 + strlen
        p = _align(p, 4)
        if base + p + 4 > end:
            status[i] = SHORT
            continue
        nnames = np.int64(_u32(buf, base + p))
        p += 4
        index = -1
        ok = True
        for j in range(nnames):
            p = _align(p, 4)
            if base + p + 4 > end:
                ok = False
                break
            ln = np.int64(_u32(buf, base + p))
            p += 4
            if base + p + ln > end:
                ok = False
                break
            # the CDR string length counts the terminating NUL
            if index < 0 and ln == jl + 1:
                same = True
                for c in range(jl):
                    if buf[base + p + c] != joint[c]:
                        same = False
                        break
                if same:
                    index = j
            p += ln
        if not ok:
            status[i] = SHORT
            continue
        if index < 0:
            if nnames <= 1 and not strict:
                index = 0
            else:
                status[i] = NO_JOINT
                continue
        p, v, has, ok = _double_array(buf, base, end, p, index, bits, fview)
        if not ok:
            status[i] = SHORT
            continue
        pos[i] = v
        flags = HAS_POSITION if has else 0
        p, v, has, ok = _double_array(buf, base, end, p, index, bits, fview)
        if not ok:
            status[i] = SHORT
            continue
        vel[i] = v
        flags |= HAS_VELOCITY if has else 0
        p, v, has, ok = _double_array(buf, base, end, p, index, bits, fview)
        if not ok:
            status[i] = SHORT
            continue
        eff[i] = v
        flags |= HAS_EFFORT if has else 0
        present[i] = flags
    return stamp, pos, vel, eff, present, status


@njit(cache=True)
def decode_float64(buf, data_start, data_length):
    """Decode ``std_msgs/Float64`` payloads (little-endian CDR): (value, status) per message."""
    m = data_start.shape[0]
    val = np.full(m, np.nan)
    status = np.zeros(m, np.uint8)
    bits = np.zeros(1, np.uint64)
    fview = bits.view(np.float64)
    for i in range(m):
        s = data_start[i]
        if data_length[i] < 12 or s + 12 > buf.shape[0]:
            status[i] = SHORT
            continue
        if buf[s] != 0 or buf[s + 1] != 1:
            status[i] = FOREIGN
            continue
        bits[0] = _u64(buf, s + 4)
        val[i] = fview[0]
    return val, status
