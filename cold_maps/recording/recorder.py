"""MCAP recording of an evaluation run, viewable in Foxglove and re-readable for re-fusion.

Recording version 3 (:data:`RECORDING_VERSION`), written with the ``foxglove-sdk`` MCAP
writer (zstd chunks); the protobuf messages are encoded by :mod:`cold_maps.recording.wire`
(the SDK's bytes, built with numpy). Channels:

- ``/gt``, ``/fused``, ``/detections/<sender>``: ``foxglove.SceneUpdate`` (the official
  Foxglove protobuf schema). One entity per polyline, a ``LINE_STRIP`` in frame ``map`` (=
  the world frame, m, z = 0), simplified to within 1 cm (Douglas-Peucker, shapely/GEOS; the
  lines are drawn 0.15 m wide, straight stretches cost two points) and rounded to 0.1 mm.
  Every update first deletes all older entities on its topic, so the 3D panel shows
  exactly the current frame.
- ``/tf``: ``foxglove.FrameTransform`` (protobuf) ``map`` -> ``<sender>`` per detection,
  the sender's reported pose (so Foxglove can follow a vehicle).
- ``/cold/detections``: ``cold.LaneDetection`` (:data:`LANE_DETECTION_SCHEMA`, JSON), the raw
  detections for re-fusion, with the sender's lane history when it sent one.
- ``/metrics``: ``cold.FrameMetrics`` (:data:`FRAME_METRICS_SCHEMA`, JSON), a flat object
  of numbers per frame, for Foxglove's plot panel.

Times: a frame at ``stamp_s`` seconds into the run is logged at ``stamp_base_ns +
stamp_s * 1e9`` ns since the Unix epoch; the base is the run's wall-clock start unless
given (``cold-eval --stamp-base``). ``cold.*`` messages carry that time as ``stamp:
{sec, nsec}``. MCAP metadata records: ``cold.run`` (``map``: the map path, ``params``: the
run parameters as a JSON object string, ``recording_version``, ``stamp_base_ns``) and
``cold.status`` (``status``: ``complete`` or ``partial``; ``reason``: the exception that
ended a partial run).

Version 2: no ``history`` key in ``cold.LaneDetection`` (otherwise as version 3). Version 1
(before foxglove-sdk; no ``recording_version``): display channels as JSON
``foxglove.SceneUpdate``, no ``/tf``, log times from 0, ``cold.*`` stamps as float seconds
``stamp_s``. :func:`read_detections` reads all three versions.

The file is written as ``<path>.partial`` and renamed when finalised; a run ended by an
exception (Ctrl-C included) is still finalised under the final name, marked ``partial``.
The optional OSI trace of the detections (:mod:`cold_maps.recording.osi`) is written and
finalised the same way, its status in its sidecar.
"""

from __future__ import annotations

import json
import math
import os
import re
import time
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any, Final, Iterator, Mapping, Sequence

import numpy as np

import fusion
from cold_maps.common.signals import signals_ignored
from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.recording import wire
from cold_maps.recording.osi import OsiTraceError, OsiTraceWriter, detection_sensor_data
from cold_maps.simulation.sensor import vehicle_to_world
from cold_maps.simulation.sensor_errors import check_polyline
from gt_matching.polyline import simplify_joined, simplify_lines

RECORDING_VERSION: Final[int] = 3
TOPIC_GT: Final[str] = "/gt"
TOPIC_FUSED: Final[str] = "/fused"
TOPIC_DETECTIONS_PREFIX: Final[str] = "/detections/"
TOPIC_TF: Final[str] = "/tf"
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
OSI_KIND: Final[str] = "osi"
"""``EncodedMessage.kind`` of an encoded ``osi3.SensorData`` for the OSI trace."""
SCENE_BATCH: Final[int] = 256
"""Scene updates a recorder keeps before it simplifies their lines together (one shapely
call) and encodes them, then writes them with the messages between them, in order (a
detached recorder keeps them, encoded, for ``take``)."""
MCAP_MAGIC: Final[bytes] = b"\x89MCAP0\r\n"
NS_PER_S: Final[int] = 1_000_000_000
MAX_STAMP_BASE_NS: Final[int] = 2**63 - 1 - 10**6 * NS_PER_S  # log times stay int64 for 11 days of frames

