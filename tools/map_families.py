"""Seeded generator of random but valid OpenDRIVE networks, by family.

Families (:data:`FAMILIES`):

- ``curves``: one two-way road of about 1.2 km, 1-4 lanes per direction, made of lines,
  clothoid-eased arcs (radius 30-600 m, never below the carriageway width + 15 m) and
  S-bends (a clothoid from one curvature straight to the opposite one); its heading stays
  within ±80° of the start, so it never crosses itself.
- ``lanes``: the same kind of road whose lane sections open a lane (width 0 → w over
  40-100 m, no predecessor) or close one (w → 0, no successor), 1-4 lanes per direction.
- ``junctions``: a 3-way junction (a through road and a side road) or a 4-way one (two
  crossing roads), crossing angle 30-150°, 1-4 lanes per direction on 180-260 m straight
  arms; a connecting road (one arc, or a line straight across) for every movement but
  U-turns carries all lanes of the incoming direction, lane k to lane k.
- ``roundabouts``: a one-way ring of 1-2 lanes (reference radius 20-40 m) with 3 or 4
  two-way arms; per arm a junction with the ring through road, an entry and an exit (each
  one arc tangent to the arm and the ring).
- ``ramps``: a motorway of 1-3 lanes per direction with an on-ramp whose lane merges into
  an auxiliary lane that closes, then an auxiliary lane that opens into an off-ramp.

Every lane is 2.75-3.75 m wide (per lane, in 0.05 m steps; connecting roads change width
smoothly from the lane they leave to the lane they enter). Road marks: solid on the
carriageway edges, broken between lanes of the same direction, a centre line (solid, or
broken on some single-lane roads); none inside junctions. Odd seeds are left-hand traffic
(``rule="LHT"``): the right-hand map mirrored across the x axis (lane ids, curvatures and
headings negated). The map of (family, seed) is the same bytes on every run and machine
(``random.Random`` seeded with text, values rounded, the writer of ``tools/make_maps.py``).
Frames: OpenDRIVE inertial (x east, y north, heading counter-clockwise from x), SI units.

Usage: ``python tools/map_families.py --out DIR [--family NAME ...] [--seeds 0-9]``.
"""

from __future__ import annotations

import argparse
import math
import random
import sys
from dataclasses import replace
from pathlib import Path
from typing import Callable, Final, Mapping, Sequence

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from make_maps import (  # noqa: E402
    LaneSpec,
    MapSpec,
    Pose,
    RoadSpec,
    SectionSpec,
    Segment,
    arc,
    chain_end,
    constant,
    end_pose,
    line,
    normalize_angle,
    reverse,
    smooth_step,
    spiral,
    to_xodr,
)

from cold_maps.opendrive.model import Connection, CubicPoly, Junction, LaneLink, RoadLink  # noqa: E402

FAMILIES: Final[tuple[str, ...]] = ("curves", "lanes", "junctions", "roundabouts", "ramps")
WIDTH_RANGE_M: Final[tuple[float, float]] = (2.75, 3.75)
WIDTH_STEP_M: Final[float] = 0.05
LANES_RANGE: Final[tuple[int, int]] = (1, 4)
CROSSING_ANGLE_RANGE_DEG: Final[tuple[float, float]] = (30.0, 150.0)
MAX_HEADING_RAD: Final[float] = math.radians(80.0)
RADIUS_RANGE_M: Final[tuple[float, float]] = (30.0, 600.0)
RADIUS_MARGIN_M: Final[float] = 15.0
"""A curve's radius exceeds the width of the carriageway side on its inside by this (m)."""
SPIRAL_RANGE_M: Final[tuple[float, float]] = (15.0, 60.0)
ARC_RANGE_M: Final[tuple[float, float]] = (10.0, 120.0)
LINE_RANGE_M: Final[tuple[float, float]] = (30.0, 150.0)
LEAD_LINE_RANGE_M: Final[tuple[float, float]] = (40.0, 120.0)
ROAD_LENGTH_M: Final[float] = 1200.0
TRANSITION_RANGE_M: Final[tuple[float, float]] = (40.0, 100.0)
JUNCTION_ID: Final[str] = "100"
ARM_LENGTH_RANGE_M: Final[tuple[float, float]] = (180.0, 260.0)
TURN_MARGIN_M: Final[float] = 3.0
"""A turning connecting road's radius exceeds the width of its lanes on the inside by this (m)."""
RING_RADIUS_RANGE_M: Final[tuple[float, float]] = (20.0, 40.0)
RING_HALF_SPAN_RANGE_DEG: Final[tuple[float, float]] = (25.0, 35.0)
RING_SEGMENT_MIN_DEG: Final[float] = 10.0
RAMP_RADIUS_RANGE_M: Final[tuple[float, float]] = (120.0, 250.0)
RAMP_SPIRAL_M: Final[float] = 40.0
MOTORWAY_MAX_HEADING_RAD: Final[float] = math.radians(20.0)
VENDOR: Final[str] = "cold-maps tools/map_families.py"


