"""Analytic roads with known borders, for tests, benchmarks and accuracy checks.

A road is a reference line given by a piecewise-linear curvature profile (straight lines,
circular arcs, clothoids) in the world frame; lane borders are lateral offsets of it
(positive to the left). :func:`detect` plays the paper's generic lane sensor
(:func:`detect_lanes` a multi-lane one);
:func:`distance_to_polyline` measures errors against the dense true borders.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Final, Sequence

import numpy as np

from fusion.errors import InvalidParameterError
from fusion.fusibility import relative_pose
from fusion.geometry import cumulative_length, distance_to_polyline, transform
from fusion.types import LaneDetection, LaneHistory, NDArrayFloat, NeighbourLane, Pose2D, RoadEdges

TABLE_STEP_M: Final[float] = 0.005


@dataclass(frozen=True)
class Segment:
    """Piece of a reference line: ``length_m`` [m] with curvature varying linearly from
    ``k_start`` to ``k_end`` [1/m] (equal for a line or an arc; positive turns left)."""

    length_m: float
    k_start: float = 0.0
    k_end: float | None = None


class AnalyticRoad:
    """Reference line from ``segments`` starting at ``(x0, y0)`` with heading ``yaw0`` [rad].

    Tabulated every 5 mm by exact integration of the heading (midpoint rule on a linear
    curvature, error < 1e-6 m over 200 m).
    """

    def __init__(self, segments: Sequence[Segment], x0: float = 0.0, y0: float = 0.0, yaw0: float = 0.0):
        if not segments or any(seg.length_m <= 0.0 for seg in segments):
            raise InvalidParameterError("AnalyticRoad needs segments of positive length")
        kappa, steps = [], []
        for seg in segments:
            n = max(1, round(seg.length_m / TABLE_STEP_M))
            k_end = seg.k_start if seg.k_end is None else seg.k_end
            kappa.append(seg.k_start + (k_end - seg.k_start) * (np.arange(n) + 0.5) / n)
            steps.append(np.full(n, seg.length_m / n))
        k_mid, step = np.concatenate(kappa), np.concatenate(steps)
        heading = np.concatenate(([yaw0], yaw0 + np.cumsum(k_mid * step)))
        h_mid = 0.5 * (heading[:-1] + heading[1:])
        chord = step * np.sinc(k_mid * step / (2 * math.pi))
        self.s = np.concatenate(([0.0], np.cumsum(step)))
        self.heading = heading
        self.xy = np.column_stack((
            x0 + np.concatenate(([0.0], np.cumsum(chord * np.cos(h_mid)))),
            y0 + np.concatenate(([0.0], np.cumsum(chord * np.sin(h_mid)))),
        ))
        self.length_m = float(self.s[-1])

    def border(self, offset_m: float, s_from: float = 0.0, s_to: float | None = None) -> NDArrayFloat:
        """Dense (5 mm) polyline of the curve at lateral ``offset_m`` between two ``s`` [m]."""
        s_to = self.length_m if s_to is None else s_to
        keep = (self.s >= s_from - 1e-9) & (self.s <= s_to + 1e-9)
        h = self.heading[keep]
        return self.xy[keep] + offset_m * np.column_stack((-np.sin(h), np.cos(h)))

    def pose(self, s: float, offset_m: float = 0.0) -> Pose2D:
        """World pose at reference ``s`` [m], shifted laterally by ``offset_m``."""
        x = float(np.interp(s, self.s, self.xy[:, 0]))
        y = float(np.interp(s, self.s, self.xy[:, 1]))
        yaw = float(np.interp(s, self.s, self.heading))
        return Pose2D(x - offset_m * math.sin(yaw), y + offset_m * math.cos(yaw), yaw)


def resample(polyline: NDArrayFloat, spacing_m: float) -> NDArrayFloat:
    """Points every ``spacing_m`` of arc length along ``polyline``, from its start."""
    s = cumulative_length(polyline)
    target = np.arange(0.0, s[-1] + 1e-9, spacing_m)
    return np.column_stack((np.interp(target, s, polyline[:, 0]), np.interp(target, s, polyline[:, 1])))


def detect(road: AnalyticRoad, s_from: float, length_m: float, left_m: float, right_m: float,
           spacing_m: float = 0.10, noise_m: float = 0.0, rng: np.random.Generator | None = None,
           sender: str = "") -> LaneDetection:
    """Generic lane sensor: borders at offsets ``left_m``/``right_m`` from ``s_from`` over
    ``length_m`` of reference line, each resampled every ``spacing_m`` of its own length,
    with i.i.d. Gaussian noise ``noise_m`` [m] per coordinate; the vehicle sits at ``s_from``
    in the lane centre. Borders are returned in the vehicle frame."""
    pose = road.pose(s_from, 0.5 * (left_m + right_m))
    c, s = math.cos(pose.yaw), math.sin(pose.yaw)
    rot = np.array([[c, -s], [s, c]])
    borders = []
    for offset in (left_m, right_m):
        pts = resample(road.border(offset, s_from, s_from + length_m), spacing_m)
        if noise_m > 0.0:
            pts = pts + (rng or np.random.default_rng(0)).normal(0.0, noise_m, pts.shape)
        borders.append((pts - (pose.x, pose.y)) @ rot)
    return LaneDetection(pose, borders[0], borders[1], sender=sender)


def with_history(road: AnalyticRoad, detection: LaneDetection, s_vehicle: float, history_m: float, left_m: float,
                 right_m: float, spacing_m: float = 0.10) -> LaneDetection:
    """``detection`` (of a vehicle at ``s_vehicle``) carrying the exact lane history of its
    last ``history_m`` [m] of reference line, borders at ``left_m``/``right_m``, each
    resampled every ``spacing_m`` of its own length, in the detection's vehicle frame."""
    start = max(0.0, s_vehicle - history_m)
    behind = detect(road, start, s_vehicle - start, left_m, right_m, spacing_m)
    borders = [transform(transform(b, behind.pose.x, behind.pose.y, behind.pose.yaw), 0.0, 0.0, -detection.pose.yaw)
               for b in (behind.left, behind.right)]
    shift = transform(np.array([[detection.pose.x, detection.pose.y]]), 0.0, 0.0, -detection.pose.yaw)[0]
    history = LaneHistory(*(b - shift for b in borders))
    return replace(detection, history=history)