RGBA = tuple[float, float, float, float]
COLOR_GT: Final[RGBA] = (0.2, 0.8, 0.2, 1.0)
COLOR_FUSED: Final[RGBA] = (0.9, 0.1, 0.1, 1.0)
COLOR_EGO: Final[RGBA] = (0.1, 0.4, 0.9, 1.0)
COLOR_COOP: Final[RGBA] = (1.0, 0.6, 0.0, 1.0)

_SENDER_PATTERN: Final = re.compile(r"[A-Za-z0-9_\-]+")


class RecordingError(Exception):
    """A recording that cannot be written or read; the message is one line naming the file."""


def _object(title: str, description: str, properties: dict[str, Any]) -> dict[str, Any]:
    return {"title": title, "description": description, "type": "object", "properties": properties,
            "required": list(properties)}


def _number(description: str) -> dict[str, str]:
    return {"type": "number", "description": description}


def _array(items: dict[str, Any], description: str) -> dict[str, Any]:
    return {"type": "array", "items": items, "description": description}


_STAMP_SCHEMA: Final[dict[str, Any]] = {
    "type": "object",
    "title": "time",
    "description": "Time of the frame (its log time): whole seconds and nanoseconds since the Unix epoch.",
    "properties": {"sec": {"type": "integer", "minimum": 0},
                   "nsec": {"type": "integer", "minimum": 0, "maximum": NS_PER_S - 1}},
    "required": ["sec", "nsec"],
}

_POLYLINE_SCHEMA: Final = {
    "type": "array",
    "items": {"type": "array", "items": {"type": "number"}, "minItems": 2, "maxItems": 2},
    "minItems": 2,
}

_EDGE_NAMES: Final[tuple[str, ...]] = ("start_left", "start_right", "end_left", "end_right")

LANE_DETECTION_SCHEMA: Final[dict[str, Any]] = _object(
    "cold.LaneDetection",
    "One vehicle's lane detection in one frame, as sent to the fusion (cold-maps recording version 3).",
    {
        "stamp": _STAMP_SCHEMA,
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
        "history": _object("cold.LaneHistory", "Optional (version 3): the lane the sender perceived over its last "
                           "metres of travel, registered with its odometry, ending where `left`/`right` start.", {
                               "left": {**_POLYLINE_SCHEMA, "description": "Left border, vehicle frame like `left`."},
                               "right": {**_POLYLINE_SCHEMA, "description": "Right border, like `left`."}}),
    },
)
LANE_DETECTION_SCHEMA["required"] = ["stamp", "frame", "sender", "pose", "left", "right"]

FRAME_METRICS_SCHEMA: Final[dict[str, Any]] = {
    "title": "cold.FrameMetrics",
    "description": "Per-frame metrics: a flat object of numbers (m, ms, counts); null where a value "
                   "does not exist in this frame (e.g. no fused lane).",
    "type": "object",
    "properties": {
        "stamp": _STAMP_SCHEMA,
        "frame": {"type": "integer", "minimum": 0, "description": "Frame index."},
    },
    "required": ["stamp", "frame"],
    "additionalProperties": {"type": ["number", "null"]},
}


def _stamp_ns(stamp_s: float) -> int:
    """``stamp_s`` (s since the stamp base) in ns."""
    if not math.isfinite(stamp_s) or stamp_s < 0:
        raise ValueError(f"stamp_s: expected a finite time >= 0 s, got {stamp_s!r}")
    return round(stamp_s * NS_PER_S)


def _check_frame(frame: int) -> int:
    if isinstance(frame, bool) or not isinstance(frame, (int, np.integer)) or frame < 0:
        raise ValueError(f"frame: expected an integer >= 0, got {frame!r}")
    return int(frame)