# ---- random values --------------------------------------------------------------------------


def _rounded(value: float, step: float) -> float:
    return round(value / step) * step


def _width(rng: random.Random) -> float:
    """A lane width (m) in :data:`WIDTH_RANGE_M`, in :data:`WIDTH_STEP_M` steps."""
    return _rounded(rng.uniform(*WIDTH_RANGE_M), WIDTH_STEP_M)


def _widths(rng: random.Random, count: int) -> list[float]:
    return [_width(rng) for _ in range(count)]


def _length(rng: random.Random, bounds: tuple[float, float]) -> float:
    """A length (m) in ``bounds``, to 0.1 m."""
    return _rounded(rng.uniform(*bounds), 0.1)


# ---- geometry -------------------------------------------------------------------------------


def start_before(end: Pose, segments: Sequence[Segment]) -> Pose:
    """The start pose from which ``segments`` laid out in order end at ``end``."""
    backwards = []
    for seg in reversed(segments):
        if seg.kind == "line":
            backwards.append(seg)
        elif seg.kind == "arc":
            backwards.append(arc(seg.length, -seg.curv_start))
        else:
            backwards.append(spiral(seg.length, -seg.curv_end, -seg.curv_start))
    return reverse(chain_end(reverse(end), backwards))


def heading_extremes(heading: float, segments: Sequence[Segment]) -> tuple[float, float, float]:
    """(lowest, highest, final) heading (rad, unwrapped) along ``segments`` from ``heading``:
    headings peak at record ends and where a clothoid's curvature passes zero."""
    found = [heading]
    for seg in segments:
        k0, k1, length = seg.curv_start, seg.curv_end, seg.length
        if seg.kind == "spiral" and k0 * k1 < 0.0:
            at_zero = length * k0 / (k0 - k1)
            found.append(heading + 0.5 * k0 * at_zero)
        heading += 0.5 * (k0 + k1) * length
        found.append(heading)
    return min(found), max(found), heading


def _clothoid_curve(rng: random.Random, sign: float, min_radius: float) -> list[Segment]:
    radius = _rounded(math.exp(rng.uniform(math.log(max(min_radius, RADIUS_RANGE_M[0])),
                                           math.log(RADIUS_RANGE_M[1]))), 0.1)
    k = sign / radius
    return [spiral(_length(rng, SPIRAL_RANGE_M), 0.0, k), arc(_length(rng, ARC_RANGE_M), k),
            spiral(_length(rng, SPIRAL_RANGE_M), k, 0.0)]


def _s_bend(rng: random.Random, sign: float, min_radius: float) -> list[Segment]:
    first, second = _clothoid_curve(rng, sign, min_radius), _clothoid_curve(rng, -sign, min_radius)
    k1, k2 = first[1].curv_start, second[1].curv_start
    return [first[0], first[1], spiral(_length(rng, (2 * SPIRAL_RANGE_M[0], 2 * SPIRAL_RANGE_M[1])), k1, k2),
            second[1], second[2]]


def wander(rng: random.Random, length_m: float, *, min_radius: float,
           max_heading: float = MAX_HEADING_RAD) -> list[Segment]:
    """Lines, clothoid-eased curves and S-bends of at least ``length_m`` in total whose
    heading stays within ±``max_heading`` of the start (a candidate that leaves the band
    is drawn again, a line after ten tries)."""
    segments: list[Segment] = [line(_length(rng, LEAD_LINE_RANGE_M))]
    heading = 0.0
    while math.fsum(seg.length for seg in segments) < length_m:
        piece: list[Segment] = [line(_length(rng, LINE_RANGE_M))]
        for _ in range(10):
            maker = rng.choice((_clothoid_curve, _clothoid_curve, _s_bend))
            candidate = maker(rng, rng.choice((-1.0, 1.0)), min_radius)
            low, high, _ = heading_extremes(heading, candidate)
            if -max_heading <= low and high <= max_heading:
                piece = [*candidate, line(_length(rng, LINE_RANGE_M))]
                break
        segments += piece
        heading = heading_extremes(heading, piece)[2]
    return segments


