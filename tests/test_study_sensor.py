"""tools/study_sensor.py: its rows read metrics.json as documented, and a small study on the
bundled junction writes them with how they were made."""

from __future__ import annotations

import hashlib
import json

import pytest

from conftest import PROJECT_ROOT, load_tool

study_sensor = load_tool("study_sensor")


def record(boundary: str, fusion: str = "local", **extra: object) -> dict[str, object]:
    base = {"fusion": fusion, "interpolation": "hermite" if fusion == "spline" else "", "d_s": 20.0 if fusion ==
            "spline" else 0.0, "boundary": boundary, "frames": 10, "fused_frames": 9, "rejected": {"ego_not_seen": 1},
            "max_error_m": 0.4, "p95_error_m": 0.2, "stopping": {"share": 0.7, "distance_m": 43.7},
            "end_reasons": {"range": 6, "unmarked": 3}}
    return base | extra


def ranges(p5: float, p50: float) -> dict[str, dict[str, float]]:
    return {"perception_range_distribution_m": {"mean": p50, "p5": p5, "p50": p50, "p95": p50}}


def test_rows_combine_the_borders_and_pick_the_correct_fusions():
    metrics = {"scenarios": [
        record("left", **ranges(10.0, 40.0)), record("right", **ranges(12.0, 38.0), end_reasons={"range": 6}),
        record("left", "spline", **ranges(50.0, 60.0), by_route={
            "own_route": {"fused": 8, "max_error_m": 1.5, "p95_error_m": 0.3},
            "branch": {"fused": 0, "max_error_m": None, "p95_error_m": None}}),
        record("right", "spline", **ranges(51.0, 59.0), by_route={
            "own_route": {"fused": 8, "max_error_m": 1.2, "p95_error_m": 0.5},
            "branch": {"fused": 1, "max_error_m": 2.5, "p95_error_m": 2.0}}),
    ]}
    local, spline = study_sensor.rows_of(metrics, 0)
    assert (local["scenario"], local["range_p5_m"], local["range_p50_m"]) == ("local", 10.0, 38.0)
    assert (local["max_error_m"], local["end_reasons"]) == (0.4, {"range": 6, "unmarked": 3})  # the left border's
    assert (spline["scenario"], spline["range_p5_m"], spline["range_p50_m"]) == ("spline-hermite-d20", 50.0, 59.0)
    assert (spline["max_error_m"], spline["p95_error_m"], spline["end_reasons"]) == (2.5, 2.0, {})
    assert spline["stopping_share"] == 0.7


def test_rows_with_a_history_use_correct_only_and_leave_out_local():
    correct = {"mean_error_m": 0.1, "max_error_m": 0.35, "p95_error_m": 0.15}
    metrics = {"scenarios": [record("left", **ranges(10.0, 40.0)), record("left", "convoy", **ranges(30.0, 65.0),
                                                                          correct_only=correct)]}
    (convoy,) = study_sensor.rows_of(metrics, 100)
    assert (convoy["scenario"], convoy["history_m"], convoy["max_error_m"], convoy["p95_error_m"]) == (
        "convoy", 100, 0.35, 0.15)


def test_a_study_on_the_junction_reports_what_cold_eval_wrote(tmp_path, capsys):
    out = tmp_path / "study"
    assert study_sensor.main(["--maps", "junction", "--routes", "1", "--frames", "8", "--gaps", "20",
                              "--workers", "1", "--out", str(out)]) == 0
    study = json.loads((out / "study.json").read_text())
    (entry,) = study["maps"]
    assert entry["sha256"] == hashlib.sha256((PROJECT_ROOT / "maps" / "junction.xodr").read_bytes()).hexdigest()
    assert [run["status"] for run in entry["runs"]] == [0, 0, 0, 0]
    # per sensor: local, convoy and two splines without history; the three fusions with one
    assert len(entry["rows"]) == 2 * (4 + 3)
    metrics = json.loads((out / "junction" / "camera" / "history0" / "metrics.json").read_text())
    local = [r for r in metrics["scenarios"] if r["fusion"] == "local"]
    row = next(r for r in entry["rows"] if r["sensor"] == "camera" and r["scenario"] == "local")
    assert row["range_p50_m"] == min(r["perception_range_distribution_m"]["p50"] for r in local)
    assert sum(row["end_reasons"].values()) + row["rejected"].get("ego_not_seen", 0) == 8
    assert "## junction" in (out / "study.md").read_text()


def test_an_unknown_map_is_a_usage_error(capsys):
    with pytest.raises(SystemExit) as exc:
        study_sensor.main(["--maps", "nowhere"])
    assert exc.value.code == 2
    assert "unknown map(s) nowhere" in capsys.readouterr().err
