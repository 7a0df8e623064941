"""Frame records streamed to columnar segments (``evaluation.records``): the results, the
``frames.csv`` rows and the pooled statistics computed from the columns equal the
record-list computation they replace (kept here as the reference), bit for bit, also when
every pool spills to a file and every store writes segments of a few records."""

from __future__ import annotations

import csv
import io
import math
import pickle
from collections import Counter
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cold_maps.evaluation import records as records_module
from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation.records import PointPool, Spool
from cold_maps.evaluation.report import (
    CONFIDENCE_THRESHOLDS,
    FRAMES_CSV_COLUMNS,
    NO_EGO_LANE,
    P95_PERCENT,
    RANGE_PERCENTS,
    ROUTE_GROUPS,
    FrameRecord,
    RouteErrors,
    RuntimeStats,
    ScenarioAccumulator,
    ScenarioKey,
    ScenarioResult,
    batch_records,
    records_to_batch,
    write_frames,
)
from cold_maps.evaluation.safety import StoppingRule
from gt_matching.metrics import P95, Calibration, ErrorStats, _percentile


# --- the reference: ScenarioAccumulator.result and csv_rows over a list of records (0abd8c1) ---

def _ratio(numerator: int, denominator: int) -> float:
    return numerator / denominator if denominator else math.nan


def _reference_route(records: list[FrameRecord]) -> RouteErrors:
    errors = np.concatenate([r.errors_m for r in records]) if records else np.empty(0)
    if not errors.size:
        return RouteErrors(len(records), math.nan, math.nan, math.nan)
    return RouteErrors(len(records), float(errors.mean()), float(errors.max()),
                       float(np.percentile(errors, P95_PERCENT)))


def _reference_calibration(fused: list[FrameRecord]) -> Calibration | None:
    stated = [r for r in fused if r.sigma_m is not None]
    if not stated:
        return None
    return Calibration.from_errors(np.concatenate([r.errors_m for r in stated]),
                                   np.concatenate([r.sigma_m for r in stated if r.sigma_m is not None]))


def _reference_calibration_correct(records: list[FrameRecord]) -> Calibration | None:
    fused = [r for r in records if r.fused]
    if _reference_calibration(fused) is None or all(r.truly_fusible is None for r in records):
        return None
    return _reference_calibration([r for r in fused if r.truly_fusible]) or Calibration(
        0, math.nan, math.nan, math.nan, math.nan)