def _turn(start: Pose, end: Pose) -> Segment:
    """The one arc (or line) from ``start`` to ``end``; ValueError when none joins them."""
    delta = normalize_angle(end.hdg - start.hdg)
    chord = math.hypot(end.x - start.x, end.y - start.y)
    if abs(delta) < 1e-12:
        seg = line(chord)
    else:
        half = 0.5 * delta
        seg = arc(chord * half / math.sin(half), 2.0 * math.sin(half) / chord)
    reached = end_pose(start, seg)
    if math.hypot(reached.x - end.x, reached.y - end.y) > 1e-6:
        raise ValueError(f"no single arc joins {start} and {end}")
    return seg


# ---- lanes ----------------------------------------------------------------------------------


def _ramp(length: float, value_from: float, value_to: float) -> tuple[CubicPoly, ...]:
    """One C¹ cubic from ``value_from`` to ``value_to`` over ``length`` m (a constant when equal)."""
    delta = value_to - value_from
    if delta == 0.0:
        return constant(value_from)
    return (CubicPoly(0.0, value_from, 0.0, 3.0 * delta / length**2, -2.0 * delta / length**3),)


def _mark(index: int, count: int, in_junction: bool) -> str:
    if in_junction:
        return "none"
    return "solid" if index == count else "broken"


def carriageway(left: Sequence[float], right: Sequence[float], *, link_back: bool = True, link_ahead: bool = True,
                opening: int = 0, closing: int = 0, transition_m: float = 0.0,
                in_junction: bool = False) -> tuple[LaneSpec, ...]:
    """Lanes of widths ``left`` (ids 1, 2, ...) and ``right`` (ids -1, -2, ...), each linked
    to the same id behind and ahead when asked; lane ``opening`` opens from zero width over
    ``transition_m`` (no predecessor), lane ``closing`` closes to zero over the whole
    section of ``transition_m`` (no successor). Marks: solid outer edge, broken between
    lanes; none in a junction."""
    lanes = []
    for widths, sign in ((left, 1), (right, -1)):
        for index, width in enumerate(widths, start=1):
            lane_id = sign * index
            if lane_id == opening:
                profile = smooth_step(0.0, transition_m, 0.0, width)
            elif lane_id == closing:
                profile = _ramp(transition_m, width, 0.0)
            else:
                profile = constant(width)
            lanes.append(LaneSpec(lane_id, profile, _mark(index, len(widths), in_junction),
                                  predecessor=lane_id if link_back and lane_id != opening else None,
                                  successor=lane_id if link_ahead and lane_id != closing else None))
    return tuple(lanes)


def _centre_mark(rng: random.Random, left: int, right: int) -> str:
    return "broken" if left == right == 1 and rng.random() < 0.5 else "solid"


def _connecting_lanes(widths_from: Sequence[float], widths_to: Sequence[float], length: float,
                      links_from: Sequence[int], links_to: Sequence[int]) -> tuple[LaneSpec, ...]:
    """Right lanes -1, -2, ... of a connecting road of ``length`` m, each changing width
    from ``widths_from`` to ``widths_to`` and linked to ``links_from`` / ``links_to``; no marks."""
    return tuple(LaneSpec(-index, _ramp(length, w_from, w_to), "none", predecessor=pred, successor=succ)
                 for index, (w_from, w_to, pred, succ)
                 in enumerate(zip(widths_from, widths_to, links_from, links_to), start=1))


# ---- families -------------------------------------------------------------------------------


