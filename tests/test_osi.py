"""``cold-eval --osi``: the OSI trace read back by an independent reader (Google protobuf with
descriptors built here from the OSI .proto field numbers, not betterosi) matches the run's
``run.mcap`` point for point; ``cold-fuse`` on the trace gives the MCAP's ``metrics.json``;
σ, boundary types, interruption, usage errors and broken traces."""

from __future__ import annotations

import json
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from conftest import bundled_map

from cold_maps.cli import evaluate, fuse
from cold_maps.recording.osi import read_sidecar, sensor_data, sidecar_path, vehicle_id
from cold_maps.recording.recorder import Recorder, read_detections

STAMP_BASE_S = 1_700_000_000
FLOAT32_EPS = float(np.finfo(np.float32).eps)

# (message, [(field name, number, type, label, message type name)]) of the OSI 3 subset read
# here; numbers from osi_sensordata.proto, osi_sensorview.proto, osi_groundtruth.proto,
# osi_object.proto, osi_detectedlane.proto, osi_detectedobject.proto, osi_lane.proto,
# osi_common.proto and osi_version.proto. Fields not listed stay unknown fields.
OPTIONAL, REPEATED = 1, 3
DOUBLE, INT64, UINT64, UINT32, INT32, STRING, MESSAGE = 1, 3, 4, 13, 5, 9, 11
OSI_SUBSET: list[tuple[str, list[tuple[str, int, int, int, str]]]] = [
    ("InterfaceVersion", [("version_major", 1, UINT32, OPTIONAL, ""), ("version_minor", 2, UINT32, OPTIONAL, ""),
                          ("version_patch", 3, UINT32, OPTIONAL, "")]),
    ("Timestamp", [("seconds", 1, INT64, OPTIONAL, ""), ("nanos", 2, UINT32, OPTIONAL, "")]),
    ("Identifier", [("value", 1, UINT64, OPTIONAL, "")]),
    ("Vector3d", [("x", 1, DOUBLE, OPTIONAL, ""), ("y", 2, DOUBLE, OPTIONAL, ""), ("z", 3, DOUBLE, OPTIONAL, "")]),
    ("Orientation3d", [("roll", 1, DOUBLE, OPTIONAL, ""), ("pitch", 2, DOUBLE, OPTIONAL, ""),
                       ("yaw", 3, DOUBLE, OPTIONAL, "")]),
    ("MountingPosition", [("position", 1, MESSAGE, OPTIONAL, "Vector3d"),
                          ("orientation", 2, MESSAGE, OPTIONAL, "Orientation3d")]),
    ("BaseMoving", [("position", 2, MESSAGE, OPTIONAL, "Vector3d"),
                    ("orientation", 3, MESSAGE, OPTIONAL, "Orientation3d")]),
    ("ExternalReference", [("reference", 1, STRING, OPTIONAL, ""), ("type", 2, STRING, OPTIONAL, ""),
                           ("identifier", 3, STRING, REPEATED, "")]),
    ("MovingObject", [("id", 1, MESSAGE, OPTIONAL, "Identifier"), ("base", 2, MESSAGE, OPTIONAL, "BaseMoving"),
                      ("source_reference", 10, MESSAGE, REPEATED, "ExternalReference")]),
    ("GroundTruth", [("timestamp", 2, MESSAGE, OPTIONAL, "Timestamp"),
                     ("host_vehicle_id", 3, MESSAGE, OPTIONAL, "Identifier"),
                     ("moving_object", 5, MESSAGE, REPEATED, "MovingObject"),
                     ("map_reference", 15, STRING, OPTIONAL, "")]),
    ("SensorView", [("sensor_id", 3, MESSAGE, OPTIONAL, "Identifier"),
                    ("mounting_position", 4, MESSAGE, OPTIONAL, "MountingPosition"),
                    ("global_ground_truth", 7, MESSAGE, OPTIONAL, "GroundTruth"),
                    ("host_vehicle_id", 8, MESSAGE, OPTIONAL, "Identifier")]),
    ("DetectedItemHeader", [("tracking_id", 1, MESSAGE, OPTIONAL, "Identifier"),
                            ("existence_probability", 3, DOUBLE, OPTIONAL, "")]),
    ("BoundaryPoint", [("position", 1, MESSAGE, OPTIONAL, "Vector3d")]),
    ("BoundaryClassification", [("type", 1, INT32, OPTIONAL, "")]),
    ("CandidateLaneBoundary", [("probability", 1, DOUBLE, OPTIONAL, ""),
                               ("classification", 2, MESSAGE, OPTIONAL, "BoundaryClassification")]),
    ("DetectedLaneBoundary", [("header", 1, MESSAGE, OPTIONAL, "DetectedItemHeader"),
                              ("candidate", 2, MESSAGE, REPEATED, "CandidateLaneBoundary"),
                              ("boundary_line", 3, MESSAGE, REPEATED, "BoundaryPoint"),
                              ("boundary_line_rmse", 4, MESSAGE, REPEATED, "BoundaryPoint")]),
    ("DetectedEntityHeader", [("measurement_time", 1, MESSAGE, OPTIONAL, "Timestamp"),
                              ("cycle_counter", 2, UINT64, OPTIONAL, "")]),
    ("SensorData", [("version", 1, MESSAGE, OPTIONAL, "InterfaceVersion"),
                    ("timestamp", 2, MESSAGE, OPTIONAL, "Timestamp"),
                    ("sensor_id", 5, MESSAGE, OPTIONAL, "Identifier"),
                    ("mounting_position", 6, MESSAGE, OPTIONAL, "MountingPosition"),
                    ("sensor_view", 8, MESSAGE, REPEATED, "SensorView"),
                    ("last_measurement_time", 9, MESSAGE, OPTIONAL, "Timestamp"),
                    ("lane_boundary_header", 20, MESSAGE, OPTIONAL, "DetectedEntityHeader"),
                    ("lane_boundary", 21, MESSAGE, REPEATED, "DetectedLaneBoundary")]),
]


