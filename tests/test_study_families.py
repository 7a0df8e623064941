"""tools/study_families.py: counts pooled from the records agree with cold-eval's metrics.json."""

from __future__ import annotations

import hashlib
import json
import math
from pathlib import Path

import numpy as np
import pytest

from cold_maps.evaluation.report import FrameRecord
from tests.conftest import load_tool

study_families = load_tool("study_families")


def _record(predicted: bool | None, truth: bool | None, relation: str = "", confidence: float = math.nan,
            detected: bool | None = None) -> FrameRecord:
    return FrameRecord(0, 0.0, "ego", "coop", np.empty(0), rejected="" if predicted else "other_lane",
                       predicted_fusible=predicted, truly_fusible=truth, relation=relation, confidence=confidence,
                       detected_fusible=detected)


def test_counts_of_records() -> None:
    records = [_record(True, True, "own", detected=True), _record(True, True, "branch", detected=False),
               _record(True, False, "adjacent"), _record(True, False, "adjacent"), _record(True, False, "opposite"),
               _record(False, True, detected=True), _record(False, True, detected=False), _record(False, False),
               _record(None, True, detected=True), _record(True, None)]
    counts = study_families.counts_of(records)
    assert (counts.true_positive, counts.false_positive, counts.false_negative, counts.true_negative) == (2, 3, 2, 1)
    assert counts.precision == pytest.approx(2 / 5) and counts.recall == pytest.approx(2 / 4)
    # given the detections: the own-lane fusion and one rejected pair (the undecided one left out)
    assert (counts.detected, counts.detected_fused, counts.recall_detected) == (2, 1, pytest.approx(1 / 2))
    assert counts.false_by_kind == (("adjacent", 2), ("opposite", 1))
    both = counts + counts
    assert (both.decisions, both.fusions, both.false_by_kind) == (16, 10, (("adjacent", 4), ("opposite", 2)))
    assert (both.detected, both.detected_fused) == (4, 2)
    assert math.isnan(study_families.Counts().precision)


def test_confidence_curve_keeps_fusions_above_the_threshold() -> None:
    records = [_record(True, True, "own", 0.95), _record(True, False, "adjacent", 0.35), _record(False, True)]
    curve = {point["threshold"]: point for point in study_families.confidence_curve(records)}
    assert (curve[0.3]["precision"], curve[0.3]["recall"]) == (pytest.approx(0.5), pytest.approx(0.5))
    assert (curve[0.4]["precision"], curve[0.4]["recall"]) == (pytest.approx(1.0), pytest.approx(0.5))
    assert curve[1.0]["precision"] is None


def test_study_agrees_with_the_runs_metrics(tmp_path: Path) -> None:
    study = study_families.study(tmp_path, ["junctions"], [0], {"lanes0": ("--lanes", "0")}, frames=30, routes="1",
                                 workers=1, seed_set="tune", command="pytest")
    metrics = json.loads((tmp_path / "runs" / "lanes0" / "junctions" / "metrics.json").read_text())
    fusions = study["families"]["junctions"]["fusions"]
    compared = 0
    for scenario in metrics["scenarios"]:
        if scenario["fusion"] == "local" or scenario["boundary"] != "left":
            continue
        cell = fusions[study_families.fusion_label(scenario["fusion"], scenario["d_s"])]["lanes0"]
        assert cell["precision"] == pytest.approx(scenario["fusibility"]["precision"])
        assert cell["recall"] == pytest.approx(scenario["fusibility"]["recall"])
        assert cell["recall_detected"] == pytest.approx(scenario["fusibility"]["recall_detected"])
        assert cell["false_by_kind"] == scenario["fusibility"]["false"]
        compared += 1
    assert compared == 4  # convoy and spline at d_s 20, 30, 50
    made = study["made"]
    assert made["seed_set"] == "tune" and made["seeds"] == "0"
    generated = load_tool("map_families").generate("junctions", 0)
    assert made["map_sha256"] == {"junctions_0000": hashlib.sha256(generated).hexdigest()}
    text = (tmp_path / "study.md").read_text()
    assert "Made by `pytest`" in text and "| junctions | spline d_s=50 |" in text
    assert json.loads((tmp_path / "study.json").read_text()) == study
    assert any("covering" in note for note in study["notes"]["junctions"]["lanes0"])


@pytest.mark.parametrize("argv", [["--seed-set", "both"], ["--seed-set", "tune", "--maps", "0"],
                                  ["--seed-set", "tune", "--add-config", "no-equals"]])
def test_bad_command_lines_exit_2(tmp_path: Path, argv: list[str]) -> None:
    with pytest.raises(SystemExit) as exit_info:
        study_families.main(["--out", str(tmp_path), *argv])
    assert exit_info.value.code == 2
