"""Lane strip and generic lane sensor against closed forms on straight and arc lanes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from cold_maps.network.lane_strip import LaneStrip
from cold_maps.simulation.sensor import LaneSensor, vehicle_to_world, world_to_vehicle

LANE_WIDTH_M = 4.0


def arc_strip(radius: float, angle: float, step: float = 0.1) -> LaneStrip:
    """A left-turning lane whose centreline is an arc of ``radius`` about the origin,
    starting at (0, -radius) heading +x; cross-sections every ``step`` m of centreline."""
    phi = np.linspace(0.0, angle, int(np.ceil(radius * angle / step)) + 1)
    def ring(r: float) -> np.ndarray:
        return np.column_stack((r * np.sin(phi), -r * np.cos(phi)))
    return LaneStrip.from_borders(ring(radius - LANE_WIDTH_M / 2), ring(radius + LANE_WIDTH_M / 2))


def straight_strip(length: float) -> LaneStrip:
    x = np.linspace(0.0, length, int(round(length / 0.5)) + 1)
    return LaneStrip.from_borders(np.column_stack((x, np.full_like(x, 2.0))), np.column_stack((x, np.full_like(x, -2.0))))


def test_straight_detection_is_the_lane_in_vehicle_frame() -> None:
    detection = LaneSensor().detect(straight_strip(100.0), 10.0)
    assert detection is not None
    assert (detection.x, detection.y, detection.yaw) == pytest.approx((10.0, 0.0, 0.0))
    assert detection.left.shape == (301, 2)
    np.testing.assert_allclose(detection.left[:, 1], 2.0, atol=1e-12)
    np.testing.assert_allclose(detection.right[:, 1], -2.0, atol=1e-12)
    np.testing.assert_allclose(detection.left[:, 0], np.arange(301) * 0.1, atol=1e-9)


def test_arc_detection_points_lie_on_their_circles_every_step() -> None:
    radius = 20.0
    strip = arc_strip(radius, np.pi)
    detection = LaneSensor().detect(strip, 5.0)
    assert detection is not None
    left, right = detection.to_world()
    # Inner (left) border on radius 18 m, outer on 22 m, up to the polyline chord sag.
    np.testing.assert_allclose(np.hypot(*left.T), radius - 2.0, atol=1e-4)
    np.testing.assert_allclose(np.hypot(*right.T), radius + 2.0, atol=1e-4)
    for border, r in ((left, radius - 2.0), (right, radius + 2.0)):
        spacing = np.hypot(*np.diff(border, axis=0).T)
        assert spacing.max() <= 0.1 + 1e-6
        assert np.all(spacing[:-1] > 0.1 - 1e-4)
        # the border spans the same 30 m of centreline: angle 30 / R, arc r * 30 / R
        assert np.sum(spacing) == pytest.approx(r * 30.0 / radius, rel=1e-4)
    # the sensor sits at the lane centre: lateral offsets of the first points are ±2 m
    assert detection.left[0] == pytest.approx((0.0, 2.0), abs=1e-4)
    assert detection.right[0] == pytest.approx((0.0, -2.0), abs=1e-4)


def test_detection_is_cut_at_the_strip_end_and_none_past_it() -> None:
    strip = straight_strip(40.0)
    detection = LaneSensor().detect(strip, 25.0)
    assert detection is not None and detection.end_station == pytest.approx(40.0)
    assert detection.left[-1, 0] == pytest.approx(15.0)
    assert LaneSensor().detect(strip, 39.95) is None


def test_from_borders_rejects_bad_input() -> None:
    good = np.zeros((3, 2))
    with pytest.raises(ValueError, match="equal N"):
        LaneStrip.from_borders(good, np.zeros((4, 2)))
    with pytest.raises(ValueError, match="NaN"):
        LaneStrip.from_borders(np.full((3, 2), np.nan), good)
    with pytest.raises(ValueError, match="two distinct"):
        LaneStrip.from_borders(good, good)


@settings(max_examples=50, deadline=None)
@given(
    x=st.floats(-1e6, 1e6),
    y=st.floats(-1e6, 1e6),
    yaw=st.floats(-np.pi, np.pi),
    points=st.lists(st.tuples(st.floats(-100, 100), st.floats(-100, 100)), min_size=1, max_size=20),
)
def test_vehicle_world_round_trip(x: float, y: float, yaw: float, points: list[tuple[float, float]]) -> None:
    local = np.array(points, dtype=np.float64)
    back = world_to_vehicle(vehicle_to_world(local, x, y, yaw), x, y, yaw)
    np.testing.assert_allclose(back, local, atol=1e-6)


@settings(max_examples=50, deadline=None)
@given(
    seed=st.integers(0, 2**16),
    count=st.integers(2, 60),
    stations=st.lists(st.floats(-10.0, 200.0), min_size=1, max_size=20),
)
def test_strip_pose_is_the_interpolated_centreline_bit_for_bit(seed: int, count: int, stations: list[float]) -> None:
    """``LaneStrip.pose`` (one station in scalars) gives exactly the centre point of
    ``interpolate`` (vectorised) at any station, clamped to the strip, vertices included."""
    rng = np.random.default_rng(seed)
    centre = np.cumsum(rng.uniform(0.05, 5.0, (count, 1)) * np.column_stack((np.ones(count), rng.normal(0.0, 0.3, count))),
                       axis=0)
    half = np.column_stack((np.zeros(count), np.full(count, 1.75)))
    strip = LaneStrip.from_borders(centre + half, centre - half)
    for station in [*stations, *strip.station.tolist(), strip.length, 0.0]:
        x, y, _ = strip.pose(station)
        expected = strip.interpolate(np.array([station]))[0][0]
        assert (x, y) == (float(expected[0]), float(expected[1]))