def _sensor_data_class() -> Any:
    """``SensorData`` of the OSI subset as a Google protobuf message class (package
    ``osi3check``, nested OSI types flattened: names do not reach the wire)."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    proto = descriptor_pb2.FileDescriptorProto(name="osi3check.proto", package="osi3check", syntax="proto2")
    for name, fields in OSI_SUBSET:
        message = proto.message_type.add(name=name)
        for field_name, number, kind, label, type_name in fields:
            field = message.field.add(name=field_name, number=number, type=kind, label=label)
            if type_name:
                field.type_name = f".osi3check.{type_name}"
    pool = descriptor_pool.DescriptorPool()
    pool.Add(proto)
    return message_factory.MessageFactory(pool).GetPrototype(pool.FindMessageTypeByName("osi3check.SensorData"))


def read_trace(path: Path) -> list[Any]:
    """Every message of a length-prefixed OSI trace, framed and decoded here."""
    cls, data, messages, at = _sensor_data_class(), path.read_bytes(), [], 0
    while at < len(data):
        (size,) = struct.unpack_from("<I", data, at)
        assert at + 4 + size <= len(data), "truncated trace"
        messages.append(cls.FromString(data[at + 4: at + 4 + size]))
        at += 4 + size
    return messages


def _points(boundary_points: Any) -> np.ndarray:
    return np.array([(p.position.x, p.position.y) for p in boundary_points], dtype=np.float64)


def _close_in_float32(a: np.ndarray, b: np.ndarray) -> bool:
    return a.shape == b.shape and bool(np.all(np.abs(a - b) <= FLOAT32_EPS * np.maximum(1.0, np.abs(b))))


@pytest.fixture(scope="module")
def run(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A short junction run with run.mcap and the OSI trace."""
    out = tmp_path_factory.mktemp("osi") / "eval"
    assert evaluate.main(["--map", str(bundled_map("junction")), "--frames", "5", "--routes", "1", "--no-plots",
                          "--workers", "1", "-q", "--stamp-base", str(STAMP_BASE_S), "--out", str(out),
                          "--osi", str(out / "run.osi")]) == 0
    return out


