"""tools/study_convoy_weights.py --maps: its rows read metrics.json as documented (correct
convoy fusions, both borders; calibration pooled over the borders' points)."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from conftest import load_tool

study = load_tool("study_convoy_weights")


def convoy(boundary: str, own: tuple[int, float, float, float], branch: tuple[int, float, float, float],
           calibration: tuple[int, float, float]) -> dict[str, object]:
    groups = {name: {"fused": g[0], "mean_error_m": g[1], "max_error_m": g[2], "p95_error_m": g[3]}
              for name, g in (("own_route", own), ("branch", branch))}
    points, one, two = calibration
    return {"fusion": "convoy", "interpolation": "", "d_s": 0.0, "boundary": boundary, "by_route": groups,
            "calibration": {"points": points, "within_1sigma": one, "within_2sigma": two, "mean_sigma_m": 0.1,
                            "mean_error_m": 0.08}}


def test_convoy_row_takes_the_larger_border_and_the_fused_weighted_mean() -> None:
    metrics = {"scenarios": [
        {"fusion": "local", "boundary": "left", "by_route": {}},
        convoy("left", (30, 0.10, 0.5, 0.2), (10, 0.20, 0.9, 0.3), (100, 0.6, 0.9)),
        convoy("right", (30, 0.05, 0.4, 0.25), (10, 0.09, 0.3, 0.1), (300, 0.7, 0.95))]}
    row = study.convoy_row(metrics)
    assert row["fused"] == 40
    assert row["max_error_m"] == pytest.approx(0.9) and row["p95_error_m"] == pytest.approx(0.3)
    # left (30·0.10 + 10·0.20) / 40 = 0.125, right (30·0.05 + 10·0.09) / 40 = 0.06
    assert row["mean_error_m"] == pytest.approx(0.5 * (0.125 + 0.06))
    [calibration] = study.calibration_rows(metrics)
    assert calibration["scenario"] == "convoy" and calibration["points"] == 400
    assert calibration["within_1sigma"] == pytest.approx((100 * 0.6 + 300 * 0.7) / 400)
    assert calibration["within_2sigma"] == pytest.approx((100 * 0.9 + 300 * 0.95) / 400)


def test_a_run_without_correct_convoy_fusions_has_no_errors() -> None:
    metrics = {"scenarios": [convoy("left", (0, 0.0, 0.0, 0.0), (0, 0.0, 0.0, 0.0), (1, 1.0, 1.0))]}
    metrics["scenarios"][0]["calibration"] = None
    row = study.convoy_row(metrics)
    assert row == {"fused": 0, "max_error_m": None, "p95_error_m": None, "mean_error_m": None}
    assert study.calibration_rows(metrics) == []


def test_parts_hold_the_convoy_maximum_and_name_where_it_lies(tmp_path: Path) -> None:
    """``--parts`` on a short camera run with 0.1 m / 5 mrad of coop pose error: the largest
    part is the maximum the study's table reads from metrics.json, and it lies in the coop's
    part past the overlap, beyond its 5 m seam blend (the coop's far range)."""
    rural = Path(__file__).resolve().parents[1] / "maps" / "rural.xodr"
    with study.convoy_parts() as parts:
        status, err, _ = study.run_eval(["--map", str(rural), "--sensor", "camera", "--pose-xy", "0.1", "--pose-yaw",
                                         "0.005", "--routes", "1", "--frames", "10", "--gaps", "20",
                                         "--interpolation", "paper", "--workers", "1", "--no-mcap", "--no-plots",
                                         "-q", "--out", str(tmp_path)])
    assert status == 0, err
    row = study.convoy_row(json.loads((tmp_path / "metrics.json").read_text()))
    assert parts["max"] == pytest.approx(row["max_error_m"], abs=1e-12)
    assert parts["max"] == max(parts[name] for name in study.PARTS)
    assert parts["max_part"] == "coop" and parts["max_past_overlap_m"] > 5.0