def _time_msg(ns: int) -> dict[str, int]:
    return {"sec": ns // NS_PER_S, "nsec": ns % NS_PER_S}


def _time_ns(stamp: Any) -> int:
    """A ``{sec, nsec}`` object in ns; ValueError naming what is wrong."""
    sec, nsec = stamp["sec"], stamp["nsec"]
    if not all(isinstance(v, int) and not isinstance(v, bool) for v in (sec, nsec)) or sec < 0 \
            or not 0 <= nsec < NS_PER_S:
        raise ValueError(f"stamp: expected integers sec >= 0 and 0 <= nsec < 1e9, got {stamp!r}")
    return sec * NS_PER_S + nsec


def _check_stamp_base(stamp_base_ns: int | None) -> int | None:
    if stamp_base_ns is not None and (isinstance(stamp_base_ns, bool) or not isinstance(stamp_base_ns, int)
                                      or not 0 <= stamp_base_ns <= MAX_STAMP_BASE_NS):
        raise ValueError(f"stamp_base_ns: expected an integer 0 ... {MAX_STAMP_BASE_NS} (ns since the Unix epoch), "
                         f"got {stamp_base_ns!r}")
    return stamp_base_ns


def display_lines(lines: Mapping[str, NDArrayFloat]) -> list[NDArrayFloat]:
    """Each ``(N, 2)`` polyline (m) as drawn: simplified to within ``DISPLAY_TOLERANCE_M``
    and rounded to ``DISPLAY_DECIMALS``."""
    return _drawn([check_polyline(name, points) for name, points in lines.items()])


def _drawn(lines: list[NDArrayFloat]) -> list[NDArrayFloat]:
    """Checked ``(N, 2)`` polylines (m) as drawn (:func:`display_lines`), simplified together."""
    return [np.round(line, DISPLAY_DECIMALS) for line in simplify_lines(lines, DISPLAY_TOLERANCE_M)]


def _timestamp(ns: int) -> Any:
    from foxglove.messages import Timestamp

    return Timestamp(ns // NS_PER_S, ns % NS_PER_S)


def scene_update(ns: int, names: Sequence[str], drawn: Sequence[NDArrayFloat], color: RGBA) -> Any:
    """A ``foxglove.SceneUpdate`` replacing everything on its topic with one entity per line
    (the reference: the recording writes :func:`wire.scene_updates`, its encoding as bytes).

    ``names`` are the entity ids of the ``(N, 2)`` world-frame polylines (m) ``drawn`` (as
    :func:`display_lines` returns them); ``ns`` is the log time (ns since the Unix epoch).
    """
    from foxglove.messages import (
        Color,
        LinePrimitive,
        LinePrimitiveLineType,
        Point3,
        Pose,
        Quaternion,
        SceneEntity,
        SceneEntityDeletion,
        SceneEntityDeletionType,
        SceneUpdate,
        Vector3,
    )

    stamp = _timestamp(ns)
    rgba = Color(r=color[0], g=color[1], b=color[2], a=color[3])
    entities = []
    for name, points in zip(names, drawn, strict=True):
        line = LinePrimitive(
            type=LinePrimitiveLineType.LineStrip,
            pose=Pose(position=Vector3(x=0.0, y=0.0, z=0.0), orientation=Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            thickness=LINE_THICKNESS_M, scale_invariant=False,
            points=[Point3(x=x, y=y, z=0.0) for x, y in points.tolist()], color=rgba)
        entities.append(SceneEntity(timestamp=stamp, frame_id=FRAME_ID, id=name, frame_locked=False, lines=[line]))
    return SceneUpdate(deletions=[SceneEntityDeletion(timestamp=stamp, type=SceneEntityDeletionType.All)],
                       entities=entities)


def frame_transform(ns: int, sender: str, x: float, y: float, yaw: float) -> Any:
    """``foxglove.FrameTransform`` ``map`` -> ``sender`` at log time ``ns``: the vehicle at
    (x m, y m) heading ``yaw`` (rad, counter-clockwise from x) in the world frame (the
    reference of :func:`wire.frame_transform`, which the recording writes)."""
    from foxglove.messages import FrameTransform, Quaternion, Vector3

    return FrameTransform(timestamp=_timestamp(ns), parent_frame_id=FRAME_ID, child_frame_id=sender,
                          translation=Vector3(x=x, y=y, z=0.0),
                          rotation=Quaternion(x=0.0, y=0.0, z=math.sin(0.5 * yaw), w=math.cos(0.5 * yaw)))


@dataclass(frozen=True, slots=True)
class EncodedMessage:
    """One message ready for the file.

    Fields:
        topic: its channel.
        kind: ``scene``, ``transform`` or the title of its JSON schema.
        log_time_ns: log time (ns since the Unix epoch).
        payload: the message, protobuf or JSON bytes.
    """

    topic: str
    kind: str
    log_time_ns: int
    payload: bytes


@dataclass(frozen=True, slots=True)
class _PendingScene:
    """A :func:`scene_update` whose lines are drawn with the next batch (``lines``: checked,
    in the order of ``names``)."""

    topic: str
    log_time_ns: int
    names: tuple[str, ...]
    lines: tuple[NDArrayFloat, ...]
    color: RGBA


class Recorder:
    """Context manager writing one run's MCAP file ``path`` (see the module docstring) and,
    given the path ``osi``, the detections as an OSI trace (:mod:`cold_maps.recording.osi`);
    ``path`` None writes the trace alone.

    ``map_path`` and ``params`` (JSON-serialisable) go into the ``cold.run`` metadata (and
    the trace's sidecar; the map also into each OSI message's ``map_reference``);
    ``stamp_base_ns`` (ns since the Unix epoch) is the log time of stamp 0 s, by default
    the wall-clock time when the recording opens. A :meth:`detached` recorder has no file:
    it keeps its messages encoded for another recorder's :meth:`log`.
    """

    def __init__(self, path: str | os.PathLike[str] | None, *, map_path: str | os.PathLike[str] = "",
                 params: Mapping[str, Any] | None = None, stamp_base_ns: int | None = None,
                 osi: str | os.PathLike[str] | None = None):
        if path is None and osi is None:
            raise ValueError("Recorder: give an MCAP path, an OSI trace path or both")
        self.mcap = path is not None
        self.path = Path(path if path is not None else osi)  # type: ignore[arg-type]
        self.partial_path = self.path.with_name(self.path.name + ".partial")
        self.osi_path = None if osi is None else Path(osi)
        self._map_path = str(map_path)
        self._params = json.dumps(dict(params or {}), sort_keys=True)
        self._requested_base_ns = _check_stamp_base(stamp_base_ns)
        self.stamp_base_ns = 0
        self._open = False
        self._writer: Any = None
        self._osi: OsiTraceWriter | None = None
        self._context: Any = None
        self._channels: dict[str, Any] = {}
        self._queue: list[EncodedMessage | _PendingScene] = []
        self._scenes = 0
        self._detached = False

    @classmethod
    def detached(cls, stamp_base_ns: int, *, mcap: bool = True, osi: bool = False,
                 map_path: str | os.PathLike[str] = "") -> Recorder:
        """A recorder without a file (in a worker process): its writes are kept, encoded and
        in order, for :meth:`take`; a recorder with the same ``stamp_base_ns``, outputs and
        ``map_path`` writes them into its files with :meth:`log`."""
        recorder = cls(os.devnull if mcap else None, stamp_base_ns=stamp_base_ns, map_path=map_path,
                       osi=os.devnull if osi else None)
        recorder.stamp_base_ns = stamp_base_ns
        recorder._detached = True
        return recorder

    def take(self) -> list[EncodedMessage]:
        """The messages written to this detached recorder since the last call, in order."""
        if not self._detached:
            raise RecordingError(f"{self.path}: only a detached recorder hands out its messages")
        return self._take_queue()

    def log(self, messages: Sequence[EncodedMessage]) -> None:
        """Writes the messages of a detached recorder (same stamp base) after this one's."""
        if not self._open:
            raise RecordingError(f"{self.path}: recording is not open (use it as a context manager)")
        self._write(self._take_queue())
        self._write(messages)

    def __enter__(self) -> Recorder:
        import foxglove
        from foxglove.mcap import MCAPCompression, MCAPWriteOptions

        if self._detached:
            raise RecordingError("a detached recorder has no file to open")
        if self._open:
            raise RecordingError(f"{self.path}: recording is already open")
        osi_partial = [self.osi_path.with_name(self.osi_path.name + ".partial")] if self.osi_path else []
        for partial in ([self.partial_path] if self.mcap else []) + osi_partial:
            if not partial.parent.is_dir():
                raise RecordingError(f"{partial}: cannot create recording: no folder {partial.parent}")
        self.stamp_base_ns = time.time_ns() if self._requested_base_ns is None else self._requested_base_ns
        if self.osi_path is not None:
            self._osi = OsiTraceWriter(self.osi_path, {"map": self._map_path, "params": json.loads(self._params),
                                                       "stamp_base_ns": self.stamp_base_ns})
            try:
                self._osi.open()
            except OsiTraceError as exc:
                self._osi = None
                raise RecordingError(str(exc)) from exc
        self._open = True
        if not self.mcap:
            return self
        self._context = foxglove.Context()
        try:
            # a path, not a Python file object: the SDK then writes without calling back into
            # Python, so a Ctrl-C or SIGTERM can never land inside one of its writes (which
            # would leave the writer failed and the file unfinished)
            self._writer = foxglove.open_mcap(self.partial_path, allow_overwrite=True, context=self._context,
                                              writer_options=MCAPWriteOptions(compression=MCAPCompression.Zstd,
                                                                              profile=""))
            self._writer.write_metadata(METADATA_RUN, {
                "map": self._map_path, "params": self._params, "recording_version": str(RECORDING_VERSION),
                "stamp_base_ns": str(self.stamp_base_ns)})
        except Exception as exc:
            self._writer = None
            self._open = False
            self.partial_path.unlink(missing_ok=True)
            if self._osi is not None:
                self._osi.discard()
                self._osi = None
            raise RecordingError(f"{self.partial_path}: cannot start recording: {exc}") from exc
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        if exc_type is None:
            self._finish({"status": STATUS_COMPLETE})
        else:
            self._finish({"status": STATUS_PARTIAL, "reason": exc_type.__name__})

    def _finish(self, status: dict[str, str]) -> None:
        """Writes what is queued and finalises the file with ``status``, Ctrl-C and SIGTERM
        held meanwhile (a file marked complete holds every message given to it)."""
        if not self._open:
            raise RecordingError(f"{self.path}: recording is not open")
        with signals_ignored():
            try:
                self._write(self._take_queue())
            finally:
                self._close(status)

    def _close(self, status: dict[str, str]) -> None:
        writer, channels, trace = self._writer, self._channels, self._osi
        self._writer = self._context = self._osi = None
        self._channels = {}
        self._open = False
        if trace is not None:
            trace.close(status)
        if writer is None:
            return
        writer.write_metadata(METADATA_STATUS, status)
        writer.close()
        for channel in channels.values():
            channel.close()
        with open(self.partial_path, "rb") as written:
            os.fsync(written.fileno())
        os.replace(self.partial_path, self.path)

    def _ns(self, stamp_s: float) -> int:
        """Log time (ns since the Unix epoch) of a stamp (s since the stamp base)."""
        if not self._open and not self._detached:
            raise RecordingError(f"{self.path}: recording is not open (use it as a context manager)")
        return self.stamp_base_ns + _stamp_ns(stamp_s)

    def _channel(self, topic: str, kind: str) -> Any:
        """The channel of ``topic``: ``kind`` is ``scene``, ``transform`` (the Foxglove
        protobuf schemas) or a JSON schema title."""
        channel = self._channels.get(topic)
        if channel is None:
            import foxglove
            from foxglove.messages import FrameTransform, SceneUpdate

            if kind in ("scene", "transform"):
                schema = (SceneUpdate if kind == "scene" else FrameTransform).get_schema()
                channel = foxglove.Channel(topic, message_encoding="protobuf", context=self._context, schema=schema)
            else:
                document = {s["title"]: s for s in (LANE_DETECTION_SCHEMA, FRAME_METRICS_SCHEMA)}[kind]
                channel = foxglove.Channel(topic, message_encoding="json", context=self._context, schema=foxglove.Schema(
                    name=kind, encoding="jsonschema", data=json.dumps(document).encode()))
            self._channels[topic] = channel
        return channel

    def _emit(self, topic: str, kind: str, ns: int, payload: bytes) -> None:
        self._queue.append(EncodedMessage(topic, kind, ns, payload))

    def _emit_scene(self, topic: str, ns: int, lines: Mapping[str, NDArrayFloat], color: RGBA, *,
                    checked: bool = False) -> None:
        """Queues the :func:`scene_update` of ``lines`` (checked now unless ``checked``: finite
        ``(N >= 2, 2)`` float64 arrays already; drawn with the batch); nothing without an MCAP file."""
        if not self.mcap:
            return
        polylines = tuple(lines.values()) if checked else tuple(check_polyline(n, p) for n, p in lines.items())
        self._queue.append(_PendingScene(topic, ns, tuple(lines), polylines, color))
        self._scenes += 1
        if self._scenes >= SCENE_BATCH:
            encoded = self._take_queue()
            if self._detached:  # kept, encoded, for take()
                self._queue = list(encoded)
            else:
                self._write(encoded)

    def _take_queue(self) -> list[EncodedMessage]:
        """The queued messages, in order, the scene updates' lines simplified together."""
        queue, self._queue, self._scenes = self._queue, [], 0
        scenes = [item for item in queue if isinstance(item, _PendingScene)]
        lines = [line for item in scenes for line in item.lines]
        if lines:
            coordinates, counts = simplify_joined(lines, DISPLAY_TOLERANCE_M)
            coordinates = np.round(coordinates, DISPLAY_DECIMALS)
        else:
            coordinates, counts = np.empty((0, 2)), np.empty(0, dtype=np.int64)
        payloads = iter(wire.scene_updates([(item.log_time_ns, item.names, item.color) for item in scenes],
                                           coordinates, counts, LINE_THICKNESS_M, FRAME_ID))
        return [item if isinstance(item, EncodedMessage) else EncodedMessage(item.topic, "scene", item.log_time_ns,
                                                                             next(payloads)) for item in queue]

    def _write(self, messages: Sequence[EncodedMessage]) -> None:
        for message in messages:
            if message.kind == OSI_KIND:
                if self._osi is not None:
                    self._osi.write(message.payload)
                continue
            self._channel(message.topic, message.kind).log(message.payload, log_time=message.log_time_ns)

    def _write_json(self, topic: str, ns: int, message: Mapping[str, Any]) -> None:
        import orjson

        if not self.mcap:
            return

        schema = LANE_DETECTION_SCHEMA if topic == TOPIC_RAW_DETECTIONS else FRAME_METRICS_SCHEMA
        self._emit(topic, schema["title"], ns, orjson.dumps(message, option=orjson.OPT_SERIALIZE_NUMPY))

    def write_gt(self, stamp_s: float, lines: Mapping[str, NDArrayFloat]) -> None:
        """Ground-truth polylines (world frame, m) of one frame on ``/gt``."""
        self._emit_scene(TOPIC_GT, self._ns(stamp_s), lines, COLOR_GT)

    def write_fused(self, stamp_s: float, lines: Mapping[str, NDArrayFloat]) -> None:
        """The fused lane's polylines (world frame, m) of one frame on ``/fused``; {} clears it."""
        self._emit_scene(TOPIC_FUSED, self._ns(stamp_s), lines, COLOR_FUSED)

    def write_detection(self, stamp_s: float, frame: int, sender: str, pose: tuple[float, float, float],
                        left: NDArrayFloat, right: NDArrayFloat, *, ego: bool = False,
                        lanes: fusion.LaneDetection | None = None) -> None:
        """One detection: raw on ``/cold/detections``, drawn on ``/detections/<sender>`` and
        the sender's frame on ``/tf``.

        ``pose`` is the sender's reported (x m, y m, yaw rad) in the world frame; ``left``
        and ``right`` are ``(N, 2)`` borders in its vehicle frame (ISO 8855, m). ``lanes``:
        the detection whose neighbour lanes, road edges, branches and lane history are
        recorded with it (keys left out when it has none, so a single-lane recording is
        unchanged).
        """
        if not isinstance(sender, str) or not _SENDER_PATTERN.fullmatch(sender):
            raise ValueError(f"sender: expected letters, digits, '_' or '-', got {sender!r}")
        x, y, yaw = (float(v) for v in pose)
        if not all(math.isfinite(v) for v in (x, y, yaw)):
            raise ValueError(f"pose of {sender}: expected finite (x, y, yaw), got {pose!r}")
        left = np.ascontiguousarray(check_polyline(f"{sender} left", left))
        right = np.ascontiguousarray(check_polyline(f"{sender} right", right))
        ns = self._ns(stamp_s)
        if self.osi_path is not None:
            self._emit("", OSI_KIND, ns, detection_sensor_data(ns - self.stamp_base_ns, _check_frame(frame), sender,
                                                                (x, y, yaw), left, right, lanes, self._map_path))
        if not self.mcap:
            return
        raw = {"stamp": _time_msg(ns), "frame": _check_frame(frame), "sender": sender,
               "pose": {"x": x, "y": y, "yaw": yaw}, "left": left, "right": right}
        if lanes is not None:
            raw.update(_multi_lane(lanes))
        self._write_json(TOPIC_RAW_DETECTIONS, ns, raw)
        self._emit(TOPIC_TF, "transform", ns, wire.frame_transform(ns, FRAME_ID, sender, x, y, yaw))
        world = vehicle_to_world(np.concatenate((left, right)), x, y, yaw)
        if not np.isfinite(world).all():
            raise ValueError(f"{sender}: detection too far out to draw in the world frame")
        self._emit_scene(TOPIC_DETECTIONS_PREFIX + sender, ns, {"left": world[:len(left)], "right": world[len(left):]},
                         COLOR_EGO if ego else COLOR_COOP, checked=True)

    def write_metrics(self, stamp_s: float, frame: int, values: Mapping[str, float | int | None]) -> None:
        """Per-frame metrics on ``/metrics``; NaN and None are written as null."""
        ns = self._ns(stamp_s)
        message: dict[str, Any] = {"stamp": _time_msg(ns), "frame": _check_frame(frame)}
        for key, value in values.items():
            if key in message or not isinstance(key, str):
                raise ValueError(f"metrics: invalid or reserved key {key!r}")
            if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float, np.number))):
                raise ValueError(f"metrics[{key!r}]: expected a number or None, got {value!r}")
            message[key] = None if value is None or not math.isfinite(value) else float(value)
        self._write_json(TOPIC_METRICS, ns, message)


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


