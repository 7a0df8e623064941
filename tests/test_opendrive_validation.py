"""Values that cannot describe a road are refused in one line naming file, road, element
and attribute; values that can are evaluated finitely, in work bounded by the geometry."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from adversarial_maps import LANE_WIDTH_M, LaneSpec, RoadSpec, SectionSpec, document, geometry
from conftest import bundled_map, load_tool

from cold_maps.cli import evaluate as cold_eval
from cold_maps.cli import maps
from cold_maps.opendrive.errors import OpenDriveError
from cold_maps.opendrive.geometry.cubic_curve import CubicCurve, arc_length_table
from cold_maps.opendrive.model import CubicPoly
from cold_maps.opendrive.parser import parse_opendrive
from cold_maps.opendrive.reference_line import reference_pose
from cold_maps.opendrive.sampling import MAX_SAMPLES, sample_road, sample_s
from cold_maps.opendrive.validation import (
    COVERAGE_TOLERANCE_FRACTION,
    MAX_EXTENT_M,
    MAX_ROAD_LENGTH_M,
    coverage_tolerance_m,
    cubic_bound,
)

SMALL_MAP = Path(__file__).parent / "data" / "small_1_8.xodr"
NAME = "extreme.xodr"
FAR_OFFSET_M = 1e7


bench_far_road = load_tool("bench_far_road")


def variant(source: Path, old: str, new: str) -> bytes:
    """The map with the first ``old`` replaced by ``new``."""
    text = source.read_text(encoding="utf-8")
    assert old in text, old
    return text.replace(old, new, 1).encode()


def refused(data: bytes) -> OpenDriveError:
    with pytest.raises(OpenDriveError) as info:
        parse_opendrive(data, path=NAME)
    return info.value


# (map, old text, new text, element, attribute(s) named, reason fragment)
REFUSED = [
    ("curve90", '<arc curvature="-0.05"/>', '<arc curvature="-1e308"/>', "arc", "attribute 'curvature'", "1/m"),
    ("rural", 'curvEnd="0.00666666666667"', 'curvEnd="1e308"', "spiral", "attribute 'curvEnd'", "1/m"),
    ("curve90", 'length="331.415926536"', 'length="3.3e7"', "road", "attribute 'length'", "a road may be"),
    ("curve90", 'length="331.415926536"', 'length="2147483648"', "road", "attribute 'length'", "a road may be"),
    ("curve90", 'length="331.415926536"', 'length="5000"', "road", "attribute 'length'", "records end at s=331"),
    ("curve90", 'hdg="-1.57079632679" length="150"', 'hdg="-1.57079632679" length="1e308"', "geometry",
     "attribute 'length'", "ends after the road length"),
    ("straight", 'x="0" y="0" hdg="0" length="1000"', 'x="1e9" y="0" hdg="0" length="1000"', "geometry",
     "attribute 'x'", "from the origin"),
    ("straight", 'x="0" y="0" hdg="0" length="1000"', 'x="0" y="0" hdg="1e7" length="1000"', "geometry",
     "attribute 'hdg'", "rad"),
    ("curve90", 's="150" x="150" y="0"', 's="150" x="10000000" y="0"', "geometry", "attributes x, y",
     "may jump"),
    ("curve90", '<width sOffset="0" a="4" b="0" c="0" d="0"/>', '<width sOffset="0" a="4" b="0" c="0" d="1e308"/>',
     "width", "attributes a, b, c, d", "lane 1 of the section at s=0"),
    ("curve90", '<elevation s="0" a="0" b="0" c="0" d="0"/>', '<elevation s="0" a="0" b="0" c="1e308" d="0"/>',
     "elevation", "attributes a, b, c, d", "elevation"),
    ("highway", '<width sOffset="0" a="4"', '<width sOffset="-1e7" a="4"', "width", "attribute 'sOffset'",
     "requires it to be >= 0"),
    ("highway", '<laneOffset s="250" a="2" b="0" c="0" d="0"/>', '<laneOffset s="250" a="2" b="1e308" c="0" d="0"/>',
     "laneOffset", "attributes a, b, c, d", "s=250"),
]


@pytest.mark.parametrize(("name", "old", "new", "element", "attribute", "reason"), REFUSED,
                         ids=[f"{r[0]}-{r[3]}-{r[2][:24]}" for r in REFUSED])
def test_refused_naming_file_road_element_attribute(name, old, new, element, attribute, reason) -> None:
    error = refused(variant(bundled_map(name), old, new))
    message = str(error)
    assert "\n" not in message
    assert message.startswith(f"{NAME}:")
    assert error.element == element
    assert "road '1'" in message or "road '" in message
    assert attribute in message and reason in message


@pytest.mark.parametrize(("old", "new", "element"), [
    ('cV="0.02" dV="0.003"', 'cV="0.02" dV="1e308"', "paramPoly3"),
    ('<poly3 a="0" b="0.1" c="0.001" d="-0.0001"/>', '<poly3 a="0" b="0.1" c="1e308" d="-0.0001"/>', "poly3"),
])
def test_cubic_geometry_coefficients_bounded(old: str, new: str, element: str) -> None:
    error = refused(variant(SMALL_MAP, old, new))
    assert error.element == element and "road '1'" in str(error) and "more than 1e+08 m" in str(error)


CURVE90_ARC_M = 31.4159265359
"""Length (m) of curve90's arc record (curvature 0.05 1/m), between two 150 m lines."""


