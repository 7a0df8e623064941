"""Lane history by dead reckoning (simulation.odometry) and lane messages in the loop
(simulation.messages): generation rule, loss, latency, exchange and decode errors."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import fusion
from cold_maps.network.lane_strip import LaneStrip
from cold_maps.simulation.drive import Track
from cold_maps.simulation.messages import (
    LAYOUT_BYTES,
    NEIGHBOUR_BYTES,
    POSE_BYTES,
    ROAD_EDGES_BYTES,
    LaneChannel,
    LaneMessage,
    MessageModel,
    decode,
    encode,
    message_bytes,
)
from cold_maps.simulation.odometry import OdometryModel, dead_reckoned, lane_history
from cold_maps.simulation.sensor_errors import SensorErrorModel
from fusion.analytic import AnalyticRoad, Segment, detect, detect_lanes, with_history


def _straight_track(length_m=300.0):
    x = np.arange(0.0, length_m + 0.05, 0.5)
    left = np.column_stack((x, np.full_like(x, 1.75)))
    right = np.column_stack((x, np.full_like(x, -1.75)))
    return Track((), LaneStrip.from_borders(left, right), np.array([0.0, length_m]))


def test_exact_odometry_history_is_the_lane_behind():
    track = _straight_track()
    history = lane_history(track, 150.0, 100.0, SensorErrorModel(), OdometryModel(), np.random.default_rng(0))
    assert history.left[0] == pytest.approx((-100.0, 1.75))
    assert history.left[-1] == pytest.approx((0.0, 1.75))  # ends at the vehicle, where its detection starts
    assert np.abs(history.right[:, 1] + 1.75).max() < 1e-6
    assert np.diff(history.left[:, 0]).max() == pytest.approx(0.1)
    assert lane_history(track, 0.1, 100.0, SensorErrorModel(), OdometryModel(), np.random.default_rng(0)) is None


def test_heading_drift_bends_the_history_by_the_closed_form():
    track = _straight_track()
    k, e = 2e-4, 0.01
    u = np.array([0.0, 10.0, 40.0, 80.0])  # m behind the vehicle at station 150
    points = np.column_stack((150.0 - u, np.full_like(u, 1.75)))
    moved = dead_reckoned(points, 150.0 - u, track, 150.0, k, e)
    # back along a straight: ĉ(u) = −(1+e)∫R(k·t)dt, a point on it at lateral 1.75 turned by k·u
    expect_x = 150.0 - (1.0 + e) * np.sin(k * u) / k - 1.75 * np.sin(k * u)
    expect_y = -(1.0 + e) * (1.0 - np.cos(k * u)) / k + 1.75 * np.cos(k * u)
    np.testing.assert_allclose(moved[:, 0], expect_x, atol=2e-6)
    np.testing.assert_allclose(moved[:, 1], expect_y, atol=2e-6)
    assert moved[-1, 1] - 1.75 == pytest.approx(-(1.0 + e) * k * 80.0**2 / 2.0, rel=0.01)  # lateral k·u²/2


def test_odometry_draws_only_when_enabled():
    rng = np.random.default_rng(3)
    state = rng.bit_generator.state
    assert OdometryModel().draw(rng) == (0.0, 0.0)
    assert rng.bit_generator.state == state
    with pytest.raises(ValueError, match="scale_error"):
        OdometryModel(scale_error=-0.1)


ROAD = AnalyticRoad([Segment(100.0), Segment(60.0, 1.0 / 30.0), Segment(200.0)])


def _detection(s, history_m=0.0):
    det = detect(ROAD, s, 30.0, 1.75, -1.75, sender="coop")
    return with_history(ROAD, det, s, history_m, 1.75, -1.75) if history_m else det


@pytest.mark.parametrize("exchange", ["sampled", "bezier"])
def test_exchange_round_trip_error_and_size(exchange):
    det = _detection(110.0, history_m=50.0)
    model = MessageModel(exchange)
    message = encode(det, model)
    back = decode(message, det.pose, 1.5, "coop", model)
    assert back.stamp == 1.5 and back.history is not None
    for sent, got in ((det.left, back.left), (det.right, back.right), (det.history.left, back.history.left)):
        error = fusion.geometry.distance_to_polyline(sent, got).max()
        assert error <= (model.bezier_tolerance_m + 0.005 if exchange == "bezier" else 1e-4)
    size = message_bytes(message, model)
    if exchange == "sampled":
        assert size == POSE_BYTES + 12 * (det.points.shape[0] + det.history.left.shape[0] + det.history.right.shape[0])
    else:
        assert size == POSE_BYTES + len(message.lane) + len(message.history) and size < 1000


@pytest.mark.parametrize("exchange", ["sampled", "bezier"])
def test_neighbour_lanes_road_edges_and_branches_survive_the_exchange(exchange):
    """A multi-lane detection (middle lane of three, both neighbours, both road edges, a branch)
    with its history comes back with every part, each lane within the format's error, and its
    layout counted on air: 3 bytes, 2 per neighbour lane, 4 for the road edges."""
    lanes = detect_lanes(ROAD, 110.0, 30.0, 1, 3, 3.5, sender="coop")
    branch = fusion.LaneBranch(lanes.right[100:] + (0.0, -0.5), lanes.right[100:] + (0.0, -4.0))
    det = with_history(ROAD, replace(lanes, branches=(branch,)), 110.0, 50.0, 7.0, 3.5)
    model = MessageModel(exchange)
    message = encode(det, model)
    back = decode(message, det.pose, 1.5, "coop", model)
    tolerance = model.bezier_tolerance_m + 0.005 if exchange == "bezier" else 1e-4
    assert back.road_edges == det.road_edges == fusion.RoadEdges(1, -1, 1, -1)
    assert [(n.index, n.at_start, n.at_end) for n in back.neighbours] == [(1, True, True), (-1, True, True)]
    pairs = [(det.history.left, back.history.left), (det.branches[0].left, back.branches[0].left)]
    pairs += [(sent.right, got.right) for sent, got in zip(det.neighbours, back.neighbours)]
    for sent, got in pairs:
        assert fusion.geometry.distance_to_polyline(sent, got).max() <= tolerance
    single = message_bytes(encode(replace(det, neighbours=(), road_edges=None, branches=()), model), model)
    lane_bytes = sum(message_bytes(LaneMessage(p), model) - POSE_BYTES for p in (*(n[3] for n in message.neighbours),
                                                                                  *message.branches))
    assert message_bytes(message, model) == single + lane_bytes + LAYOUT_BYTES + 2 * NEIGHBOUR_BYTES + ROAD_EDGES_BYTES


def _drive(channel, seconds=3.0, speed=10.0, start=100.0, seed=0):
    rng = np.random.default_rng(seed)
    sent = []
    for i in range(int(seconds * 10) + 1):
        stamp = i / 10.0
        det = _detection(start + speed * stamp)
        sent.append(channel.step(fusion.LaneDetection(det.pose, det.left, det.right, stamp=stamp, sender="coop"),
                                 stamp, rng))
    return sent


def test_generation_rule_sends_on_movement_and_at_most_every_max_interval():
    moving = LaneChannel(MessageModel("bezier"))
    sent = _drive(moving, speed=10.0)
    # 10 m/s, moved > 4 m: every 5th frame (0.5 s), from the first frame
    assert [i for i, b in enumerate(sent) if b] == list(range(0, 31, 5))
    assert moving.messages == 7 and moving.bytes_sent == sum(sent)
    standing = LaneChannel(MessageModel("bezier"))
    sent = _drive(standing, speed=0.0)
    assert [i for i, b in enumerate(sent) if b] == [0, 10, 20, 30]  # unchanged lane: every T = 1 s


def test_loss_and_latency():
    lossy = LaneChannel(MessageModel("sampled", loss_probability=1.0))
    _drive(lossy)
    assert lossy.received is None and lossy.lost == lossy.messages > 0
    late = LaneChannel(MessageModel("bezier", latency_s=0.3))
    rng = np.random.default_rng(0)
    received = []
    for i in range(8):
        det = _detection(100.0 + i)
        late.step(fusion.LaneDetection(det.pose, det.left, det.right, stamp=i / 10.0), i / 10.0, rng)
        received.append(None if late.received is None else late.received.stamp)
    # sent at 0.0 and 0.5 s (moved 5 m), each received 0.3 s later, with its send-time pose
    assert received == [None, None, None, 0.0, 0.0, 0.0, 0.0, 0.0]
    assert late.received.pose.x == pytest.approx(_detection(100.0).pose.x, abs=1e-4)
    half = LaneChannel(MessageModel("bezier", loss_probability=0.5))
    _drive(half, seconds=100.0, speed=1.0, seed=4)
    assert 0.3 < half.lost / half.messages < 0.7


def test_a_message_that_does_not_decode_is_dropped_and_the_last_one_kept():
    channel = LaneChannel(MessageModel("bezier"))
    _drive(channel, seconds=0.0)
    kept = channel.received
    assert kept is not None
    good = encode(_detection(120.0), channel.model)
    channel.in_flight.append((1.0, replace(good, lane=good.lane[:-5]), kept.pose, 1.0, "coop"))  # truncated
    channel.deliver(1.0)
    assert channel.decode_errors == 1 and channel.received is kept
    sampled = LaneChannel(MessageModel("sampled"))
    sampled.in_flight.append((0.0, LaneMessage(b"\x00" * 7), kept.pose, 0.0, "coop"))
    sampled.deliver(0.0)
    assert sampled.decode_errors == 1 and sampled.received is None


def test_message_model_rejects_bad_values():
    with pytest.raises(ValueError, match="exchange"):
        MessageModel("json")
    with pytest.raises(ValueError, match="loss_probability"):
        MessageModel("bezier", loss_probability=1.5)
    with pytest.raises(ValueError, match="max_interval_s"):
        MessageModel("bezier", min_interval_s=2.0)
    assert math.isfinite(MessageModel().max_interval_s)