def _lane_events(rng: random.Random, length: float, left: list[float], right: list[float]) -> tuple[SectionSpec, ...]:
    """Sections of 150-300 m along a road of ``length`` m, each after the first opening or
    closing the outermost lane of one side, 1-4 lanes per side."""
    sections: list[SectionSpec] = []
    s, opening = 0.0, 0
    while True:
        last = s + 450.0 > length
        lanes = carriageway(left, right, link_back=bool(sections), link_ahead=not last, opening=opening,
                            transition_m=_length(rng, TRANSITION_RANGE_M) if opening else 0.0)
        sections.append(SectionSpec(s, _centre_mark(rng, len(left), len(right)), lanes))
        if last:
            return tuple(sections)
        s = _rounded(s + rng.uniform(150.0, 300.0), 0.1)
        side, sign = rng.choice(((left, 1), (right, -1)))
        opening = 0
        if len(side) < LANES_RANGE[1] and (len(side) == LANES_RANGE[0] or rng.random() < 0.5):
            side.append(_width(rng))
            opening = sign * len(side)
        else:
            closing_m = _length(rng, TRANSITION_RANGE_M)
            lanes = carriageway(left, right, closing=sign * len(side), transition_m=closing_m)
            sections.append(SectionSpec(s, _centre_mark(rng, len(left), len(right)), lanes))
            side.pop()
            s = _rounded(s + closing_m, 0.1)


def _road_min_radius(left: Sequence[float], right: Sequence[float], most_lanes: int = 0) -> float:
    widest = max(sum(left), sum(right), most_lanes * WIDTH_RANGE_M[1])
    return widest + RADIUS_MARGIN_M


def build_curves(rng: random.Random, name: str) -> MapSpec:
    """One two-way road: constant lanes, curves, clothoids and S-bends."""
    left, right = _widths(rng, rng.randint(*LANES_RANGE)), _widths(rng, rng.randint(*LANES_RANGE))
    segments = wander(rng, ROAD_LENGTH_M, min_radius=_road_min_radius(left, right))
    lanes = carriageway(left, right, link_back=False, link_ahead=False)
    road = RoadSpec("1", name, Pose(0.0, 0.0, 0.0), tuple(segments),
                    (SectionSpec(0.0, _centre_mark(rng, len(left), len(right)), lanes),), "rural", 80.0)
    return MapSpec(name, (road,))


def build_lanes(rng: random.Random, name: str) -> MapSpec:
    """One two-way road whose lane sections open and close lanes."""
    left, right = _widths(rng, rng.randint(*LANES_RANGE)), _widths(rng, rng.randint(*LANES_RANGE))
    segments = wander(rng, ROAD_LENGTH_M, min_radius=_road_min_radius(left, right, LANES_RANGE[1]))
    length = math.fsum(seg.length for seg in segments)
    road = RoadSpec("1", name, Pose(0.0, 0.0, 0.0), tuple(segments), _lane_events(rng, length, left, right),
                    "rural", 80.0)
    return MapSpec(name, (road,))


def _unit(angle: float) -> tuple[float, float]:
    return math.cos(angle), math.sin(angle)


def _junction_radius(angles: Sequence[float], side_m: float) -> float:
    """Distance (m) from the junction centre to where the arms start: adjacent arms'
    carriageways do not overlap there and every right turn's radius exceeds the width of
    its inner lanes by :data:`TURN_MARGIN_M`."""
    ordered = sorted(a % (2 * math.pi) for a in angles)
    gaps = [(b - a) % (2 * math.pi) for a, b in zip(ordered, ordered[1:] + ordered[:1])]
    radius = max(15.0, side_m / math.sin(0.5 * min(gaps)) + 2.0)
    for a in angles:
        for b in angles:
            delta = normalize_angle(b - a - math.pi)
            if a != b and delta < -1e-9:  # a right turn: its right lanes are inside
                chord_per_radius = abs(_unit(b)[0] - _unit(a)[0] + 1j * (_unit(b)[1] - _unit(a)[1]))
                turn_radius_per_radius = chord_per_radius / (2.0 * math.sin(0.5 * abs(delta)))
                radius = max(radius, (side_m + TURN_MARGIN_M) / turn_radius_per_radius)
    return math.ceil(radius * 10.0) / 10.0


