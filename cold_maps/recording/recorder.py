"""MCAP recording of an evaluation run, viewable in Foxglove and re-readable for re-fusion.

Channels (all JSON-encoded, schemas in ``jsonschema``):

- ``/gt``, ``/fused``, ``/detections/<sender>``: ``foxglove.SceneUpdate`` (the Foxglove
  JSON schema, with the item schemas of the primitive lists we always leave empty reduced to
  their title). One entity per polyline, a ``LINE_STRIP`` in frame ``map`` (= the world
  frame, m, z = 0), simplified to within 1 cm (Douglas-Peucker; the lines are drawn
  0.15 m wide, straight stretches cost two points) and rounded to 0.1 mm. Every update
  first deletes all older entities on its topic, so the 3D panel shows exactly the
  current frame.
- ``/cold/detections``: ``cold.LaneDetection`` (:data:`LANE_DETECTION_SCHEMA`), the raw
  detections for re-fusion.
- ``/metrics``: ``cold.FrameMetrics`` (:data:`FRAME_METRICS_SCHEMA`), a flat object of
  numbers per frame, for Foxglove's plot panel.

MCAP metadata records: ``cold.run`` (``map``: the map path, ``params``: the run
parameters as a JSON object string) and ``cold.status`` (``status``: ``complete`` or
``partial``; ``reason``: the exception that ended a partial run).

Log times are the frame stamps in ns. The file is written as ``<path>.partial`` and
renamed when finalised; a run ended by an exception (Ctrl-C included) is still finalised
under the final name, marked ``partial``.
"""

from __future__ import annotations

import json
import math
import os
import re
from pathlib import Path
from types import TracebackType
from typing import Any, Final, Iterator, Mapping

import numpy as np

import fusion
from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.simulation.sensor import vehicle_to_world
from cold_maps.simulation.sensor_errors import check_polyline
from gt_matching.polyline import simplify

TOPIC_GT: Final[str] = "/gt"
TOPIC_FUSED: Final[str] = "/fused"
TOPIC_DETECTIONS_PREFIX: Final[str] = "/detections/"
TOPIC_RAW_DETECTIONS: Final[str] = "/cold/detections"
TOPIC_METRICS: Final[str] = "/metrics"
FRAME_ID: Final[str] = "map"
METADATA_RUN: Final[str] = "cold.run"
METADATA_STATUS: Final[str] = "cold.status"
STATUS_COMPLETE: Final[str] = "complete"
STATUS_PARTIAL: Final[str] = "partial"
LINE_THICKNESS_M: Final[float] = 0.15
DISPLAY_DECIMALS: Final[int] = 4  # SceneUpdate coordinates rounded to 0.1 mm (raw detections stay exact)
DISPLAY_TOLERANCE_M: Final[float] = 0.01  # SceneUpdate lines simplified to within this distance
MCAP_MAGIC: Final[bytes] = b"\x89MCAP0\r\n"

RGBA = tuple[float, float, float, float]
COLOR_GT: Final[RGBA] = (0.2, 0.8, 0.2, 1.0)
COLOR_FUSED: Final[RGBA] = (0.9, 0.1, 0.1, 1.0)
COLOR_EGO: Final[RGBA] = (0.1, 0.4, 0.9, 1.0)
COLOR_COOP: Final[RGBA] = (1.0, 0.6, 0.0, 1.0)

_SENDER_PATTERN: Final = re.compile(r"[A-Za-z0-9_\-]+")


class RecordingError(Exception):
    """A recording that cannot be written or read; the message is one line naming the file."""


def _object(title: str, description: str, properties: dict[str, Any], required: bool = True) -> dict[str, Any]:
    schema: dict[str, Any] = {"title": title, "description": description, "type": "object", "properties": properties}
    if required:
        schema["required"] = list(properties)
    return schema


def _number(description: str) -> dict[str, str]:
    return {"type": "number", "description": description}


