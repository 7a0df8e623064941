"""Arrow columns to and from numpy through their buffers.

pyarrow's converters (``pa.array``, ``Array.to_numpy``, ``np.asarray`` of an array) check
whether their input is a pandas object, and their first call imports pandas (about 0.4 s of
CPU in every process that records frames). The columns of the frame records are plain
(int64, float64, bool, string and list<float64>, with nulls), so they are built from and read
through their buffers instead, which touches neither pandas nor a Python loop over values.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any, Sequence

import numpy as np

if TYPE_CHECKING:
    import pyarrow as pa

_NUMPY_TYPES = {"int32": np.int32, "int64": np.int64, "double": np.float64}
"""numpy dtype of each fixed-width Arrow type these functions handle, by Arrow type name."""


def _bits(values: np.ndarray) -> pa.Buffer:
    """A little-endian bitmap of the booleans ``values``."""
    import pyarrow as pa

    return pa.py_buffer(np.packbits(np.asarray(values, dtype=bool), bitorder="little"))


def _validity(valid: np.ndarray | None, length: int) -> tuple[pa.Buffer | None, int]:
    """(bitmap, null count) of ``valid`` (None or all True: no bitmap)."""
    if valid is None:
        return None, 0
    valid = np.asarray(valid, dtype=bool)
    if len(valid) != length:
        raise ValueError(f"validity of {len(valid)} values for a column of {length}")
    nulls = length - int(np.count_nonzero(valid))
    return (_bits(valid), nulls) if nulls else (None, 0)


def from_numpy(values: np.ndarray, arrow_type: pa.DataType, valid: np.ndarray | None = None) -> pa.Array:
    """An int32, int64, float64 or bool column of ``values`` (``valid`` False: null)."""
    import pyarrow as pa

    length = len(values)
    bitmap, nulls = _validity(valid, length)
    if arrow_type == pa.bool_():
        data = _bits(values)
    else:
        data = pa.py_buffer(np.ascontiguousarray(values, dtype=_NUMPY_TYPES[str(arrow_type)]))
    return pa.Array.from_buffers(arrow_type, length, [bitmap, data], null_count=nulls)


def from_strings(values: Sequence[str | None]) -> pa.Array:
    """A string column of ``values`` (None: null); ASCII strings without a null are encoded
    in one piece (a character a byte: the offsets are the strings' lengths)."""
    import pyarrow as pa

    if None not in values:
        text = "".join(values)  # type: ignore[arg-type]  # no None
        if text.isascii():
            offsets = np.zeros(len(values) + 1, dtype=np.int32)
            np.cumsum(list(map(len, values)), out=offsets[1:])  # type: ignore[arg-type]  # no None
            return pa.Array.from_buffers(pa.string(), len(values),
                                         [None, pa.py_buffer(offsets), pa.py_buffer(text.encode("ascii"))],
                                         null_count=0)
    encoded = [b"" if v is None else v.encode("utf-8") for v in values]
    offsets = np.zeros(len(encoded) + 1, dtype=np.int32)
    np.cumsum([len(e) for e in encoded], out=offsets[1:])
    bitmap, nulls = _validity(np.array([v is not None for v in values], dtype=bool), len(values))
    return pa.Array.from_buffers(pa.string(), len(values), [bitmap, pa.py_buffer(offsets), pa.py_buffer(b"".join(encoded))],
                                 null_count=nulls)


def repeated_string(value: str, length: int) -> pa.Array:
    """A string column of ``length`` copies of ``value`` (no nulls): :func:`from_strings` of
    them, without encoding each."""
    import pyarrow as pa

    encoded = value.encode("utf-8")
    offsets = np.arange(length + 1, dtype=np.int32) * np.int32(len(encoded))
    return pa.Array.from_buffers(pa.string(), length, [None, pa.py_buffer(offsets), pa.py_buffer(encoded * length)],
                                 null_count=0)


def from_lists(arrays: Sequence[np.ndarray | None]) -> pa.Array:
    """A list<float64> column of ``arrays`` (None: null)."""
    import pyarrow as pa

    offsets = np.zeros(len(arrays) + 1, dtype=np.int32)
    np.cumsum([0 if a is None else len(a) for a in arrays], out=offsets[1:])
    present = [a for a in arrays if a is not None and len(a)]
    values = from_numpy(np.concatenate(present) if present else np.empty(0), pa.float64())
    bitmap, nulls = _validity(np.array([a is not None for a in arrays], dtype=bool), len(arrays))
    return pa.Array.from_buffers(pa.list_(pa.float64()), len(arrays), [bitmap, pa.py_buffer(offsets)],
                                 null_count=nulls, children=[values])


def from_values(values: Sequence[Any], arrow_type: pa.DataType) -> pa.Array:
    """A column of ``arrow_type`` (int64, float64, bool or string) of Python values (None: null)."""
    import pyarrow as pa

    if arrow_type == pa.string():
        return from_strings(values)
    dtype = bool if arrow_type == pa.bool_() else _NUMPY_TYPES[str(arrow_type)]
    if None not in values:
        return from_numpy(np.array(values, dtype=dtype), arrow_type)
    valid = np.array([v is not None for v in values], dtype=bool)
    filled = np.array([0 if v is None else v for v in values], dtype=dtype)
    return from_numpy(filled, arrow_type, valid)


def to_strings(column: pa.Array) -> list[str | None]:
    """The values of a string column (``Array.to_pylist``), each distinct value one shared
    ``str``: a long column of few values costs a pointer per row, not a string object
    (deduplicated here: ``Array.dictionary_encode`` would import ``pyarrow.compute``, 0.1 s)."""
    shared: dict[str, str] = {}
    return [None if value is None else shared.setdefault(value, value) for value in column.to_pylist()]


def nulls(column: pa.Array) -> np.ndarray:
    """Where ``column`` is null, as a bool array."""
    bitmap = column.buffers()[0]
    if bitmap is None or column.null_count == 0:
        return np.zeros(len(column), dtype=bool)
    return ~_unpack(bitmap, column.offset, len(column))


def _unpack(bitmap: pa.Buffer, offset: int, length: int) -> np.ndarray:
    bits = np.unpackbits(np.frombuffer(bitmap, dtype=np.uint8), bitorder="little")
    return bits[offset:offset + length].astype(bool)


def to_numpy(column: pa.Array, fill: Any = None) -> np.ndarray:
    """The values of an int32, int64, float64 or bool column as ``Array.to_numpy`` gives them:
    a read-only view of its buffer when it has no nulls, else a copy with each null as
    ``fill`` (None: NaN, an integer column's values as float64; a bool column needs a
    ``fill``)."""
    import pyarrow as pa

    data = column.buffers()[1]
    if column.type == pa.bool_():
        values = _unpack(data, column.offset, len(column))
        if column.null_count and fill is None:
            raise ValueError("a bool column with nulls has no numpy form without a fill value")
    else:
        values = np.frombuffer(data, dtype=_NUMPY_TYPES[str(column.type)])[column.offset:column.offset + len(column)]
    if not column.null_count:
        return values
    values = values.astype(np.float64) if fill is None else values.copy()
    values[nulls(column)] = np.nan if fill is None else fill
    return values
