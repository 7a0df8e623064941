"""MCAP recording: Foxglove-valid channels, round trip, interrupted runs, foreign files,
version-1 recordings still readable."""

from __future__ import annotations

import json
import math
import tempfile
import time
from pathlib import Path

import jsonschema
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.writer import Writer
from mcap_helpers import read_all, write_v1_recording

from cold_maps.recording.recorder import (
    DISPLAY_TOLERANCE_M,
    FRAME_METRICS_SCHEMA,
    LANE_DETECTION_SCHEMA,
    RECORDING_VERSION,
    Recorder,
    RecordingError,
    display_lines,
    read_detections,
    read_metadata,
    read_stamp_base,
)
from gt_matching.polyline import simplify_lines

FRAMES = 3
DT_S = 0.1
EGO_POSE = (10.0, 5.0, math.pi / 2)
COOP_POSE = (10.0, 30.0, math.pi / 2)
BASE_NS = 1_700_000_000_123_456_789  # stamp base of the session recording, ns since the Unix epoch


def lane(frame: int) -> tuple[np.ndarray, np.ndarray]:
    """A straight detection in the vehicle frame, 1.75 m either side, a frame-dependent length."""
    x = np.arange(0.0, 5.0 + frame, 0.1) + 0.013 * frame
    return np.column_stack((x, np.full_like(x, 1.75))), np.column_stack((x, np.full_like(x, -1.75)))


def record_frames(recorder: Recorder, frames: range) -> None:
    for frame in frames:
        stamp = frame * DT_S
        left, right = lane(frame)
        recorder.write_gt(stamp, {"left": np.array([[0.0, 0.0], [0.0, 50.0]]), "right": np.array([[3.5, 0.0], [3.5, 50.0]])})
        recorder.write_detection(stamp, frame, "ego", EGO_POSE, left, right, ego=True)
        recorder.write_detection(stamp, frame, "coop1", COOP_POSE, left, right)
        recorder.write_fused(stamp, {"left": np.array([[8.25, 5.0], [8.25, 60.0]])})
        recorder.write_metrics(stamp, frame, {"mean_error_m": 0.01 * frame, "max_error_m": float("nan"), "fused": 1})


