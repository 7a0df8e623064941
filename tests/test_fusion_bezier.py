"""Bézier exchange format (paper sec. III-C): size, accuracy, splitting, versioned layout."""

from __future__ import annotations

import math
import struct

import numpy as np
import pytest

from fusion import BezierDecodeError, InvalidDetectionError, InvalidParameterError, bezier
from fusion.analytic import AnalyticRoad, Segment, detect
from fusion.geometry import distance_to_polyline


def cubic_border(ctrl: np.ndarray, n: int = 301) -> np.ndarray:
    t = np.linspace(0.0, 1.0, n)[:, None]
    return ((1 - t) ** 3 * ctrl[0] + 3 * (1 - t) ** 2 * t * ctrl[1] + 3 * (1 - t) * t**2 * ctrl[2] + t**3 * ctrl[3])


def test_straight_lane_costs_96_bytes_of_payload_instead_of_7200() -> None:
    x = np.arange(300) * 0.1
    left, right = np.column_stack((x, np.full(300, 2.0))), np.column_stack((x, np.full(300, -2.0)))
    stats = bezier.exchange_stats(left, right)
    assert stats.payload_bytes == 96
    assert stats.bezier_bytes == 96 + bezier.HEADER.size
    assert stats.sampled_bytes == 7200
    assert stats.segments == (1, 1)
    assert stats.max_error_m < 1e-5


def test_layout_is_the_documented_version_1() -> None:
    ctrl = np.array([[0.0, 1.0], [10.0, 3.0], [20.0, -2.0], [30.0, 0.5]])
    data = bezier.encode(cubic_border(ctrl), cubic_border(ctrl - (0.0, 4.0)))
    assert data[:2] == b"CB" and data[2] == 1 and data[3] == 0
    assert struct.unpack_from("<HH", data, 4) == (1, 1)
    values = np.frombuffer(data, "<f4", offset=8).reshape(2, 4, 3)
    np.testing.assert_allclose(values[0, :, :2], ctrl, atol=0.05)  # the fit recovers the cubic
    np.testing.assert_allclose(values[0, [0, 3], :2], ctrl[[0, 3]], atol=1e-5)  # ends exactly
    np.testing.assert_array_equal(values[:, :, 2], 0.0)
    left, right = bezier.decode(data)
    assert np.hypot(*np.diff(left, axis=0).T).max() <= 0.1 + 1e-6
    np.testing.assert_allclose(left[[0, -1]], ctrl[[0, 3]], atol=1e-5)


@pytest.mark.parametrize("tolerance", [0.05, 0.01, 0.002])
def test_curved_lane_splits_until_within_tolerance(tolerance: float) -> None:
    road = AnalyticRoad([Segment(10.0), Segment(math.pi / 2 * 20.0, -1 / 20.0), Segment(40.0)])
    det = detect(road, 5.0, 30.0, 0.0, -4.0)
    stats = bezier.exchange_stats(det.left, det.right, tolerance_m=tolerance)
    assert stats.max_error_m <= tolerance
    assert stats.bezier_bytes == bezier.HEADER.size + 48 * sum(stats.segments)
    left, right = bezier.decode(bezier.encode(det.left, det.right, tolerance_m=tolerance))
    assert distance_to_polyline(left, det.left).max() <= tolerance + 0.01


def test_tighter_tolerance_needs_more_segments() -> None:
    road = AnalyticRoad([Segment(10.0), Segment(math.pi / 2 * 20.0, -1 / 20.0), Segment(40.0)])
    det = detect(road, 5.0, 30.0, 0.0, -4.0)
    loose = bezier.exchange_stats(det.left, det.right, tolerance_m=0.05).segments
    tight = bezier.exchange_stats(det.left, det.right, tolerance_m=0.002).segments
    assert sum(tight) > sum(loose) >= 2


@pytest.mark.parametrize(
    ("mutate", "message"),
    [(lambda d: d[:5], "truncated"),
     (lambda d: b"XX" + d[2:], "magic"),
     (lambda d: d[:2] + bytes([2]) + d[3:], "version 2"),
     (lambda d: d[:-4], "header announces"),
     (lambda d: d[:4] + struct.pack("<HH", 0, 1) + d[8:], "each needs"),
     (lambda d: d[:8] + np.float32(np.nan).tobytes() + d[12:], "NaN"),
     (lambda d: "text", "must be bytes")],
)
def test_decode_rejects_malformed_messages(mutate, message: str) -> None:
    x = np.arange(300) * 0.1
    data = bezier.encode(np.column_stack((x, x * 0 + 2)), np.column_stack((x, x * 0 - 2)))
    with pytest.raises(BezierDecodeError, match=message):
        bezier.decode(mutate(data))


def test_encode_rejects_bad_borders_and_tolerance() -> None:
    good = np.column_stack((np.arange(10.0), np.zeros(10)))
    with pytest.raises(InvalidDetectionError, match="right"):
        bezier.encode(good, np.array([[0.0, np.inf], [1.0, 0.0]]))
    with pytest.raises(InvalidParameterError, match="tolerance_m"):
        bezier.encode(good, good, tolerance_m=0.0)
