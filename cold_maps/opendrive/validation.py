"""Plausibility of a parsed map: values that cannot describe a road are refused.

The parser checks syntax (finite numbers, known enumerations, consistent ids); this
module checks that the numbers describe road geometry the engine can evaluate without
overflow, in work bounded by the geometry itself. Every problem raises one
``OpenDriveError`` naming the file, the road (with its source line), the element and the
attribute.

From the specification (ASAM OpenDRIVE 1.4-1.8, ``<road>`` and ``<planView>``): the
road's ``length`` is the total length of its reference line, which the ``<geometry>``
records describe one after another from s = 0, so the records lie inside [0, length] and
the last one ends at ``length``. We refuse a record that starts or ends more than
``coverage_tolerance_m(length)`` outside [0, length] and a last record that ends more
than that before ``length``: max(``COVERAGE_TOLERANCE_M``, ``COVERAGE_TOLERANCE_FRACTION``
· length), i.e. 1 m, or 1 % on roads longer than 100 m (the CARLA towns and the esmini
maps agree to 2e-13 m; the tolerance leaves room for rounding writers, and gaps between
records are reported elsewhere). Lane sections start inside the road (the parser checks
that), and the ``s``/``sOffset`` of ``<elevation>``, ``<laneOffset>``, ``<width>`` and
``<border>`` records is >= 0 (the schema's t_grEqZero; a negative one made the Lanelet2
converter loop over 1e7 m). The records of one reference line follow each other, so the end of one and the
start of the next may be apart by rounding (real maps: up to 10 cm), not by
kilometres: a jump of more than max(``MAX_JUMP_M``, the length the records draw), i.e.
10 m or the whole drawn reference line, is refused. Such a jump (a record moved 1e7 m
away) is no road, yet every border and the Lanelet2 ground truth sampled every 0.02 m
along it would span it, so the work would follow the jump rather than the geometry.

Bounds on magnitudes (none is in the specification, which allows any double): a map is a
piece of the Earth's surface, so every geometry record's start (a record draws at most
its length from there, or the bounded reach of its cubic) and every lateral offset,
width, border and elevation stays within ``MAX_EXTENT_M`` = 1e8 m of the origin,
above any projected coordinate on Earth (UTM eastings < 1e6 m, northings < 1e7 m, Web
Mercator < 2.1e7 m; the maps we know stay within 1.5 km). A road is at most
``MAX_ROAD_LENGTH_M`` = 1e5 m (the longest road of the CARLA and esmini maps is 1.5 km),
which bounds the samples of a road to 1e6 at the default 0.1 m step. Curvatures are at
most ``MAX_CURVATURE_PER_M`` = 1e3 1/m (a 1 mm radius; the maps we know stay below 0.5)
and headings at most ``MAX_HEADING_RAD`` = 1e6 rad in magnitude (the maps we know write
up to 9.5); a superelevation rolls the road by at most ``MAX_SUPERELEVATION_RAD`` = 1.4
rad (borders rise by tan(roll) · t, without bound towards π/2). A cubic record is bounded over the span it applies to by the sum of its
coefficients' magnitudes times the powers of that span, so a coefficient of 1e308 or a
width that reaches 1e9 m within its section is refused, while a large coefficient on a
record that ends a few centimetres later is not. A border that lies t m from a reference
line of curvature k is up to (1 + |t|·|k|) times as long as the reference line there, so
with the bound of |t| (laneOffset plus the widths outwards, or a border record) the sum
over the geometry records of (1 + |t|·k) times the s the record covers, k its largest
arc or spiral curvature, must stay within ``MAX_ROAD_LENGTH_M``: a 1e7 m wide lane on a
20 m radius is refused, a 65 µm spiral of curvature 247 1/m at a road's end is not; in
the CARLA, esmini and bundled maps borders reach at most 53 m and that bound is at most
1.9 km.
"""

from __future__ import annotations

from typing import Final, Sequence

import numpy as np

from cold_maps.opendrive import cubic_poly
from cold_maps.opendrive.errors import OpenDriveError
from cold_maps.opendrive.geometry import evaluate as evaluate_record
from cold_maps.opendrive.geometry import param_poly3, poly3
from cold_maps.opendrive.geometry.cubic_curve import arc_length_table
from cold_maps.opendrive.model import CubicPoly, Geometry, LaneSection, Road
from cold_maps.opendrive.reference_line import S_TOLERANCE_M