def _time(title: str, description: str, sec_minimum: bool) -> dict[str, Any]:
    sec: dict[str, Any] = {"type": "integer", "minimum": 0} if sec_minimum else {"type": "integer"}
    return {
        "type": "object",
        "title": title,
        "properties": {"sec": sec, "nsec": {"type": "integer", "minimum": 0, "maximum": 999999999}},
        "description": description,
    }


def _enum(title: str, description: str, values: list[tuple[str, int, str]]) -> dict[str, Any]:
    return {
        "title": title,
        "description": description,
        "oneOf": [{"title": name, "const": value, "description": text} for name, value, text in values],
    }


def _color(description: str) -> dict[str, Any]:
    return _object("foxglove.Color", description, {c: _number(f"{n} value between 0 and 1") for c, n in
                                                   (("r", "Red"), ("g", "Green"), ("b", "Blue"), ("a", "Alpha"))})


def _pose(description: str) -> dict[str, Any]:
    position = _object("foxglove.Vector3", "Point denoting position in 3D space",
                       {a: _number(f"{a} coordinate length") for a in "xyz"})
    orientation = _object("foxglove.Quaternion", "Quaternion denoting orientation in 3D space",
                          {a: _number(f"{a} value") for a in "xyzw"})
    return _object("foxglove.Pose", description, {"position": position, "orientation": orientation})


def _array(items: dict[str, Any], description: str) -> dict[str, Any]:
    return {"type": "array", "items": items, "description": description}


def _unused_primitives(title: str, description: str) -> dict[str, Any]:
    return _array({"title": title, "type": "object"}, description)


_LINE_PRIMITIVE: Final = _object(
    "foxglove.LinePrimitive",
    "A primitive representing a series of points connected by lines",
    {
        "type": _enum("foxglove.LineType", "Drawing primitive to use for lines", [
            ("LINE_STRIP", 0, "Connected line segments: 0-1, 1-2, ..., (n-1)-n"),
            ("LINE_LOOP", 1, "Closed polygon: 0-1, 1-2, ..., (n-1)-n, n-0"),
            ("LINE_LIST", 2, "Individual line segments: 0-1, 2-3, 4-5, ..."),
        ]),
        "pose": _pose("Origin of lines relative to reference frame"),
        "thickness": _number("Line thickness"),
        "scale_invariant": {"type": "boolean", "description": "Indicates whether `thickness` is a fixed size in "
                            "screen pixels (true), or specified in world coordinates and scales with distance "
                            "from the camera (false)"},
        "points": _array(_object("foxglove.Point3", "A point representing a position in 3D space",
                                 {a: _number(f"{a} coordinate position") for a in "xyz"}), "Points along the line"),
        "color": _color("Solid color to use for the whole line. Ignored if `colors` is non-empty."),
        "colors": _array(_color("A color in RGBA format"),
                         "Per-point colors (if non-empty, must have the same length as `points`)."),
        "indices": _array({"type": "integer", "minimum": 0}, "Indices into the `points` and `colors` attribute "
                          "arrays, which can be used to avoid duplicating attribute data. If omitted or empty, "
                          "indexing will not be used."),
    },
)

