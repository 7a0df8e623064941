"""Arrow columns built and read through their buffers agree with pyarrow's own converters,
and recording frames does not import pandas."""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
from conftest import bundled_map
from hypothesis import given, settings
from hypothesis import strategies as st

from cold_maps.evaluation.columns import (from_lists, from_numpy, from_values, nulls, repeated_string, to_numpy,
                                         to_strings)

FLOATS = st.one_of(st.none(), st.floats(allow_nan=True, allow_infinity=True, width=64))
INTS = st.one_of(st.none(), st.integers(-(2 ** 63), 2 ** 63 - 1))
TEXTS = st.one_of(st.none(), st.text(max_size=8))
FLAGS = st.one_of(st.none(), st.booleans())
COLUMNS = st.one_of(st.tuples(st.just(pa.float64()), st.lists(FLOATS, max_size=40)),
                    st.tuples(st.just(pa.int64()), st.lists(INTS, max_size=40)),
                    st.tuples(st.just(pa.string()), st.lists(TEXTS, max_size=40)),
                    st.tuples(st.just(pa.bool_()), st.lists(FLAGS, max_size=40)))


@settings(max_examples=300, deadline=None)
@given(COLUMNS)
def test_from_values_equals_pyarrows_converter(column):
    arrow_type, values = column
    built = from_values(values, arrow_type)
    built.validate(full=True)
    reference = pa.array(values, type=arrow_type)
    assert built.type == reference.type and _same(built.to_pylist(), reference.to_pylist())
    assert built.null_count == sum(v is None for v in values)


@settings(max_examples=200, deadline=None)
@given(st.lists(st.one_of(st.none(), st.lists(st.floats(allow_nan=False, width=64), max_size=5)), max_size=30))
def test_from_lists_equals_pyarrows_converter(lists):
    built = from_lists([None if v is None else np.array(v, dtype=np.float64) for v in lists])
    built.validate(full=True)
    assert built.equals(pa.array(lists, type=pa.list_(pa.float64())))


@settings(max_examples=100, deadline=None)
@given(st.text(max_size=6), st.integers(0, 40))
def test_repeated_string_equals_pyarrows_converter(value, length):
    built = repeated_string(value, length)
    built.validate(full=True)
    assert built.equals(pa.array([value] * length, type=pa.string())) and built.null_count == 0


@settings(max_examples=300, deadline=None)
@given(COLUMNS, st.data())
def test_to_numpy_and_nulls_equal_pyarrows_on_slices(column, data):
    arrow_type, values = column
    if arrow_type == pa.string():
        return
    array = pa.array(values, type=arrow_type)
    start = data.draw(st.integers(0, len(values)))
    stop = data.draw(st.integers(start, len(values)))
    part = array.slice(start, stop - start)
    assert list(nulls(part)) == [v is None for v in values[start:stop]]
    if arrow_type == pa.bool_():
        assert to_numpy(part, fill=True).tolist() == part.fill_null(True).to_numpy(zero_copy_only=False).tolist()
        part = part.fill_null(False)
    elif part.null_count:
        filled = to_numpy(part, fill=7)
        assert filled.dtype == np.dtype(arrow_type.to_pandas_dtype())
        assert _same(filled.tolist(), part.fill_null(7).to_numpy(zero_copy_only=False).tolist())
    mine, theirs = to_numpy(part), part.to_numpy(zero_copy_only=False)
    assert mine.dtype == theirs.dtype and _same(mine.tolist(), theirs.tolist())


def _same(a: list, b: list) -> bool:
    """Equal values, NaN equal to NaN."""
    return len(a) == len(b) and all(x == y or (isinstance(x, float) and isinstance(y, float) and math.isnan(x)
                                               and math.isnan(y)) for x, y in zip(a, b))


@settings(max_examples=200, deadline=None)
@given(st.lists(st.one_of(st.none(), st.sampled_from(["", "other_lane", "no_gap", "ü"])), max_size=60), st.data())
def test_to_strings_equals_to_pylist_on_slices_with_one_object_per_value(values, data):
    array = pa.array(values, type=pa.string())
    start = data.draw(st.integers(0, len(values)))
    stop = data.draw(st.integers(start, len(values)))
    strings = to_strings(array.slice(start, stop - start))
    assert strings == values[start:stop]
    assert len({id(v) for v in strings if v is not None}) == len({v for v in strings if v is not None})


def test_a_bool_column_with_nulls_has_no_numpy_form():
    with pytest.raises(ValueError, match="without a fill value"):
        to_numpy(pa.array([True, None]))


def test_validity_of_the_wrong_length_is_refused():
    with pytest.raises(ValueError, match="validity of 2 values for a column of 3"):
        from_numpy(np.zeros(3), pa.float64(), valid=np.array([True, False]))


def test_a_run_records_its_frames_without_importing_pandas(tmp_path):
    """pyarrow's converters import pandas at their first call (~0.4 s per process): a run that
    records, reports and writes frames.parquet in one process never calls them."""
    code = ("import sys; from cold_maps.cli.evaluate import main; "
            f"status = main(['--map', {str(bundled_map('junction'))!r}, '--frames', '30', '--routes', '1', "
            f"'--workers', '1', '--out', {str(tmp_path / 'out')!r}]); "
            "print(status, 'pandas' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=Path(__file__).resolve().parents[1], timeout=300)
    assert done.stdout.split()[-2:] == ["0", "False"], done.stderr
    assert (tmp_path / "out" / "frames.parquet").stat().st_size > 0