MAX_EXTENT_M: Final[float] = 1e8
"""Largest |x|, |y|, |z|, lateral offset, width or border (m) a map may describe."""
MAX_ROAD_LENGTH_M: Final[float] = 1e5
"""Longest road (m)."""
MAX_CURVATURE_PER_M: Final[float] = 1e3
"""Largest |curvature| (1/m) of an arc or spiral end."""
MAX_HEADING_RAD: Final[float] = 1e6
"""Largest |hdg| (rad) of a geometry record."""
MAX_SUPERELEVATION_RAD: Final[float] = 1.4
"""Largest |roll| (rad, 80°) of a superelevation: borders rise by tan(roll) · t, 5.8 · t
here and without bound towards π/2, where the road stands on its side (the esmini maps
reach 1.2 rad, in a unit test of extreme roll; CARLA's none)."""
SUPERELEVATION_STEP_M: Final[float] = 0.1
"""Spacing (m) of the stations where the roll is compared with its bound."""
MAX_JUMP_M: Final[float] = 10.0
"""Largest jump (m) between consecutive geometry records on a road whose records draw less."""
COVERAGE_TOLERANCE_M: Final[float] = 1.0
"""Absolute part of the tolerance (m) between the geometry records' extent and the road length."""
COVERAGE_TOLERANCE_FRACTION: Final[float] = 0.01
"""Relative part of that tolerance (fraction of the road length)."""


def drawn_length_m(record: Geometry) -> float:
    """Length (m) of the curve a record draws: its ``length``, or for a poly3/paramPoly3 the
    cubic curve's own arc length when that is longer (the engine stretches ds over it)."""
    if record.kind not in ("poly3", "paramPoly3"):
        return record.length
    curve = (poly3 if record.kind == "poly3" else param_poly3).curve_of(record)
    with np.errstate(all="ignore"):  # a non-finite arc length is refused by arc_length_table
        return max(record.length, arc_length_table(curve).total)


def coverage_tolerance_m(length: float) -> float:
    """How far (m) the geometry records may extend past [0, length] or end before length."""
    return max(COVERAGE_TOLERANCE_M, COVERAGE_TOLERANCE_FRACTION * length)


def validate_road(road: Road, path: str = "") -> None:
    """``OpenDriveError`` (naming ``path``) at the first value of the road that cannot
    describe a road; the parser calls it for every road."""
    _RoadCheck(path, road).run()


def cubic_bound(record: CubicPoly, span: float) -> float:
    """Upper bound of |a + b·ds + c·ds² + d·ds³| for ds in [0, span] (inf on overflow)."""
    return abs(record.a) + span * (abs(record.b) + span * (abs(record.c) + span * abs(record.d)))