SCENE_UPDATE_SCHEMA: Final[dict[str, Any]] = _object(
    "foxglove.SceneUpdate",
    "An update to the entities displayed in a 3D scene",
    {
        "deletions": _array(_object("foxglove.SceneEntityDeletion", "Command to remove previously published entities", {
            "timestamp": _time("time", "Timestamp of the deletion. Only matching entities earlier than this "
                               "timestamp will be deleted.", sec_minimum=True),
            "type": _enum("foxglove.SceneEntityDeletionType", "Type of deletion action to perform", [
                ("MATCHING_ID", 0, "Delete the existing entity on the same topic that has the provided `id`"),
                ("ALL", 1, "Delete all existing entities on the same topic"),
            ]),
            "id": {"type": "string", "description": "Identifier which must match if `type` is `MATCHING_ID`."},
        }), "Scene entities to delete"),
        "entities": _array(_object(
            "foxglove.SceneEntity",
            "A visual element in a 3D scene. An entity may be composed of multiple primitives which all share "
            "the same frame of reference.",
            {
                "timestamp": _time("time", "Timestamp of the entity", sec_minimum=True),
                "frame_id": {"type": "string", "description": "Frame of reference"},
                "id": {"type": "string", "description": "Identifier for the entity. A entity will replace any "
                       "prior entity on the same topic with the same `id`."},
                "lifetime": _time("duration", "Length of time (relative to `timestamp`) after which the entity "
                                  "should be automatically removed. Zero value indicates the entity should "
                                  "remain visible until it is replaced or deleted.", sec_minimum=False),
                "frame_locked": {"type": "boolean", "description": "Whether the entity should keep its location "
                                 "in the fixed frame (false) or follow the frame specified in `frame_id` as it "
                                 "moves relative to the fixed frame (true)"},
                "metadata": _array(_object("foxglove.KeyValuePair", "A key with its associated value", {
                    "key": {"type": "string", "description": "Key"},
                    "value": {"type": "string", "description": "Value"},
                }), "Additional user-provided metadata associated with the entity. Keys must be unique."),
                "arrows": _unused_primitives("foxglove.ArrowPrimitive", "Arrow primitives"),
                "cubes": _unused_primitives("foxglove.CubePrimitive", "Cube primitives"),
                "spheres": _unused_primitives("foxglove.SpherePrimitive", "Sphere primitives"),
                "cylinders": _unused_primitives("foxglove.CylinderPrimitive", "Cylinder primitives"),
                "lines": _array(_LINE_PRIMITIVE, "Line primitives"),
                "triangles": _unused_primitives("foxglove.TriangleListPrimitive", "Triangle list primitives"),
                "texts": _unused_primitives("foxglove.TextPrimitive", "Text primitives"),
                "models": _unused_primitives("foxglove.ModelPrimitive", "Model primitives"),
            },
        ), "Scene entities to add or replace"),
    },
)

_POLYLINE_SCHEMA: Final = {
    "type": "array",
    "items": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
    "minItems": 2,
}

_EDGE_NAMES: Final[tuple[str, ...]] = ("start_left", "start_right", "end_left", "end_right")

LANE_DETECTION_SCHEMA: Final[dict[str, Any]] = _object(
    "cold.LaneDetection",
    "One vehicle's lane detection in one frame, as sent to the fusion (cold-maps).",
    {
        "stamp_s": _number("Time of the frame (s since the start of the run)."),
        "frame": {"type": "integer", "minimum": 0, "description": "Frame index."},
        "sender": {"type": "string", "description": "Vehicle id, e.g. 'ego' or 'coop1'."},
        "pose": _object("cold.Pose2D", "The sender's pose as it reports it (localisation error included), "
                        "world frame (OpenDRIVE inertial: x east, y north).", {
                            "x": _number("m"), "y": _number("m"),
                            "yaw": _number("rad, counter-clockwise from x")}),
        "left": {**_POLYLINE_SCHEMA, "description": "Left border [[x, y], ...] in m, vehicle frame "
                 "(ISO 8855: x forward, y left), in driving order."},
        "right": {**_POLYLINE_SCHEMA, "description": "Right border, like `left`."},
        "neighbours": _array(_object("cold.NeighbourLane", "A lane beside the sender's, same direction.", {
            "index": {"type": "integer", "description": "+k: k-th lane to the left, -k: to the right."},
            "left": {**_POLYLINE_SCHEMA, "description": "Left border like the detection's, where the lane exists."},
            "right": {**_POLYLINE_SCHEMA, "description": "Right border, like `left`."},
            "at_start": {"type": "boolean", "description": "The lane exists at the sender."},
            "at_end": {"type": "boolean", "description": "The lane exists one sensor range ahead."}}),
            "Optional (multi-lane sensor): the lanes beside the sender's."),
        "road_edges": {"type": ["object", "null"], "description": "Optional: index of the lane whose outer border is "
                       "the road edge, at the detection's start and end, left and right (null: not seen).",
                       "properties": {name: {"type": ["integer", "null"]} for name in _EDGE_NAMES}},
        "branches": _array(_object("cold.LaneBranch", "A lane leaving the sender's at a fork inside the detection.", {
            "left": {**_POLYLINE_SCHEMA, "description": "Left border from the fork on, vehicle frame."},
            "right": {**_POLYLINE_SCHEMA, "description": "Right border, like `left`."}}),
            "Optional (multi-lane sensor): lanes leaving the sender's lane at forks."),
    },
)
LANE_DETECTION_SCHEMA["required"] = ["stamp_s", "frame", "sender", "pose", "left", "right"]

