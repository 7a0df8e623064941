"""Lane borders (widths, borders, laneOffset), elevation and sampling against closed forms."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import brentq
from test_opendrive_geometry import parabola_length, quadrature_pose

from cold_maps.opendrive.lanes import lane_border_offsets, section_borders
from cold_maps.opendrive.model import CubicPoly, Geometry, Lane, LaneSection, Road
from cold_maps.opendrive.sampling import (
    LaneBorderSamples,
    elevation,
    road_to_world,
    sample_lane_borders,
    sample_road,
    sample_s,
)


def const(width: float, s0: float = 0.0) -> tuple[CubicPoly, ...]:
    return (CubicPoly(s0, width, 0.0, 0.0, 0.0),)


def make_road(
    plan_view: tuple[Geometry, ...],
    sections: tuple[LaneSection, ...],
    *,
    offsets: tuple[CubicPoly, ...] = (),
    elevation_records: tuple[CubicPoly, ...] = (),
    road_id: str = "1",
) -> Road:
    length = plan_view[-1].s + plan_view[-1].length
    return Road(road_id, "", length, "-1", "RHT", None, None, plan_view, elevation_records, offsets, sections)


def section(s: float, s_end: float, left=(), right=()) -> LaneSection:
    return LaneSection(s, s_end, False, tuple(left), Lane(0, "none"), tuple(right))


# Road "1": straight along +x from (1e6, -2e6), 100 m, two sections.
#   section 0 [0, 40]: lanes 1 (3.5 m), 2 (cubic width), -1 (3.25 m), -2 (zero width), -3 (2 m)
#   section 1 [40, 100]: lane -1 with width records at sOffset 0 and 20 (relative to s=40)
CUBIC_WIDTH = CubicPoly(0.0, 3.0, 0.05, -0.002, 1e-5)
STRAIGHT = make_road(
    (Geometry("line", 0.0, 1e6, -2e6, 0.0, 100.0),),
    (
        section(
            0.0,
            40.0,
            left=(Lane(1, "driving", widths=const(3.5)), Lane(2, "sidewalk", widths=(CUBIC_WIDTH,))),
            right=(
                Lane(-1, "driving", widths=const(3.25)),
                Lane(-2, "driving", widths=const(0.0)),
                Lane(-3, "driving", widths=const(2.0)),
            ),
        ),
        section(
            40.0,
            100.0,
            right=(Lane(-1, "driving", widths=(CubicPoly(0.0, 3.0, 0.0, 0.0, 0.0), CubicPoly(20.0, 3.0, 0.01, 0.0, 0.0))),),
        ),
    ),
    offsets=(CubicPoly(0.0, 0.5, 0.0, 0.0, 0.0), CubicPoly(40.0, 0.5, -0.01, 0.0, 0.0)),
    elevation_records=(CubicPoly(0.0, 10.0, 0.02, 0.0, 1e-6),),
)


def offset_at(s):
    return np.where(s < 40.0, 0.5, 0.5 - 0.01 * (s - 40.0))


def test_constant_and_cubic_widths_with_lane_offset():
    s = np.linspace(0.0, 40.0, 17)
    off = offset_at(s)
    cubic = 3.0 + 0.05 * s - 0.002 * s**2 + 1e-5 * s**3
    expected = {
        1: (off, off + 3.5),
        2: (off + 3.5, off + 3.5 + cubic),
        -1: (off, off - 3.25),
        -2: (off - 3.25, off - 3.25),
        -3: (off - 3.25, off - 5.25),
    }
    for lane_id, (inner, outer) in expected.items():
        got_inner, got_outer = lane_border_offsets(STRAIGHT, 0, lane_id, s)
        np.testing.assert_allclose(got_inner, inner, atol=1e-12, err_msg=f"lane {lane_id}")
        np.testing.assert_allclose(got_outer, outer, atol=1e-12, err_msg=f"lane {lane_id}")


def test_width_records_are_relative_to_the_section_start():
    s = np.array([40.0, 59.9, 60.0, 80.0, 100.0])
    inner, outer = lane_border_offsets(STRAIGHT, 1, -1, s)
    width = np.where(s < 60.0, 3.0, 3.0 + 0.01 * (s - 60.0))
    np.testing.assert_allclose(inner, offset_at(s), atol=1e-12)
    np.testing.assert_allclose(outer, offset_at(s) - width, atol=1e-12)


def test_border_records_are_outer_borders_from_the_offset_centre_lane():
    border = CubicPoly(0.0, -4.0, -0.02, 0.0, 0.0)
    road = make_road(
        (Geometry("line", 0.0, 0.0, 0.0, 0.0, 50.0),),
        (
            section(
                10.0,
                50.0,
                right=(
                    Lane(-1, "driving", borders=(border,)),
                    Lane(-2, "driving", widths=const(2.5)),
                    # widths win over borders when a lane has both
                    Lane(-3, "driving", widths=const(1.0), borders=(CubicPoly(0.0, -100.0, 0, 0, 0),)),
                ),
            ),
        ),
        offsets=(CubicPoly(0.0, 0.3, 0.001, 0.0, 0.0),),
    )
    s = np.array([10.0, 25.0, 50.0])
    offset = 0.3 + 0.001 * s
    outer_1 = offset - 4.0 - 0.02 * (s - 10.0)
    borders = section_borders(road, 0, s)
    np.testing.assert_allclose(borders[-1][0], offset, atol=1e-12)
    np.testing.assert_allclose(borders[-1][1], outer_1, atol=1e-12)
    np.testing.assert_allclose(borders[-2][0], outer_1, atol=1e-12)
    np.testing.assert_allclose(borders[-2][1], outer_1 - 2.5, atol=1e-12)
    np.testing.assert_allclose(borders[-3][1], outer_1 - 3.5, atol=1e-12)


def test_elevation_profile():
    s = np.array([0.0, 10.0, 100.0])
    np.testing.assert_allclose(elevation(STRAIGHT, s), 10.0 + 0.02 * s + 1e-6 * s**3, atol=1e-12)


def test_sampled_borders_of_a_straight_road_far_from_origin():
    samples = sample_lane_borders(STRAIGHT, 0, 2, step=0.1)
    assert samples.s[0] == 0.0 and samples.s[-1] == 40.0
    assert samples.s.size == 401
    cubic = 3.0 + 0.05 * samples.s - 0.002 * samples.s**2 + 1e-5 * samples.s**3
    np.testing.assert_allclose(samples.inner[:, 0] - 1e6, samples.s, atol=1e-9)
    np.testing.assert_allclose(samples.inner[:, 1] + 2e6, 0.5 + 3.5, atol=1e-9)
    np.testing.assert_allclose(samples.outer[:, 1] + 2e6, 0.5 + 3.5 + cubic, atol=1e-9)
    np.testing.assert_allclose(samples.outer[:, 2], 10.0 + 0.02 * samples.s + 1e-6 * samples.s**3, atol=1e-12)


@pytest.mark.parametrize("curvature", [0.02, -0.05])
def test_arc_road_borders_are_concentric_circles(curvature):
    road = make_road(
        (Geometry("arc", 0.0, -3e5, 4e5, 0.7, 60.0, curvature=curvature),),
        (section(0.0, 60.0, left=(Lane(1, "driving", widths=const(3.0)),), right=(Lane(-1, "driving", widths=const(3.5)),)),),
        offsets=(CubicPoly(0.0, 0.25, 0.0, 0.0, 0.0),),
    )
    radius = 1.0 / curvature
    cx, cy = -3e5 - radius * math.sin(0.7), 4e5 + radius * math.cos(0.7)
    for samples in sample_road(road, step=0.5):
        side = 1.0 if samples.lane_id > 0 else -1.0
        for points, t in ((samples.inner, 0.25), (samples.outer, 0.25 + side * (3.0 if side > 0 else 3.5))):
            # a border at t is the circle of radius R - t (R signed by the curvature)
            np.testing.assert_allclose(np.hypot(points[:, 0] - cx, points[:, 1] - cy), abs(radius - t), atol=1e-6)


def test_sample_road_filters_types_and_samples_both_section_ends():
    driving = sample_road(STRAIGHT)
    assert [(b.section, b.lane_id) for b in driving] == [(0, 1), (0, -1), (0, -2), (0, -3), (1, -1)]
    everything = sample_road(STRAIGHT, lane_types=None)
    assert [(b.section, b.lane_id) for b in everything] == [(0, 1), (0, 2), (0, -1), (0, -2), (0, -3), (1, -1)]
    assert sample_road(STRAIGHT, lane_types=("sidewalk",))[0].lane_id == 2
    first, last = driving[0], driving[-1]
    assert (first.s[0], first.s[-1], last.s[0], last.s[-1]) == (0.0, 40.0, 40.0, 100.0)
    # sampling the whole road equals sampling each lane on its own
    for samples in driving:
        alone = sample_lane_borders(STRAIGHT, samples.section, samples.lane_id, step=0.1)
        np.testing.assert_array_equal(alone.inner, samples.inner)
        np.testing.assert_array_equal(alone.outer, samples.outer)
    zero = next(b for b in driving if b.lane_id == -2)
    np.testing.assert_array_equal(zero.inner, zero.outer)
    assert isinstance(first, LaneBorderSamples) and first.inner.shape == (first.s.size, 3)


def test_road_to_world_on_an_arc():
    road = make_road((Geometry("arc", 0.0, 0.0, 0.0, 0.0, 50.0, curvature=0.1),), (section(0.0, 50.0),))
    s = np.array([0.0, 5 * math.pi])
    x, y = road_to_world(road, s, np.array([2.0, 2.0]))
    # centre (0, 10), radius 10: t = 2 to the left is radius 8
    np.testing.assert_allclose(x, [0.0, 8.0], atol=1e-12)
    np.testing.assert_allclose(y, [2.0, 10.0], atol=1e-12)


def test_bad_lane_section_and_s_raise_naming_the_road():
    with pytest.raises(KeyError, match="road 1: lane section 0 has no lane 3"):
        lane_border_offsets(STRAIGHT, 0, 3, np.array([1.0]))
    with pytest.raises(IndexError, match="road 1: no lane section 5"):
        sample_lane_borders(STRAIGHT, 5, -1)
    with pytest.raises(ValueError, match="road 1: s in"):
        lane_border_offsets(STRAIGHT, 0, -1, np.array([101.0]))
    with pytest.raises(ValueError, match="road 1: t contains NaN"):
        road_to_world(STRAIGHT, np.array([1.0]), np.array([np.nan]))


# ---------------------------------------------------------------- sample_s


@settings(max_examples=200, deadline=None)
@given(st.floats(-1e4, 1e4), st.floats(0.0, 500.0), st.floats(0.01, 50.0))
def test_sample_s_grid_properties(start, length, step):
    end = start + length
    s = sample_s(start, end, step)
    assert s[0] == start and s[-1] == end
    gaps = np.diff(s)
    assert np.all(gaps > 0.0)
    assert np.all(gaps <= step * (1.0 + 1e-9))
    # uniform except the last interval
    np.testing.assert_allclose(gaps[:-1], step, rtol=1e-6, atol=1e-9)


def test_sample_s_examples_and_errors():
    np.testing.assert_allclose(sample_s(0.0, 0.3, 0.1), [0.0, 0.1, 0.2, 0.3], atol=1e-15)
    np.testing.assert_allclose(sample_s(2.0, 3.05, 0.5), [2.0, 2.5, 3.0, 3.05])
    np.testing.assert_array_equal(sample_s(4.0, 4.0, 0.1), [4.0])
    with pytest.raises(ValueError, match="step must be a positive"):
        sample_s(0.0, 1.0, 0.0)
    with pytest.raises(ValueError, match="before s_start"):
        sample_s(1.0, 0.0, 0.1)
    with pytest.raises(ValueError, match="finite"):
        sample_s(0.0, float("nan"), 0.1)


def test_section_end_uses_the_left_limit_of_road_level_jumps():
    # laneOffset and elevation jump at s = 30 where section 1 starts; the plan view has a
    # 1 cm gap there. Section 0's closing border keeps section 0's values.
    road = make_road(
        (Geometry("line", 0.0, 0.0, 0.0, 0.0, 30.0), Geometry("line", 30.0, 30.0, 0.01, 0.0, 20.0)),
        (
            section(0.0, 30.0, right=(Lane(-1, "driving", widths=const(3.0)),)),
            section(30.0, 50.0, right=(Lane(-1, "driving", widths=const(3.0)),)),
        ),
        offsets=(CubicPoly(0.0, 0.0, 0.0, 0.0, 0.0), CubicPoly(30.0, -2.0, 0.0, 0.0, 0.0)),
        elevation_records=(CubicPoly(0.0, 1.0, 0.0, 0.0, 0.0), CubicPoly(30.0, 5.0, 0.0, 0.0, 0.0)),
    )
    first, second = sample_road(road, step=1.0)
    np.testing.assert_allclose(first.inner[-1], [30.0, 0.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(first.outer[-1], [30.0, -3.0, 1.0], atol=1e-12)
    np.testing.assert_allclose(second.inner[0], [30.0, 0.01 - 2.0, 5.0], atol=1e-12)
    np.testing.assert_allclose(lane_border_offsets(road, 0, -1, np.array([30.0]))[1], [-3.0])
    np.testing.assert_allclose(lane_border_offsets(road, 1, -1, np.array([30.0]))[1], [-5.0])


def independent_reference(geom: Geometry, ds: float) -> tuple[float, float, float]:
    """Reference pose by a route independent of ours: quadrature (spiral) or the parabola's closed form."""
    if geom.kind == "spiral":
        rate = (geom.curv_end - geom.curv_start) / geom.length
        return quadrature_pose(geom.x, geom.y, geom.hdg, geom.curv_start, rate, ds)
    c = geom.c if geom.kind == "poly3" else geom.cv / geom.bu**2
    u = brentq(lambda x: float(parabola_length(c, np.array(x))) - ds, 0.0, ds + 1.0, xtol=1e-14)
    v = c * u * u
    cos_h, sin_h = math.cos(geom.hdg), math.sin(geom.hdg)
    return geom.x + u * cos_h - v * sin_h, geom.y + u * sin_h + v * cos_h, geom.hdg + math.atan(2 * c * u)


