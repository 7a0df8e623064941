"""Run reports: pooled aggregation, metrics.json schema and round trip, atomic writes."""

from __future__ import annotations

import csv
import io
import json
import math
import os
import re
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cold_maps.evaluation import report
from cold_maps.common.progress import ProgressBar
from cold_maps.evaluation.report import (
    FRAMES_CSV_COLUMNS,
    PAPER_TABLE_I_MS,
    PAPER_TABLE_II,
    FrameRecord,
    ReportError,
    ScenarioAccumulator,
    ScenarioKey,
    ScenarioResult,
    paper_comparison_markdown,
    read_metrics_json,
    write_report,
)

PAPER_TEX = Path(__file__).resolve().parents[1].parent / "shared" / "paper" / "cold-fusion-paper.tex"
KEY = ScenarioKey("Town04", "spline", "paper", 20.0, "left")
NAN = math.nan


def worked_example() -> ScenarioAccumulator:
    """Five evaluations with hand-computed aggregates (see the test below)."""
    acc = ScenarioAccumulator(KEY)
    acc.add(FrameRecord(0, 0.0, "ego", "coop1", np.array([0.1, 0.2, 0.3]), 80.0, 2.0,
                        predicted_fusible=True, truly_fusible=True))
    acc.add(FrameRecord(1, 0.1, "ego", "coop1", np.array([1.0]), 90.0, 4.0,
                        predicted_fusible=True, truly_fusible=True))
    acc.add(FrameRecord(2, 0.2, "ego", "coop1", np.empty(0), runtime_ms=6.0, rejected="no_overlap",
                        predicted_fusible=True, truly_fusible=False))
    acc.add(FrameRecord(3, 0.3, "ego", "coop1", np.empty(0), rejected="not_fusible",
                        predicted_fusible=False, truly_fusible=False))
    acc.add(FrameRecord(4, 0.4, "ego", "coop1", [], rejected="no_overlap"))
    return acc


def test_aggregates_pool_point_distances_not_frame_averages():
    r = worked_example().result()
    assert r.points == 4
    assert r.mean_error_m == pytest.approx(1.6 / 4)  # not (0.2 + 1.0) / 2
    assert r.rmse_m == pytest.approx(math.sqrt((0.01 + 0.04 + 0.09 + 1.0) / 4))
    assert r.max_error_m == 1.0
    assert r.p95_error_m == pytest.approx(0.3 + 0.85 * 0.7)  # rank 0.95 * 3 = 2.85
    assert r.mean_frame_max_error_m == pytest.approx((0.3 + 1.0) / 2)
    assert r.perception_range_m == pytest.approx(85.0)
    assert (r.frames, r.fused_frames) == (5, 2)
    assert r.rejected == (("no_overlap", 2), ("not_fusible", 1))
    assert (r.runtime_ms.mean, r.runtime_ms.std, r.runtime_ms.max) == pytest.approx((4.0, 2.0, 6.0))
    assert r.fusibility_precision == pytest.approx(2 / 3)  # predicted 3, correct 2
    assert r.fusibility_recall == 1.0  # both truly fusible pairs found


@settings(max_examples=60, deadline=None)
@given(st.lists(st.lists(st.floats(0.0, 10.0), min_size=1, max_size=30), min_size=1, max_size=12))
def test_pooled_mean_is_the_point_weighted_mean_of_frames(frames):
    acc = ScenarioAccumulator(KEY)
    for i, errors in enumerate(frames):
        acc.add(FrameRecord(i, 0.1 * i, "ego", "coop1", np.array(errors)))
    r = acc.result()
    counts = np.array([len(e) for e in frames])
    frame_means = np.array([np.mean(e) for e in frames])
    assert r.points == counts.sum()
    assert r.mean_error_m == pytest.approx(np.dot(counts, frame_means) / counts.sum(), abs=1e-9)
    assert r.mean_error_m <= r.rmse_m + 1e-12 and r.p95_error_m <= r.max_error_m + 1e-12
    assert r.max_error_m == max(max(e) for e in frames)


