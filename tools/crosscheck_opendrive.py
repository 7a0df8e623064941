"""Cross-check our sampled lane borders against commonroad-scenario-designer's OpenDRIVE code.

For every lane of the selected types, our inner and outer border points (``sample_road``,
every --step m plus both ends of every ``<geometry>`` record, as ``cold-maps export``
writes them) are compared with crdesigner's own parser and lane-border evaluation
(``OpenDriveConverter.lane_section_to_parametric_lanes`` → ``ParametricLane`` borders),
sampled on the same s grid into a polyline. Printed per map: p50 / p99 / max of the
distance from each of our points to the other implementation's polyline of the same
lane border, the worst point, and lanes present on one side only. Maps with what
crdesigner rejects although valid (non-integer ids, constant-curvature spirals) are
rewritten first (``converters.crdesigner_bridge.crdesigner_copy``). crdesigner is evaluated
at our s values (plus the ends of its width pieces), so where both agree the distances
are round-off, and a purely along-track disagreement is absorbed by the polyline. Where
we sample a record's end and the next record's start at one s, crdesigner is evaluated
``RECORD_END_OFFSET_M`` before that s as well, so a jump between records is compared
point for point, not against a chord.

Usage: crosscheck_opendrive.py MAP.xodr [MAP.xodr ...] [--step 0.1] [--all-lanes]
"""

from __future__ import annotations

import argparse
import logging
import sys
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Final, Iterable, Sequence

import numpy as np

PROJECT_ROOT: Final[Path] = Path(__file__).resolve().parents[1]
if str(PROJECT_ROOT) not in sys.path:
    sys.path.insert(0, str(PROJECT_ROOT))

from cold_maps.opendrive.cubic_poly import NDArrayFloat  # noqa: E402
from cold_maps.opendrive.errors import OpenDriveError  # noqa: E402
from cold_maps.opendrive.parser import load_opendrive  # noqa: E402
from cold_maps.opendrive.sampling import sample_road, sample_s  # noqa: E402
from converters.crdesigner_bridge import crdesigner_copy  # noqa: E402

RECORD_END_OFFSET_M: Final[float] = 1e-7
"""crdesigner evaluates a record's end this far (m) before the next record's start."""

LaneKey = tuple[str, int, int]
"""(road id, lane-section index, lane id)."""


class CrdesignerError(RuntimeError):
    """crdesigner cannot read a map that our parser accepts (message names the file)."""


@dataclass(frozen=True)
class CrosscheckResult:
    """Distances (m) from our border points to the other implementation's border polylines.

    Fields:
        path: the map.
        distances: (P,) one distance per compared border point (inner and outer).
        worst: (road id, section, lane id, s in m) of the largest distance.
        lanes_compared: lanes found by both implementations.
        missing_in_theirs: lanes we sample that crdesigner does not produce.
        missing_in_ours: lanes crdesigner produces that we do not sample.
    """

    path: str
    distances: NDArrayFloat
    worst: tuple[str, int, int, float]
    lanes_compared: int
    missing_in_theirs: tuple[LaneKey, ...]
    missing_in_ours: tuple[LaneKey, ...]

    def summary(self) -> str:
        """One line: counts and p50 / p99 / max in mm."""
        p50, p99 = np.percentile(self.distances, [50, 99]) * 1e3 if self.distances.size else (np.nan, np.nan)
        worst = self.distances.max() * 1e3 if self.distances.size else np.nan
        road, section, lane, s = self.worst
        return (
            f"{Path(self.path).name}: lanes compared={self.lanes_compared} points={self.distances.size} "
            f"p50={p50:.4f}mm p99={p99:.4f}mm max={worst:.4f}mm "
            f"(worst road {road} section {section} lane {lane} s={s:.2f}) "
            f"missing in crdesigner={len(self.missing_in_theirs)} {list(self.missing_in_theirs)[:5]} "
            f"missing in ours={len(self.missing_in_ours)} {list(self.missing_in_ours)[:5]}"
        )