FRAME_METRICS_SCHEMA: Final[dict[str, Any]] = {
    "title": "cold.FrameMetrics",
    "description": "Per-frame metrics: a flat object of numbers (m, ms, counts); null where a value "
                   "does not exist in this frame (e.g. no fused lane).",
    "type": "object",
    "properties": {
        "stamp_s": _number("Time of the frame (s)."),
        "frame": {"type": "integer", "minimum": 0, "description": "Frame index."},
    },
    "required": ["stamp_s", "frame"],
    "additionalProperties": {"type": ["number", "null"]},
}


def _stamp_ns(stamp_s: float) -> int:
    if not math.isfinite(stamp_s) or stamp_s < 0:
        raise ValueError(f"stamp_s: expected a finite time >= 0 s, got {stamp_s!r}")
    return round(stamp_s * 1e9)


def _check_frame(frame: int) -> int:
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or frame < 0:
        raise ValueError(f"frame: expected an integer >= 0, got {frame!r}")
    return int(frame)


def _time_msg(ns: int) -> dict[str, int]:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


def _simplified(points: NDArrayFloat) -> NDArrayFloat:
    """The polyline's points within ``DISPLAY_TOLERANCE_M`` (Douglas-Peucker)."""
    return points[simplify(points, DISPLAY_TOLERANCE_M)] if len(points) > 2 else points