def test_border_length_bound() -> None:
    """curve90: two 150 m lines around a 31.4 m arc of curvature 0.05 1/m. A border W m
    from the reference line draws at most 300 + (1 + 0.05 W) · 31.4 m (each record by its
    own length): 99 990 m at W = 63 000 (accepted), 100 775 m at W = 63 500 (refused)."""
    width = '<width sOffset="0" a="4" b="0" c="0" d="0"/>'

    def bound_m(reach: float) -> float:
        return 300.0 + (1.0 + 0.05 * reach) * CURVE90_ARC_M

    assert bound_m(63000.0) < MAX_ROAD_LENGTH_M < bound_m(63500.0)
    parse_opendrive(variant(bundled_map("curve90"), width, width.replace('a="4"', 'a="63000"')), path=NAME)
    error = refused(variant(bundled_map("curve90"), width, width.replace('a="4"', 'a="63500"')))
    assert error.element == "lane" and "up to 63500 m" in str(error)
    assert f"{bound_m(63500.0):.6g} m long" in str(error)


def test_a_tiny_sharp_last_record_is_bounded_by_its_own_length() -> None:
    """A 300 m straight road ending in a 65 µm spiral of curvature -247 1/m (a public map):
    with borders 3.5 m out each record draws at most (1 + 3.5 · k) times its length, 300.056 m
    in all; the whole road's length times the largest curvature (259 650 m) was refused."""
    tiny_m, curvature = 65e-6, -247.0
    records = (geometry(0.0, 0.0, 0.0, 0.0, 300.0, "<line/>"),
               geometry(300.0, 300.0, 0.0, 0.0, tiny_m, f'<spiral curvStart="0" curvEnd="{curvature!r}"/>'))
    section = SectionSpec(0.0, (LaneSpec(1), LaneSpec(-1)))
    text = document([RoadSpec("1", records, 300.0 + tiny_m, (section,))])
    odr_map = parse_opendrive(text.encode(), path=NAME)
    samples = sample_road(odr_map.roads["1"], step=1.0)[0]
    border = np.sum(np.hypot(*np.diff(samples.outer[:, :2], axis=0).T))
    assert 300.0 < border <= 300.0 + (1.0 + LANE_WIDTH_M * abs(curvature)) * tiny_m
    assert (1.0 + LANE_WIDTH_M * abs(curvature)) * (300.0 + tiny_m) > MAX_ROAD_LENGTH_M