class _RoadCheck:
    """The checks of one road; knows the file for the error messages."""

    def __init__(self, path: str, road: Road) -> None:
        self.path = path
        self.road = road

    def refuse(self, element: str, attribute: str, reason: str) -> OpenDriveError:
        """The error for ``attribute`` (or several, comma-separated) of ``element``."""
        named = f"attributes {attribute}" if "," in attribute else f"attribute '{attribute}'"
        return OpenDriveError(f"road {self.road.id!r}: {named} {reason}", path=self.path, element=element,
                              line=self.road.line or None)

    def run(self) -> None:
        road = self.road
        if road.length > MAX_ROAD_LENGTH_M:
            raise self.refuse("road", "length", f"is {road.length:.6g} m, more than the {MAX_ROAD_LENGTH_M:g} m "
                              "a road may be")
        for geometry in road.plan_view:
            self.record(geometry)
        self.coverage()
        self.jumps()
        self.profiles("elevation", road.elevation, road.length, "s")
        self.profiles("superelevation", road.superelevation, road.length, "s")
        self.roll_bound()
        reach = self.profiles("laneOffset", road.lane_offsets, road.length, "s")
        reach += max(self.section_reach(section) for section in road.lane_sections)
        self.border_length(reach)

    def section_reach(self, section: LaneSection) -> float:
        """Bound (m) of |t| of any border of the section, measured from the centre lane."""
        length = section.s_end - section.s
        reach = 0.0
        for side in (section.left, section.right):
            inner = 0.0
            for lane in side:
                owner = f"(lane {lane.id} of the section at s={section.s:.6g}) "
                width = self.profiles("width", lane.widths, length, "sOffset", owner)
                border = self.profiles("border", lane.borders, length, "sOffset", owner)
                inner = inner + width if lane.widths or not lane.borders else border
                reach = max(reach, inner)
        return reach

    def border_length(self, reach: float) -> None:
        """A border ``reach`` m from a record curving at k is up to (1 + reach·k) times as
        long as the s the record covers (to the next record's s, the first from 0); summed
        over the records, it may be no longer than the longest road."""
        road = self.road
        curvatures = [max(abs(g.curvature), abs(g.curv_start), abs(g.curv_end)) for g in road.plan_view]
        starts = [0.0] + [g.s for g in road.plan_view[1:]] + [road.length]
        spans = [max(end - start, 0.0) for start, end in zip(starts, starts[1:])]
        longest = sum((1.0 + reach * k) * span for span, k in zip(spans, curvatures))
        if longest > MAX_ROAD_LENGTH_M:
            raise self.refuse("lane", "width, border, laneOffset", f"put borders up to {reach:.6g} m from a "
                              f"reference line curving at up to {max(curvatures):.6g} 1/m: a border could be "
                              f"{longest:.6g} m long, more than the {MAX_ROAD_LENGTH_M:g} m a road may be")

    def coverage(self) -> None:
        road = self.road
        tolerance = coverage_tolerance_m(road.length)
        for geometry in road.plan_view:
            where = f"of the <geometry> at s={geometry.s:.6g}"
            if geometry.s < -tolerance or geometry.s > road.length + tolerance:
                raise self.refuse("geometry", "s", f"{where} is outside the road [0, {road.length:.6g}] m "
                                  f"(tolerance {tolerance:g} m)")
            if geometry.s + geometry.length > road.length + tolerance:
                raise self.refuse("geometry", "length", f"{where} is {geometry.length:.6g} m: the record ends "
                                  f"after the road length {road.length:.6g} m (tolerance {tolerance:g} m)")
        last = road.plan_view[-1]
        end = last.s + last.length
        if end < road.length - tolerance:
            raise self.refuse("road", "length", f"is {road.length:.6g} m but its <geometry> records end at "
                              f"s={end:.6g} m (tolerance {tolerance:g} m)")

    def jumps(self) -> None:
        """Consecutive records join within the length the records draw (after the bounds: evaluation is safe)."""
        road = self.road
        try:
            limit = max(MAX_JUMP_M, sum(drawn_length_m(record) for record in road.plan_view))
        except ValueError as exc:
            raise self.refuse("geometry", "a, b, c, d", f"of a cubic <geometry>: {exc}") from None
        for before, after in zip(road.plan_view, road.plan_view[1:]):
            end_x, end_y = self.point(before, before.length)
            start_x, start_y = self.point(after, 0.0)
            jump = float(np.hypot(end_x - start_x, end_y - start_y))
            if not jump <= limit:
                raise self.refuse("geometry", "x, y", f"of the <geometry> at s={after.s:.6g} are {jump:.6g} m from "
                                  f"the end of the record before it, more than the {limit:g} m a reference line "
                                  "may jump (the length its records draw)")

    def point(self, record: Geometry, ds: float) -> tuple[float, float]:
        """x, y (m) of ``record`` ds m from its start; refused when it cannot be evaluated
        (a paramPoly3 that draws a single point)."""
        try:
            with np.errstate(all="ignore"):  # a non-finite point is refused by the jump bound
                x, y, _ = evaluate_record(record, np.array([ds]))
        except ValueError as exc:
            raise self.refuse(record.kind, "length", f"of the <geometry> at s={record.s:.6g}: {exc}") from None
        return float(x[0]), float(y[0])

    def record(self, geometry: Geometry) -> None:
        where = f"of the <geometry> at s={geometry.s:.6g}"
        for attribute in ("x", "y"):
            value = getattr(geometry, attribute)
            if abs(value) > MAX_EXTENT_M:
                raise self.refuse("geometry", attribute, f"{where} is {value:.6g} m, farther than "
                                  f"{MAX_EXTENT_M:g} m from the origin")
        if abs(geometry.hdg) > MAX_HEADING_RAD:
            raise self.refuse("geometry", "hdg", f"{where} is {geometry.hdg:.6g} rad, more than "
                              f"{MAX_HEADING_RAD:g} rad in magnitude")
        if geometry.kind in ("arc", "spiral"):
            names = ("curvature",) if geometry.kind == "arc" else ("curvStart", "curvEnd")
            fields = ("curvature",) if geometry.kind == "arc" else ("curv_start", "curv_end")
            for name, field in zip(names, fields):
                value = getattr(geometry, field)
                if abs(value) > MAX_CURVATURE_PER_M:
                    raise self.refuse(geometry.kind, name, f"{where} is {value:.6g} 1/m, more than "
                                      f"{MAX_CURVATURE_PER_M:g} 1/m in magnitude")
        elif geometry.kind == "poly3":
            self.curve_bound("poly3", CubicPoly(0.0, geometry.a, geometry.b, geometry.c, geometry.d),
                             geometry.length, where, "a, b, c, d")
        elif geometry.kind == "paramPoly3":
            p_end = geometry.length if geometry.p_range == "arcLength" else 1.0
            u = CubicPoly(0.0, geometry.au, geometry.bu, geometry.cu, geometry.du)
            v = CubicPoly(0.0, geometry.av, geometry.bv, geometry.cv, geometry.dv)
            self.curve_bound("paramPoly3", u, p_end, where, "aU, bU, cU, dU")
            self.curve_bound("paramPoly3", v, p_end, where, "aV, bV, cV, dV")

    def roll_bound(self) -> None:
        """The superelevation stays within ``MAX_SUPERELEVATION_RAD`` (sampled every
        ``SUPERELEVATION_STEP_M`` and at each record's start)."""
        records = self.road.superelevation
        if not records:
            return
        s = np.unique(np.r_[np.arange(0.0, self.road.length, SUPERELEVATION_STEP_M), self.road.length,
                            [min(max(r.s0, 0.0), self.road.length) for r in records]])
        roll = np.abs(cubic_poly.evaluate(records, s))
        worst = int(np.argmax(roll))
        if roll[worst] > MAX_SUPERELEVATION_RAD:
            raise self.refuse("superelevation", "a, b, c, d", f"roll the road by {roll[worst]:.6g} rad at "
                              f"s={s[worst]:.6g} m, more than {MAX_SUPERELEVATION_RAD:g} rad (borders rise by "
                              "tan(roll) times their offset)")

    def curve_bound(self, element: str, record: CubicPoly, span: float, where: str, names: str) -> None:
        """A local curve coordinate (m) over the parameter range [0, span]."""
        bound = cubic_bound(record, span)
        if not bound <= MAX_EXTENT_M:
            raise self.refuse(element, names, f"{where} reach {bound:.6g} m over the record, more than "
                              f"{MAX_EXTENT_M:g} m")

    def profiles(self, element: str, records: Sequence[CubicPoly], end: float, s_name: str, owner: str = "") -> float:
        """The largest bound (m) of a cubic profile's records, each applying from its s0 to
        the next record or ``end`` (in the profile's own s: road s, or s relative to the
        section for lanes); refused beyond ``MAX_EXTENT_M``."""
        largest = 0.0
        for index, record in enumerate(records):
            if record.s0 < -S_TOLERANCE_M:
                raise self.refuse(element, s_name, f"{owner}of a <{element}> is {record.s0:.6g} m: the specification "
                                  "requires it to be >= 0")
            following = records[index + 1].s0 if index + 1 < len(records) else end
            span = max(min(following, end) - record.s0, 0.0)
            bound = cubic_bound(record, span)
            if not bound <= MAX_EXTENT_M:
                raise self.refuse(element, "a, b, c, d", f"{owner}of the <{element}> at {s_name}={record.s0:.6g} "
                                  f"reach {bound:.6g} m over its {span:.6g} m, more than {MAX_EXTENT_M:g} m")
            largest = max(largest, bound)
        return largest