def build_junctions(rng: random.Random, name: str) -> MapSpec:
    """A 3-way or 4-way junction of straight arms crossing at 30-150°."""
    count = rng.randint(*LANES_RANGE)
    crossing = math.radians(_rounded(rng.uniform(*CROSSING_ANGLE_RANGE_DEG), 0.1))
    base = math.radians(_rounded(rng.uniform(0.0, 360.0), 0.1))
    offsets = [0.0, math.pi, crossing] + ([crossing + math.pi] if rng.random() < 0.5 else [])
    angles = sorted(normalize_angle(base + offset) for offset in offsets)
    widths = [(_widths(rng, count), _widths(rng, count)) for _ in angles]  # (left = in, right = out) per arm
    radius = _junction_radius(angles, count * WIDTH_RANGE_M[1])
    link = RoadLink("junction", JUNCTION_ID)
    arms = tuple(
        RoadSpec(str(i + 1), f"arm_{i + 1}", Pose(radius * _unit(a)[0], radius * _unit(a)[1], a),
                 (line(_length(rng, ARM_LENGTH_RANGE_M)),),
                 (SectionSpec(0.0, _centre_mark(rng, count, count),
                              carriageway(left, right, link_back=False, link_ahead=False)),),
                 "town", 50.0, predecessor=link)
        for i, (a, (left, right)) in enumerate(zip(angles, widths)))
    connecting: list[RoadSpec] = []
    connections: list[Connection] = []
    ids = list(range(1, count + 1))
    for i, arm_in in enumerate(arms):
        for j, arm_out in enumerate(arms):
            if i == j:
                continue
            seg = _turn(reverse(arm_in.start), arm_out.start)
            road_id = str(int(JUNCTION_ID) + 1 + len(connecting))
            lanes = _connecting_lanes(widths[i][0], widths[j][1], seg.length, ids, [-k for k in ids])
            connecting.append(RoadSpec(road_id, f"{arm_in.name}_to_{arm_out.name}", reverse(arm_in.start), (seg,),
                                       (SectionSpec(0.0, "none", lanes),), "town", 30.0,
                                       predecessor=RoadLink("road", arm_in.id, "start"),
                                       successor=RoadLink("road", arm_out.id, "start"), junction=JUNCTION_ID))
            connections.append(Connection(str(len(connections)), arm_in.id, road_id, "start",
                                          tuple(LaneLink(k, -k) for k in ids)))
    return MapSpec(name, arms + tuple(connecting), (Junction(JUNCTION_ID, "junction", tuple(connections)),))


def _arm_angles(rng: random.Random, arms: int, min_gap: float) -> list[float]:
    """``arms`` angles (rad) about evenly spread with jitter, adjacent ones at least ``min_gap`` apart."""
    step = 2.0 * math.pi / arms
    jitter = 0.5 * (step - min_gap)
    base = rng.uniform(0.0, 2.0 * math.pi)
    return [normalize_angle(_rounded(base + i * step + rng.uniform(-0.5, 0.5) * jitter, 1e-3)) for i in range(arms)]