def reference_result(key: ScenarioKey, records: list[FrameRecord]) -> ScenarioResult:
    """``ScenarioAccumulator.result`` as it was computed from the records in memory."""
    fused = [r for r in records if r.fused]
    errors = np.concatenate([r.errors_m for r in fused]) if fused else np.empty(0)
    nan = math.nan
    ranges = [r.perception_range_m for r in fused if math.isfinite(r.perception_range_m)]
    ranges += [0.0] * len({r.frame for r in records if r.rejected in NO_EGO_LANE})
    runtimes = np.array([r.runtime_ms for r in records if math.isfinite(r.runtime_ms)])
    decided = [(r.predicted_fusible, r.truly_fusible) for r in records
               if r.predicted_fusible is not None and r.truly_fusible is not None]
    true_positive = sum(p and t for p, t in decided)
    detected = [bool(r.predicted_fusible) for r in records
                if r.predicted_fusible is not None and r.truly_fusible is not None and r.detected_fusible]
    correct = [r.errors_m for r in fused if r.truly_fusible] if key.vehicles > 0 else []
    right = np.concatenate(correct) if correct else np.empty(0)
    fused_pairs = [r for r in records if r.predicted_fusible and r.truly_fusible is not None and r.relation]
    scored = [(r.confidence if r.predicted_fusible else -math.inf, bool(r.truly_fusible)) for r in records
              if r.predicted_fusible is not None and r.truly_fusible is not None
              and (not r.predicted_fusible or math.isfinite(r.confidence))]
    by_confidence = tuple(
        (t, _ratio(sum(c >= t and truth for c, truth in scored), sum(c >= t for c, _ in scored)),
         _ratio(sum(c >= t and truth for c, truth in scored), sum(truth for _, truth in scored)))
        for t in CONFIDENCE_THRESHOLDS) if any(math.isfinite(r.confidence) for r in records) else ()
    splits = [r.split_errors() for r in fused]
    measured = [r for r in records if r.stopping is not None]
    stoppings = {r.stopping for r in measured}
    return ScenarioResult(
        range_percentiles_m=tuple(float(np.percentile(ranges, q)) for q in RANGE_PERCENTS) if ranges
        else (math.nan,) * len(RANGE_PERCENTS),
        near=ErrorStats.of(np.concatenate([near for near, _ in splits]) if splits else np.empty(0)),
        far=ErrorStats.of(np.concatenate([far for _, far in splits]) if splits else np.empty(0)),
        stopping=stoppings.pop() if stoppings else None,
        stopping_frames=len({r.frame for r in measured}),
        stopping_known_frames=len({r.frame for r in measured if r.known_to_stop}),
        end_reasons=tuple(sorted(Counter(r.end_reason for r in records if r.end_reason).items())),
        key=key, points=int(errors.size),
        mean_error_m=float(errors.mean()) if errors.size else nan,
        rmse_m=float(np.sqrt(np.mean(errors**2))) if errors.size else nan,
        max_error_m=float(errors.max()) if errors.size else nan,
        p95_error_m=float(np.percentile(errors, P95_PERCENT)) if errors.size else nan,
        mean_frame_max_error_m=float(np.mean([r.errors_m.max() for r in fused])) if fused else nan,
        perception_range_m=float(np.mean(ranges)) if ranges else nan,
        frames=len(records), fused_frames=len(fused),
        rejected=tuple(sorted(Counter(r.rejected for r in records if r.rejected).items())),
        runtime_ms=RuntimeStats(mean=float(runtimes.mean()) if runtimes.size else nan,
                                std=float(runtimes.std(ddof=1)) if runtimes.size > 1 else nan,
                                max=float(runtimes.max()) if runtimes.size else nan),
        fusibility_precision=_ratio(true_positive, sum(p for p, _ in decided)),
        fusibility_recall=_ratio(true_positive, sum(t for _, t in decided)),
        fusibility_recall_detected=_ratio(sum(detected), len(detected)),
        correct_mean_error_m=float(right.mean()) if right.size else nan,
        correct_max_error_m=float(right.max()) if right.size else nan,
        correct_p95_error_m=float(np.percentile(right, P95_PERCENT)) if right.size else nan,
        gt_unmatched=tuple(sorted(Counter(r.gt_unmatched for r in records if r.gt_unmatched).items())),
        fused_by_relation=tuple(sorted(Counter(r.relation for r in fused_pairs if r.truly_fusible).items())),
        false_by_relation=tuple(sorted(Counter(r.relation for r in fused_pairs if not r.truly_fusible).items())),
        by_confidence=by_confidence,
        by_route=tuple((group, _reference_route([r for r in fused_pairs if r.fused and r.truly_fusible
                                                 and r.relation == kind]))
                       for group, kind in ROUTE_GROUPS.items()) if fused_pairs else (),
        calibration=_reference_calibration(fused), calibration_correct=_reference_calibration_correct(records))


def reference_csv_rows(key: ScenarioKey, records: list[FrameRecord]) -> list[dict[str, Any]]:
    """``ScenarioAccumulator.csv_rows`` as it was computed from the records in memory."""
    def flag(value: bool | None) -> str:
        return "" if value is None else str(int(value))

    def number(value: float) -> str:
        return "" if not math.isfinite(value) else repr(float(value))

    return [{
        "map": key.map, "fusion": key.fusion, "interpolation": key.interpolation, "d_s": repr(float(key.d_s)),
        "boundary": key.boundary, "frame": r.frame, "stamp_s": number(r.stamp_s), "ego": r.ego, "coop": r.coop,
        "fused": int(r.fused), "rejected": r.rejected, "points": len(r.errors_m),
        "mean_error_m": number(float(np.mean(r.errors_m))) if r.fused else "",
        "max_error_m": number(float(np.max(r.errors_m))) if r.fused else "",
        "perception_range_m": number(r.perception_range_m), "runtime_ms": number(r.runtime_ms),
        "predicted_fusible": flag(r.predicted_fusible), "truly_fusible": flag(r.truly_fusible),
        "relation": r.relation, "confidence": number(r.confidence), "end_reason": r.end_reason,
        "near_points": "" if r.near_points is None else r.near_points,
        "near_max_error_m": number(float(np.max(near))) if near.size else "",
        "far_max_error_m": number(float(np.max(far))) if far.size else "",
        "known_to_m": number(r.known_to_m),
        "stopping_distance_m": "" if r.stopping is None else number(r.stopping.distance_m),
        "detected_fusible": flag(r.detected_fusible),
    } for r, (near, far) in ((r, r.split_errors()) for r in records)]