C_PARABOLA, U_END = 0.004, 90.0
PARABOLA_LENGTH = float(parabola_length(C_PARABOLA, np.array(U_END)))


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
@pytest.mark.parametrize(
    "geom",
    [
        Geometry("spiral", 0.0, 1.2e6, -8e5, 2.0, 140.0, curv_start=0.015, curv_end=-0.02),
        Geometry("poly3", 0.0, -9e5, 1.1e6, -0.7, PARABOLA_LENGTH, c=C_PARABOLA),
        Geometry(
            "paramPoly3", 0.0, 9e5, 9e5, 0.3, PARABOLA_LENGTH,
            bu=U_END, cv=C_PARABOLA * U_END**2, p_range="normalized",
        ),
    ],
    ids=["spiral", "poly3", "paramPoly3"],
)
def test_curved_road_borders_far_from_origin_match_independent_evaluation(geom):
    road = make_road(
        (geom,),
        (section(0.0, geom.length, left=(Lane(1, "driving", widths=const(3.5)),), right=(Lane(-1, "driving", widths=const(2.0)),)),),
        offsets=(CubicPoly(0.0, 0.3, 0.0, 0.0, 0.0),),
    )
    worst = 0.0
    for samples in sample_road(road, step=7.0):
        t_outer = 3.8 if samples.lane_id > 0 else -1.7
        for k, s in enumerate(samples.s):
            x, y, h = independent_reference(geom, float(s))
            for points, t in ((samples.inner, 0.3), (samples.outer, t_outer)):
                worst = max(worst, math.hypot(points[k, 0] - (x - t * math.sin(h)), points[k, 1] - (y + t * math.cos(h))))
    assert worst < 1e-6


