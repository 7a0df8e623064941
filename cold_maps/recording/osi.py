"""The lane detections of a run as an ASAM OSI trace (``cold-eval --osi``), read back by ``cold-fuse``.

The trace is the standard binary OSI trace: one ``osi3.SensorData`` (OSI :data:`OSI_VERSION`,
written with betterosi) per vehicle and frame, each preceded by its length as a 4-byte
little-endian unsigned integer. Per message (docs/guide/osi.md has the whole table):

- ``timestamp`` = ``last_measurement_time`` = ``lane_boundary_header.measurement_time``: the
  frame's stamp, s since the run's start (OSI's zero time: the start of the simulation);
  ``lane_boundary_header.cycle_counter``: the frame index.
- ``sensor_id``: the vehicle's id (:func:`vehicle_id`); ``mounting_position`` zero: the
  sensor frame is the sender's vehicle frame (ISO 8855: x forward, y left, z up; origin at
  the pose it reports).
- ``sensor_view[0].global_ground_truth``: ``host_vehicle_id`` and one ``moving_object`` with
  that id at the pose the sender reports (world frame = the OpenDRIVE inertial frame; yaw
  counter-clockwise from x; ``bbcenter_to_rear`` zero, so the vehicle frame's origin is
  ``base.position``), the sender's name in ``source_reference`` (type
  :data:`SENDER_REFERENCE_TYPE`), the map file in ``map_reference``.
- ``lane_boundary``: the left (``header.tracking_id`` :data:`LEFT_TRACKING_ID`) and right
  (:data:`RIGHT_TRACKING_ID`) border of the sender's lane in the sensor frame, m, in driving
  order (z left unset: 0, a third less to store); ``existence_probability`` 1 (the simulated sensor sends only what it sees); one
  candidate, probability 1, its ``classification.type`` the border's marking
  (``LaneBoundary.Classification.Type`` numbers, :class:`~cold_maps.opendrive.road_marks.BoundaryType`;
  UNKNOWN until the detection carries one); ``boundary_line_rmse`` the per-point lateral
  σ split along the border's normal in x and y, absent when the detection states no σ.

Beside the trace, ``<trace>.json`` (:func:`sidecar_path`) records what OSI has no place
for: the status (``complete``, or ``partial`` with the reason for a run cut short), the
stamp base (ns since the Unix epoch of stamp 0, as in ``run.mcap``) and the run's
parameters. The trace is written as ``<trace>.partial`` and renamed when finalised.
"""

from __future__ import annotations

import json
import os
import struct
import zlib
from pathlib import Path
from typing import Any, BinaryIO, Final, Iterator, Mapping

import numpy as np

import fusion
from cold_maps.network.lane_strip import NDArrayFloat
from cold_maps.simulation.sensor_errors import check_polyline

OSI_VERSION: Final[tuple[int, int, int]] = (3, 8, 0)
LENGTH_PREFIX: Final[struct.Struct] = struct.Struct("<I")
"""The length of each message in the trace: 4 bytes, little-endian, unsigned."""
SENDER_REFERENCE_TYPE: Final[str] = "net.cold-maps.sender"
"""``ExternalReference.type`` of the moving object's reference that holds the sender's name."""
LEFT_TRACKING_ID: Final[int] = 0
RIGHT_TRACKING_ID: Final[int] = 1
EXISTENCE_PROBABILITY: Final[float] = 1.0
UNKNOWN_BOUNDARY_TYPE: Final[int] = 0
SIDECAR_FORMAT: Final[str] = "cold-maps.osi-trace"
SIDECAR_VERSION: Final[int] = 1
NS_PER_S: Final[int] = 1_000_000_000


class OsiTraceError(Exception):
    """An OSI trace that cannot be written or read; the message is one line naming the file."""


def sidecar_path(path: str | os.PathLike[str]) -> Path:
    """The metadata file beside the trace ``path``: ``<path>.json``."""
    path = Path(path)
    return path.with_name(path.name + ".json")


def vehicle_id(sender: str) -> int:
    """The OSI id of a vehicle: the CRC-32 of its name (stable across processes and runs)."""
    return zlib.crc32(sender.encode())


def _normal_rmse(points: NDArrayFloat, sigma: NDArrayFloat) -> NDArrayFloat:
    """``(N, 2)`` per-point (x, y) RMSE of a lateral σ (m) along the polyline's unit normal."""
    tangent = np.gradient(points, axis=0)
    length = np.hypot(tangent[:, 0], tangent[:, 1])
    unit = tangent / np.where(length > 0.0, length, 1.0)[:, None]
    return np.abs(unit[:, ::-1]) * sigma[:, None]


