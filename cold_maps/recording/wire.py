"""Protobuf wire encoding of the two Foxglove messages the recording writes, built as bytes
with numpy instead of through foxglove-sdk's message objects (one object per point).

The bytes equal foxglove-sdk's ``encode()`` of the same message (prost: fields in number
order, proto3 zero scalars left out, ``-0.0`` included, sub-messages that are set written
even when empty); ``tests/test_recording_wire.py`` checks them against it. Only what the
recording sets is encoded: ``foxglove.SceneUpdate`` with one ``All`` deletion and one
``LINE_STRIP`` entity per line (identity pose, one colour), and ``foxglove.FrameTransform``.
Timestamps past 2106 (2**32 s), which the SDK refuses, are encoded as protobuf's int64.
"""

from __future__ import annotations

import math
import struct
from typing import Final, Sequence

import numpy as np

from cold_maps.network.lane_strip import NDArrayFloat

NS_PER_S: Final[int] = 1_000_000_000
_POINT: Final = np.dtype([("tag", "u1"), ("size", "u1"), ("x_tag", "u1"), ("x", "<f8"), ("y_tag", "u1"),
                          ("y", "<f8")])
"""A ``Point3`` field of a ``LinePrimitive`` with x and y set (z = 0 is left out): 20 bytes."""
_POINT_TAG: Final[int] = 0x2A  # LinePrimitive.points, field 5, length-delimited
_DOUBLE: Final = struct.Struct("<d")


_ONE_BYTE: Final[tuple[bytes, ...]] = tuple(bytes((value,)) for value in range(0x80))
"""The varints of 0 ... 127 (most lengths and tags)."""


def _varint(value: int) -> bytes:
    """``value >= 0`` as a protobuf varint."""
    if value < 0x80:
        return _ONE_BYTE[value]
    out = bytearray()
    while value > 0x7F:
        out.append(value & 0x7F | 0x80)
        value >>= 7
    out.append(value)
    return bytes(out)


def _nested(tag: int, payload: bytes) -> bytes:
    """A length-delimited field (``tag``: field number << 3 | 2, below 128)."""
    return _ONE_BYTE[tag] + _varint(len(payload)) + payload


def _double(tag: int, value: float) -> bytes:
    """A double field (``tag``: field number << 3 | 1); nothing for 0.0 and -0.0 (proto3)."""
    return b"" if value == 0.0 else _ONE_BYTE[tag] + _DOUBLE.pack(value)


def _string(tag: int, text: str) -> bytes:
    return _nested(tag, text.encode()) if text else b""


def timestamp(ns: int) -> bytes:
    """A ``google.protobuf.Timestamp`` of ``ns >= 0`` ns since the Unix epoch."""
    seconds, nanos = divmod(ns, NS_PER_S)
    return (b"\x08" + _varint(seconds) if seconds else b"") + (b"\x10" + _varint(nanos) if nanos else b"")


def _xyz(x: float, y: float, z: float) -> bytes:
    return _double(0x09, x) + _double(0x11, y) + _double(0x19, z)


def _quaternion(x: float, y: float, z: float, w: float) -> bytes:
    return _xyz(x, y, z) + _double(0x21, w)


def color(rgba: tuple[float, float, float, float]) -> bytes:
    """A ``foxglove.Color`` of (r, g, b, a) in 0 ... 1."""
    return _quaternion(*rgba)


def points(coordinates: NDArrayFloat) -> tuple[bytes, NDArrayFloat]:
    """The ``LinePrimitive.points`` fields of ``(M, 2)`` points (m; z = 0), concatenated,
    and the byte offset where each point's field starts (``M + 1`` offsets)."""
    records = np.empty(len(coordinates), _POINT)
    records["tag"], records["x_tag"], records["y_tag"] = _POINT_TAG, 0x09, 0x11
    records["x"], records["y"] = coordinates[:, 0], coordinates[:, 1]
    has_x, has_y = coordinates[:, 0] != 0.0, coordinates[:, 1] != 0.0
    records["size"] = 9 * has_x + 9 * has_y
    raw = records.view(np.uint8).reshape(-1, _POINT.itemsize)
    if has_x.all() and has_y.all():
        data = raw.tobytes()
    else:  # a zero coordinate is left out of its point
        keep = np.ones(raw.shape, dtype=bool)
        keep[:, 2:11], keep[:, 11:] = has_x[:, None], has_y[:, None]
        data = raw[keep].tobytes()
    return data, np.concatenate(([0], np.cumsum(2 + records["size"].astype(np.int64))))


def scene_updates(updates: Sequence[tuple[int, Sequence[str], tuple[float, float, float, float]]],
                  coordinates: NDArrayFloat, counts: Sequence[int], thickness_m: float, frame_id: str) -> list[bytes]:
    """Encoded ``foxglove.SceneUpdate`` messages, as ``recorder.scene_update`` builds them.

    ``updates``: per message (log time ns, entity ids, colour); its lines are the next
    ``len(ids)`` runs of ``counts`` points of ``coordinates`` (``(M, 2)``, world frame, m,
    as drawn), each ``thickness_m`` wide, in the frame ``frame_id``.
    """
    data, offsets = points(coordinates)
    sizes = np.asarray(counts, dtype=np.int64)
    ends = np.cumsum(sizes)
    starts = offsets[ends - sizes].tolist()
    stops = offsets[ends].tolist()
    pose = _nested(0x12, _nested(0x0A, b"") + _nested(0x12, _quaternion(0.0, 0.0, 0.0, 1.0)))
    head = pose + _double(0x19, thickness_m)
    frame = _string(0x12, frame_id)
    encoded, line = [], 0
    for ns, names, rgba in updates:
        stamp = _nested(0x0A, timestamp(ns))
        tail = _nested(0x32, color(rgba))
        message = [_nested(0x0A, stamp + b"\x10\x01")]  # deletion: type All
        for name in names:
            body = head + data[starts[line]:stops[line]] + tail
            message.append(_nested(0x12, stamp + frame + _string(0x1A, name) + _nested(0x5A, body)))
            line += 1
        encoded.append(b"".join(message))
    return encoded


def frame_transform(ns: int, parent: str, child: str, x: float, y: float, yaw: float) -> bytes:
    """An encoded ``foxglove.FrameTransform`` ``parent`` -> ``child``: (x m, y m) heading
    ``yaw`` (rad, counter-clockwise from x), z = 0, at log time ``ns``."""
    return (_nested(0x0A, timestamp(ns)) + _string(0x12, parent) + _string(0x1A, child)
            + _nested(0x22, _xyz(x, y, 0.0)) + _nested(0x2A, _quaternion(0.0, 0.0, math.sin(0.5 * yaw),
                                                                           math.cos(0.5 * yaw))))