@pytest.fixture(scope="session")
def recording(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    with Recorder(path, map_path="maps/straight.xodr", params={"d_s": 20.0, "fusion": "spline"},
                  stamp_base_ns=BASE_NS) as recorder:
        record_frames(recorder, range(FRAMES))
    return path


def test_recording_has_the_channels_schemas_counts_and_summary(recording):
    summary, _, metadata = read_all(recording)
    assert summary is not None and summary.statistics is not None
    topics = {c.topic: c for c in summary.channels.values()}
    assert set(topics) == {"/gt", "/fused", "/detections/ego", "/detections/coop1", "/tf", "/cold/detections",
                           "/metrics"}
    counts = {c.topic: summary.statistics.channel_message_counts[cid] for cid, c in summary.channels.items()}
    assert counts == {"/gt": FRAMES, "/fused": FRAMES, "/detections/ego": FRAMES, "/detections/coop1": FRAMES,
                      "/tf": 2 * FRAMES, "/cold/detections": 2 * FRAMES, "/metrics": FRAMES}
    schema_of = {c.topic: summary.schemas[c.schema_id] for c in summary.channels.values()}
    scene = ("foxglove.SceneUpdate", "protobuf", "protobuf")
    assert {t: (s.name, s.encoding, topics[t].message_encoding) for t, s in schema_of.items()} == {
        "/gt": scene, "/fused": scene, "/detections/ego": scene, "/detections/coop1": scene,
        "/tf": ("foxglove.FrameTransform", "protobuf", "protobuf"),
        "/cold/detections": ("cold.LaneDetection", "jsonschema", "json"),
        "/metrics": ("cold.FrameMetrics", "jsonschema", "json")}
    assert len(summary.schemas) == 4  # one schema record shared by the SceneUpdate channels
    assert summary.statistics.message_start_time == BASE_NS
    assert summary.statistics.message_end_time == BASE_NS + round((FRAMES - 1) * DT_S * 1e9)
    assert metadata["cold.status"] == {"status": "complete"}
    assert metadata["cold.run"]["map"] == "maps/straight.xodr"
    assert metadata["cold.run"]["recording_version"] == str(RECORDING_VERSION) == "3"
    assert int(metadata["cold.run"]["stamp_base_ns"]) == BASE_NS == read_stamp_base(recording)
    assert json.loads(metadata["cold.run"]["params"]) == {"d_s": 20.0, "fusion": "spline"}
    assert not recording.with_name("run.mcap.partial").exists()


def test_json_messages_validate_against_their_schemas_and_carry_sec_nsec_stamps(recording):
    schemas = {s["title"]: s for s in (LANE_DETECTION_SCHEMA, FRAME_METRICS_SCHEMA)}
    for schema in schemas.values():
        jsonschema.Draft202012Validator.check_schema(schema)
    _, messages, _ = read_all(recording)
    json_messages = [(name, payload, log_time) for _, name, payload, log_time in messages if name in schemas]
    assert len(json_messages) == 3 * FRAMES
    for name, payload, log_time in json_messages:
        jsonschema.validate(payload, schemas[name], cls=jsonschema.Draft202012Validator)
        assert payload["stamp"] == {"sec": log_time // 10**9, "nsec": log_time % 10**9}
    with pytest.raises(jsonschema.ValidationError):  # the schema does constrain: stamps are {sec, nsec}
        bad = dict(json_messages[0][1], stamp=0.1)
        jsonschema.validate(bad, LANE_DETECTION_SCHEMA)


def test_scene_updates_are_line_strips_in_the_map_frame_at_the_world_pose(recording):
    _, messages, _ = read_all(recording)
    ego = [(p, t) for topic, _, p, t in messages if topic == "/detections/ego"]
    update, log_time = ego[2]
    assert log_time == BASE_NS + 200_000_000
    sec, nsec = divmod(log_time, 10**9)
    [deletion] = update.deletions
    assert (deletion.timestamp.seconds, deletion.timestamp.nanos, deletion.type) == (sec, nsec, 1)  # 1 = ALL
    entities = {e.id: e for e in update.entities}
    assert set(entities) == {"left", "right"}
    [line] = entities["left"].lines
    assert entities["left"].frame_id == "map" and line.type == 0  # LINE_STRIP
    assert (entities["left"].timestamp.seconds, entities["left"].timestamp.nanos) == (sec, nsec)
    assert line.thickness == pytest.approx(0.15) and (line.color.r, line.color.b) == pytest.approx((0.1, 0.9))
    assert (line.pose.orientation.w, line.pose.position.x) == (1.0, 0.0)
    # ego at (10, 5) heading north: vehicle (x, 1.75) -> world (10 - 1.75, 5 + x)
    # a straight border is drawn as its two end points (1 cm simplification, 0.1 mm rounding)
    left, _ = lane(2)
    points = np.array([[p.x, p.y, p.z] for p in line.points])
    np.testing.assert_allclose(points[:, 0], 10.0 - 1.75, atol=0.5e-4)
    np.testing.assert_allclose(points[:, 1], 5.0 + left[[0, -1], 0], atol=0.5e-4)
    np.testing.assert_array_equal(points[:, 2], 0.0)
    fused_cleared = [p for topic, _, p, _ in messages if topic == "/fused"]
    assert [len(u.entities) for u in fused_cleared] == [1] * FRAMES
    metrics = [p for topic, _, p, _ in messages if topic == "/metrics"]
    assert metrics[1] == {"stamp": {"sec": BASE_NS // 10**9, "nsec": BASE_NS % 10**9 + 100_000_000}, "frame": 1,
                          "mean_error_m": 0.01, "max_error_m": None, "fused": 1.0}


def test_frame_transforms_place_each_vehicle_at_its_pose(recording):
    _, messages, _ = read_all(recording)
    transforms = [(t, log_time) for topic, _, t, log_time in messages if topic == "/tf"]
    assert [t.child_frame_id for t, _ in transforms] == ["ego", "coop1"] * FRAMES
    for (transform, log_time), pose in zip(transforms, [EGO_POSE, COOP_POSE] * FRAMES):
        assert transform.parent_frame_id == "map"
        assert transform.timestamp.seconds * 10**9 + transform.timestamp.nanos == log_time
        assert (transform.translation.x, transform.translation.y, transform.translation.z) == (pose[0], pose[1], 0.0)
        q = transform.rotation
        # a rotation by yaw about z: the vehicle's x axis (1, 0) maps to (cos yaw, sin yaw)
        x_axis = (1.0 - 2.0 * (q.y ** 2 + q.z ** 2), 2.0 * (q.x * q.y + q.z * q.w))
        assert x_axis == pytest.approx((math.cos(pose[2]), math.sin(pose[2])), abs=1e-12)
        assert q.x**2 + q.y**2 + q.z**2 + q.w**2 == pytest.approx(1.0)


def test_log_times_start_at_the_wall_clock_by_default(tmp_path):
    before = time.time_ns()
    with Recorder(tmp_path / "now.mcap") as recorder:
        record_frames(recorder, range(2))
    after = time.time_ns()
    summary, _, metadata = read_all(tmp_path / "now.mcap")
    base = int(metadata["cold.run"]["stamp_base_ns"])
    assert before <= base <= after and recorder.stamp_base_ns == base
    assert summary.statistics.message_start_time == base
    assert summary.statistics.message_end_time == base + 100_000_000


def test_read_detections_round_trips_exactly(recording):
    frames = list(read_detections(recording))
    assert [frame for frame, _ in frames] == list(range(FRAMES))
    for frame, detections in frames:
        assert [d["sender"] for d in detections] == ["ego", "coop1"]
        left, right = lane(frame)
        for detection, pose in zip(detections, (EGO_POSE, COOP_POSE)):
            np.testing.assert_array_equal(detection["left"], left)
            np.testing.assert_array_equal(detection["right"], right)
            assert detection["left"].dtype == np.float64
            assert detection["pose"] == dict(zip("x y yaw".split(), pose))
            assert detection["stamp_s"] == pytest.approx(frame * DT_S, abs=1e-9) and detection["frame"] == frame


def test_version_1_recordings_are_still_read(tmp_path):
    path = tmp_path / "v1.mcap"
    detections = []
    for frame in range(FRAMES):
        left, right = lane(frame)
        detections += [(frame * DT_S, frame, "ego", EGO_POSE, left, right),
                       (frame * DT_S, frame, "coop1", COOP_POSE, left + 0.5, right)]
    write_v1_recording(path, detections)
    assert read_stamp_base(path) == 0 and "recording_version" not in read_metadata(path)["cold.run"]
    frames = list(read_detections(path))
    assert [frame for frame, _ in frames] == list(range(FRAMES))
    read = [d for _, group in frames for d in group]
    for detection, (stamp, frame, sender, pose, left, right) in zip(read, detections, strict=True):
        assert (detection["stamp_s"], detection["frame"], detection["sender"]) == (stamp, frame, sender)
        assert tuple(detection["pose"].values()) == pose
        np.testing.assert_array_equal(detection["left"], left)
        np.testing.assert_array_equal(detection["right"], right)


@pytest.mark.parametrize("interrupt", [RuntimeError, KeyboardInterrupt])
def test_interrupted_run_is_finalised_and_marked_partial(tmp_path, interrupt):
    path = tmp_path / "cut.mcap"
    with pytest.raises(interrupt):
        with Recorder(path, map_path="m.xodr") as recorder:
            record_frames(recorder, range(2))
            assert recorder.partial_path.exists() and not path.exists()
            raise interrupt()
    assert path.exists() and not recorder.partial_path.exists()
    summary, messages, metadata = read_all(path)
    assert summary is not None
    assert metadata["cold.status"] == {"status": "partial", "reason": interrupt.__name__}
    assert read_metadata(path)["cold.status"]["status"] == "partial"
    assert sum(topic == "/cold/detections" for topic, *_ in messages) == 4
    assert [frame for frame, _ in read_detections(path)] == [0, 1]


def write_foreign(path: Path, topic: str, schema_name: str) -> None:
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema(name=schema_name, encoding="jsonschema", data=b"{}")
        channel = writer.register_channel(topic=topic, message_encoding="json", schema_id=schema)
        writer.add_message(channel_id=channel, log_time=0, publish_time=0, data=b"{}")
        writer.finish()


def test_foreign_and_broken_files_give_one_line_errors(tmp_path, recording):
    text = tmp_path / "notes.mcap"
    text.write_text("hello, not an mcap\n")
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(recording.read_bytes()[: recording.stat().st_size // 2])
    other_topic = tmp_path / "other.mcap"
    write_foreign(other_topic, "/camera", "foxglove.CompressedImage")
    other_schema = tmp_path / "schema.mcap"
    write_foreign(other_schema, "/cold/detections", "acme.Lanes")
    cases = [
        (text, "not an MCAP file"),
        (truncated, "truncated or not finalised"),
        (other_topic, "no /cold/detections channel"),
        (other_schema, r"\('acme.Lanes', 'jsonschema', 'json'\), expected \('cold.LaneDetection'"),
        (tmp_path / "missing.mcap", "cannot open recording"),
    ]
    for path, message in cases:
        with pytest.raises(RecordingError, match=message) as info:
            read_detections(path)
        assert str(path) in str(info.value) and "\n" not in str(info.value)


@pytest.mark.parametrize("change, error", [
    ({"left": [[0, 0]]}, "left: expected at least 2 points"),
    ({"stamp": {"sec": 0, "nsec": 10**9}}, "stamp: expected integers sec >= 0 and 0 <= nsec < 1e9"),
    ({"stamp": 0.5}, "TypeError|not subscriptable|indices"),
    ({"left": [[0, 0], [1, float("nan")]]}, ""),  # NaN is not JSON
])
def test_malformed_detection_message_names_the_message(tmp_path, change, error):
    path = tmp_path / "bad.mcap"
    with open(path, "wb") as stream:
        writer = Writer(stream)
        writer.start()
        schema = writer.register_schema(name="cold.LaneDetection", encoding="jsonschema",
                                        data=json.dumps(LANE_DETECTION_SCHEMA).encode())
        channel = writer.register_channel(topic="/cold/detections", message_encoding="json", schema_id=schema)
        message = {"stamp": {"sec": 0, "nsec": 0}, "frame": 0, "sender": "ego", "pose": {"x": 0, "y": 0, "yaw": 0},
                   "left": [[0, 0], [1, 0]], "right": [[0, -1], [1, -1]], **change}
        writer.add_message(channel_id=channel, log_time=0, publish_time=0, data=json.dumps(message).encode())
        writer.finish()
    with pytest.raises(RecordingError, match="/cold/detections message 0: invalid cold.LaneDetection: " + error):
        list(read_detections(path))


def test_bad_input_is_rejected_with_the_name(tmp_path):
    left, right = lane(0)
    with Recorder(tmp_path / "x.mcap") as recorder:
        with pytest.raises(ValueError, match="sender: expected letters"):
            recorder.write_detection(0.0, 0, "ego car", EGO_POSE, left, right)
        with pytest.raises(ValueError, match="ego right: expected an \\(N, 2\\) polyline"):
            recorder.write_detection(0.0, 0, "ego", EGO_POSE, left, right[:, 0])
        with pytest.raises(ValueError, match="stamp_s: expected a finite time >= 0 s"):
            recorder.write_gt(-1.0, {"left": left})
        with pytest.raises(ValueError, match="frame: expected an integer >= 0"):
            recorder.write_metrics(0.0, -3, {})
        with pytest.raises(ValueError, match=r"metrics\['x'\]: expected a number or None"):
            recorder.write_metrics(0.0, 0, {"x": "high"})
    for bad in (-1, 2**63, 1.5, True):
        with pytest.raises(ValueError, match="stamp_base_ns: expected an integer 0"):
            Recorder(tmp_path / "z.mcap", stamp_base_ns=bad)
    with pytest.raises(RecordingError, match="not open"):
        recorder.write_gt(0.0, {"left": left})
    with pytest.raises(RecordingError, match="nowhere/y.mcap.partial: cannot create recording"):
        with Recorder(tmp_path / "nowhere" / "y.mcap"):
            pass


coordinates = st.floats(-1e6, 1e6, allow_nan=False, allow_infinity=False)
polylines = st.integers(2, 40).flatmap(lambda n: st.lists(st.tuples(coordinates, coordinates), min_size=n, max_size=n))


@settings(max_examples=25, deadline=None)
@given(left=polylines, right=polylines, pose=st.tuples(coordinates, coordinates, st.floats(-4.0, 4.0)),
       frame=st.integers(0, 10**6))
def test_raw_detections_round_trip_bit_exactly(left, right, pose, frame):
    with tempfile.TemporaryDirectory() as folder:
        path = Path(folder) / "p.mcap"
        with Recorder(path) as recorder:
            recorder.write_detection(frame * DT_S, frame, "coop_2", pose, np.array(left), np.array(right))
        [(read_frame, [detection])] = list(read_detections(path))
    assert read_frame == frame
    np.testing.assert_array_equal(detection["left"], np.array(left))
    np.testing.assert_array_equal(detection["right"], np.array(right))
    assert tuple(detection["pose"].values()) == pose


def _distance_to_polyline(points: np.ndarray, line: np.ndarray) -> np.ndarray:
    start, direction = line[:-1], np.diff(line, axis=0)
    along = np.einsum("psk,sk->ps", points[:, None, :] - start[None], direction)
    along = np.clip(along / np.maximum(np.einsum("sk,sk->s", direction, direction), 1e-300), 0.0, 1.0)
    foot = start[None] + along[..., None] * direction[None]
    return np.min(np.linalg.norm(points[:, None, :] - foot, axis=2), axis=1)


def simplify_polyline(points: np.ndarray, tolerance: float = DISPLAY_TOLERANCE_M) -> np.ndarray:
    [simple] = simplify_lines([points], tolerance)
    return simple


def test_simplify_collapses_a_straight_line_and_keeps_an_arc_within_tolerance() -> None:
    x = np.linspace(0.0, 100.0, 1001)
    assert simplify_polyline(np.column_stack((x, 0.5 * x + 3.0))).tolist() == [[0.0, 3.0], [100.0, 53.0]]
    radius, tolerance = 16.0, 1e-3
    phi = np.linspace(0.0, np.pi / 2, 252)
    arc = np.column_stack((radius * np.cos(phi), radius * np.sin(phi)))
    simple = simplify_polyline(arc, tolerance)
    assert _distance_to_polyline(arc, simple).max() <= tolerance
    # a chord of an arc with sag h spans sqrt(8 R h); halving spans, Douglas-Peucker uses at
    # most twice the fewest chords that keep the sag
    assert len(simple) - 1 <= 2 * math.ceil(radius * np.pi / 2 / math.sqrt(8 * radius * tolerance))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=2, max_size=40),
       st.floats(1e-4, 1.0))
def test_simplified_lines_keep_ends_order_and_tolerance(points: list[tuple[float, float]], tolerance: float) -> None:
    line = np.array(points, dtype=np.float64)
    simple = simplify_polyline(line, tolerance)
    assert simple[0].tolist() == line[0].tolist() and simple[-1].tolist() == line[-1].tolist()
    remaining = iter(line.tolist())
    assert all(point in remaining for point in simple.tolist())  # an ordered subsequence of the line
    if len(simple) >= 2:
        assert _distance_to_polyline(line, simple).max() <= tolerance + 1e-9


@settings(max_examples=30, deadline=None)
@given(st.lists(st.lists(st.tuples(st.floats(-50, 50), st.floats(-50, 50)), min_size=2, max_size=12),
                min_size=1, max_size=5))
def test_lines_simplified_together_equal_each_alone(lines: list[list[tuple[float, float]]]) -> None:
    arrays = [np.array(line, dtype=np.float64) for line in lines]
    together = simplify_lines(arrays, 0.5)
    assert len(together) == len(arrays)
    for simple, line in zip(together, arrays):
        assert simple.tolist() == simplify_polyline(line, 0.5).tolist()
    drawn = display_lines({str(i): line for i, line in enumerate(arrays)})
    for shown, simple in zip(drawn, simplify_lines(arrays, DISPLAY_TOLERANCE_M), strict=True):
        np.testing.assert_allclose(shown, simple, atol=0.5e-4 + 1e-12)