def sensor_data(stamp_ns: int, frame: int, sender: str, pose: tuple[float, float, float],
                left: NDArrayFloat, right: NDArrayFloat, *, map_reference: str = "",
                sigmas: tuple[NDArrayFloat | None, NDArrayFloat | None] = (None, None),
                boundary_types: tuple[int, int] = (UNKNOWN_BOUNDARY_TYPE, UNKNOWN_BOUNDARY_TYPE)) -> bytes:
    """One vehicle's detection in one frame as an encoded ``osi3.SensorData`` (see the module
    docstring). ``stamp_ns``: ns since the run's start; ``pose``: the sender's reported (x m,
    y m, yaw rad), world frame; ``left``/``right``: ``(N, 2)`` borders in its vehicle frame
    (m); ``sigmas``: per-point lateral 1σ (m) of each border or None; ``boundary_types``:
    ``LaneBoundary.Classification.Type`` numbers of the two borders."""
    import betterosi as osi

    stamp = osi.Timestamp(seconds=stamp_ns // NS_PER_S, nanos=stamp_ns % NS_PER_S)
    version = osi.InterfaceVersion(version_major=OSI_VERSION[0], version_minor=OSI_VERSION[1],
                                   version_patch=OSI_VERSION[2])
    ident = osi.Identifier(value=vehicle_id(sender))
    x, y, yaw = pose

    def origin() -> Any:
        return osi.MountingPosition(position=osi.Vector3d(x=0.0, y=0.0, z=0.0),
                                    orientation=osi.Orientation3d(roll=0.0, pitch=0.0, yaw=0.0))

    vehicle = osi.MovingObject(
        id=ident, base=osi.BaseMoving(position=osi.Vector3d(x=x, y=y, z=0.0),
                                      orientation=osi.Orientation3d(roll=0.0, pitch=0.0, yaw=yaw)),
        vehicle_attributes=osi.MovingObject.VehicleAttributes(bbcenter_to_rear=osi.Vector3d(x=0.0, y=0.0, z=0.0)),
        source_reference=[osi.ExternalReference(type=SENDER_REFERENCE_TYPE, identifier=[sender])])
    truth = osi.GroundTruth(version=version, timestamp=stamp, host_vehicle_id=ident, moving_object=[vehicle],
                            map_reference=map_reference)
    view = osi.SensorView(version=version, timestamp=stamp, sensor_id=ident, mounting_position=origin(),
                          global_ground_truth=truth, host_vehicle_id=ident)

    def boundary(tracking_id: int, points: NDArrayFloat, sigma: NDArrayFloat | None, kind: int) -> Any:
        rmse = [] if sigma is None else [
            osi.LaneBoundary.BoundaryPoint(position=osi.Vector3d(x=ex, y=ey))
            for ex, ey in _normal_rmse(points, sigma).tolist()]
        return osi.DetectedLaneBoundary(
            header=osi.DetectedItemHeader(tracking_id=osi.Identifier(value=tracking_id),
                                          existence_probability=EXISTENCE_PROBABILITY,
                                          measurement_state=osi.DetectedItemHeader.MeasurementState.MEASURED,
                                          sensor_id=[ident]),
            candidate=[osi.DetectedLaneBoundary.CandidateLaneBoundary(
                probability=1.0, classification=osi.LaneBoundary.Classification(
                    type=osi.LaneBoundary.Classification.Type(kind)))],
            boundary_line=[osi.LaneBoundary.BoundaryPoint(position=osi.Vector3d(x=px, y=py))
                           for px, py in points.tolist()],
            boundary_line_rmse=rmse)

    message = osi.SensorData(
        version=version, timestamp=stamp, sensor_id=ident, mounting_position=origin(), sensor_view=[view],
        last_measurement_time=stamp,
        lane_boundary_header=osi.DetectedEntityHeader(
            measurement_time=stamp, cycle_counter=frame,
            data_qualifier=osi.DetectedEntityHeader.DataQualifier.AVAILABLE),
        lane_boundary=[boundary(LEFT_TRACKING_ID, left, sigmas[0], boundary_types[0]),
                       boundary(RIGHT_TRACKING_ID, right, sigmas[1], boundary_types[1])])
    return message.to_binary()


def detection_sensor_data(stamp_ns: int, frame: int, sender: str, pose: tuple[float, float, float],
                          left: NDArrayFloat, right: NDArrayFloat, detection: fusion.LaneDetection | None,
                          map_reference: str) -> bytes:
    """:func:`sensor_data` of a detection: its σ where it states one, and the boundary types
    of :func:`boundary_types`."""
    sigmas = (None, None) if detection is None else (detection.left_sigma, detection.right_sigma)
    return sensor_data(stamp_ns, frame, sender, pose, left, right, map_reference=map_reference, sigmas=sigmas,
                       boundary_types=boundary_types(detection))


def boundary_types(detection: fusion.LaneDetection | None) -> tuple[int, int]:
    """The ``LaneBoundary.Classification.Type`` of the detection's left and right border: the
    hook for a sensor that reports the marking it saw (``road_marks.classify_border`` gives
    these numbers); UNKNOWN (0) while ``fusion.LaneDetection`` carries no marking."""
    return UNKNOWN_BOUNDARY_TYPE, UNKNOWN_BOUNDARY_TYPE


class OsiTraceWriter:
    """Writes one trace: ``<path>.partial`` while open, renamed to ``path`` by :meth:`close`,
    which also writes the sidecar (``metadata`` and the status)."""

    def __init__(self, path: str | os.PathLike[str], metadata: Mapping[str, Any]) -> None:
        self.path = Path(path)
        self.partial_path = self.path.with_name(self.path.name + ".partial")
        self._metadata = dict(metadata)
        self._stream: BinaryIO | None = None
        self.messages = 0

    def open(self) -> None:
        """Creates ``<path>.partial``; OsiTraceError naming it when it cannot."""
        try:
            self._stream = open(self.partial_path, "wb")
        except OSError as exc:
            raise OsiTraceError(f"{self.partial_path}: cannot create OSI trace: {exc.strerror}") from exc

    def write(self, payload: bytes) -> None:
        """Appends one encoded message with its length prefix."""
        if self._stream is None:
            raise OsiTraceError(f"{self.path}: OSI trace is not open")
        self._stream.write(LENGTH_PREFIX.pack(len(payload)) + payload)
        self.messages += 1

    def discard(self) -> None:
        """Closes and removes ``<path>.partial`` (a recording that could not start)."""
        stream, self._stream = self._stream, None
        if stream is not None:
            stream.close()
        self.partial_path.unlink(missing_ok=True)

    def close(self, status: Mapping[str, str]) -> None:
        """Flushes the trace to disk, renames it to ``path`` and writes the sidecar with ``status``."""
        from converters.atomic_io import atomic_output

        stream, self._stream = self._stream, None
        if stream is None:
            return
        with stream:
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(self.partial_path, self.path)
        document = {"format": SIDECAR_FORMAT, "version": SIDECAR_VERSION,
                    "osi_version": ".".join(map(str, OSI_VERSION)), "messages": self.messages,
                    **self._metadata, **status}
        with atomic_output(sidecar_path(self.path)) as out:
            out.write(json.dumps(document, indent=2, sort_keys=True) + "\n")


def read_sidecar(path: str | os.PathLike[str]) -> dict[str, Any]:
    """The sidecar of the trace ``path`` ({} when there is none: a trace from another tool)."""
    side = sidecar_path(path)
    try:
        document = json.loads(side.read_text(encoding="utf-8"))
    except FileNotFoundError:
        return {}
    except (OSError, ValueError) as exc:
        raise OsiTraceError(f"{side}: unreadable OSI trace metadata: {exc}") from exc
    if not isinstance(document, dict) or document.get("format") != SIDECAR_FORMAT:
        raise OsiTraceError(f"{side}: not a cold-maps OSI trace metadata file (format {SIDECAR_FORMAT!r})")
    return document


def iter_messages(path: Path, stream: BinaryIO) -> Iterator[bytes]:
    """The messages of a length-prefixed trace; OsiTraceError for a truncated one."""
    index = 0
    while header := stream.read(LENGTH_PREFIX.size):
        if len(header) < LENGTH_PREFIX.size:
            raise OsiTraceError(f"{path}: truncated OSI trace (length prefix of message {index})")
        (size,) = LENGTH_PREFIX.unpack(header)
        payload = stream.read(size)
        if len(payload) < size:
            raise OsiTraceError(f"{path}: truncated OSI trace (message {index}: {len(payload)} of {size} bytes)")
        yield payload
        index += 1


def _sender(message: Any) -> tuple[str, tuple[float, float, float], str]:
    """The sender's name, reported pose (world frame) and the map reference of a SensorData."""
    host = message.sensor_id.value
    truth = message.sensor_view[0].global_ground_truth
    vehicle = next(o for o in truth.moving_object if o.id.value == host)
    names = [i for r in vehicle.source_reference if r.type == SENDER_REFERENCE_TYPE for i in r.identifier]
    base = vehicle.base
    return (names[0] if names else str(host)), (base.position.x, base.position.y, base.orientation.yaw), \
        truth.map_reference or ""


def _border(boundaries: Mapping[int, Any], tracking_id: int) -> tuple[NDArrayFloat, NDArrayFloat | None]:
    boundary = boundaries[tracking_id]
    side = "left" if tracking_id == LEFT_TRACKING_ID else "right"
    points = check_polyline(side, [(p.position.x, p.position.y) for p in boundary.boundary_line])
    if not boundary.boundary_line_rmse:
        return points, None
    rmse = np.array([(p.position.x, p.position.y) for p in boundary.boundary_line_rmse], dtype=np.float64)
    if rmse.shape[0] != points.shape[0]:
        raise ValueError(f"{side}: {rmse.shape[0]} boundary_line_rmse for {points.shape[0]} boundary_line points")
    return points, np.hypot(rmse[:, 0], rmse[:, 1])


def decode_detection(payload: bytes) -> dict[str, Any]:
    """One SensorData as the detection dict of ``recorder.read_detections`` (keys ``stamp_s``,
    ``frame``, ``sender``, ``pose``, ``left``, ``right``, ``neighbours``, ``branches``,
    ``road_edges``, ``history``) plus ``left_sigma``/``right_sigma`` and ``map``; ValueError
    (or a decoding error) for a message that is not such a detection."""
    import betterosi as osi

    message = osi.SensorData.from_binary(payload)
    if message.timestamp is None or message.sensor_id is None or not message.sensor_view:
        raise ValueError("SensorData without timestamp, sensor_id or sensor_view")
    sender, pose, map_reference = _sender(message)
    boundaries = {b.header.tracking_id.value: b for b in message.lane_boundary}
    if set(boundaries) != {LEFT_TRACKING_ID, RIGHT_TRACKING_ID}:
        raise ValueError(f"expected lane boundaries with tracking ids {LEFT_TRACKING_ID} (left) and "
                         f"{RIGHT_TRACKING_ID} (right), got {sorted(boundaries)}")
    left, left_sigma = _border(boundaries, LEFT_TRACKING_ID)
    right, right_sigma = _border(boundaries, RIGHT_TRACKING_ID)
    header = message.lane_boundary_header
    stamp_ns = message.timestamp.seconds * NS_PER_S + message.timestamp.nanos
    return {"stamp_s": stamp_ns / NS_PER_S, "frame": int(header.cycle_counter if header is not None else 0),
            "sender": sender, "pose": dict(zip(("x", "y", "yaw"), map(float, pose))), "left": left, "right": right,
            "left_sigma": left_sigma, "right_sigma": right_sigma, "neighbours": (), "branches": (),
            "road_edges": None, "history": None, "map": map_reference}


def read_osi_detections(path: str | os.PathLike[str]) -> Iterator[tuple[int, list[dict[str, Any]]]]:
    """The detections of an OSI trace grouped by frame (``cycle_counter``) in trace order, as
    :func:`decode_detection` gives them; OsiTraceError naming the file and message for a
    truncated trace or a message that is no such detection."""
    path = Path(path)
    try:
        stream = open(path, "rb")
    except OSError as exc:
        raise OsiTraceError(f"{path}: cannot open OSI trace: {exc.strerror}") from exc
    return _grouped(path, stream)


def _grouped(path: Path, stream: BinaryIO) -> Iterator[tuple[int, list[dict[str, Any]]]]:
    frame, group = -1, []
    with stream:
        for index, payload in enumerate(iter_messages(path, stream)):
            try:
                detection = decode_detection(payload)
            except Exception as exc:  # noqa: BLE001 - the decoder's errors vary; all mean a foreign message
                raise OsiTraceError(f"{path}: message {index}: not a lane detection SensorData: "
                                    f"{type(exc).__name__}: {exc}") from exc
            if group and detection["frame"] != frame:
                yield frame, group
                group = []
            frame = detection["frame"]
            group.append(detection)
    if group:
        yield frame, group


def first_map_reference(path: str | os.PathLike[str]) -> str:
    """The ``map_reference`` of the trace's first message ("" when it names none or is empty)."""
    for _, detections in read_osi_detections(path):
        return str(detections[0]["map"])
    return ""
