"""Uncertainty in the evaluation (issue 25): ``--convoy-weights`` into the plan; calibration of
the stated σ per point and per scenario, in ``metrics.json`` and ``summary.md``, only where the
fused lanes state σ."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from conftest import bundled_map
from fusion_method_example import STATED_SIGMA_M

from cold_maps.cli import evaluate
from cold_maps.evaluation.report import FrameRecord, ReportError, ScenarioAccumulator, ScenarioKey, read_metrics_json
from fusion.uncertainty import BRIDGE_SIGMA_FLOOR_PER_M
from gt_matching.metrics import Calibration

METHOD = "fusion_method_example:stated_sigma"


@pytest.mark.parametrize("argv, weights", [([], "paper"), (["--convoy-weights", "inverse-variance"], "inverse-variance"),
                                           (["--paper", "--convoy-weights", "mean"], "mean")])
def test_convoy_weights_reach_every_plan(argv: list[str], weights: str) -> None:
    args = evaluate.build_parser().parse_args(argv if "--paper" in argv else ["--map", "a.xodr", *argv])
    plans = evaluate._plans(args)
    assert plans and all(plan.params.convoy_weights == weights for plan in plans)


@pytest.mark.parametrize("argv, rule", [([], "legacy"), (["--association", "strict"], "strict"),
                                        (["--paper", "--association", "confidence"], "confidence")])
def test_association_reaches_every_plan(argv: list[str], rule: str) -> None:
    args = evaluate.build_parser().parse_args(argv if "--paper" in argv else ["--map", "a.xodr", *argv])
    plans = evaluate._plans(args)
    assert plans and all(plan.params.association == rule for plan in plans)


def test_a_bad_convoy_weights_value_is_a_usage_error(capsys) -> None:
    with pytest.raises(SystemExit) as exited:
        evaluate.main(["--map", "a.xodr", "--convoy-weights", "median"])
    assert exited.value.code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--convoy-weights" in err and "median" in err
    assert "(default paper)" in " ".join(evaluate.build_parser().format_help().split())


def test_calibration_counts_errors_within_one_and_two_sigma() -> None:
    found = Calibration.from_errors(np.array([0.1, 0.3, 0.5, 0.0]), np.array([0.2, 0.2, 0.2, 0.0]))
    assert (found.points, found.within_1sigma, found.within_2sigma) == (4, 0.5, 0.75)
    assert found.mean_sigma_m == pytest.approx(0.15) and found.mean_error_m == pytest.approx(0.225)
    with pytest.raises(ValueError, match="as many σ as errors"):
        Calibration.from_errors(np.array([0.1]), np.array([0.1, 0.2]))


def test_a_scenario_pools_the_points_that_state_sigma() -> None:
    accumulator = ScenarioAccumulator(ScenarioKey("m", "convoy", "", 0.0, "left"))
    accumulator.add(FrameRecord(0, 0.0, "ego", "c", np.array([0.1, 0.3]), sigma_m=np.array([0.2, 0.2])))
    accumulator.add(FrameRecord(1, 0.1, "ego", "c", np.array([0.5, 0.05]), sigma_m=np.array([0.1, 0.1])))
    accumulator.add(FrameRecord(2, 0.2, "ego", "c", np.array([9.0])))  # states no σ: left out
    calibration = accumulator.result().calibration
    assert calibration is not None and calibration.points == 4
    assert (calibration.within_1sigma, calibration.within_2sigma) == (0.5, 0.75)
    assert ScenarioAccumulator(ScenarioKey("m", "convoy", "", 0.0, "left")).result().calibration is None
    with pytest.raises(ReportError, match="sigma_m"):
        FrameRecord(3, 0.3, "ego", "c", np.array([0.1, 0.2]), sigma_m=np.array([0.1]))
    with pytest.raises(ReportError, match="sigma_m"):
        FrameRecord(3, 0.3, "ego", "c", np.array([0.1]), sigma_m=np.array([math.nan]))


def test_calibration_of_correct_fusions_excludes_a_false_fusion() -> None:
    accumulator = ScenarioAccumulator(ScenarioKey("m", "spline", "paper", 20.0, "left"))
    accumulator.add(FrameRecord(0, 0.0, "ego", "c", np.array([0.1, 0.3]), sigma_m=np.array([0.2, 0.2]),
                                predicted_fusible=True, truly_fusible=True))
    # a false fusion: the coop's lane turns away, metres off, its σ states none of it
    accumulator.add(FrameRecord(1, 0.1, "ego", "c", np.array([5.0, 6.0]), sigma_m=np.array([0.2, 0.2]),
                                predicted_fusible=True, truly_fusible=False))
    accumulator.add(FrameRecord(2, 0.2, "ego", "c", np.array([0.05, 0.5]), sigma_m=np.array([0.1, 0.1]),
                                predicted_fusible=True, truly_fusible=True))
    accumulator.add(FrameRecord(3, 0.3, "ego", "c", np.array([0.01]), sigma_m=np.array([0.1]),
                                predicted_fusible=True))  # truth unknown: not a correct fusion
    result = accumulator.result()
    every, correct = result.calibration, result.calibration_correct
    assert every is not None and correct is not None
    assert (every.points, every.within_1sigma, every.within_2sigma) == (7, 3 / 7, 4 / 7)
    assert every.mean_error_m == pytest.approx(11.96 / 7)
    assert (correct.points, correct.within_1sigma, correct.within_2sigma) == (4, 0.5, 0.75)
    assert correct.mean_sigma_m == pytest.approx(0.15) and correct.mean_error_m == pytest.approx(0.2375)
    record = result.to_dict()
    assert record["calibration_correct"] == {"points": 4, "within_1sigma": 0.5, "within_2sigma": 0.75,
                                             "mean_sigma_m": correct.mean_sigma_m,
                                             "mean_error_m": correct.mean_error_m}
    again = type(result).from_dict(json.loads(json.dumps(record)))
    assert again.calibration_correct == correct and again.calibration == every
    assert calibration_row(result) == "| m | spline | paper | 20.0 | left | 7 | 42.9 | 57.1 | 0.157 | 1.709 | 4 | 50.0 | 75.0 | 0.150 | 0.237 |"


def test_calibration_of_correct_fusions_is_absent_without_truth_and_empty_without_a_correct_one() -> None:
    local = ScenarioAccumulator(ScenarioKey("m", "local", "", 0.0, "left"))
    local.add(FrameRecord(0, 0.0, "ego", "", np.array([0.1]), sigma_m=np.array([0.2])))  # no truth: the ego alone
    result = local.result()
    assert result.calibration is not None and result.calibration_correct is None
    assert "calibration_correct" not in result.to_dict()
    assert calibration_row(result).endswith("| – | – | – | – | – |")
    false = ScenarioAccumulator(ScenarioKey("m", "convoy", "", 0.0, "left"))
    false.add(FrameRecord(0, 0.0, "ego", "c", np.array([3.0]), sigma_m=np.array([0.2]), truly_fusible=False))
    record = false.result().to_dict()
    assert record["calibration"]["points"] == 1 and record["calibration"]["within_2sigma"] == 0.0
    assert record["calibration_correct"] == {"points": 0, "within_1sigma": None, "within_2sigma": None,
                                             "mean_sigma_m": None, "mean_error_m": None}


def calibration_row(result) -> str:
    from cold_maps.evaluation.report import calibration_markdown

    return calibration_markdown([result]).splitlines()[-1]


def test_cold_eval_reports_calibration_only_for_lanes_that_state_sigma(tmp_path) -> None:
    out = tmp_path / "out"
    status = evaluate.main(["--map", str(bundled_map("straight")), "--frames", "4", "--routes", "1", "--gaps", "30",
                            "--interpolation", "paper", "--method", METHOD, "--workers", "1", "--no-mcap", "--out", str(out), "-q"])
    assert status == 0
    records = json.loads((out / "metrics.json").read_text())["scenarios"]
    stated = [r for r in records if r["interpolation"] == METHOD]
    assert len(stated) == 2 and all("calibration" not in r for r in records if r["interpolation"] != METHOD)
    for record in stated:
        calibration = record["calibration"]
        assert calibration["points"] == record["points"] > 0  # every fused point states its σ
        assert calibration["within_1sigma"] == calibration["within_2sigma"] == 1.0  # noise-free straight: exact
        # ego and coop points state 0.05 m, the straight 30 m bridge more (its k₀·d term): the mean lies between
        assert STATED_SIGMA_M < calibration["mean_sigma_m"] < STATED_SIGMA_M + BRIDGE_SIGMA_FLOOR_PER_M["paper"] * 15.0
        assert calibration["mean_error_m"] == pytest.approx(record["mean_error_m"])
        assert record["calibration_correct"] == calibration  # one straight lane: every fusion is correct
    results, _ = read_metrics_json(out / "metrics.json")
    assert [r.calibration for r in results if r.key.interpolation == METHOD][0].points == stated[0]["calibration"]["points"]
    summary = (out / "summary.md").read_text()
    assert "## Calibration of the stated σ" in summary and f"| straight | spline | {METHOD} | 30.0 | left |" in summary
    assert "`--convoy-weights paper`" in summary
    assert (out / "plots" / "reliability_straight.png").is_file()  # only the lanes that state σ have one


def test_reliability_points_compare_observed_with_gaussian_coverage() -> None:
    from cold_maps.evaluation.plots import RELIABILITY_SIGMAS, reliability_points

    accumulator = ScenarioAccumulator(ScenarioKey("m", "convoy", "", 0.0, "left"))
    errors = np.abs(np.random.default_rng(3).normal(0.0, 0.1, 20000))  # calibrated: σ 0.1 stated
    accumulator.add(FrameRecord(0, 0.0, "ego", "c", errors, sigma_m=np.full(errors.size, 0.1)))
    accumulator.add(FrameRecord(1, 0.1, "ego", "c", np.array([0.3])))  # no σ: not in the curve
    curve = reliability_points([accumulator])["convoy"]
    assert curve.shape == (RELIABILITY_SIGMAS.size, 2)
    np.testing.assert_allclose(curve[:, 1], curve[:, 0], atol=0.01)  # observed = stated for Gaussian errors
    assert reliability_points([ScenarioAccumulator(ScenarioKey("m", "convoy", "", 0.0, "left"))]) == {}
