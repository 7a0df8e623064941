"""Maps that crash crdesigner 0.8.5 and convert through the rewritten copy it is handed
(``converters.crdesigner_bridge.crdesigner_copy``): other encodings than UTF-8, crosswalks
outlined with ``<cornerRoad>`` (issue 28)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from adversarial_maps import LANE_WIDTH_M
from small_maps import straight_road

from converters.crdesigner_bridge import crdesigner_copy, odr_to_lanelets
from cold_maps.opendrive.parser import parse_opendrive

ROAD_M = 60.0
"""Length (m) of the straight two-way road the tests convert (along +x from the origin)."""


def _straight_text() -> str:
    return straight_road(ROAD_M).replace('name="straight-road"', 'name="Straße"')


def _lane_borders_y(lanelets) -> list[tuple[float, float]]:
    """(left y, right y) in m of each lanelet, sorted; every lanelet must run the whole road."""
    found = []
    for lanelet in lanelets:
        xs = np.concatenate((lanelet.left[:, 0], lanelet.right[:, 0]))
        assert xs.min() == pytest.approx(0.0, abs=1e-6) and xs.max() == pytest.approx(ROAD_M, abs=1e-6)
        left_y, right_y = np.unique(np.round(lanelet.left[:, 1], 6)), np.unique(np.round(lanelet.right[:, 1], 6))
        assert len(left_y) == len(right_y) == 1
        found.append((float(left_y[0]), float(right_y[0])))
    return sorted(found)


@pytest.mark.parametrize("encoding", ["UTF-16", "UTF-16-BE", "ISO-8859-1"])
def test_a_map_in_another_encoding_is_handed_over_as_utf8(tmp_path: Path, encoding: str) -> None:
    """crdesigner opens the file as text in the locale's encoding (UnicodeDecodeError on
    UTF-16's byte-order mark, or on Latin-1's ß)."""
    text = _straight_text().replace('encoding="UTF-8"', f'encoding="{encoding}"')
    data = text.encode(encoding)
    copy, renamed = crdesigner_copy(data)
    assert renamed == {} and copy.decode("utf-8").startswith("<?xml version='1.0' encoding='UTF-8'?>")
    assert 'name="Straße"' in copy.decode("utf-8")
    assert parse_opendrive(copy).roads == parse_opendrive(data).roads
    path = tmp_path / "encoded.xodr"
    path.write_bytes(data)
    lanelets, _ = odr_to_lanelets(path)
    w = LANE_WIDTH_M
    # lane -1 along +x (left border y 0), lane 1 along -x (left border y 0, right y 3.5)
    assert _lane_borders_y(lanelets) == [(0.0, -w), (0.0, w)]


def test_a_utf8_map_is_not_rewritten() -> None:
    assert crdesigner_copy(_straight_text().encode("utf-8")) is None


def _with_crosswalk(corner: str) -> str:
    """The straight road with a 4 m × 7 m crosswalk across it at s = 30 m, outlined by four
    ``corner`` elements (``cornerRoad`` in road s, t; ``cornerLocal`` in u, v)."""
    if corner == "cornerRoad":
        corners = [(28.0, -3.5), (32.0, -3.5), (32.0, 3.5), (28.0, 3.5)]
        outline = "".join(f'<cornerRoad s="{s}" t="{t}" dz="0" height="0"/>' for s, t in corners)
    else:
        corners = [(-2.0, -3.5), (2.0, -3.5), (2.0, 3.5), (-2.0, 3.5)]
        outline = "".join(f'<cornerLocal u="{u}" v="{v}" z="0" height="0"/>' for u, v in corners)
    crosswalk = (f'<objects><object type="crosswalk" id="7" s="30" t="0" zOffset="0" hdg="0" roll="0" pitch="0" '
                 f'orientation="none" length="4" width="7"><outlines><outline id="0">{outline}</outline></outlines>'
                 "</object></objects>")
    return _straight_text().replace("</lanes>", "</lanes>" + crosswalk, 1)


@pytest.mark.parametrize(("corner", "crosswalks"), [("cornerRoad", 0), ("cornerLocal", 1)])
def test_crosswalks_outlined_with_corner_road_are_dropped(tmp_path: Path, corner: str, crosswalks: int) -> None:
    """crdesigner reads only ``<cornerLocal>`` (shapely NotImplementedError on a
    ``<cornerRoad>`` outline); the crosswalk it can read stays."""
    path = tmp_path / "crosswalk.xodr"
    path.write_text(_with_crosswalk(corner))
    lanelets, _ = odr_to_lanelets(path)
    lanes = [lanelet for lanelet in lanelets if "crosswalk" not in lanelet.types]
    assert len(lanelets) - len(lanes) == crosswalks
    assert _lane_borders_y(lanes) == [(0.0, -LANE_WIDTH_M), (0.0, LANE_WIDTH_M)]