def test_cubic_bound_is_the_sum_of_magnitudes_times_powers_of_the_span() -> None:
    record = CubicPoly(0.0, 1.0, -2.0, 3.0, -4.0)
    assert cubic_bound(record, 2.0) == 1.0 + 2.0 * 2.0 + 3.0 * 4.0 + 4.0 * 8.0
    # the bound is attained where every term has the same sign: ds = -2 flips b and d only
    assert abs(1.0 - 2.0 * -2.0 + 3.0 * 4.0 - 4.0 * -8.0) == cubic_bound(record, 2.0)
    assert cubic_bound(CubicPoly(0.0, 0.0, 0.0, 0.0, 1e308), 10.0) == np.inf


def test_large_coefficient_on_a_short_record_is_accepted() -> None:
    """Bounds follow the span a record applies to: d = 1e9 over 1 mm reaches 1 m."""
    data = variant(bundled_map("curve90"), '<width sOffset="0" a="4" b="0" c="0" d="0"/>',
                   '<width sOffset="0" a="4" b="0" c="0" d="1e9"/><width sOffset="0.001" a="4" b="0" c="0" d="0"/>')
    road = parse_opendrive(data, path=NAME).roads["1"]
    lane = road.lane_sections[0].left[0]
    assert cubic_bound(lane.widths[0], 0.001) == pytest.approx(4.0 + 1e9 * 1e-9)


@pytest.mark.filterwarnings("error")
def test_record_that_never_applies_is_not_evaluated() -> None:
    """A width record starting at sOffset 1e308 never applies: the lane stays 4 m wide, and
    its cubic is not evaluated at ds = -1e308 (an overflow warning)."""
    width = '<width sOffset="0" a="4" b="0" c="0" d="0"/>'
    data = variant(bundled_map("curve90"), width, width + '<width sOffset="1e308" a="0" b="0" c="0" d="-1"/>')
    road = parse_opendrive(data, path=NAME).roads["1"]
    for samples in sample_road(road, step=1.0):
        np.testing.assert_allclose(np.hypot(*(samples.outer - samples.inner)[:, :2].T), 4.0, atol=1e-9)


def test_coverage_tolerance() -> None:
    assert coverage_tolerance_m(50.0) == 1.0
    assert coverage_tolerance_m(1000.0) == pytest.approx(COVERAGE_TOLERANCE_FRACTION * 1000.0)
    # the road may be 1 % longer than its 331.4 m of records (3.35 m of 334.7 m), not 3 % (340 m)
    parse_opendrive(variant(bundled_map("curve90"), 'length="331.415926536"', 'length="334.7"'), path=NAME)
    refused(variant(bundled_map("curve90"), 'length="331.415926536"', 'length="340"'))


def test_tiny_spiral_is_finite_and_keeps_its_start() -> None:
    """A 5e-324 m spiral (its rate overflows): the road has a 40 m gap in s that the
    record's starting arc (k0 = 0: a line along hdg 0 from (150, 0)) fills."""
    data = variant(bundled_map("rural"), 'hdg="0" length="40"', 'hdg="0" length="5e-324"')
    road = parse_opendrive(data, path=NAME).roads["1"]
    x, y, hdg = reference_pose(road, np.array([150.0, 170.0, 189.0]))
    np.testing.assert_allclose(x, [150.0, 170.0, 189.0], atol=1e-9)
    np.testing.assert_allclose(y, 0.0, atol=1e-9)
    np.testing.assert_allclose(hdg, 0.0, atol=1e-9)
    for samples in sample_road(road, step=1.0):
        assert np.all(np.isfinite(samples.inner)) and np.all(np.isfinite(samples.outer))


def test_far_off_road_is_a_translated_copy(tmp_path: Path) -> None:
    path = bench_far_road.with_far_road(bundled_map("curve90"), tmp_path / "far.xodr", FAR_OFFSET_M)
    odr_map = parse_opendrive(path.read_bytes(), path=NAME)
    near, far = sample_road(odr_map.roads["1"], step=0.5), sample_road(odr_map.roads["far"], step=0.5)
    for a, b in zip(near, far, strict=True):
        np.testing.assert_allclose(b.outer[:, 0] - a.outer[:, 0], FAR_OFFSET_M, atol=1e-6)
        np.testing.assert_allclose(b.outer[:, 1:], a.outer[:, 1:], atol=1e-6)