def test_empty_scenario_has_nulls_not_zeros(tmp_path):
    acc = ScenarioAccumulator(ScenarioKey("m", "convoy", "", 0.0, "right"))
    acc.add(FrameRecord(0, 0.0, "ego", "coop1", np.empty(0), rejected="no_coop"))
    write_report(tmp_path, [acc])
    record = json.loads((tmp_path / "metrics.json").read_text())["scenarios"][0]
    assert record["mean_error_m"] is None and record["p95_error_m"] is None
    assert record["runtime_ms"] == {"mean": None, "std": None, "max": None}
    assert record["fusibility"] == {"precision": None, "recall": None, "recall_detected": None, "fused": {}, "false": {}, "by_confidence": []}
    assert (record["frames"], record["fused_frames"], record["rejected"]) == (1, 0, {"no_coop": 1})


def test_report_files_schema_and_round_trip(tmp_path):
    local = ScenarioAccumulator(ScenarioKey("Town04", "local", "", 0.0, "left"))
    for i in range(3):
        local.add(FrameRecord(i, 0.1 * i, "ego", "", np.full(4, 0.005 * (i + 1)), 30.0, 0.5 + i,
                              predicted_fusible=True, truly_fusible=i != 1))
    results = write_report(tmp_path, [worked_example(), local])
    assert sorted(os.listdir(tmp_path)) == ["frames.csv", "frames.parquet", "metrics.json", "summary.md"]  # no temp files
    document = json.loads((tmp_path / "metrics.json").read_text())
    assert document["schema_version"] == 1 and document["partial"] is False
    required = {"map", "fusion", "interpolation", "d_s", "boundary", "mean_error_m", "rmse_m", "max_error_m",
                "p95_error_m", "perception_range_m", "frames", "fused_frames", "runtime_ms", "rejected",
                "fusibility", "perception_range_distribution_m", "by_distance", "stopping", "end_reasons"}
    for record in document["scenarios"]:
        assert required <= set(record)
    back, partial = read_metrics_json(tmp_path / "metrics.json")
    assert not partial
    assert back[1] == results[1]  # no NaN in the local scenario: exact equality
    assert back[0].to_dict() == results[0].to_dict()

    with open(tmp_path / "frames.csv", newline="") as stream:
        rows = list(csv.DictReader(stream))
    assert tuple(rows[0]) == FRAMES_CSV_COLUMNS and len(rows) == 5 + 3
    assert float(rows[0]["mean_error_m"]) == pytest.approx(0.2) and float(rows[0]["max_error_m"]) == 0.3
    assert rows[0]["points"] == "3" and rows[0]["fused"] == "1" and rows[1]["coop"] == "coop1"
    assert rows[2]["rejected"] == "no_overlap" and rows[2]["mean_error_m"] == "" and rows[2]["fused"] == "0"
    assert rows[4]["predicted_fusible"] == "" and rows[3]["predicted_fusible"] == "0"

    summary = (tmp_path / "summary.md").read_text()
    assert "| Town04 | spline | paper | 20.0 | left | 0.400 | 0.534 | 1.000 | 0.895 | 85.0 | 2 / 5 | " \
           "no_overlap: 2, not_fusible: 1 | 0.667 | 1.000 |" in summary
    assert "| Town04 | spline-paper-d20 | 4.00 / 2.00 / 6.00 | – | 3.62 / 0.70 / 6.62 |" in summary
    assert summary.index("| Town04 | local |") < summary.index("| Town04 | spline |")
    assert "PARTIAL" not in summary


def test_partial_flag_marks_all_outputs(tmp_path):
    write_report(tmp_path, [worked_example()], partial=True)
    assert json.loads((tmp_path / "metrics.json").read_text())["partial"] is True
    assert read_metrics_json(tmp_path / "metrics.json")[1] is True
    assert "PARTIAL RUN" in (tmp_path / "summary.md").read_text()