def build_roundabouts(rng: random.Random, name: str) -> MapSpec:
    """A one-way ring (counter-clockwise in right-hand traffic) with 3 or 4 two-way arms,
    one junction per arm: ring through road, entry and exit arcs."""
    count = rng.randint(1, 2)
    ring_radius = _length(rng, RING_RADIUS_RANGE_M)
    half_span = math.radians(_rounded(rng.uniform(*RING_HALF_SPAN_RANGE_DEG), 0.1))
    arm_count = rng.randint(3, 4)
    angles = sorted(_arm_angles(rng, arm_count, 2.0 * half_span + math.radians(RING_SEGMENT_MIN_DEG + 10.0)))
    ring = _widths(rng, count)
    # the entry arc ends tangent to the ring at half_span past the arm and starts on the arm's axis
    turn_radius = ring_radius * math.sin(half_span) / (1.0 - math.sin(half_span))
    arm_start = (ring_radius + turn_radius) * math.cos(half_span)
    ids = list(range(1, count + 1))

    def on_ring(angle: float) -> Pose:
        return Pose(ring_radius * math.cos(angle), ring_radius * math.sin(angle), angle + 0.5 * math.pi)

    roads: list[RoadSpec] = []
    junctions: list[Junction] = []
    arms = []
    for i, phi in enumerate(angles):
        left, right = _widths(rng, count), _widths(rng, count)
        arms.append((left, right))
        roads.append(RoadSpec(str(i + 1), f"arm_{i + 1}", Pose(arm_start * math.cos(phi), arm_start * math.sin(phi), phi),
                              (line(_length(rng, ARM_LENGTH_RANGE_M)),),
                              (SectionSpec(0.0, _centre_mark(rng, count, count),
                                           carriageway(left, right, link_back=False, link_ahead=False)),),
                              "town", 50.0, predecessor=RoadLink("junction", str(500 + i))))
    for i, phi in enumerate(angles):
        following = angles[(i + 1) % arm_count] + (2.0 * math.pi if i + 1 == arm_count else 0.0)
        span = following - phi - 2.0 * half_span
        roads.append(RoadSpec(str(11 + i), f"ring_{i + 1}", on_ring(phi + half_span),
                              (arc(ring_radius * span, 1.0 / ring_radius),),
                              (SectionSpec(0.0, "solid", carriageway((), ring, link_back=False, link_ahead=False)),), "town", 30.0,
                              predecessor=RoadLink("junction", str(500 + i)),
                              successor=RoadLink("junction", str(500 + (i + 1) % arm_count))))
    for i, phi in enumerate(angles):
        arm, (left, right) = roads[i], arms[i]
        before, after = str(11 + (i - 1) % arm_count), str(11 + i)
        junction_id = str(500 + i)
        through_seg = arc(ring_radius * 2.0 * half_span, 1.0 / ring_radius)
        entry_seg = _turn(reverse(arm.start), on_ring(phi + half_span))
        exit_seg = _turn(on_ring(phi - half_span), arm.start)
        specs = (
            (str(200 + i), "through", on_ring(phi - half_span), through_seg, ring, ring, [-k for k in ids],
             [-k for k in ids],
             RoadLink("road", before, "end"), RoadLink("road", after, "start"), before),
            (str(300 + i), "exit", on_ring(phi - half_span), exit_seg, ring, right, [-k for k in ids],
             [-k for k in ids], RoadLink("road", before, "end"), RoadLink("road", arm.id, "start"), before),
            (str(400 + i), "entry", reverse(arm.start), entry_seg, left, ring, ids, [-k for k in ids],
             RoadLink("road", arm.id, "start"), RoadLink("road", after, "start"), arm.id),
        )
        connections = []
        for road_id, kind, start, seg, w_from, w_to, links_from, links_to, pred, succ, incoming in specs:
            lanes = _connecting_lanes(w_from, w_to, seg.length, links_from, links_to)
            roads.append(RoadSpec(road_id, f"{kind}_{i + 1}", start, (seg,), (SectionSpec(0.0, "none", lanes),),
                                  "town", 30.0, predecessor=pred, successor=succ, junction=junction_id))
            connections.append(Connection(str(len(connections)), incoming, road_id, "start",
                                          tuple(LaneLink(a, -k) for a, k in zip(links_from, ids))))
        junctions.append(Junction(junction_id, f"roundabout_arm_{i + 1}", tuple(connections)))
    return MapSpec(name, tuple(roads), tuple(junctions))


