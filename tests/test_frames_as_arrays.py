"""Frames as arrays: the block path (``Drive.states_block``, ``detection.sense_block``, the
evaluator's run over blocks) gives exactly what the frame loop gives (``Drive.states``,
``detection.sense`` frame by frame, vehicle by vehicle), bit for bit, with the same seeded
draws: ideal and camera sensor, sensor errors and lane-model error, neighbour lanes,
history and message exchange, blocks cut anywhere."""

from __future__ import annotations

import math
from dataclasses import fields

import numpy as np
import pytest
from conftest import bundled_map, carla_map
from hypothesis import given, settings
from hypothesis import strategies as st

import fusion
from cold_maps.cli.evaluate import _plans, build_parser
from cold_maps.evaluation.collector import Collector
from cold_maps.evaluation import evaluator as evaluator_module
from cold_maps.evaluation.evaluator import FRAME_RATE_HZ, MapEvaluator
from cold_maps.simulation.detection import NO_OBSTACLES, Sensed, obstacles_of, sense, sense_block
from cold_maps.simulation.lane_model_error import LaneModelErrorSampler
from cold_maps.simulation.sensor_errors import SensorErrorModel
from fusion.types import clean_borders, stacked_arclength, stacked_arclengths

ERRORS = ["--lateral-offset", "0.05", "--noise", "0.03", "--heading-bias", "0.002", "--range-jitter", "3",
          "--drop", "0.1", "--pose-xy", "0.2", "--pose-yaw", "0.01"]
"""Every sensor error model on (each draws from the drive's generator)."""
KNOWN_ERRORS = ["--lateral-offset", "0.05", "--noise", "0.03", "--heading-bias", "0.002", "--pose-xy", "0.2",
                "--pose-yaw", "0.01"]
"""The error models whose draws per detection are known before drawing (no drop, no jitter):
drawn for a whole block at once."""


def _evaluator(map_path, *options: str) -> MapEvaluator:
    args = build_parser().parse_args(["--map", str(map_path), "--frames", "40", "--routes", "2", *options])
    return MapEvaluator(_plans(args)[0])


def _frame_loop(evaluator: MapEvaluator, drive_index: int, frames: range,
                lane_error: LaneModelErrorSampler | None, rng: np.random.Generator,
                offset: int = 0) -> list[dict[str, Sensed]]:
    """The reference: states and detections frame by frame, vehicle by vehicle (frame f at
    the time of global frame ``offset + f``)."""
    drive, plan = evaluator.drives[drive_index], evaluator.plan
    out = []
    for frame in frames:
        states = drive.states(frame)
        obstacles = obstacles_of(states) if plan.sensor.kind == "camera" else {}
        out.append({name: sense(state, evaluator.sensor, plan.errors, rng, stamp_s=(offset + frame) / FRAME_RATE_HZ,
                                neighbours=evaluator.neighbours, obstacles=obstacles.get(name, NO_OBSTACLES),
                                lane_error=lane_error)
                    for name, state in states.items()})
    return out


def _samplers(evaluator: MapEvaluator, drive_index: int) -> tuple[LaneModelErrorSampler | None, ...]:
    """Two fresh lane-model error samplers of the drive (None when the plan has none)."""
    if evaluator.lane_errors is None:
        return None, None
    return tuple(LaneModelErrorSampler(evaluator.plan.sensor.lane_error, evaluator.plan.seed, drive_index)
                 for _ in range(2))


def _same_array(a, b) -> bool:
    if a is None or b is None:
        return a is None and b is None
    return a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b) and not b.flags.writeable


def _assert_same_detection(a: fusion.LaneDetection, b: fusion.LaneDetection) -> None:
    assert (a.pose, a.stamp, a.sender, a.road_edges, a.end_reason) == (b.pose, b.stamp, b.sender, b.road_edges,
                                                                       b.end_reason)
    for name in ("points", "left", "right", "arclength", "left_sigma", "right_sigma", "pose_cov",
                 "lane_model_sigma"):
        assert _same_array(getattr(a, name), getattr(b, name)), name
    assert [n.index for n in a.neighbours] == [n.index for n in b.neighbours]
    for one, other in zip((*a.neighbours, *a.branches), (*b.neighbours, *b.branches)):
        assert np.array_equal(one.left, other.left) and np.array_equal(one.right, other.right)
    assert len(a.branches) == len(b.branches)


def _assert_same_frames(reference: list[dict[str, Sensed]], block: list[dict[str, Sensed]]) -> int:
    """Asserts equal frames; returns the number of detections compared."""
    assert len(reference) == len(block)
    compared = 0
    for one, other in zip(reference, block):
        assert list(one) == list(other)
        for name in one:
            a, b = one[name], other[name]
            assert (a.state, a.end_reason, a.seen, a.read_ends) == (b.state, b.end_reason, b.seen, b.read_ends), name
            assert type(a.state.station) is type(b.state.station) is float
            assert (a.detection is None) == (b.detection is None), name
            if a.detection is not None and b.detection is not None:
                assert a.detection.end_reason == a.end_reason in fusion.types.END_REASONS, name
                _assert_same_detection(a.detection, b.detection)
                compared += 1
    return compared