def _line_entity(entity_id: str, ns: int, points: NDArrayFloat, color: RGBA) -> dict[str, Any]:
    line = {
        "type": 0,
        "pose": {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
        "thickness": LINE_THICKNESS_M,
        "scale_invariant": False,
        "points": [{"x": x, "y": y, "z": 0.0}
                   for x, y in np.round(_simplified(points), DISPLAY_DECIMALS).tolist()],
        "color": dict(zip("rgba", color)),
        "colors": [],
        "indices": [],
    }
    return {
        "timestamp": _time_msg(ns), "frame_id": FRAME_ID, "id": entity_id,
        "lifetime": {"sec": 0, "nsec": 0}, "frame_locked": False, "metadata": [],
        "arrows": [], "cubes": [], "spheres": [], "cylinders": [], "lines": [line],
        "triangles": [], "texts": [], "models": [],
    }


def scene_update(ns: int, lines: Mapping[str, NDArrayFloat], color: RGBA) -> dict[str, Any]:
    """A ``foxglove.SceneUpdate`` replacing everything on its topic with one entity per line.

    ``lines`` maps entity ids to ``(N, 2)`` world-frame polylines (m); ``ns`` is the stamp.
    """
    return {
        "deletions": [{"timestamp": _time_msg(ns), "type": 1, "id": ""}],
        "entities": [_line_entity(name, ns, check_polyline(name, points), color) for name, points in lines.items()],
    }


class Recorder:
    """Context manager writing one run's MCAP file (see the module docstring).

    ``map_path`` and ``params`` (JSON-serialisable) go into the ``cold.run`` metadata.
    """

    def __init__(self, path: str | os.PathLike[str], *, map_path: str | os.PathLike[str] = "",
                 params: Mapping[str, Any] | None = None):
        self.path = Path(path)
        self.partial_path = self.path.with_name(self.path.name + ".partial")
        self._run_metadata = {"map": str(map_path), "params": json.dumps(dict(params or {}), sort_keys=True)}
        self._writer: Any = None
        self._stream: Any = None
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._sequence = 0

    def __enter__(self) -> Recorder:
        from mcap.writer import CompressionType, Writer

        if self._writer is not None:
            raise RecordingError(f"{self.path}: recording is already open")
        try:
            self._stream = open(self.partial_path, "wb")
        except OSError as exc:
            raise RecordingError(f"{self.partial_path}: cannot create recording: {exc.strerror}") from exc
        self._writer = Writer(self._stream, compression=CompressionType.ZSTD)
        self._writer.start(profile="", library="cold-maps")
        self._writer.add_metadata(METADATA_RUN, self._run_metadata)
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            self._finish({"status": STATUS_COMPLETE})
        else:
            self._finish({"status": STATUS_PARTIAL, "reason": exc_type.__name__})

    def _finish(self, status: dict[str, str]) -> None:
        if self._writer is None:
            raise RecordingError(f"{self.path}: recording is not open")
        writer, stream = self._writer, self._stream
        self._writer = self._stream = None
        try:
            writer.add_metadata(METADATA_STATUS, status)
            writer.finish()
            stream.flush()
            os.fsync(stream.fileno())
        finally:
            stream.close()
        os.replace(self.partial_path, self.path)

    def _channel(self, topic: str, schema: Mapping[str, Any]) -> int:
        if self._writer is None:
            raise RecordingError(f"{self.path}: recording is not open (use it as a context manager)")
        if topic not in self._channels:
            name = schema["title"]
            if name not in self._schemas:
                self._schemas[name] = self._writer.register_schema(
                    name=name, encoding="jsonschema", data=json.dumps(schema).encode())
            self._channels[topic] = self._writer.register_channel(
                topic=topic, message_encoding="json", schema_id=self._schemas[name])
        return self._channels[topic]

    def _write(self, topic: str, schema: Mapping[str, Any], ns: int, message: Mapping[str, Any]) -> None:
        channel = self._channel(topic, schema)
        self._writer.add_message(channel_id=channel, log_time=ns, publish_time=ns, sequence=self._sequence,
                                 data=json.dumps(message, allow_nan=False, separators=(",", ":")).encode())
        self._sequence += 1

    def write_gt(self, stamp_s: float, lines: Mapping[str, NDArrayFloat]) -> None:
        """Ground-truth polylines (world frame, m) of one frame on ``/gt``."""
        ns = _stamp_ns(stamp_s)
        self._write(TOPIC_GT, SCENE_UPDATE_SCHEMA, ns, scene_update(ns, lines, COLOR_GT))

    def write_fused(self, stamp_s: float, lines: Mapping[str, NDArrayFloat]) -> None:
        """The fused lane's polylines (world frame, m) of one frame on ``/fused``; {} clears it."""
        ns = _stamp_ns(stamp_s)
        self._write(TOPIC_FUSED, SCENE_UPDATE_SCHEMA, ns, scene_update(ns, lines, COLOR_FUSED))

    def write_detection(self, stamp_s: float, frame: int, sender: str, pose: tuple[float, float, float],
                        left: NDArrayFloat, right: NDArrayFloat, *, ego: bool = False,
                        lanes: fusion.LaneDetection | None = None) -> None:
        """One detection: raw on ``/cold/detections`` and drawn on ``/detections/<sender>``.

        ``pose`` is the sender's reported (x m, y m, yaw rad) in the world frame; ``left``
        and ``right`` are ``(N, 2)`` borders in its vehicle frame (ISO 8855, m). ``lanes``:
        the detection whose neighbour lanes, road edges and branches are recorded with it
        (keys left out when it has none, so a single-lane recording is unchanged).
        """
        if not isinstance(sender, str) or not _SENDER_PATTERN.fullmatch(sender):
            raise ValueError(f"sender: expected letters, digits, '_' or '-', got {sender!r}")
        x, y, yaw = (float(v) for v in pose)
        if not all(math.isfinite(v) for v in (x, y, yaw)):
            raise ValueError(f"pose of {sender}: expected finite (x, y, yaw), got {pose!r}")
        left, right = check_polyline(f"{sender} left", left), check_polyline(f"{sender} right", right)
        ns = _stamp_ns(stamp_s)
        raw = {"stamp_s": float(stamp_s), "frame": _check_frame(frame), "sender": sender,
               "pose": {"x": x, "y": y, "yaw": yaw}, "left": left.tolist(), "right": right.tolist()}
        if lanes is not None:
            raw.update(_multi_lane(lanes))
        self._write(TOPIC_RAW_DETECTIONS, LANE_DETECTION_SCHEMA, ns, raw)
        world = {"left": vehicle_to_world(left, x, y, yaw), "right": vehicle_to_world(right, x, y, yaw)}
        self._write(TOPIC_DETECTIONS_PREFIX + sender, SCENE_UPDATE_SCHEMA, ns,
                    scene_update(ns, world, COLOR_EGO if ego else COLOR_COOP))

    def write_metrics(self, stamp_s: float, frame: int, values: Mapping[str, float | int | None]) -> None:
        """Per-frame metrics on ``/metrics``; NaN and None are written as null."""
        ns = _stamp_ns(stamp_s)
        message: dict[str, Any] = {"stamp_s": float(stamp_s), "frame": _check_frame(frame)}
        for key, value in values.items():
            if key in message or not isinstance(key, str):
                raise ValueError(f"metrics: invalid or reserved key {key!r}")
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float, np.number))):
                raise ValueError(f"metrics[{key!r}]: expected a number or None, got {value!r}")
            message[key] = None if value is None or not math.isfinite(value) else float(value)
        self._write(TOPIC_METRICS, FRAME_METRICS_SCHEMA, ns, message)