def _their_borders(
    path: Path, step: float, lane_types: Sequence[str] | None, grids: dict[LaneKey, NDArrayFloat]
) -> dict[LaneKey, tuple[NDArrayFloat, NDArrayFloat]]:
    """crdesigner's (inner, outer) border polylines (N, 2) per lane, in increasing s.

    Each lane is evaluated at our s grid for it (``grids``; every ``step`` m of its section
    for lanes we do not have) plus the ends of each of crdesigner's width pieces.
    """
    from crdesigner.map_conversion.opendrive.odr2cr.opendrive_conversion.converter import OpenDriveConverter
    from crdesigner.map_conversion.opendrive.odr2cr.opendrive_parser.parser import parse_opendrive

    logging.getLogger("crdesigner").setLevel(logging.ERROR)
    renumbered = crdesigner_copy(path.read_bytes())
    original = {} if renumbered is None else renumbered[1]
    with warnings.catch_warnings(), tempfile.TemporaryDirectory(prefix="crosscheck-") as folder:
        warnings.simplefilter("ignore")
        source = path
        if renumbered is not None:  # ids crdesigner cannot read as integers, constant spirals
            source = Path(folder) / path.name
            source.write_bytes(renumbered[0])
        try:
            opendrive = parse_opendrive(source)
        except Exception as exc:  # crdesigner raises anything
            raise CrdesignerError(f"{path}: crdesigner cannot parse the map: {type(exc).__name__}: {exc}") from exc
    borders: dict[LaneKey, tuple[NDArrayFloat, NDArrayFloat]] = {}
    for road in opendrive.roads:
        reference = OpenDriveConverter.create_reference_border(road.plan_view, road.lanes.lane_offsets)
        for section in road.lanes.lane_sections:
            groups = OpenDriveConverter.lane_section_to_parametric_lanes(
                section, reference, [], [], [], road.driving_direction
            )
            for group in groups:
                if lane_types is not None and group.type not in lane_types:
                    continue
                road_id, section_index, lane_id, _ = group.id_.split(".")
                key = (original.get(road_id, road_id), int(section_index), int(lane_id))
                grid = grids.get(key)
                if grid is None:
                    grid = sample_s(section.sPos, section.sPos + section.length, step)
                inner: list = []
                outer: list = []
                planes = sorted(group.parametric_lanes, key=lambda plane: plane.border_group.outer_border_offset)
                for plane in planes:
                    if plane.length <= 0.0:
                        continue
                    local = grid - section.sPos - plane.border_group.outer_border_offset
                    local = np.unique(np.concatenate(([0.0], local[(local > 0) & (local < plane.length)], [plane.length])))
                    for s in local:
                        last = bool(np.isclose(s, plane.length))
                        pieces = plane.border_group
                        inner.append(pieces.calc_border_position("inner", s, 0.0, last, compute_curvature=False)[0])
                        outer.append(pieces.calc_border_position("outer", s, 0.0, last, compute_curvature=False)[0])
                borders[key] = (np.asarray(inner, dtype=float).reshape(-1, 2), np.asarray(outer, dtype=float).reshape(-1, 2))
    return borders


def _record_end_grid(s: NDArrayFloat) -> NDArrayFloat:
    """Our s grid with the first of each doubled s (a record's end) moved just before it."""
    grid = s.copy()
    grid[np.flatnonzero(np.diff(grid) == 0.0)] -= RECORD_END_OFFSET_M
    return grid


def point_to_polyline(points: NDArrayFloat, polyline: NDArrayFloat) -> NDArrayFloat:
    """Distance (m) from each point (P, 2) to the polyline (N, 2): nearest vertex, then its two segments.

    Repeated vertices (crdesigner samples both ends of consecutive width records) are
    dropped first, so the two segments next to the nearest vertex are never degenerate.
    """
    from scipy.spatial import cKDTree

    keep = np.concatenate(([True], np.hypot(*np.diff(polyline, axis=0).T) > 1e-9))
    polyline = polyline[keep]
    if polyline.shape[0] == 1:
        return np.hypot(*(points - polyline[0]).T)
    _, nearest = cKDTree(polyline).query(points)
    best = np.full(points.shape[0], np.inf)
    for first in (nearest - 1, nearest):
        first = np.clip(first, 0, polyline.shape[0] - 2)
        a, b = polyline[first], polyline[first + 1]
        ab = b - a
        length2 = np.einsum("ij,ij->i", ab, ab)
        u = np.clip(np.einsum("ij,ij->i", points - a, ab) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
        foot = a + u[:, None] * ab
        best = np.minimum(best, np.hypot(*(points - foot).T))
    return best


def crosscheck(path: Path, step: float = 0.1, lane_types: Sequence[str] | None = ("driving",)) -> CrosscheckResult:
    """Compare every selected lane's sampled borders with crdesigner's."""
    odr_map = load_opendrive(path)
    ours = {
        (b.road_id, b.section, b.lane_id): b
        for road in odr_map.roads.values()
        for b in sample_road(road, step=step, lane_types=lane_types, record_ends=True)
    }
    theirs = _their_borders(path, step, lane_types, {key: _record_end_grid(b.s) for key, b in ours.items()})
    distances: list[NDArrayFloat] = []
    worst = ("", 0, 0, float("nan"))
    worst_value = -1.0
    for key in sorted(ours.keys() & theirs.keys()):
        samples = ours[key]
        for mine, other in ((samples.inner, theirs[key][0]), (samples.outer, theirs[key][1])):
            d = point_to_polyline(mine[:, :2], other)
            distances.append(d)
            if d.max() > worst_value:
                worst_value = float(d.max())
                worst = (*key, float(samples.s[int(np.argmax(d))]))
    return CrosscheckResult(
        path=str(path),
        distances=np.concatenate(distances) if distances else np.empty(0),
        worst=worst,
        lanes_compared=len(ours.keys() & theirs.keys()),
        missing_in_theirs=tuple(sorted(ours.keys() - theirs.keys())),
        missing_in_ours=tuple(sorted(theirs.keys() - ours.keys())),
    )


def main(argv: Iterable[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("maps", nargs="+", type=Path, help="OpenDRIVE files")
    parser.add_argument("--step", type=float, default=0.1, help="sampling step along s (m)")
    parser.add_argument("--all-lanes", action="store_true", help="compare every lane type, not only driving")
    args = parser.parse_args(list(argv) if argv is not None else None)
    if not (args.step > 0.0):
        print(f"crosscheck_opendrive: --step must be > 0, got {args.step}", file=sys.stderr)
        return 2
    for path in args.maps:
        try:
            result = crosscheck(path, args.step, None if args.all_lanes else ("driving",))
        except (OSError, OpenDriveError, CrdesignerError) as error:
            print(f"crosscheck_opendrive: {error}", file=sys.stderr)
            return 1
        print(result.summary())
    return 0


if __name__ == "__main__":
    sys.exit(main())