def test_an_independent_reader_gets_the_recorded_detections(run: Path) -> None:
    messages = read_trace(run / "run.osi")
    recorded = [d for _, frame in read_detections(run / "run.mcap") for d in frame]
    assert len(messages) == len(recorded) > 10
    for message, expected in zip(messages, recorded, strict=True):
        assert (message.version.version_major, message.version.version_minor) == (3, 8)
        stamp_ns = message.timestamp.seconds * 10**9 + message.timestamp.nanos
        assert stamp_ns == round(expected["stamp_s"] * 1e9)
        assert message.last_measurement_time == message.timestamp
        assert message.lane_boundary_header.cycle_counter == expected["frame"]
        mount = message.mounting_position
        assert (mount.position.x, mount.position.y, mount.orientation.yaw) == (0.0, 0.0, 0.0)
        assert message.sensor_id.value == vehicle_id(expected["sender"])
        truth = message.sensor_view[0].global_ground_truth
        assert truth.host_vehicle_id.value == message.sensor_id.value
        assert truth.map_reference == str(bundled_map("junction"))
        (vehicle,) = truth.moving_object
        assert list(vehicle.source_reference[0].identifier) == [expected["sender"]]
        pose = np.array([vehicle.base.position.x, vehicle.base.position.y, vehicle.base.orientation.yaw])
        assert _close_in_float32(pose, np.array(list(expected["pose"].values())))
        left, right = message.lane_boundary
        assert (left.header.tracking_id.value, right.header.tracking_id.value) == (0, 1)
        for boundary, border in ((left, expected["left"]), (right, expected["right"])):
            assert _close_in_float32(_points(boundary.boundary_line), border)
            assert not boundary.boundary_line[0].position.HasField("z")  # unset: OSI's default 0
            assert boundary.header.existence_probability == 1.0
            assert not boundary.boundary_line_rmse  # the ideal sensor states no σ
            (candidate,) = boundary.candidate
            assert (candidate.probability, candidate.classification.type) == (1.0, 0)


def test_the_sidecar_says_complete_with_the_stamp_base(run: Path) -> None:
    sidecar = read_sidecar(run / "run.osi")
    assert sidecar["status"] == "complete"
    assert sidecar["stamp_base_ns"] == STAMP_BASE_S * 10**9
    assert sidecar["messages"] == len(read_trace(run / "run.osi"))
    assert sidecar["map"] == str(bundled_map("junction"))


def _without_runtime(document: Any) -> Any:
    if isinstance(document, dict):
        return {k: _without_runtime(v) for k, v in document.items() if "runtime" not in k}
    if isinstance(document, list):
        return [_without_runtime(v) for v in document]
    return document


def test_cold_fuse_scores_the_trace_as_the_mcap(run: Path, tmp_path: Path) -> None:
    reports = {}
    for name in ("run.mcap", "run.osi"):
        report = tmp_path / name
        assert fuse.main(["--input", str(run / name), "-o", str(tmp_path / f"{name}.fused.mcap"), "--report",
                          str(report), "-q"]) == 0
        reports[name] = json.loads((report / "metrics.json").read_text())
    scored = [s for s in reports["run.osi"]["scenarios"] if s["fusion"] != "local" and s.get("fused_frames")]
    assert scored, "the trace's coops were fused and scored"
    provenances = {name: report.pop("provenance") for name, report in reports.items()}
    assert _without_runtime(reports["run.osi"]) == _without_runtime(reports["run.mcap"])
    assert [f["name"] for f in provenances["run.osi"]["inputs"]][:1] == ["run.osi"]  # each names its own input
    stamps = {d["stamp_s"] for _, frame in read_detections(tmp_path / "run.osi.fused.mcap") for d in frame}
    assert stamps == {0.0, 0.1, 0.2, 0.3, 0.4}


def test_workers_and_no_mcap_write_the_same_trace(run: Path, tmp_path: Path) -> None:
    assert evaluate.main(["--map", str(bundled_map("junction")), "--frames", "5", "--routes", "1", "--no-plots",
                          "--workers", "2", "-q", "--stamp-base", str(STAMP_BASE_S), "--no-mcap", "--out",
                          str(tmp_path / "eval"), "--osi", str(tmp_path / "new" / "t.osi")]) == 0
    assert (tmp_path / "new" / "t.osi").read_bytes() == (run / "run.osi").read_bytes()
    assert not (tmp_path / "eval" / "run.mcap").exists()


