"""Lane messages in the loop: encoding, generation rule, loss and latency (all seeded).

A cooperative vehicle broadcasts its lane (with its lane history, neighbour lanes, road
edges and branches, when it has them) as a message (:class:`LaneMessage`); the ego fuses
the *last message it received*, with the sender's pose at send time — never the sender's
current detection.

**Encoding** (``exchange``): ``sampled`` — every border point as 3 float32 (x, y, z = 0;
:data:`fusion.bezier.SAMPLED_POINT_BYTES`), so the receiver sees the points rounded to
float32; ``bezier`` — :func:`fusion.bezier.encode` per lane, history, neighbour lane and branch
(tolerance ``bezier_tolerance_m``), decoded by :func:`fusion.bezier.decode` every 0.10 m.
Every message also carries :data:`POSE_BYTES` of header: the sender's pose (x, y, yaw) and
its time stamp as float32; a multi-lane one its layout (:func:`message_bytes`). A message
that does not decode (:class:`fusion.BezierDecodeError`) is lost.

**Generation rule** (checked every frame, :meth:`LaneChannel.step`): a vehicle sends when
at least ``min_interval_s`` passed since its last message and (a) ``max_interval_s`` passed,
or (b) it moved more than ``move_tolerance_m`` since, or (c) its lane changed: the RMS distance of the
new lane's points from the last sent lane exceeds ``change_tolerance_m`` on either border
(both in the world frame, over the stretch they share; RMS rather than max so that
detection noise of a few cm alone does not trigger it). This mirrors the object-inclusion rules of the ETSI
Collective Perception Message (ETSI TS 103 324; values as commonly cited, not checked
against the standard's text here): CPMs are generated between T_GenCpmMin = 100 ms and
T_GenCpmMax = 1 s apart, and a perceived object is included again when it moved more than
4 m, its speed changed by more than 0.5 m/s, its orientation by more than 4°, or 1 s passed.
Here the "object" is the lane: the 4 m position rule becomes the sender's own displacement
(the lane ahead then holds 4 m of new road), the orientation and speed rules become the
shape-change tolerance (a lane has no speed; its geometry changes only where new road
comes into view or the perception changes), and T_GenCpmMax stays 1 s.

**Channel**: each message is lost with probability ``loss_probability`` and otherwise
arrives ``latency_s`` later (one draw per message; loss draws only when enabled).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Final, Literal

import numpy as np

import fusion
from fusion.bezier import SAMPLED_POINT_BYTES
from fusion.geometry import distance_to_polyline, to_world

Exchange = Literal["none", "sampled", "bezier"]
EXCHANGES: Final[tuple[str, ...]] = ("none", "sampled", "bezier")
POSE_BYTES: Final[int] = 4 * 4
"""Message header: sender x, y (m), yaw (rad) and stamp (s) as float32 (the receiver sees the
pose rounded to float32: 3·10⁻⁵ m at 500 m from the map origin)."""
LAYOUT_BYTES: Final[int] = 3
"""Layout of a multi-lane message: neighbour lane count, branch count, flags (history, road
edges) as uint8."""
NEIGHBOUR_BYTES: Final[int] = 2
"""Per neighbour lane: its index (int8) and its at_start / at_end flags (one byte)."""
ROAD_EDGES_BYTES: Final[int] = 4
"""Road edges: four int8 lane indices (−128 = not seen)."""
DEFAULT_MAX_INTERVAL_S: Final[float] = 1.0
"""Longest time (s) between two messages (ETSI's T_GenCpmMax)."""
DEFAULT_CHANGE_TOLERANCE_M: Final[float] = 0.10
"""RMS lane change (m) that triggers a message."""
DECODE_SPACING_M: Final[float] = 0.10
"""Point spacing (m) of a decoded Bézier lane (the sensor's)."""


@dataclass(frozen=True, slots=True)
class MessageModel:
    """How lanes are exchanged; ``exchange="none"`` (default) fuses detections directly.

    Fields:
        exchange: ``none``, ``sampled`` or ``bezier`` (module docstring).
        bezier_tolerance_m: fit tolerance of the Bézier encoding (m).
        min_interval_s, max_interval_s: shortest and longest time between two messages (s).
        move_tolerance_m: sender displacement that triggers a message (m).
        change_tolerance_m: lane shape change that triggers a message (m).
        loss_probability: probability that a message is lost (0..1).
        latency_s: delay from sending to reception (s).
    """

    exchange: Exchange = "none"
    bezier_tolerance_m: float = fusion.bezier.DEFAULT_TOLERANCE_M
    min_interval_s: float = 0.1
    max_interval_s: float = DEFAULT_MAX_INTERVAL_S
    move_tolerance_m: float = 4.0
    change_tolerance_m: float = DEFAULT_CHANGE_TOLERANCE_M
    loss_probability: float = 0.0
    latency_s: float = 0.0

    def __post_init__(self) -> None:
        if self.exchange not in EXCHANGES:
            raise ValueError(f"MessageModel.exchange: expected one of {EXCHANGES}, got {self.exchange!r}")
        for name in ("bezier_tolerance_m", "min_interval_s", "max_interval_s", "move_tolerance_m",
                     "change_tolerance_m", "loss_probability", "latency_s"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"MessageModel.{name}: expected a finite number >= 0, got {value!r}")
        if self.bezier_tolerance_m == 0:
            raise ValueError("MessageModel.bezier_tolerance_m: must be > 0")
        if self.loss_probability > 1:
            raise ValueError(f"MessageModel.loss_probability: must be <= 1, got {self.loss_probability!r}")
        if self.max_interval_s < self.min_interval_s:
            raise ValueError(f"MessageModel.max_interval_s ({self.max_interval_s}) < min_interval_s "
                             f"({self.min_interval_s})")

    @property
    def enabled(self) -> bool:
        """Whether lanes go through messages at all."""
        return self.exchange != "none"


@dataclass(frozen=True, slots=True)
class LaneMessage:
    """The payloads of one lane message, each lane encoded on its own (:func:`encode`).

    Fields:
        lane: the sender's lane.
        history: its lane history, or None.
        neighbours: ``(index, at_start, at_end, lane)`` of each neighbour lane
            (:class:`fusion.NeighbourLane`).
        road_edges: the road edges (:class:`fusion.RoadEdges`), or None.
        branches: each lane leaving the sender's at a fork (:class:`fusion.LaneBranch`).
    """

    lane: bytes
    history: bytes | None = None
    neighbours: tuple[tuple[int, bool, bool, bytes], ...] = ()
    road_edges: fusion.RoadEdges | None = None
    branches: tuple[bytes, ...] = ()

    @property
    def multi_lane(self) -> bool:
        """Whether the message carries neighbour lanes, road edges or branches."""
        return bool(self.neighbours or self.branches) or self.road_edges is not None

    def payloads(self) -> tuple[bytes, ...]:
        """Every encoded lane: lane, history, neighbours, branches."""
        return (self.lane, *(() if self.history is None else (self.history,)),
                *(payload for *_, payload in self.neighbours), *self.branches)


def _encode_lane(left: fusion.NDArrayFloat, right: fusion.NDArrayFloat, model: MessageModel) -> bytes:
    if model.exchange == "bezier":
        return fusion.bezier.encode(left, right, tolerance_m=model.bezier_tolerance_m)
    return np.concatenate((left, right)).astype("<f4").tobytes() + np.uint32(left.shape[0]).tobytes()


def _decode_lane(payload: bytes, model: MessageModel) -> tuple[fusion.NDArrayFloat, fusion.NDArrayFloat]:
    if model.exchange == "bezier":
        return fusion.bezier.decode(payload, spacing_m=DECODE_SPACING_M)
    if len(payload) < 4 or (len(payload) - 4) % 8:
        raise fusion.BezierDecodeError(f"sampled lane payload of {len(payload)} bytes is malformed")
    points = np.frombuffer(payload[:-4], dtype="<f4").astype(np.float64).reshape(-1, 2)
    n_left = int(np.frombuffer(payload[-4:], dtype="<u4")[0])
    if not 0 < n_left < points.shape[0]:
        raise fusion.BezierDecodeError(f"sampled lane payload announces {n_left} of {points.shape[0]} points")
    return points[:n_left], points[n_left:]


def encode(detection: fusion.LaneDetection, model: MessageModel) -> LaneMessage:
    """The message of a detection: its lane, history, neighbour lanes and branches encoded
    each on its own, the road edges as they are."""
    history = detection.history
    return LaneMessage(
        _encode_lane(detection.left, detection.right, model),
        None if history is None else _encode_lane(history.left, history.right, model),
        tuple((int(lane.index), bool(lane.at_start), bool(lane.at_end), _encode_lane(lane.left, lane.right, model))
              for lane in detection.neighbours),
        detection.road_edges,
        tuple(_encode_lane(branch.left, branch.right, model) for branch in detection.branches))


def decode(message: LaneMessage, pose: fusion.Pose2D, stamp: float, sender: str,
           model: MessageModel) -> fusion.LaneDetection:
    """The detection the receiver rebuilds from :func:`encode`'s message (raises
    :class:`fusion.BezierDecodeError` or :class:`fusion.InvalidDetectionError` on a bad one)."""
    left, right = _decode_lane(message.lane, model)
    history = None if message.history is None else fusion.LaneHistory(*_decode_lane(message.history, model))
    neighbours = tuple(fusion.NeighbourLane(index, *_decode_lane(payload, model), at_start, at_end)
                       for index, at_start, at_end, payload in message.neighbours)
    branches = tuple(fusion.LaneBranch(*_decode_lane(payload, model)) for payload in message.branches)
    x, y, yaw = np.array([pose.x, pose.y, pose.yaw], dtype=np.float32).tolist()
    return fusion.LaneDetection(fusion.Pose2D(x, y, yaw), left, right, stamp=stamp, sender=sender, history=history,
                                neighbours=neighbours, road_edges=message.road_edges, branches=branches)


def message_bytes(message: LaneMessage, model: MessageModel) -> int:
    """Bytes on air of one message: header, encoded lanes (sampled: 12 bytes per point) and,
    for a multi-lane message, its layout (:data:`LAYOUT_BYTES`, :data:`NEIGHBOUR_BYTES` per
    neighbour lane, :data:`ROAD_EDGES_BYTES` with road edges)."""
    payloads = message.payloads()
    if model.exchange == "bezier":
        size = POSE_BYTES + sum(len(p) for p in payloads)
    else:
        size = POSE_BYTES + sum((len(p) - 4) // 8 * SAMPLED_POINT_BYTES for p in payloads)
    if message.multi_lane:
        size += (LAYOUT_BYTES + NEIGHBOUR_BYTES * len(message.neighbours)
                 + (ROAD_EDGES_BYTES if message.road_edges is not None else 0))
    return size


@dataclass
class LaneChannel:
    """One sender's messages to the ego: generation rule, loss, latency (module docstring).

    Fields:
        model: the exchange set-up.
        sent_at: stamp (s) and world position (m) of the last message sent, or None.
        sent_lane: the last sent lane's world borders (for the change rule).
        in_flight: (arrival stamp s, message, pose, stamp, sender) of messages on the way.
        received: the last detection received, or None.
        messages, bytes_sent: messages sent and their bytes on air so far.
        lost, decode_errors: messages lost on the channel and messages that did not decode.
    """

    model: MessageModel
    sent_at: tuple[float, complex] | None = None
    sent_lane: tuple[fusion.NDArrayFloat, fusion.NDArrayFloat] | None = None
    in_flight: list[tuple[float, LaneMessage, fusion.Pose2D, float, str]] = field(default_factory=list)
    received: fusion.LaneDetection | None = None
    messages: int = 0
    bytes_sent: int = 0
    lost: int = 0
    decode_errors: int = 0

    def due(self, detection: fusion.LaneDetection, stamp: float) -> bool:
        """Whether the generation rule sends ``detection`` at ``stamp`` (s)."""
        if self.sent_at is None:
            return True
        last_stamp, last_position = self.sent_at
        elapsed = stamp - last_stamp
        if elapsed < self.model.min_interval_s - 1e-9:
            return False
        if elapsed >= self.model.max_interval_s - 1e-9:
            return True
        if abs(complex(detection.pose.x, detection.pose.y) - last_position) > self.model.move_tolerance_m:
            return True
        assert self.sent_lane is not None
        for border, before in zip((detection.left, detection.right), self.sent_lane):
            shared = _shared(to_world(border, detection.pose), before)
            if shared.shape[0] and math.sqrt(float(np.mean(distance_to_polyline(shared, before) ** 2))) > \
                    self.model.change_tolerance_m:
                return True
        return False

    def step(self, detection: fusion.LaneDetection | None, stamp: float, rng: np.random.Generator) -> int:
        """Offers the sender's detection at ``stamp`` (s; None when it has none), delivers what
        has arrived by then; returns the bytes sent this step (0 when nothing was sent)."""
        sent = 0
        if detection is not None and self.due(detection, stamp):
            message = encode(detection, self.model)
            sent = message_bytes(message, self.model)
            self.messages += 1
            self.bytes_sent += sent
            self.sent_at = (stamp, complex(detection.pose.x, detection.pose.y))
            self.sent_lane = (to_world(detection.left, detection.pose), to_world(detection.right, detection.pose))
            if self.model.loss_probability > 0 and rng.random() < self.model.loss_probability:
                self.lost += 1
            else:
                self.in_flight.append((stamp + self.model.latency_s, message, detection.pose, detection.stamp,
                                       detection.sender))
        self.deliver(stamp)
        return sent

    def deliver(self, stamp: float) -> None:
        """Receives every message that has arrived by ``stamp`` (s), in order; one that does not
        decode is counted and dropped (the previous one stays the last received)."""
        arrived = [m for m in self.in_flight if m[0] <= stamp + 1e-9]
        self.in_flight = [m for m in self.in_flight if m[0] > stamp + 1e-9]
        for _, message, pose, sent_stamp, sender in arrived:
            try:
                self.received = decode(message, pose, sent_stamp, sender, self.model)
            except fusion.FusionError:
                self.decode_errors += 1


def _shared(points: fusion.NDArrayFloat, before: fusion.NDArrayFloat) -> fusion.NDArrayFloat:
    """The points (m, world) between the normals through the first and last point of the
    polyline ``before``: the stretch of a new lane that the last sent lane also covers."""
    start, end = before[min(1, before.shape[0] - 1)] - before[0], before[-1] - before[max(0, before.shape[0] - 2)]
    inside = ((points - before[0]) @ start >= 0.0) & ((points - before[-1]) @ end <= 0.0)
    return points[inside]