def _open_reader(path: Path, stream: Any) -> tuple[Any, Any]:
    from mcap.exceptions import McapError
    from mcap.reader import make_reader

    if stream.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
        raise RecordingError(f"{path}: not an MCAP file")
    stream.seek(0)
    reader = make_reader(stream)
    try:
        summary = reader.get_summary()
    except (McapError, EOFError, ValueError, OSError) as exc:
        raise RecordingError(f"{path}: truncated or not finalised MCAP file (no valid footer)") from exc
    if summary is None:
        raise RecordingError(f"{path}: MCAP file has no summary section (not finalised)")
    return reader, summary


def read_metadata(path: str | os.PathLike[str]) -> dict[str, dict[str, str]]:
    """The MCAP metadata records of a recording, by name (``cold.run``, ``cold.status``)."""
    path = Path(path)
    with _open_file(path) as stream:
        reader, _ = _open_reader(path, stream)
        return {record.name: dict(record.metadata) for record in reader.iter_metadata()}


def _open_file(path: Path) -> Any:
    try:
        return open(path, "rb")
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open recording: {exc.strerror}") from exc


def _multi_lane(detection: fusion.LaneDetection) -> dict[str, Any]:
    """The optional ``cold.LaneDetection`` keys of a multi-lane detection (none without)."""
    extra: dict[str, Any] = {}
    if detection.neighbours:
        extra["neighbours"] = [{"index": int(lane.index), "left": lane.left.tolist(), "right": lane.right.tolist(),
                                "at_start": bool(lane.at_start), "at_end": bool(lane.at_end)}
                               for lane in detection.neighbours]
    if detection.road_edges is not None:
        extra["road_edges"] = {name: getattr(detection.road_edges, name) for name in _EDGE_NAMES}
    if detection.branches:
        extra["branches"] = [{"left": b.left.tolist(), "right": b.right.tolist()} for b in detection.branches]
    return extra