def test_lanes_drawn_over_their_inner_neighbour_are_reported(caplog) -> None:
    """The adversarial border map's signed borders are fine; written as distances (the
    right lanes' a, b, c, d negated: positive, as crdesigner reads them) lane -1 lies on
    the left of lane 0 by as much as its border's peak and lane -2 on the left of -1. A
    width polynomial that dips below zero is reported the same way."""
    from adversarial_maps import border_map

    from cold_maps.opendrive.lanes import WRONG_SIDE_TOLERANCE_M, wrong_side_lanes
    from cold_maps.opendrive.parser import parse_opendrive

    signed = border_map()
    assert wrong_side_lanes(parse_opendrive(signed.encode()).roads["7"]) == []
    distances = signed.replace('a="-3.5" b="0.0" c="-0.001" d="1e-05"', 'a="3.5" b="0.0" c="0.001" d="-1e-05"')
    distances = distances.replace('a="-6.5" b="-0.02"', 'a="6.5" b="0.02"')
    with caplog.at_level("WARNING"):
        found = wrong_side_lanes(parse_opendrive(distances.encode(), path="d.xodr").roads["7"])
    assert [(lane.section, lane.lane_id, lane.from_borders) for lane in found] == [(0, -1, True), (0, -2, True)]
    peak_s = 2 * 0.001 / (3 * 1e-5)  # where the border 3.5 + 0.001 s² - 1e-5 s³ (lane 0 at t = 0) is widest
    assert found[0].width_m == pytest.approx(-(3.5 + 0.001 * peak_s**2 - 1e-5 * peak_s**3), abs=WRONG_SIDE_TOLERANCE_M)
    assert "d.xodr: road 7: 2 lane(s) have their outer border on the inner side" in caplog.text
    assert "writes right lanes' borders as distances" in caplog.text
    caplog.clear()
    narrowing = signed.replace('<border sOffset="0.0" a="-3.5" b="0.0" c="-0.001" d="1e-05"/>',
                               '<width sOffset="0.0" a="3.0" b="-0.1" c="0.0" d="0.0"/>')
    with caplog.at_level("WARNING"):
        found = wrong_side_lanes(parse_opendrive(narrowing.encode(), path="w.xodr").roads["7"])
    # width 3 - 0.1 s reaches -5 m at the road's end (80 m); lane -2's border is t, unchanged
    assert [(lane.lane_id, lane.from_borders) for lane in found] == [(-1, False)]
    assert found[0].width_m == pytest.approx(3.0 - 0.1 * 80.0)
    assert "width -5.000 m from its <width> records" in caplog.text and "as distances" not in caplog.text