# --- records to compare on ---

RULE = StoppingRule(1.5, 4.0)


def make_records(seed: int, count: int, sigma: bool) -> list[FrameRecord]:
    """``count`` records of frames in order with every field varied (rejections, flags,
    relations, confidences, near splits, stopping, σ), some errors tied."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(count):
        frame = i // 3
        fused = rng.random() < 0.7
        n = int(rng.integers(1, 40)) if fused else 0
        errors = np.round(rng.exponential(0.05, n), int(rng.integers(2, 6)))
        predicted = [None, True, False][int(rng.integers(3))]
        truly = [None, True, False][int(rng.integers(3))]
        out.append(FrameRecord(
            frame=frame, stamp_s=frame / 10.0, ego="ego", coop=["", "coop1", "distractor2"][i % 3], errors_m=errors,
            perception_range_m=float(rng.uniform(10, 90)) if fused and rng.random() < 0.9 else math.nan,
            runtime_ms=float(rng.uniform(0.1, 3)) if rng.random() < 0.8 else math.nan,
            rejected="" if fused else ["no_overlap", "ego_not_seen", "gt_unmatched", "ego_dropped"][i % 4],
            predicted_fusible=predicted, truly_fusible=truly,
            gt_unmatched="past_gt_end" if not fused and i % 4 == 2 else "",
            relation=["", "own", "branch", "adjacent"][int(rng.integers(4))],
            confidence=float(rng.random()) if predicted else math.nan,
            end_reason=["", "range", "map_end"][i % 3], near_points=int(rng.integers(0, n + 1)) if rng.random() < 0.8
            else None, known_to_m=float(rng.uniform(0, 80)) if fused else math.nan,
            stopping=RULE.at(12.0) if rng.random() < 0.6 else None,
            sigma_m=rng.uniform(0.01, 0.1, n) if sigma and rng.random() < 0.7 else None,
            detected_fusible=None if not truly else [None, True, False][int(rng.integers(3))]))
    return out


@pytest.fixture
def tiny_limits(monkeypatch: pytest.MonkeyPatch) -> None:
    """Segments of a few records, pools spilled past a few points, read in blocks of 16."""
    monkeypatch.setattr(records_module, "FLUSH_RECORDS", 7)
    monkeypatch.setattr(records_module, "FLUSH_POINTS", 50)
    monkeypatch.setattr(records_module, "POOL_MEMORY_POINTS", 20)
    monkeypatch.setattr(records_module, "READ_POINTS", 16)


def _same(a: Any, b: Any) -> bool:
    """Equal, NaN equal to NaN, through tuples and dataclasses (bit for bit on floats)."""
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    if isinstance(a, tuple) and isinstance(b, tuple):
        return len(a) == len(b) and all(_same(x, y) for x, y in zip(a, b))
    if hasattr(a, "__dataclass_fields__") and type(a) is type(b):
        return all(_same(getattr(a, name), getattr(b, name)) for name in a.__dataclass_fields__)
    return bool(a == b)


@pytest.mark.parametrize("vehicles", [0, 2])
@pytest.mark.parametrize("spilled", [False, True])
def test_result_from_columns_equals_the_record_list(vehicles: int, spilled: bool, request: pytest.FixtureRequest) -> None:
    if spilled:
        request.getfixturevalue("tiny_limits")
    key = ScenarioKey("m", "spline", "paper", 20.0, "left", vehicles)
    for seed in range(6):
        records = make_records(seed, 200, sigma=seed % 2 == 0)
        accumulator = ScenarioAccumulator(key, records)
        assert (len(accumulator.records.segments) > 5) == spilled
        got, want = accumulator.result(), reference_result(key, records)
        differing = [name for name in ScenarioResult.__dataclass_fields__
                     if not _same(getattr(got, name), getattr(want, name))]
        assert not differing, (seed, differing)
        assert got.to_dict() == want.to_dict()


def test_empty_scenario_result_equals_the_reference() -> None:
    key = ScenarioKey("m", "local", "", 0.0, "right")
    got, want = ScenarioAccumulator(key).result(), reference_result(key, [])
    assert got.to_dict() == want.to_dict() and got.points == 0 and math.isnan(got.mean_error_m)


def test_frames_csv_from_columns_equals_the_record_rows(tiny_limits: None, tmp_path: Any) -> None:
    keys = [ScenarioKey("m", "convoy", "", 0.0, "left"), ScenarioKey("m", "convoy", "", 0.0, "right")]
    lists = [make_records(10 + k, 60, sigma=True) for k in range(2)]
    accumulators = [ScenarioAccumulator(key, records) for key, records in zip(keys, lists)]
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=FRAMES_CSV_COLUMNS, lineterminator="\n")
    writer.writeheader()
    for key, records in zip(keys, lists):
        writer.writerows(reference_csv_rows(key, records))
    write_frames(tmp_path / "frames.csv", tmp_path / "frames.parquet", accumulators)
    assert (tmp_path / "frames.csv").read_text(encoding="utf-8") == buffer.getvalue()
    import pyarrow.parquet as pq

    table = pq.read_table(tmp_path / "frames.parquet")
    assert table.column_names == list(FRAMES_CSV_COLUMNS) and table.num_rows == 120
    rows = list(csv.DictReader(io.StringIO(buffer.getvalue())))
    for row, typed in zip(rows, table.to_pylist()):  # the same row: a null where the CSV is empty
        for name in FRAMES_CSV_COLUMNS:
            value = typed[name]
            text = "" if value is None else str(int(value)) if isinstance(value, bool) else \
                repr(value) if isinstance(value, float) else str(value)
            assert text == row[name], (name, value, row[name])


def test_frames_parquet_gathers_segments_into_row_groups(tiny_limits: None, tmp_path: Any,
                                                         monkeypatch: pytest.MonkeyPatch) -> None:
    import pyarrow.parquet as pq

    from cold_maps.evaluation import report as report_module

    monkeypatch.setattr(report_module, "ROW_GROUP_ROWS", 25)
    keys = [ScenarioKey("m", "convoy", "", 0.0, "left"), ScenarioKey("m", "convoy", "", 0.0, "right")]
    accumulators = [ScenarioAccumulator(key, make_records(20 + k, 60, sigma=True)) for k, key in enumerate(keys)]
    segments = sum(len(a.records.segments) + bool(a.records.pending) for a in accumulators)
    write_frames(tmp_path / "frames.csv", tmp_path / "frames.parquet", accumulators)
    metadata = pq.ParquetFile(tmp_path / "frames.parquet").metadata
    rows = [metadata.row_group(i).num_rows for i in range(metadata.num_row_groups)]
    assert segments > 12 and sum(rows) == 120  # segments of at most 7 records (tiny_limits)
    assert all(25 <= n < 25 + 7 for n in rows[:-1]) and 0 < rows[-1] < 25 + 7 and len(rows) <= 120 // 25 + 1


def test_records_round_trip_through_a_segment() -> None:
    records = make_records(3, 50, sigma=True)
    back = list(batch_records(records_to_batch(records)))
    for a, b in zip(records, back, strict=True):
        for name in FrameRecord.__dataclass_fields__:
            x, y = getattr(a, name), getattr(b, name)
            if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
                assert (x is None) == (y is None) and np.array_equal(x, y)
            else:
                assert _same(x, y), name


def test_merge_adopts_a_pickled_collectors_segments_in_order(tiny_limits: None) -> None:
    key = ScenarioKey("m", "convoy", "", 0.0, "left")
    records = make_records(5, 90, sigma=False)
    whole = Collector()
    for record in records:
        whole.add(key, record)
    parent = Collector()
    for part in (records[:40], records[40:]):  # as two work units spooled into the parent's folder
        unit = Collector(spool=Spool(parent.spool.path))
        for record in part:
            unit.add(key, record)
        parent.merge(pickle.loads(pickle.dumps(unit)))
    store = parent.accumulators[key].records
    assert len(store) == 90 and all(path.parent == parent.spool.path for path in store.segments)
    assert [r.frame for r in store] == [r.frame for r in records]
    assert parent.accumulators[key].result().to_dict() == whole.accumulators[key].result().to_dict()
    folder = parent.spool.path
    parent.spool.close()
    assert not folder.exists()


def test_merged_units_write_the_segments_of_one_store(tiny_limits: None, tmp_path: Any) -> None:
    key = ScenarioKey("m", "convoy", "", 0.0, "left")
    records = make_records(7, 90, sigma=True)
    whole = Collector()
    for record in records:
        whole.add(key, record)
    units: list[list[FrameRecord]] = [[]]
    for record in records:  # units of 1 to 3 records, none filling a segment of its own
        if len(units[-1]) > len(units) % 3 or sum(len(r.errors_m) for r in [*units[-1], record]) >= 50:
            units.append([])
        units[-1].append(record)
    parent = Collector()
    for part in units:  # each pickled as a worker hands it back
        unit = Collector(spool=Spool(parent.spool.path))
        for record in part:
            unit.add(key, record)
        assert not unit.accumulators[key].records.segments
        pickled = pickle.loads(pickle.dumps(unit))
        assert not pickled.accumulators[key].records.pending  # the records travel encoded
        parent.merge(pickled)
    merged, single = parent.accumulators[key].records, whole.accumulators[key].records
    assert len(merged) == 90 and merged.pending_rows == single.pending_rows
    sizes = [[(batch.num_rows, len(batch.column("errors_m").values)) for batch in store.batches()]
             for store in (merged, single)]
    assert sizes[0] == sizes[1] and len(sizes[0]) > 10  # the same segments: the same parquet row groups
    for name, collector in (("merged", parent), ("single", whole)):
        write_frames(tmp_path / f"{name}.csv", tmp_path / f"{name}.parquet", collector.accumulators.values())
    for suffix in ("csv", "parquet"):
        assert (tmp_path / f"merged.{suffix}").read_bytes() == (tmp_path / f"single.{suffix}").read_bytes()
    assert parent.accumulators[key].result().to_dict() == whole.accumulators[key].result().to_dict()


finite = st.floats(min_value=0.0, max_value=1e3, allow_nan=False, width=64)


@settings(max_examples=150, deadline=None)
@given(values=st.lists(st.one_of(finite, st.sampled_from([0.0, 0.5, 1.0])), min_size=1, max_size=400),
       limit=st.integers(1, 64), parts=st.integers(1, 9),
       percent=st.sampled_from([0.0, 5.0, 50.0, 95.0, 100.0]))
def test_spilled_pool_statistics_equal_numpy(values: list[float], limit: int, parts: int, percent: float) -> None:
    array = np.array(values)
    spool = Spool()
    pool = PointPool(spool, limit=limit)
    for chunk in np.array_split(array, parts):
        pool.append(chunk)
    try:
        assert pool.size == array.size and pool.spilled == (array.size > limit)
        records_module_read = records_module.READ_POINTS
        records_module.READ_POINTS = 8  # blocks smaller than numpy's: the pairwise split is replayed
        try:
            assert pool.mean() == float(np.mean(array))
            assert pool.mean(np.square) == float(np.mean(array**2))
            assert pool.max() == float(array.max())
            assert pool.percentile(percent) == float(np.percentile(array, percent))
            assert pool.partition_percentile(P95) == _percentile(array, P95)
        finally:
            records_module.READ_POINTS = records_module_read
    finally:
        pool.close()
        spool.close()


def test_pairwise_sum_replays_numpy_on_a_large_array() -> None:
    values = np.random.default_rng(7).exponential(0.1, 1_234_567)
    total = records_module.pairwise_sum(lambda start, count: values[start:start + count], 0, values.size)
    assert total == float(np.sum(values)) and total != math.fsum(values)  # numpy's rounding, not the exact sum


def test_result_columns_own_their_memory(tiny_limits: None) -> None:
    """The per-record columns loaded for a result are copies: a view would keep every segment's
    points in memory until the result is done (a 10 000-frame Town04 run peaked 150 MB higher)."""
    accumulator = ScenarioAccumulator(ScenarioKey("m", "convoy", "", 0.0, "left"), make_records(2, 60, sigma=False))
    assert len(accumulator.records.segments) > 1
    arrays = [v for v in accumulator._scalars().values() if isinstance(v, np.ndarray)]
    assert arrays and all(a.base is None for a in arrays)
    assert all(r.errors_m.base is None for r in accumulator.records)