def _metadata(reader: Any) -> dict[str, dict[str, str]]:
    return {record.name: dict(record.metadata) for record in reader.iter_metadata()}


def read_metadata(path: str | os.PathLike[str]) -> dict[str, dict[str, str]]:
    """The MCAP metadata records of a recording, by name (``cold.run``, ``cold.status``)."""
    path = Path(path)
    with _open_file(path) as stream:
        reader, _ = _open_reader(path, stream)
        return _metadata(reader)


def _stamp_base(path: Path, metadata: Mapping[str, Mapping[str, str]]) -> int:
    """The ``stamp_base_ns`` of ``cold.run`` (0 without one: version 1 or another source)."""
    text = metadata.get(METADATA_RUN, {}).get("stamp_base_ns", "0")
    try:
        return _check_stamp_base(int(text)) or 0
    except ValueError as exc:
        raise RecordingError(f"{path}: {METADATA_RUN} stamp_base_ns: {exc}") from exc


def read_stamp_base(path: str | os.PathLike[str]) -> int:
    """The log time (ns since the Unix epoch) of stamp 0 s of a recording; 0 for version 1."""
    return _stamp_base(Path(path), read_metadata(path))


def _open_file(path: Path) -> Any:
    try:
        return open(path, "rb")
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open recording: {exc.strerror}") from exc