def _decode_multi_lane(message: Mapping[str, Any]) -> dict[str, Any]:
    """``neighbours``, ``road_edges``, ``branches`` of a decoded message as fusion objects."""
    edges = message.get("road_edges")
    return {
        "neighbours": tuple(fusion.NeighbourLane(int(n["index"]), n["left"], n["right"], bool(n["at_start"]),
                                                 bool(n["at_end"])) for n in message.get("neighbours", ())),
        "road_edges": None if edges is None else fusion.RoadEdges(**{name: edges.get(name) for name in _EDGE_NAMES}),
        "branches": tuple(fusion.LaneBranch(b["left"], b["right"]) for b in message.get("branches", ())),
    }


def _decode_detection(path: Path, index: int, data: bytes) -> dict[str, Any]:
    where = f"{path}: {TOPIC_RAW_DETECTIONS} message {index}"
    try:
        message = json.loads(data)
        pose = message["pose"]
        detection = {
            "stamp_s": float(message["stamp_s"]),
            "frame": _check_frame(message["frame"]),
            "sender": str(message["sender"]),
            "pose": {"x": float(pose["x"]), "y": float(pose["y"]), "yaw": float(pose["yaw"])},
            "left": check_polyline("left", message["left"]),
            "right": check_polyline("right", message["right"]),
            **_decode_multi_lane(message),
        }
    except (ValueError, KeyError, TypeError, fusion.FusionError) as exc:
        raise RecordingError(f"{where}: invalid cold.LaneDetection: {exc}") from exc
    return detection


def _check_detection_channel(path: Path, summary: Any) -> None:
    channels = [c for c in summary.channels.values() if c.topic == TOPIC_RAW_DETECTIONS]
    if not channels:
        raise RecordingError(f"{path}: no {TOPIC_RAW_DETECTIONS} channel (not a cold-maps recording)")
    expected = (LANE_DETECTION_SCHEMA["title"], "jsonschema", "json")
    for channel in channels:
        schema = summary.schemas.get(channel.schema_id)
        found = (schema.name if schema else None, schema.encoding if schema else None, channel.message_encoding)
        if found != expected:
            raise RecordingError(f"{path}: {TOPIC_RAW_DETECTIONS} has schema, schema encoding, message encoding "
                                 f"{found}, expected {expected}")


def read_detections(path: str | os.PathLike[str]) -> Iterator[tuple[int, list[dict[str, Any]]]]:
    """The raw detections of a recording, grouped by frame in recording order.

    Yields ``(frame, detections)``; each detection is a dict with the keys of
    :data:`LANE_DETECTION_SCHEMA`, ``left`` and ``right`` as ``(N, 2)`` float64 arrays,
    ``neighbours`` and ``branches`` as tuples of ``fusion.NeighbourLane`` / ``LaneBranch``
    (empty when not recorded) and ``road_edges`` as ``fusion.RoadEdges`` or None.
    Raises :class:`RecordingError` at once for a file that is not a finalised MCAP, has no
    ``/cold/detections`` channel or carries a foreign schema, and while iterating for a
    malformed message.
    """
    path = Path(path)
    stream = _open_file(path)
    try:
        reader, summary = _open_reader(path, stream)
        _check_detection_channel(path, summary)
    except BaseException:
        stream.close()
        raise
    return _iter_detections(path, stream, reader)


def _iter_detections(path: Path, stream: Any, reader: Any) -> Iterator[tuple[int, list[dict[str, Any]]]]:
    from mcap.exceptions import McapError

    frame = -1
    group: list[dict[str, Any]] = []
    try:
        messages = reader.iter_messages(topics=[TOPIC_RAW_DETECTIONS], log_time_order=False)
        for index, (_, _, message) in enumerate(messages):
            detection = _decode_detection(path, index, message.data)
            if group and detection["frame"] != frame:
                yield frame, group
                group = []
            frame = detection["frame"]
            group.append(detection)
    except (McapError, EOFError, OSError) as exc:
        raise RecordingError(f"{path}: corrupt MCAP data: {exc}") from exc
    finally:
        stream.close()
    if group:
        yield frame, group