def detect_lanes(road: AnalyticRoad, s_from: float, length_m: float, position: int, lanes: int, width_m: float,
                 count: int = 1, sender: str = "") -> LaneDetection:
    """:func:`detect` of lane ``position`` (0 = rightmost) of a road of ``lanes`` lanes ``width_m``
    wide whose reference line is its right edge, with the lanes up to ``count`` either side
    (:class:`NeighbourLane`, the sender's frame) and the road edges where they are within
    ``count`` lanes, as a multi-lane sensor reports them."""
    own = detect(road, s_from, length_m, (position + 1) * width_m, position * width_m, sender=sender)
    neighbours = []
    for k in [k for n in range(1, count + 1) for k in (n, -n) if 0 <= position + k < lanes]:
        other = detect(road, s_from, length_m, (position + k + 1) * width_m, (position + k) * width_m)
        relative = relative_pose(own.pose, other.pose)
        neighbours.append(NeighbourLane(k, transform(other.left, *relative), transform(other.right, *relative)))
    left = lanes - 1 - position if lanes - 1 - position <= count else None
    right = -position if position <= count else None
    return replace(own, neighbours=tuple(neighbours), road_edges=RoadEdges(left, right, left, right))


FAMILIES: Final[tuple[str, ...]] = ("corner", "clothoid corner", "arc", "s-bend")


def bend_segments(curvature: float, turn_rad: float, entry_m: float = 0.0) -> list[Segment]:
    """A bend turning by ``turn_rad`` [rad] on an arc of ``curvature`` [1/m] (its sign the turn
    direction), with clothoids of ``entry_m`` [m] into and out of it when > 0 (the arc keeps at
    least 0.5 m); the whole bend turns by ``turn_rad`` either way."""
    arc = max(0.5, turn_rad / abs(curvature) - entry_m)
    body = [Segment(arc, curvature)]
    return [Segment(entry_m, 0.0, curvature), *body, Segment(entry_m, curvature, 0.0)] if entry_m else body