def _check_drives(evaluator: MapEvaluator, cuts: tuple[int, ...] = (17,)) -> int:
    """Every drive through the frame loop and through blocks cut at ``cuts``; compares them
    and the generators' states after; returns the detections compared."""
    compared = 0
    for index, drive in enumerate(evaluator.drives):
        reference_errors, block_errors = _samplers(evaluator, index)
        reference_rng, block_rng = np.random.default_rng(index), np.random.default_rng(index)
        reference = _frame_loop(evaluator, index, range(drive.frames), reference_errors, reference_rng)
        edges = [0, *(cut for cut in cuts if 0 < cut < drive.frames), drive.frames]
        block: list[dict[str, Sensed]] = []
        for start, stop in zip(edges, edges[1:]):
            frames = range(start, stop)
            block += sense_block(drive.states_block(frames), evaluator.sensor, evaluator.plan.errors, block_rng,
                                 stamps_s=[frame / FRAME_RATE_HZ for frame in frames],
                                 neighbours=evaluator.neighbours, lane_error=block_errors)
        compared += _assert_same_frames(reference, block)
        assert reference_rng.random() == block_rng.random()
    return compared


@pytest.mark.parametrize("options", [(), tuple(ERRORS), tuple(KNOWN_ERRORS), ("--lanes", "1"),
                                     ("--lanes", "1", *ERRORS), ("--lanes", "1", *KNOWN_ERRORS)],
                         ids=["ideal", "errors", "known-errors", "lanes1", "lanes1-errors", "lanes1-known-errors"])
def test_blocks_of_the_ideal_sensor_equal_the_frame_loop_on_the_junction(options) -> None:
    assert _check_drives(_evaluator(bundled_map("junction"), *options)) > 0


@pytest.mark.parametrize("options", [(), tuple(ERRORS), tuple(KNOWN_ERRORS)],
                         ids=["lane-error", "lane-error-errors", "lane-error-known-errors"])
def test_blocks_of_the_camera_equal_the_frame_loop_on_the_junction(options) -> None:
    evaluator = _evaluator(bundled_map("junction"), "--sensor", "camera", "--frames", "20", *options)
    assert evaluator.lane_errors is not None
    assert _check_drives(evaluator, cuts=(1, 5, 13)) > 0


@pytest.mark.parametrize("sensor", ["ideal", "camera"])
def test_blocks_equal_the_frame_loop_on_town01(sensor) -> None:
    evaluator = _evaluator(carla_map("Town01"), "--sensor", sensor, "--frames", "30")
    assert _check_drives(evaluator) > 0


def test_states_block_equals_states_on_the_paper_maps() -> None:
    for name in ("straight", "curve90", "rural", "junction"):
        evaluator = _evaluator(bundled_map(name))
        for drive in evaluator.drives:
            assert drive.states_block(range(drive.frames)) == [drive.states(f) for f in range(drive.frames)]


@settings(max_examples=20, deadline=None)
@given(start=st.integers(0, 39), length=st.integers(0, 40))
def test_states_block_equals_states_for_any_block(start, length) -> None:
    drive = _junction().drives[0]
    frames = range(start, min(start + length, drive.frames))
    assert drive.states_block(frames) == [drive.states(f) for f in frames]


_JUNCTION: list[MapEvaluator] = []


def _junction() -> MapEvaluator:
    if not _JUNCTION:
        _JUNCTION.append(_evaluator(bundled_map("junction")))
    return _JUNCTION[0]


def test_states_block_rejects_frames_outside_the_drive() -> None:
    drive = _junction().drives[0]
    with pytest.raises(ValueError, match="outside the drive"):
        drive.states_block(range(drive.frames - 1, drive.frames + 1))


def _records(collector: Collector) -> list[tuple]:
    """Every record of the collector as comparable tuples (runtimes left out)."""
    out = []
    for key, accumulator in collector.accumulators.items():
        for record in accumulator.records:
            row = [key]
            for field in fields(record):
                value = getattr(record, field.name)
                if field.name.startswith("runtime"):
                    continue
                if isinstance(value, np.ndarray):
                    value = (value.dtype.str, value.shape, value.tobytes())
                elif isinstance(value, float) and math.isnan(value):
                    value = "nan"
                row.append((field.name, value))
            out.append(tuple(row))
    return out


@pytest.mark.parametrize("options", [("--history", "20", "--coops", "2", "--lanes", "1", *ERRORS),
                                     ("--exchange", "bezier", "--sensor", "camera")],
                         ids=["history-coops-lanes", "exchange-camera"])
