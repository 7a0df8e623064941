"""The routing relations ``GroundTruth`` queries (``following``, ``previous``,
``conflicting``), computed per lanelet on first use.

lanelet2's ``RoutingGraph`` computes every relation of every lanelet when it is built,
among them every pair of overlapping lanelets: on a junction whose n connections cross
one another that is n² polygon tests. ``LaneletRelations`` answers the same three
queries with the same lanelets in the same order (the rules of lanelet2's
``RoutingGraphBuilder``, 2-D: no participant height), costing only the lanelets asked
about: ``following`` and ``previous`` look up the lanelets that share the lanelet's end
or start points, ``conflicting`` tests the lanelets whose bounding boxes meet it.
lanelet2 is imported lazily.
"""

from __future__ import annotations

from typing import Any

PointPair = tuple[int, int]
"""Ids of two points, the smaller first."""


def _pair(first: Any, second: Any) -> PointPair:
    a, b = int(first.id), int(second.id)
    return (a, b) if a < b else (b, a)


def _key(lanelet: Any) -> tuple[int, bool]:
    return int(lanelet.id), bool(lanelet.inverted())


class LaneletRelations:
    """``following``, ``previous`` and ``conflicting`` of lanelet2's
    ``RoutingGraph(lanelet_map, traffic_rules)`` (2-D), each computed when first asked
    for a lanelet and kept. The map must not change after construction.

    Construction indexes the lanelets the rules let pass (a two-way one in both
    orientations, as lanelet2 does) by the point pairs of their ends and bounds; that is
    linear in the map. A lanelet the rules do not let pass has no relations."""

    def __init__(self, lanelet_map: Any, traffic_rules: Any = None) -> None:
        """``traffic_rules``: lanelet2's (default: Germany, vehicle, as ``GroundTruth``)."""
        import lanelet2

        self.lanelet_map = lanelet_map
        self.traffic_rules = traffic_rules or lanelet2.traffic_rules.create(
            lanelet2.traffic_rules.Locations.Germany, lanelet2.traffic_rules.Participants.Vehicle
        )
        rules = self.traffic_rules
        forward = [lanelet for lanelet in lanelet_map.laneletLayer if rules.canPass(lanelet)]
        self._two_way = {int(lanelet.id) for lanelet in forward if rules.canPass(lanelet.invert())}
        vertices = forward + [lanelet.invert() for lanelet in forward if int(lanelet.id) in self._two_way]
        self._position = {_key(lanelet): index for index, lanelet in enumerate(vertices)}
        self._by_points: dict[PointPair, list[Any]] = {}
        for lanelet in vertices:
            left, right = lanelet.leftBound, lanelet.rightBound
            for pair in (_pair(left[0], right[0]), _pair(left[-1], right[-1]),
                         _pair(left[0], left[-1]), _pair(right[0], right[-1])):
                self._by_points.setdefault(pair, []).append(lanelet)
        self._found: dict[tuple[tuple[int, bool], str], list[Any]] = {}

    def following(self, lanelet: Any) -> list[Any]:
        """The lanelets a vehicle may drive on to from the end of ``lanelet`` (no lane
        change), in lanelet2's order."""
        return self._cached(lanelet, "following", self._following)

    def previous(self, lanelet: Any) -> list[Any]:
        """The lanelets ``lanelet`` is ``following`` of, in lanelet2's order."""
        return self._cached(lanelet, "previous", self._previous)

    def conflicting(self, lanelet: Any) -> list[Any]:
        """The passable lanelets whose area overlaps that of ``lanelet`` (lanelet2's
        ``overlaps2d``, tested both ways as the graph's builder does: it is not symmetric
        where borders touch; neighbours and lanelets that follow each other never
        overlap)."""
        return self._cached(lanelet, "conflicting", self._conflicting)

    def _cached(self, lanelet: Any, way: str, compute: Any) -> list[Any]:
        key = (_key(lanelet), way)
        found = self._found.get(key)
        if found is None:
            found = self._found[key] = compute(lanelet) if key[0] in self._position else []
        return found

    def _following(self, lanelet: Any) -> list[Any]:
        from lanelet2.geometry import follows

        ends = _pair(lanelet.leftBound[-1], lanelet.rightBound[-1])
        return [other for other in self._by_points.get(ends, ())
                if follows(lanelet, other) and self.traffic_rules.canPass(lanelet, other)]

    def _previous(self, lanelet: Any) -> list[Any]:
        key = _key(lanelet)
        starts = _pair(lanelet.leftBound[0], lanelet.rightBound[0])
        candidates = {_key(other): other for other in self._by_points.get(starts, ())}
        found = []
        for _, other in sorted(candidates.items(), key=lambda item: self._position[item[0]]):
            found.extend(other for after in self.following(other) if _key(after) == key)
        return found

    def _conflicting(self, lanelet: Any) -> list[Any]:
        from lanelet2.geometry import boundingBox2d, overlaps2d

        ident, inverted = _key(lanelet)
        found = []
        for other in self.lanelet_map.laneletLayer.search(boundingBox2d(lanelet)):
            other_id = int(other.id)
            if (other_id, False) not in self._position:
                continue
            if other_id == ident:
                if inverted:
                    found.append(other)
                elif ident in self._two_way:
                    found.append(other.invert())
                continue
            if overlaps2d(lanelet, other) or (not inverted and overlaps2d(other, lanelet)):
                found.append(other)
            if not inverted and other_id in self._two_way and overlaps2d(other.invert(), lanelet):
                found.append(other.invert())
        return found