def test_sigma_becomes_rmse_along_the_normal_and_types_are_written() -> None:
    """A border along the 45° diagonal with σ 0.2 m: RMSE 0.2/√2 m in x and in y; a straight
    border along x: all of σ in y. Boundary types as given."""
    diagonal = np.column_stack((np.arange(5.0), np.arange(5.0)))
    along_x = np.column_stack((np.arange(5.0), np.full(5, -1.75)))
    sigma = np.full(5, 0.2)
    payload = sensor_data(123_456_789, 7, "coop1", (1.0, 2.0, 0.5), diagonal, along_x, sigmas=(sigma, 2 * sigma),
                          boundary_types=(3, 4))
    message = _sensor_data_class().FromString(payload)
    left, right = message.lane_boundary
    assert np.allclose(_points(left.boundary_line_rmse), 0.2 / math.sqrt(2), atol=1e-15)
    assert np.allclose(_points(right.boundary_line_rmse), [[0.0, 0.4]] * 5, atol=1e-15)
    assert [b.candidate[0].classification.type for b in (left, right)] == [3, 4]
    assert (message.timestamp.seconds, message.timestamp.nanos) == (0, 123_456_789)
    from cold_maps.recording.osi import decode_detection

    decoded = decode_detection(payload)
    assert np.allclose(decoded["left_sigma"], 0.2) and np.allclose(decoded["right_sigma"], 0.4)
    assert decoded["sender"] == "coop1" and decoded["frame"] == 7


def test_a_detection_stating_sigma_is_recorded_with_its_rmse(tmp_path: Path) -> None:
    import fusion
    from cold_maps.recording.osi import read_osi_detections

    trace = tmp_path / "t.osi"
    left = np.column_stack((np.arange(0.0, 3.0, 0.1), np.full(30, 1.75)))
    sigma = np.linspace(0.05, 0.2, 30)
    detection = fusion.LaneDetection(fusion.Pose2D(0.0, 0.0, 0.0), left, left - [0.0, 3.5], left_sigma=sigma)
    with Recorder(None, osi=trace, stamp_base_ns=0) as recorder:
        recorder.write_detection(0.0, 0, "coop1", (0.0, 0.0, 0.0), detection.left, detection.right, lanes=detection)
    (message,) = read_trace(trace)
    left_boundary, right_boundary = message.lane_boundary
    assert np.allclose(_points(left_boundary.boundary_line_rmse), np.column_stack((np.zeros(30), sigma)), atol=1e-15)
    assert not right_boundary.boundary_line_rmse
    ((_, (read,)),) = list(read_osi_detections(trace))
    assert np.allclose(read["left_sigma"], sigma, atol=1e-15) and read["right_sigma"] is None


@pytest.mark.parametrize("interrupt", [RuntimeError, KeyboardInterrupt])
def test_an_interrupted_trace_is_finalised_and_marked_partial(tmp_path: Path, interrupt: type[Exception]) -> None:
    trace = tmp_path / "t.osi"
    border = np.column_stack((np.arange(3.0), np.zeros(3)))
    with pytest.raises(interrupt):
        with Recorder(None, osi=trace, stamp_base_ns=0, map_path="m.xodr") as recorder:
            recorder.write_detection(0.1, 1, "ego", (0.0, 0.0, 0.0), border, border + [0.0, -3.5])
            raise interrupt()
    assert not (tmp_path / "t.osi.partial").exists()
    assert read_sidecar(trace)["status"] == "partial" and read_sidecar(trace)["reason"] == interrupt.__name__
    (message,) = read_trace(trace)
    assert _points(message.lane_boundary[1].boundary_line)[:, 1].tolist() == [-3.5] * 3
    assert sidecar_path(trace) == tmp_path / "t.osi.json"


@pytest.mark.parametrize("extra, message", [(["--lanes", "1"], "--lanes"), (["--history"], "--history")])
def test_what_osi_cannot_carry_is_a_usage_error(tmp_path: Path, capsys: pytest.CaptureFixture[str],
                                                extra: list[str], message: str) -> None:
    status = evaluate.main(["--map", str(bundled_map("junction")), "--osi", str(tmp_path / "t.osi"), "--out",
                            str(tmp_path / "o"), *extra])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and message in err[0] and "(see cold-eval --help)" in err[0]
    assert not (tmp_path / "o").exists()


def test_a_folder_as_trace_is_a_usage_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exit_:
        evaluate.main(["--map", str(bundled_map("junction")), "--osi", str(tmp_path), "--out", str(tmp_path / "o")])
    assert exit_.value.code == 2 and "--osi" in capsys.readouterr().err


def test_a_truncated_trace_is_one_error_line(run: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    broken = tmp_path / "broken.osi"
    data = (run / "run.osi").read_bytes()
    broken.write_bytes(data[: len(data) - 10])
    status = fuse.main(["--input", str(broken), "-o", str(tmp_path / "f.mcap"), "--no-gt", "-q"])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 1 and len(err) == 1 and str(broken) in err[0] and "truncated" in err[0]