def test_the_evaluator_over_blocks_equals_its_frame_loop(options, monkeypatch) -> None:
    monkeypatch.setattr(evaluator_module, "BLOCK_FRAMES", 4)
    evaluator = _evaluator(bundled_map("junction"), "--frames", "10", "--routes", "1", *options)
    evaluator.prepare()
    blocks = Collector()
    evaluator.run(blocks)
    reference = _evaluator(bundled_map("junction"), "--frames", "10", "--routes", "1", *options)
    reference.prepare()
    loop = Collector()
    reference.note_drives(loop)
    offset = 0
    for index, drive in enumerate(reference.drives):
        lane_error = None if reference.lane_errors is None else reference.lane_errors[index]
        frames = _frame_loop(reference, index, range(drive.frames), lane_error, reference.drive_rngs[index], offset)
        for frame, sensed in enumerate(frames):
            fused = reference._fuse_frame(loop, index, offset + frame, sensed)
            lanes = [lane for _, lane, _ in fused.steps if lane is not None]
            reference._finish_frame(fused, iter(reference._measure_many(lanes)), None)
        offset += drive.frames
    reference.note_unmatched(loop)
    assert _records(blocks) == _records(loop)
    assert len(_records(loop)) > 0


@settings(max_examples=40, deadline=None)
@given(lengths=st.lists(st.integers(0, 12), min_size=1, max_size=8), seed=st.integers(0, 2**16),
       repeat=st.integers(-1, 11))
def test_block_checks_equal_the_detection_checks(lengths, seed, repeat) -> None:
    """clean_borders and stacked_arclengths over a stack of borders agree with the checking
    constructor border by border (a repeated point or too few points: not clean)."""
    rng = np.random.default_rng(seed)
    borders = [np.round(np.cumsum(rng.normal(size=(n, 2)), axis=0), 6) for n in lengths]
    if 0 <= repeat < len(borders[0]) - 1:
        borders[0][repeat + 1] = borders[0][repeat]
    offsets = np.concatenate(([0], np.cumsum(lengths)))
    points = np.concatenate(borders) if sum(lengths) else np.empty((0, 2))
    clean = clean_borders(points, offsets)
    for border, ok in zip(borders, clean):
        try:
            kept = fusion.types.validated_border("border", border)
        except fusion.InvalidDetectionError:
            assert not ok
        else:
            assert ok == (len(kept) == len(border))
    if all(lengths):
        arclength = stacked_arclengths(points, offsets)
        for k in range(0, len(borders) - 1, 2):
            pair = np.concatenate(borders[k: k + 2])
            assert np.array_equal(arclength[offsets[k]: offsets[k + 2]], stacked_arclength(pair, lengths[k]))


@settings(max_examples=30, deadline=None)
@given(lengths=st.lists(st.integers(2, 30), min_size=2, max_size=10).filter(lambda n: len(n) % 2 == 0),
       seed=st.integers(0, 2**16), offset=st.sampled_from([0.0, -0.2]), noise=st.sampled_from([0.0, 0.05]),
       bias=st.sampled_from([0.0, 0.01]), pose_xy=st.sampled_from([0.0, 0.3]), pose_yaw=st.sampled_from([0.0, 0.02]))
def test_apply_block_equals_apply_then_perturb_pose(lengths, seed, offset, noise, bias, pose_xy, pose_yaw) -> None:
    """SensorErrorModel.apply_block draws what apply and perturb_pose draw, detection by
    detection, and moves every point and pose the same, bit for bit."""
    errors = SensorErrorModel(lateral_offset_m=offset, noise_sigma_m=noise, heading_bias_rad=bias,
                              pose_sigma_xy_m=pose_xy, pose_sigma_yaw_rad=pose_yaw)
    borders = [np.column_stack((np.arange(n) * 0.1, np.sin(np.arange(n) * 0.1) + side))
               for n, side in zip(lengths, [1.5, -1.5] * len(lengths))]
    pairs = list(zip(borders[::2], borders[1::2]))
    poses = [None if k % 3 == 0 else (float(k), -float(k), 0.1 * k) for k in range(len(pairs))]
    one, other = np.random.default_rng(seed), np.random.default_rng(seed)
    expected_borders, expected_poses = [], []
    for (left, right), pose in zip(pairs, poses):
        expected_borders.append(errors.apply(left, right, one))
        expected_poses.append(None if pose is None else errors.perturb_pose(*pose, one))
    got_borders, got_poses = errors.apply_block(pairs, poses, other)
    assert got_poses == expected_poses
    for (a, b), (c, d) in zip(expected_borders, got_borders):
        assert np.array_equal(a, c) and np.array_equal(b, d)
    assert one.random() == other.random()


def test_apply_block_refuses_models_that_draw_as_they_go() -> None:
    with pytest.raises(ValueError, match="apply_block"):
        SensorErrorModel(drop_probability=0.1).apply_block([], [], np.random.default_rng(0))