def test_a_failed_write_keeps_the_old_file_and_leaves_no_temp(tmp_path, monkeypatch):
    target = tmp_path / "metrics.json"
    target.write_text("old")

    def broken_replace(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(report.os, "replace", broken_replace)
    with pytest.raises(OSError, match="disk full"):
        report.write_metrics_json(target, [worked_example().result()])
    assert target.read_text() == "old" and os.listdir(tmp_path) == ["metrics.json"]
    with pytest.raises(ReportError, match="output folder does not exist"):
        write_report(tmp_path / "nowhere", [])


def test_paper_comparison_puts_our_values_next_to_the_papers():
    curve = ScenarioAccumulator(ScenarioKey("curve90", "spline", "paper", 20.0, "right"))
    curve.add(FrameRecord(0, 0.0, "ego", "coop1", np.array([0.1, 0.3]), 81.0, 3.0))
    straight = ScenarioAccumulator(ScenarioKey("straight", "spline", "hermite", 50.0, "left"))
    straight.add(FrameRecord(0, 0.0, "ego", "coop1", np.array([0.01, 0.02]), 110.0, 3.0))
    rural = ScenarioAccumulator(ScenarioKey("rural", "spline", "paper", 40.0, "left"))
    rural.add(FrameRecord(0, 0.0, "ego", "coop1", np.array([0.5]), 100.0, 3.0))
    types = {"curve90": "right_curve_90", "straight": "straight", "rural": "rural"}
    text = paper_comparison_markdown([curve.result(), straight.result(), rural.result()], types)
    # Table II at the paper's own gap, with its 2 r_lane + d_s range
    assert "| curve90 | right_curve_90 | spline | paper | 20.0 | right | 0.200 | 0.030 | 0.300 | 0.707 | 81.0 | 80 |" \
        in text
    # the text's figures at d_s = 50 m on the straight lane: max only, range 110 m
    assert "| straight | straight | spline | hermite | 50.0 | left | 0.015 | – | 0.020 | 0.050 | 110.0 | 110 |" in text
    # a gap the paper quotes nothing for
    assert "| rural | rural | spline | paper | 40.0 | left | 0.500 | – | 0.500 | – | 100.0 | – |" in text
    with pytest.raises(ReportError, match="road type of map 'x'"):
        paper_comparison_markdown([], {"x": "motorway"})


def test_paper_constants_match_the_paper_tables():
    if not PAPER_TEX.is_file():
        pytest.skip(f"paper {PAPER_TEX} not present (../shared is outside this clone)")
    tex = PAPER_TEX.read_text()
    table_ii = tex[tex.index(r"\label{tab:runtime}"):tex.index(r"\label{tab:results}")]
    pairs = [tuple(map(float, p)) for p in re.findall(r"\((\d\.\d+) / (\d\.\d+)\)", table_ii)]
    assert len(pairs) == 18  # 3 road types x (MSE, MAX) x (l_ego, convoy, spline)
    for road_index, road in enumerate(("straight", "right_curve_90", "rural")):
        mse, mx = pairs[6 * road_index: 6 * road_index + 3], pairs[6 * road_index + 3: 6 * road_index + 6]
        for method_index, method in enumerate(("local", "convoy", "spline")):
            ours = PAPER_TABLE_II[(road, method)]
            assert (ours["left"][0], ours["right"][0]) == mse[method_index]
            assert (ours["left"][1], ours["right"][1]) == mx[method_index]
    for name, method in (("Convoy Fusion", "convoy"), ("Spline Fusion", "spline")):
        row = re.search(name + r"\s*&\s*([\d.]+)\s*&\s*([\d.]+)\s*&\s*([\d.]+)", tex)
        assert tuple(map(float, row.groups())) == PAPER_TABLE_I_MS[method]


@pytest.mark.parametrize(
    ("make", "message"),
    [
        (lambda: FrameRecord(0, 0.0, "ego", "c", np.array([0.1, NAN])), "frame 0: errors_m must be"),
        (lambda: FrameRecord(7, 0.0, "ego", "c", np.array([0.1]), rejected="late"), "frame 7: an evaluation with"),
        (lambda: ScenarioKey("m", "kalman", "", 0.0, "left"), "fusion: expected one of"),
        (lambda: ScenarioKey("m", "convoy", "", -1.0, "left"), "d_s: expected a finite distance"),
        (lambda: ScenarioKey("m", "convoy", "", 0.0, "centre"), "boundary: expected one of"),
    ],
)
def test_invalid_records_are_named(make, message):
    with pytest.raises(ReportError, match=message):
        make()


def test_a_trusted_record_equals_the_constructors():
    """``FrameRecord.trusted`` of valid values holds what the constructor holds (its arrays
    the same objects); an unknown field is refused."""
    errors, sigma = np.array([0.1, 0.4, 0.2]), np.array([0.3, 0.3, 0.5])
    fields = dict(perception_range_m=42.0, relation="convoy", near_points=2, known_to_m=12.5, sigma_m=sigma,
                  detected_fusible=False)
    trusted = FrameRecord.trusted(3, 0.3, "ego", "c", errors, **fields)
    built = FrameRecord(3, 0.3, "ego", "c", errors, **fields)
    assert trusted.errors_m is built.errors_m is errors and trusted.sigma_m is built.sigma_m is sigma
    assert trusted == built  # the defaults (runtime_ms NaN, rejected "", stopping None) included
    assert math.isnan(trusted.runtime_ms) and (trusted.rejected, trusted.stopping) == ("", None)
    assert [part.tolist() for part in trusted.split_errors()] == [[0.1, 0.4], [0.2]]
    with pytest.raises(TypeError, match="unknown fields \\['range_m'\\]"):
        FrameRecord.trusted(3, 0.3, "ego", "c", errors, range_m=1.0)


def test_broken_metrics_json_names_file_and_key(tmp_path):
    path = tmp_path / "metrics.json"
    path.write_text("{not json")
    with pytest.raises(ReportError, match="metrics.json: not JSON"):
        read_metrics_json(path)
    record = worked_example().result().to_dict()
    del record["rmse_m"]
    path.write_text(json.dumps({"schema_version": 1, "scenarios": [record]}))
    with pytest.raises(ReportError, match=r"scenarios\[0\]: missing key 'rmse_m'"):
        read_metrics_json(path)
    record = worked_example().result().to_dict() | {"boundary": "middle"}
    path.write_text(json.dumps({"schema_version": 1, "scenarios": [record]}))
    with pytest.raises(ReportError, match=r"scenarios\[0\]: boundary: expected one of"):
        read_metrics_json(path)
    path.write_text(json.dumps({"schema_version": 2, "scenarios": []}))
    with pytest.raises(ReportError, match="schema_version 2, expected 1"):
        read_metrics_json(path)
    assert ScenarioResult.from_dict(worked_example().result().to_dict()).key == KEY


class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_bar_is_silent_on_a_non_tty_stream():
    stream = io.StringIO()
    with ProgressBar(5, "frames", stream=stream, min_interval_s=0.0) as bar:
        for _ in range(5):
            bar.update()
    assert bar.done == 5 and stream.getvalue() == ""


def test_a_progress_bar_starts_no_thread():
    """Drawn or not, a bar adds no thread to its process (no tqdm monitor): the plot
    workers of a run are forked from it after the bar. Threads other tests left are not
    the bar's."""
    import threading

    before = set(threading.enumerate())
    for stream in (io.StringIO(), FakeTerminal()):
        with ProgressBar(3, "frames", stream=stream) as bar:
            bar.update(3)
            assert set(threading.enumerate()) - before == set()


def test_progress_bar_draws_proportionally_on_a_tty():
    stream = FakeTerminal()
    with ProgressBar(8, "frames", stream=stream, width=16, min_interval_s=0.0) as bar:
        bar.update(2)
        assert stream.getvalue().split("\r")[-1].startswith("frames [" + "#" * 4 + "." * 12 + "] 2/8  ETA ")
        bar.update(100)  # clamped to the total
        assert bar.done == 8
    lines = stream.getvalue().split("\r")
    assert lines[-1].startswith("frames [" + "#" * 16 + "] 8/8  ETA 00:00") and lines[-1].endswith("\n")
    throttled = FakeTerminal()
    with ProgressBar(1000, stream=throttled, min_interval_s=3600.0) as bar:
        for _ in range(1000):
            bar.update()
    drawn = [line for line in throttled.getvalue().split("\r") if line]
    assert len(drawn) <= 4 and drawn[-1].startswith("[" + "#" * 30 + "] 1000/1000")  # start, first, last
    with pytest.raises(ValueError, match="total: expected an integer > 0"):
        ProgressBar(0)