def _multi_lane(detection: fusion.LaneDetection) -> dict[str, Any]:
    """The optional ``cold.LaneDetection`` keys of a multi-lane detection and of a lane history
    (none without)."""
    extra: dict[str, Any] = {}
    if detection.history is not None:
        extra["history"] = {"left": detection.history.left, "right": detection.history.right}
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
    """``neighbours``, ``road_edges``, ``branches``, ``history`` of a decoded message as fusion
    objects."""
    edges, history = message.get("road_edges"), message.get("history")
    return {
        "history": None if history is None else fusion.LaneHistory(history["left"], history["right"]),
        "neighbours": tuple(fusion.NeighbourLane(int(n["index"]), n["left"], n["right"], bool(n["at_start"]),
                                                 bool(n["at_end"])) for n in message.get("neighbours", ())),
        "road_edges": None if edges is None else fusion.RoadEdges(**{name: edges.get(name) for name in _EDGE_NAMES}),
        "branches": tuple(fusion.LaneBranch(b["left"], b["right"]) for b in message.get("branches", ())),
    }


def _decode_detection(path: Path, index: int, data: bytes, stamp_base_ns: int) -> dict[str, Any]:
    import orjson

    where = f"{path}: {TOPIC_RAW_DETECTIONS} message {index}"
    try:
        message = orjson.loads(data)
        pose = message["pose"]
        stamp_s = ((_time_ns(message["stamp"]) - stamp_base_ns) / NS_PER_S if "stamp" in message
                   else float(message["stamp_s"]))
        detection = {
            "stamp_s": stamp_s,
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
    """The raw detections of a recording (version 1, 2 or 3), grouped by frame in recording order.

    Yields ``(frame, detections)``; each detection is a dict with the keys ``stamp_s`` (s
    since the recording's stamp base, ns resolution), ``frame``, ``sender``, ``pose``,
    ``left`` and ``right`` as ``(N, 2)`` float64 arrays, ``neighbours`` and ``branches`` as
    tuples of ``fusion.NeighbourLane`` / ``LaneBranch`` (empty when not recorded),
    ``road_edges`` as ``fusion.RoadEdges`` or None and ``history`` as ``fusion.LaneHistory`` or
    None (not recorded: versions 1 and 2, or no history sent). Raises
    :class:`RecordingError` at once for a file that is not a finalised MCAP, has no
    ``/cold/detections`` channel or carries a foreign schema, and while iterating for a
    malformed message.
    """
    path = Path(path)
    stream = _open_file(path)
    try:
        reader, summary = _open_reader(path, stream)
        _check_detection_channel(path, summary)
        stamp_base_ns = _stamp_base(path, _metadata(reader))
    except BaseException:
        stream.close()
        raise
    return _iter_detections(path, stream, reader, stamp_base_ns)


def _iter_detections(path: Path, stream: Any, reader: Any,
                     stamp_base_ns: int) -> Iterator[tuple[int, list[dict[str, Any]]]]:
    from mcap.exceptions import McapError

    frame = -1
    group: list[dict[str, Any]] = []
    try:
        messages = reader.iter_messages(topics=[TOPIC_RAW_DETECTIONS], log_time_order=False)
        for index, (_, _, message) in enumerate(messages):
            detection = _decode_detection(path, index, message.data, stamp_base_ns)
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