def build_ramps(rng: random.Random, name: str) -> MapSpec:
    """A motorway with an on-ramp merging into an auxiliary lane that closes, then an
    auxiliary lane that opens into an off-ramp; ramps on the right (left in LHT)."""
    count = rng.randint(LANES_RANGE[0], LANES_RANGE[1] - 1)
    left, right, aux = _widths(rng, count), _widths(rng, count), _width(rng)
    ids = list(range(1, count + 1))
    offset = -math.fsum(right)  # the ramps' one lane sits beside the outermost main lane
    ramp_k = -1.0 / _length(rng, RAMP_RADIUS_RANGE_M)
    main_lanes = dict(left=left, right=right)
    junction_on, junction_off = RoadLink("junction", "100"), RoadLink("junction", "200")
    min_radius = _road_min_radius(left, [*right, aux])

    main_1 = RoadSpec("1", "main_1", Pose(0.0, 0.0, 0.0),
                      (*wander(rng, 300.0, min_radius=min_radius, max_heading=MOTORWAY_MAX_HEADING_RAD),
                       line(_length(rng, (250.0, 300.0)))),
                      (SectionSpec(0.0, "solid", carriageway(**main_lanes, link_back=False, link_ahead=False)),),
                      "motorway", 130.0, successor=junction_on)
    through_on = RoadSpec("101", "through_on", main_1.end, (line(40.0),),
                          (SectionSpec(0.0, "none", carriageway(left, right, in_junction=True)),), "motorway", 130.0,
                          predecessor=RoadLink("road", "1", "end"), successor=RoadLink("road", "2", "start"),
                          junction="100")
    merge_seg = spiral(RAMP_SPIRAL_M, ramp_k, 0.0)
    merge = RoadSpec("102", "merge", start_before(through_on.end, (merge_seg,)), (merge_seg,),
                     (SectionSpec(0.0, "none", _connecting_lanes([aux], [aux], RAMP_SPIRAL_M, [-1], [-(count + 1)])),),
                     "motorway", 80.0, predecessor=RoadLink("road", "3", "end"), successor=RoadLink("road", "2", "start"),
                     junction="100", lane_offsets=constant(offset))
    on_segments = (line(_length(rng, (150.0, 250.0))), spiral(RAMP_SPIRAL_M, 0.0, ramp_k),
                   arc(_length(rng, (40.0, 100.0)), ramp_k))
    ramp_lane = (SectionSpec(0.0, "solid", (LaneSpec(-1, constant(aux), "solid"),)),)
    on_ramp = RoadSpec("3", "on_ramp", start_before(merge.start, on_segments), on_segments, ramp_lane,
                       "motorway", 80.0, successor=junction_on, lane_offsets=constant(offset))

    keep, close_m, middle, open_m = (_length(rng, (100.0, 200.0)), _length(rng, TRANSITION_RANGE_M),
                                     _length(rng, (300.0, 500.0)), _length(rng, TRANSITION_RANGE_M))
    tail = _length(rng, (150.0, 250.0))
    main_2_length = keep + close_m + middle + open_m + tail
    main_2 = RoadSpec("2", "main_2", through_on.end, (line(main_2_length),), (
        SectionSpec(0.0, "solid", carriageway(left, [*right, aux], link_back=False)),
        SectionSpec(keep, "solid", carriageway(left, [*right, aux], closing=-(count + 1), transition_m=close_m)),
        SectionSpec(keep + close_m, "solid", carriageway(**main_lanes)),
        SectionSpec(keep + close_m + middle, "solid",
                    carriageway(left, [*right, aux], opening=-(count + 1), transition_m=open_m, link_ahead=False)),
    ), "motorway", 130.0, predecessor=junction_on, successor=junction_off)
    through_off = RoadSpec("201", "through_off", main_2.end, (line(30.0),),
                           (SectionSpec(0.0, "none", carriageway(left, right, in_junction=True)),), "motorway", 130.0,
                           predecessor=RoadLink("road", "2", "end"), successor=RoadLink("road", "4", "start"),
                           junction="200")
    diverge_seg = spiral(RAMP_SPIRAL_M, 0.0, ramp_k)
    diverge = RoadSpec("202", "diverge", main_2.end, (diverge_seg,),
                       (SectionSpec(0.0, "none", _connecting_lanes([aux], [aux], RAMP_SPIRAL_M, [-(count + 1)], [-1])),),
                       "motorway", 80.0, predecessor=RoadLink("road", "2", "end"),
                       successor=RoadLink("road", "5", "start"), junction="200", lane_offsets=constant(offset))
    off_ramp = RoadSpec("5", "off_ramp", diverge.end,
                        (arc(_length(rng, (40.0, 100.0)), ramp_k), spiral(RAMP_SPIRAL_M, ramp_k, 0.0),
                         line(_length(rng, (150.0, 250.0)))),
                        ramp_lane, "motorway", 80.0, predecessor=junction_off, lane_offsets=constant(offset))
    main_3 = RoadSpec("4", "main_3", through_off.end,
                      (line(_length(rng, (100.0, 200.0))),
                       *wander(rng, 300.0, min_radius=min_radius, max_heading=MOTORWAY_MAX_HEADING_RAD)),
                      (SectionSpec(0.0, "solid", carriageway(**main_lanes, link_back=False, link_ahead=False)),),
                      "motorway", 130.0, predecessor=junction_off)
    right_links = tuple(LaneLink(-k, -k) for k in ids)
    left_links = tuple(LaneLink(k, k) for k in ids)
    junctions = (
        Junction("100", "on_ramp", (Connection("0", "1", "101", "start", right_links),
                                    Connection("1", "3", "102", "start", (LaneLink(-1, -1),)),
                                    Connection("2", "2", "101", "end", left_links))),
        Junction("200", "off_ramp", (Connection("0", "2", "201", "start", right_links),
                                     Connection("1", "2", "202", "start", (LaneLink(-(count + 1), -1),)),
                                     Connection("2", "4", "201", "end", left_links))),
    )
    return MapSpec(name, (main_1, main_2, main_3, on_ramp, off_ramp, through_on, merge, through_off, diverge),
                   junctions)


BUILDERS: Final[Mapping[str, Callable[[random.Random, str], MapSpec]]] = {
    "curves": build_curves,
    "lanes": build_lanes,
    "junctions": build_junctions,
    "roundabouts": build_roundabouts,
    "ramps": build_ramps,
}


# ---- left-hand traffic ----------------------------------------------------------------------