def test_sample_count_checked_before_allocation() -> None:
    with pytest.raises(ValueError, match="more than 10000000"):
        sample_s(0.0, MAX_ROAD_LENGTH_M, MAX_ROAD_LENGTH_M / MAX_SAMPLES)
    assert len(sample_s(0.0, MAX_ROAD_LENGTH_M, 0.1)) == 1_000_001
    road = parse_opendrive(bundled_map("straight").read_bytes(), path=NAME).roads["1"]
    with pytest.raises(ValueError, match=r"sampling \[0, 1000\] m every 1e-05 m"):
        sample_road(road, step=1e-5)


def test_arc_length_table_refuses_a_non_finite_length() -> None:
    curve = CubicCurve(u=(0.0, 1e308, 1e308, 0.0), v=(0.0, 0.0, 0.0, 0.0), p_end=1e3)
    with np.errstate(all="ignore"), pytest.raises(ValueError, match="arc length is not finite"):
        arc_length_table(curve)


def test_extent_bound_above_any_projected_coordinate() -> None:
    """UTM northings < 1e7 m, Web Mercator < 2.1e7 m: both load."""
    data = variant(bundled_map("straight"), 'x="0" y="0" hdg="0" length="1000"',
                   'x="500000" y="2.1e7" hdg="0" length="1000"')
    road = parse_opendrive(data, path=NAME).roads["1"]
    assert road.plan_view[0].y < MAX_EXTENT_M


REFUSED_MAP = ("curve90", '<arc curvature="-0.05"/>', '<arc curvature="-1e308"/>')


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("command", ["info", "export", "convert", "check", "cold-eval"])
def test_every_command_refuses_in_one_line_and_writes_nothing(command, tmp_path, capsys, monkeypatch) -> None:
    monkeypatch.setenv("COLD_MAPS_CACHE_DIR", str(tmp_path / "cache"))
    path = tmp_path / "refused.xodr"
    path.write_bytes(variant(bundled_map(REFUSED_MAP[0]), *REFUSED_MAP[1:]))
    out = tmp_path / "out"
    if command == "cold-eval":
        status = cold_eval.main(["--map", str(path), "--out", str(out), "--frames", "2"])
    else:
        argv = {"info": [], "export": ["-o", str(out)], "convert": ["-o", str(out)], "check": []}[command]
        status = maps.main([command, str(path), *argv])
    captured = capsys.readouterr()
    assert status == 1
    lines = captured.err.splitlines()
    assert len(lines) == 1 and "curvature" in lines[0] and "road '1'" in lines[0], captured.err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["refused.xodr"]


@pytest.mark.parametrize(("record", "worst"), [
    ('a="1.2" b="0" c="0" d="0"', None),  # esmini's pitch_by_super_elevation: steep, finite
    ('a="0" b="-0.05" c="0" d="0"', (30.0, 1.5)),  # the 30 m road ends rolled by -1.5 rad (past -1.4 after 28 m)
    ('a="1.5708" b="0" c="0" d="0"', (0.0, 1.5708)),  # on its side: tan(roll) ~ 1e5
])
def test_a_roll_beyond_the_bound_is_refused(record, worst) -> None:
    from cold_maps.opendrive.validation import MAX_SUPERELEVATION_RAD

    data = variant(SMALL_MAP, '<superelevation s="0" a="0" b="0" c="0" d="0"/>', f'<superelevation s="0" {record}/>')
    if worst is None:
        road = next(iter(parse_opendrive(data, path=NAME).roads.values()))
        assert all(np.isfinite(samples.inner).all() and np.isfinite(samples.outer).all()
                   for samples in sample_road(road, lane_types=None))
        return
    error = refused(data)
    s_m, roll_rad = worst
    assert error.element == "superelevation"
    assert f"roll the road by {roll_rad:.6g} rad at s={s_m:.6g} m, more than {MAX_SUPERELEVATION_RAD:g} rad" in str(error)