def family_case(family: str, rng: np.random.Generator) -> tuple[AnalyticRoad, float, float]:
    """A random road of a held-out ``family`` and a gap on it: ``(road, s_end, s_coop)`` [m].

    ``corner``: straight, arc of radius 8–60 m turning 30–120°, straight; the gap holds the
    whole turn plus 2–20 m of straight on each side. ``clothoid corner``: the same with
    5–20 m clothoids into and out of the arc. ``arc``: a straight then an arc of radius
    15–300 m; both gap ends lie 3–10 m or more inside the arc (curve90-like), gap 5–20 m.
    ``s-bend``: two opposite arcs of radius 30–100 m, 10–25 m each; the gap holds the
    inflection and ends inside the arcs. Turn directions are random.
    """
    sign = rng.choice((-1.0, 1.0))
    if family in ("corner", "clothoid corner"):
        radius, turn = rng.uniform(8.0, 60.0), math.radians(rng.uniform(30.0, 120.0))
        entry = rng.uniform(5.0, 20.0) if family == "clothoid corner" else 0.0
        pre, post = rng.uniform(2.0, 20.0, 2)
        body = bend_segments(sign / radius, turn, entry)
        road = AnalyticRoad([Segment(80.0), *body, Segment(80.0)])
        return road, 80.0 - pre, 80.0 + sum(piece.length_m for piece in body) + post
    if family == "arc":
        radius = rng.uniform(15.0, 300.0)
        length = min(120.0, 1.5 * math.pi * radius)
        road = AnalyticRoad([Segment(60.0), Segment(length, sign / radius)])
        s_end = 60.0 + rng.uniform(3.0, 10.0)
        return road, s_end, s_end + rng.uniform(5.0, min(20.0, length - 45.0 - (s_end - 60.0)))
    if family == "s-bend":
        k, first, second = sign / rng.uniform(30.0, 100.0), rng.uniform(10.0, 25.0), rng.uniform(10.0, 25.0)
        road = AnalyticRoad([Segment(60.0), Segment(first, k), Segment(second, -k), Segment(60.0)])
        return road, 60.0 + rng.uniform(2.0, first), 60.0 + first + rng.uniform(2.0, second)
    raise InvalidParameterError(f"unknown road family {family!r}; expected one of {FAMILIES}")


def gap_errors(road: AnalyticRoad, s_end: float, s_coop: float, noise_m: float = 0.0,
               rng: np.random.Generator | None = None, offsets: tuple[float, float] = (0.0, -4.0),
               ) -> dict[str, float] | None:
    """Max distance [m] of the gap points of each interpolation from the true borders.

    Keys: ``paper``, ``hermite``, and ``arc`` (hermite with the largest arc for every turn,
    i.e. without the clothoid pair between straight ends). The ego detects 30 m up to
    ``s_end``, the coop 30 m from ``s_coop``, on the lane between ``offsets``; ``None`` when
    the pair is not fused as a spline by the geometric rules (``association="legacy"``: the
    interpolation is measured, not the association's confidence).
    """
    from fusion.api import fuse
    from fusion.geometry import to_world
    from fusion.spline import hermite_lane, lane_end_fits
    from fusion.types import FusionParams, Source

    ego = detect(road, s_end - 30.0, 30.0, *offsets, noise_m=noise_m, rng=rng)
    coop = detect(road, s_coop, 30.0, *offsets, noise_m=noise_m, rng=rng)
    truth = [road.border(offset) for offset in offsets]
    errors: dict[str, float] = {}
    for interpolation in ("paper", "hermite"):
        result = fuse(ego, coop, mode="spline", interpolation=interpolation,
                      params=FusionParams(association="legacy"))
        if result.kind != "spline":
            return None
        gaps = (result.left[result.left_source == Source.INTERPOLATED],
                result.right[result.right_source == Source.INTERPOLATED])
        errors[interpolation] = max(float(distance_to_polyline(g, t).max()) if g.shape[0] else 0.0
                                    for g, t in zip(gaps, truth))
    fits = lane_end_fits((to_world(ego.left, ego.pose), to_world(ego.right, ego.pose)),
                         (to_world(coop.left, coop.pose), to_world(coop.right, coop.pose)),
                         FusionParams().heading_window_m)
    arc_gaps = hermite_lane(fits, FusionParams().spacing_m, share=0.0)
    arc = max(float(distance_to_polyline(g, t).max()) if g.shape[0] else 0.0 for g, t in zip(arc_gaps, truth))
    errors["arc"] = arc
    return errors