def _mirror_pose(pose: Pose) -> Pose:
    return Pose(pose.x, -pose.y, -pose.hdg)


def _mirror_segment(seg: Segment) -> Segment:
    return replace(seg, curv_start=-seg.curv_start, curv_end=-seg.curv_end)


def _mirror_poly(poly: CubicPoly) -> CubicPoly:
    return CubicPoly(poly.s0, -poly.a, -poly.b, -poly.c, -poly.d)


def _flip(lane_id: int | None) -> int | None:
    return None if lane_id is None else -lane_id


def _mirror_lane(lane: LaneSpec) -> LaneSpec:
    return replace(lane, id=-lane.id, predecessor=_flip(lane.predecessor), successor=_flip(lane.successor))


def mirror(spec: MapSpec) -> MapSpec:
    """``spec`` mirrored across the x axis as left-hand traffic: every lane keeps its
    driving direction along s and moves to the other side of the reference line."""
    roads = tuple(replace(
        road, start=_mirror_pose(road.start), segments=tuple(map(_mirror_segment, road.segments)),
        sections=tuple(replace(section, lanes=tuple(map(_mirror_lane, section.lanes))) for section in road.sections),
        lane_offsets=tuple(map(_mirror_poly, road.lane_offsets)), rule="LHT") for road in spec.roads)
    junctions = tuple(replace(junction, connections=tuple(
        replace(c, lane_links=tuple(LaneLink(-link.from_lane, -link.to_lane) for link in c.lane_links))
        for c in junction.connections)) for junction in spec.junctions)
    return replace(spec, roads=roads, junctions=junctions)


# ---- entry points ---------------------------------------------------------------------------


def map_name(family: str, seed: int) -> str:
    """The file stem of (``family``, ``seed``)."""
    return f"{family}_{seed:04d}"


def build(family: str, seed: int) -> MapSpec:
    """The map of ``family`` and ``seed`` (left-hand traffic for odd seeds)."""
    if family not in BUILDERS:
        raise ValueError(f"unknown map family {family!r}; expected one of {', '.join(FAMILIES)}")
    if seed < 0:
        raise ValueError(f"map seed must be >= 0, got {seed}")
    spec = BUILDERS[family](random.Random(f"cold-maps/{family}/{seed}"), map_name(family, seed))
    spec = replace(spec, vendor=f"{VENDOR} (family {family}, seed {seed})")
    return mirror(spec) if seed % 2 else spec


def generate(family: str, seed: int) -> bytes:
    """The OpenDRIVE document of ``family`` and ``seed``."""
    return to_xodr(build(family, seed))


def seed_range(text: str) -> list[int]:
    """Seeds from ``A-B`` (inclusive), ``A,B,C`` or a mix; argparse error on anything else."""
    seeds: list[int] = []
    try:
        for part in text.split(","):
            low, _, high = part.strip().partition("-")
            seeds += list(range(int(low), int(high or low) + 1))
    except ValueError:
        raise argparse.ArgumentTypeError(f"seeds: expected 'A-B' or 'A,B,...' of integers >= 0, got {text!r}") from None
    if not seeds or min(seeds) < 0:
        raise argparse.ArgumentTypeError(f"seeds: expected 'A-B' or 'A,B,...' of integers >= 0, got {text!r}")
    return list(dict.fromkeys(seeds))


def write_maps(out: Path, families: Sequence[str], seeds: Sequence[int]) -> list[Path]:
    """Writes ``<family>_<seed>.xodr`` for every family and seed into ``out``; the paths."""
    from converters.atomic_io import atomic_output

    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for family in families:
        for seed in seeds:
            path = out / f"{map_name(family, seed)}.xodr"
            with atomic_output(path, "wb") as handle:
                handle.write(generate(family, seed))
            paths.append(path)
    return paths


def main(argv: Sequence[str] | None = None) -> int:
    """CLI entry point; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--family", action="append", choices=FAMILIES, help="family (repeatable; default: all)")
    parser.add_argument("--seeds", type=seed_range, default=seed_range("0-4"), help="seeds, e.g. 0-9 (default 0-4)")
    args = parser.parse_args(argv)
    try:
        paths = write_maps(args.out, args.family or FAMILIES, args.seeds)
    except OSError as error:
        print(f"map_families: cannot write maps to {args.out}: {error.strerror or error}", file=sys.stderr)
        return 1
    print(f"map_families: {len(paths)} maps -> {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
