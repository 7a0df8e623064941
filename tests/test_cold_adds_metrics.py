"""What CoLD adds (issue 26 deliverable 4): the stopping distance, the share of frames with the
lane known out to it, the perception range's percentiles, errors near / far from the ego and
why the ego's detections ended — against closed forms on crafted records and borders."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cold_maps.cli import evaluate
from cold_maps.evaluation.report import (
    NO_EGO_LANE,
    FrameRecord,
    ReportError,
    ScenarioAccumulator,
    ScenarioKey,
    ScenarioResult,
    read_metrics_json,
    summary_markdown,
    write_report,
)
from cold_maps.evaluation.safety import LANE_ACCURACY_M, StoppingError, StoppingRule
from cold_maps.groundtruth.meter import Measurement, ahead_of_m, chord_stations_m, covered_length_m
from cold_maps.network.lane_strip import LaneStrip
from cold_maps.simulation.sensor import END_MAP, END_RANGE, LaneSensor
from gt_matching.metrics import NEAR_FAR_SPLIT_M, ErrorStats, known_distance_m, near_count

LOCAL = ScenarioKey("m", "local", "", 0.0, "left")
SPLINE = ScenarioKey("m", "spline", "paper", 20.0, "left")
RULE = StoppingRule(2.5, 3.4)


@pytest.mark.parametrize(("speed", "reaction", "deceleration", "expected"), [
    (10.0, 2.5, 3.4, 1.1 * (25.0 + 100.0 / 6.8)),  # 43.68 m: the defaults at the default speed
    (20.0, 1.0, 5.0, 1.1 * (20.0 + 40.0)),          # 66 m
    (30.0, 0.0, 9.0, 1.1 * 50.0),                   # braking alone: v²/(2a) = 900 / 18
    (0.0, 2.5, 3.4, 0.0),                           # standing still
])
def test_stopping_distance_closed_form(speed, reaction, deceleration, expected):
    assert StoppingRule(reaction, deceleration).distance_m(speed) == pytest.approx(expected, rel=1e-12)
    assert StoppingRule(reaction, deceleration).at(speed).distance_m == pytest.approx(expected, rel=1e-12)


def test_default_stopping_rule_is_aashto():
    assert (StoppingRule().reaction_time_s, StoppingRule().deceleration_mps2) == (2.5, 3.4)
    assert StoppingRule().distance_m(10.0) == pytest.approx(43.676470588, rel=1e-9)


@pytest.mark.parametrize(("make", "message"), [
    (lambda: StoppingRule(-0.1, 3.4), "reaction time"),
    (lambda: StoppingRule(math.nan, 3.4), "reaction time"),
    (lambda: StoppingRule(1.0, 0.0), "deceleration"),
    (lambda: StoppingRule(1.0, math.inf), "deceleration"),
    (lambda: RULE.distance_m(-1.0), "speed"),
    (lambda: RULE.at(math.nan), "speed"),
])
def test_bad_stopping_values_are_named(make, message):
    with pytest.raises(StoppingError, match=message):
        make()


@pytest.mark.parametrize(("flag", "value"), [("--reaction-time", "-1"), ("--reaction-time", "nan"),
                                             ("--reaction-time", "soon"), ("--deceleration", "0"),
                                             ("--deceleration", "-3"), ("--deceleration", "inf")])
def test_bad_stopping_options_are_usage_errors(flag, value, capsys):
    with pytest.raises(SystemExit) as exit_info:
        evaluate.main(["--map", "x.xodr", flag, value])
    err = capsys.readouterr().err
    assert exit_info.value.code == 2 and flag in err and len(err.strip().splitlines()) == 1


def test_stopping_options_show_their_defaults(capsys):
    with pytest.raises(SystemExit):
        evaluate.main(["--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--reaction-time S reaction time t_r in s (default 2.5" in text
    assert "--deceleration MPS2 deceleration a in m/s² (default 3.4" in text


def test_range_percentiles_over_fused_evaluations():
    acc = ScenarioAccumulator(SPLINE)
    for i, length in enumerate(np.random.default_rng(3).permutation(np.arange(1.0, 101.0))):
        acc.add(FrameRecord(i, 0.1 * i, "ego", "coop", np.array([0.1]), perception_range_m=float(length)))
    acc.add(FrameRecord(100, 10.0, "ego", "coop", np.empty(0), rejected="no_overlap"))  # no lane: no range
    result = acc.result()
    # np.percentile (linear) of 1 ... 100: rank q/100 · 99 from 1
    assert result.perception_range_m == pytest.approx(50.5)
    assert result.range_percentiles_m == pytest.approx((5.95, 50.5, 95.05))
    assert result.to_dict()["perception_range_distribution_m"] == pytest.approx(
        {"mean": 50.5, "p5": 5.95, "p50": 50.5, "p95": 95.05})


def test_near_far_split_on_both_sides_of_40_m():
    acc = ScenarioAccumulator(SPLINE)
    acc.add(FrameRecord(0, 0.0, "ego", "coop", np.array([0.1, 0.2, 1.0, 3.0]), 60.0, near_points=2))
    acc.add(FrameRecord(1, 0.1, "ego", "coop", np.array([0.3]), 20.0, near_points=1))
    acc.add(FrameRecord(2, 0.2, "ego", "coop", np.array([9.0]), 20.0))  # distances unknown: in neither split
    result = acc.result()
    assert result.near == ErrorStats(3, pytest.approx(0.2), 0.3, pytest.approx(0.2 + 0.9 * 0.1))
    assert result.far == ErrorStats(2, 2.0, 3.0, pytest.approx(1.0 + 0.95 * 2.0))
    assert result.points == 6  # the pooled statistics keep every point
    near_only = ScenarioAccumulator(LOCAL)
    near_only.add(FrameRecord(0, 0.0, "ego", "", np.array([0.01, 0.03]), 30.0, near_points=2))
    record = near_only.result().to_dict()["by_distance"]
    assert record["split_m"] == NEAR_FAR_SPLIT_M
    assert record["far"] == {"points": 0, "mean_error_m": None, "max_error_m": None, "p95_error_m": None}
    assert "| m | local | left | 30.0 / 30.0 / 30.0 / 30.0 | 2 / 0.020 / 0.030 / 0.029 | no point |" \
        in summary_markdown([near_only.result()])


def test_near_count_and_chord_stations_on_a_straight_border():
    x = np.arange(0.0, 60.0, 0.3)
    border = np.column_stack((x, np.full_like(x, 1.75)))
    stations = chord_stations_m(border)
    assert stations == pytest.approx(x, abs=1e-9)
    assert near_count(stations) == int(np.count_nonzero(x <= 40.0)) == 134  # 0, 0.3, ..., 39.9


def test_chord_stations_on_an_arc_and_under_noise():
    radius, step = 50.0, 0.1
    theta = np.arange(0.0, 1.2, step / radius)
    arc = radius * np.column_stack((np.sin(theta), 1.0 - np.cos(theta)))
    # chords of ≈ 0.5 m shorten an arc by chord² / (24 R²) = 4e-6 relative
    assert chord_stations_m(arc) == pytest.approx(radius * theta, rel=1e-5, abs=1e-9)
    x = np.arange(0.0, 50.0, 0.1)
    noisy = np.column_stack((x, np.random.default_rng(0).normal(0.0, 0.05, x.size)))
    # along the points the noise lengthens it by ≈ σ²/step² = 25 %, along the chords by a few %,
    # exactly as it does the perception range
    assert chord_stations_m(noisy)[-1] == pytest.approx(x[-1], rel=0.03)
    assert chord_stations_m(noisy)[-1] == pytest.approx(covered_length_m(noisy, np.zeros(x.size)), rel=1e-12)


def test_known_distance_at_the_accuracy_boundary():
    ahead = np.arange(0.0, 50.05, 0.1)
    errors = np.full(ahead.size, LANE_ACCURACY_M)  # exactly at the bound counts as known
    assert known_distance_m(errors, ahead, LANE_ACCURACY_M) == pytest.approx(50.0)
    errors[200] = np.nextafter(LANE_ACCURACY_M, 1.0)  # the point at 20.0 m is just beyond
    assert known_distance_m(errors, ahead, LANE_ACCURACY_M) == pytest.approx(19.9)
    errors[0] = 1.0
    assert known_distance_m(errors, ahead, LANE_ACCURACY_M) == 0.0
    assert known_distance_m(np.empty(0), np.empty(0), LANE_ACCURACY_M) == 0.0


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(0.0, 2.0), min_size=1, max_size=60), st.floats(0.01, 6.0))
def test_known_distance_is_the_definition(errors, distance):
    """Known to D > 0 exactly when a point lies at D or beyond and every point up to the
    first such point is within the accuracy (points 0.1 m apart from the ego)."""
    errors = np.array(errors)
    ahead = 0.1 * np.arange(errors.size)
    reaching = np.flatnonzero(ahead >= distance)
    expected = bool(reaching.size) and bool(np.all(errors[:reaching[0] + 1] <= LANE_ACCURACY_M))
    assert (known_distance_m(errors, ahead, LANE_ACCURACY_M) >= distance) == expected


def test_measured_lane_is_known_as_far_as_its_worse_border():
    ahead = np.arange(0.0, 60.05, 0.1)
    left = np.where(ahead > 45.05, 1.0, 0.1)   # left known to 45.0 m
    right = np.where(ahead > 50.05, 1.0, 0.1)  # right to 50.0 m
    measured = Measurement(left, right, 60.0, 60.0, np.empty((0, 2)), np.empty((0, 2)), True, "", ahead, ahead)
    assert measured.known_to_m(LANE_ACCURACY_M) == pytest.approx(45.0)
    assert measured.near_points() == (401, 401)


def test_share_of_frames_known_to_the_stopping_distance():
    stop = RULE.at(10.0)
    d = stop.distance_m
    acc = ScenarioAccumulator(SPLINE)
    lane = np.array([0.1])
    acc.add(FrameRecord(0, 0.0, "ego", "coop", lane, 80.0, known_to_m=d, stopping=stop))  # exactly d: known
    acc.add(FrameRecord(1, 0.1, "ego", "coop", lane, 80.0, known_to_m=np.nextafter(d, 0.0), stopping=stop))
    acc.add(FrameRecord(2, 0.2, "ego", "coop", np.empty(0), rejected="no_gap", stopping=stop))
    acc.add(FrameRecord(3, 0.3, "ego", "turn", lane, 80.0, known_to_m=10.0, stopping=stop))
    acc.add(FrameRecord(3, 0.3, "ego", "coop", lane, 80.0, known_to_m=d + 30.0, stopping=stop))  # one of two
    acc.add(FrameRecord(4, 0.4, "ego", "coop", lane, 80.0, known_to_m=d + 30.0))  # not scored: not counted
    result = acc.result()
    assert (result.stopping_known_frames, result.stopping_frames) == (2, 4)
    assert result.stopping_share == 0.5
    stopping = result.to_dict()["stopping"]
    assert stopping == {"distance_m": pytest.approx(43.676470588), "speed_mps": 10.0, "reaction_time_s": 2.5,
                        "deceleration_mps2": 3.4, "accuracy_m": LANE_ACCURACY_M, "frames": 4, "known_frames": 2,
                        "share": 0.5}
    assert "| m | spline-paper-d20 | 10.0 | 2.50 | 3.40 | 43.7 | 2 / 4 | 0.500 |" in summary_markdown([result])


def test_records_of_one_scenario_share_one_stopping_distance():
    acc = ScenarioAccumulator(LOCAL)
    acc.add(FrameRecord(0, 0.0, "ego", "", np.array([0.1]), 30.0, known_to_m=30.0, stopping=RULE.at(10.0)))
    acc.add(FrameRecord(1, 0.1, "ego", "", np.array([0.1]), 30.0, known_to_m=30.0, stopping=RULE.at(12.0)))
    with pytest.raises(ReportError, match="2 different stopping distances"):
        acc.result()


def test_detection_end_reasons_counted_per_reason():
    acc = ScenarioAccumulator(LOCAL)
    for i, reason in enumerate(("range", "range", "map_end", "", "range")):
        acc.add(FrameRecord(i, 0.1 * i, "ego", "", np.array([0.1]), 30.0, end_reason=reason))
    result = acc.result()
    assert result.end_reasons == (("map_end", 1), ("range", 3))
    assert result.to_dict()["end_reasons"] == {"map_end": 1, "range": 3}
    assert "| m | map_end: 1, range: 3 |" in summary_markdown([result])


def test_ideal_sensor_ends_at_its_range_or_where_the_track_ends():
    x = np.arange(0.0, 40.05, 0.1)
    strip = LaneStrip.from_borders(np.column_stack((x, np.full_like(x, 2.0))),
                                   np.column_stack((x, np.full_like(x, -2.0))))
    sensor = LaneSensor()
    assert sensor.detect(strip, 10.0).end_reason == END_RANGE  # 10 + 30 = 40: the range is reached
    assert sensor.detect(strip, 10.5).end_reason == END_MAP


def test_new_keys_round_trip_and_old_files_still_read(tmp_path):
    acc = ScenarioAccumulator(LOCAL)
    stop = RULE.at(10.0)
    for i in range(3):
        acc.add(FrameRecord(i, 0.1 * i, "ego", "", np.array([0.1, 0.2, 0.9]), 30.0 + i, near_points=2,
                            known_to_m=29.0, stopping=stop, end_reason="range"))
    results = write_report(tmp_path, [acc])
    back, _ = read_metrics_json(tmp_path / "metrics.json")
    assert back == results
    record = json.loads((tmp_path / "metrics.json").read_text())["scenarios"][0]
    for key in ("perception_range_distribution_m", "by_distance", "stopping", "end_reasons"):
        del record[key]
    old = ScenarioResult.from_dict(record)
    assert old.stopping is None and old.near.points == 0 and math.isnan(old.range_percentiles_m[0])
    assert old.mean_error_m == results[0].mean_error_m
    rows = (tmp_path / "frames.csv").read_text().splitlines()
    assert rows[0].endswith(",end_reason,near_points,near_max_error_m,far_max_error_m,known_to_m,stopping_distance_m,"
                            "detected_fusible")
    assert rows[1].split(",")[-7:-2] == ["range", "2", "0.2", "0.9", "29.0"]
    assert float(rows[1].split(",")[-2]) == pytest.approx(43.676470588)
    assert rows[1].split(",")[-1] == ""  # a local evaluation has no pair


@pytest.mark.parametrize(("make", "message"), [
    (lambda: FrameRecord(0, 0.0, "ego", "", np.array([0.1]), near_points=2), "near_points 2 outside 0 ... 1"),
    (lambda: FrameRecord(0, 0.0, "ego", "", np.array([0.1]), known_to_m=-1.0), "known_to_m must be"),
])
def test_invalid_new_fields_are_named(make, message):
    with pytest.raises(ReportError, match=message):
        make()


def test_distance_from_the_ego_counts_a_minimum_range():
    """A border whose first point lies 3 m ahead of the vehicle (a camera's minimum range),
    the vehicle at (10, 5) heading 90°: its points are 3 m + their distance along it ahead."""
    y = np.arange(8.0, 40.0, 0.1)
    border = np.column_stack((np.full_like(y, 10.0 - 1.75), y))
    assert ahead_of_m(border, (10.0, 5.0, math.pi / 2)) == pytest.approx(y - 5.0, abs=1e-9)
    assert ahead_of_m(border, None) == pytest.approx(y - 8.0, abs=1e-9)
    # a border that starts behind the vehicle counts from its first point
    assert ahead_of_m(border, (10.0, 9.0, math.pi / 2))[0] == 0.0


@pytest.mark.parametrize("reason", sorted(NO_EGO_LANE))
def test_frames_without_an_ego_lane_count_once_as_range_zero(reason):
    acc = ScenarioAccumulator(SPLINE)
    for i, length in enumerate((10.0, 20.0, 30.0)):
        acc.add(FrameRecord(i, 0.1 * i, "ego", "coop", np.array([0.1]), perception_range_m=length))
    for coop in ("coop", "turn"):  # one frame, two pairs: counted once
        acc.add(FrameRecord(3, 0.3, "ego", coop, np.empty(0), rejected=reason))
    acc.add(FrameRecord(4, 0.4, "ego", "coop", np.empty(0), rejected="coop_not_seen"))  # the ego has its lane
    result = acc.result()
    # ranges 0, 10, 20, 30: mean 15; linear percentiles at rank q/100 · 3
    assert result.perception_range_m == pytest.approx(15.0)
    assert result.range_percentiles_m == pytest.approx((1.5, 15.0, 28.5))
    assert result.fused_frames == 3
