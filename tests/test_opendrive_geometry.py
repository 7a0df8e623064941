"""Closed-form and property tests of the cubic profiles, geometry records and reference line."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.integrate import quad
from scipy.special import fresnel

from cold_maps.opendrive import cubic_poly
from cold_maps.opendrive.geometry import evaluate
from cold_maps.opendrive.model import CubicPoly, Geometry, Road
from cold_maps.opendrive.reference_line import reference_pose

finite = st.floats(-1e3, 1e3, allow_nan=False)
curvatures = st.floats(-0.2, 0.2, allow_nan=False)
lengths = st.floats(0.5, 300.0, allow_nan=False)
headings = st.floats(-math.pi, math.pi, allow_nan=False)


def road_of(*records: Geometry, road_id: str = "r") -> Road:
    """A road with only a plan view (enough for the reference line)."""
    total = records[-1].s + records[-1].length
    return Road(road_id, "", total, "-1", "RHT", None, None, tuple(records), (), (), ())


def parabola_length(c: float, u: np.ndarray) -> np.ndarray:
    """Closed-form arc length of v = c·u² from u = 0 to u."""
    root = np.sqrt(1.0 + 4.0 * c * c * u * u)
    return 0.5 * u * root + np.arcsinh(2.0 * c * u) / (4.0 * c)


def length_ratio(g: Geometry) -> float:
    """A paramPoly3's polynomial arc length over its length attribute (by quadrature); 1 otherwise."""
    if g.kind != "paramPoly3":
        return 1.0
    p_end = g.length if g.p_range == "arcLength" else 1.0
    speed = lambda p: math.hypot(g.bu + 2 * g.cu * p + 3 * g.du * p * p, g.bv + 2 * g.cv * p + 3 * g.dv * p * p)  # noqa: E731
    return quad(speed, 0.0, p_end, epsabs=1e-12, epsrel=1e-13)[0] / g.length


def quadrature_pose(x0, y0, hdg0, k0, rate, ds):
    """Clothoid pose by numerical integration of the heading (independent of the Fresnel form)."""
    heading = lambda u: hdg0 + k0 * u + 0.5 * rate * u * u  # noqa: E731
    x = x0 + quad(lambda u: math.cos(heading(u)), 0.0, ds, epsabs=1e-13, epsrel=1e-13, limit=200)[0]
    y = y0 + quad(lambda u: math.sin(heading(u)), 0.0, ds, epsabs=1e-13, epsrel=1e-13, limit=200)[0]
    return x, y, heading(ds)


# ---------------------------------------------------------------- cubic profiles


def test_cubic_profile_is_piecewise_and_zero_before_first_record():
    records = (CubicPoly(2.0, 1.0, 0.5, -0.1, 0.01), CubicPoly(5.0, -3.0, 0.0, 0.0, 0.0))
    s = np.array([0.0, 1.999, 2.0, 3.0, 4.999, 5.0, 9.0])
    ds = s - 2.0
    expected = np.where(s < 2.0, 0.0, 1.0 + 0.5 * ds - 0.1 * ds**2 + 0.01 * ds**3)
    expected = np.where(s >= 5.0, -3.0, expected)
    np.testing.assert_allclose(cubic_poly.evaluate(records, s), expected, rtol=0, atol=1e-15)


def test_cubic_profile_s_offset_shifts_record_starts():
    records = (CubicPoly(1.0, 0.0, 2.0, 0.0, 0.0),)
    s = np.array([10.0, 11.0, 13.0])
    np.testing.assert_allclose(cubic_poly.evaluate(records, s, s_offset=10.0), [0.0, 0.0, 4.0])
    np.testing.assert_allclose(cubic_poly.derivative(records, s, s_offset=10.0), [0.0, 2.0, 2.0])


def test_cubic_profile_without_records_is_zero():
    np.testing.assert_array_equal(cubic_poly.evaluate((), np.array([0.0, 7.0])), [0.0, 0.0])


def test_cubic_profile_rejects_unordered_records():
    with pytest.raises(ValueError, match="not ordered"):
        cubic_poly.evaluate((CubicPoly(3.0, 0, 0, 0, 0), CubicPoly(1.0, 0, 0, 0, 0)), np.array([2.0]))


@settings(max_examples=50, deadline=None)
@given(st.lists(st.tuples(finite, finite, finite, finite), min_size=1, max_size=4), st.floats(0.05, 9.9))
def test_cubic_derivative_matches_central_difference(coeffs, s):
    records = tuple(CubicPoly(float(i) * 3.0, a, b * 1e-2, c * 1e-4, d * 1e-6) for i, (a, b, c, d) in enumerate(coeffs))
    h = 1e-6
    if any(abs(s - r.s0) < 2 * h for r in records):
        return
    numeric = (cubic_poly.evaluate(records, np.array([s + h])) - cubic_poly.evaluate(records, np.array([s - h]))) / (2 * h)
    assert cubic_poly.derivative(records, np.array([s]))[0] == pytest.approx(numeric[0], abs=1e-4)


# ---------------------------------------------------------------- line and arc


def test_line_closed_form():
    g = Geometry("line", 0.0, 3.0, -4.0, 0.6, 10.0)
    x, y, h = evaluate(g, np.array([0.0, 2.5, 10.0]))
    np.testing.assert_allclose(x, 3.0 + np.array([0.0, 2.5, 10.0]) * math.cos(0.6), atol=1e-12)
    np.testing.assert_allclose(y, -4.0 + np.array([0.0, 2.5, 10.0]) * math.sin(0.6), atol=1e-12)
    np.testing.assert_array_equal(h, 0.6)


@pytest.mark.parametrize("curvature", [0.05, -0.2, 1e-3, -1e-7])
def test_arc_points_lie_on_circle_of_radius_one_over_curvature(curvature):
    g = Geometry("arc", 0.0, 12.0, 7.0, 1.1, 120.0, curvature=curvature)
    ds = np.linspace(0.0, g.length, 97)
    x, y, h = evaluate(g, ds)
    radius = 1.0 / curvature
    cx, cy = g.x - radius * math.sin(g.hdg), g.y + radius * math.cos(g.hdg)
    np.testing.assert_allclose(np.hypot(x - cx, y - cy), abs(radius), rtol=1e-12)
    np.testing.assert_allclose(h, g.hdg + curvature * ds, atol=1e-14)
    # the arc between consecutive points is ds: chord = 2 R sin(k ds / 2)
    chords = np.hypot(np.diff(x), np.diff(y))
    step = ds[1] - ds[0]
    np.testing.assert_allclose(chords, 2.0 * abs(radius) * abs(math.sin(0.5 * curvature * step)), rtol=1e-9)


def test_arc_with_tiny_curvature_is_a_line_to_sub_micrometre():
    g = Geometry("arc", 0.0, 0.0, 0.0, 0.3, 500.0, curvature=1e-15)
    x, y, _ = evaluate(g, np.array([500.0]))
    assert math.hypot(x[0] - 500.0 * math.cos(0.3), y[0] - 500.0 * math.sin(0.3)) < 1e-9


# ---------------------------------------------------------------- spiral


def test_spiral_from_zero_curvature_matches_direct_fresnel():
    rate = 0.01 / 80.0
    g = Geometry("spiral", 0.0, 0.0, 0.0, 0.0, 80.0, curv_start=0.0, curv_end=0.01)
    ds = np.linspace(0.0, 80.0, 41)
    x, y, h = evaluate(g, ds)
    scale = math.sqrt(math.pi / rate)
    s_f, c_f = fresnel(ds / scale)
    np.testing.assert_allclose(x, scale * c_f, atol=1e-9)
    np.testing.assert_allclose(y, scale * s_f, atol=1e-9)
    np.testing.assert_allclose(h, 0.5 * rate * ds**2, atol=1e-14)


@pytest.mark.filterwarnings("ignore::scipy.integrate.IntegrationWarning")
@settings(max_examples=40, deadline=None)
@given(curvatures, curvatures, lengths, headings, st.sampled_from([0.0, 1e6]))
def test_spiral_matches_numerical_integration_of_heading(k0, k1, length, hdg, origin):
    g = Geometry("spiral", 0.0, origin, -origin, hdg, length, curv_start=k0, curv_end=k1)
    ds = np.array([0.3 * length, length])
    x, y, h = evaluate(g, ds)
    for i, d in enumerate(ds):
        qx, qy, qh = quadrature_pose(origin, -origin, hdg, k0, (k1 - k0) / length, d)
        assert math.hypot(x[i] - qx, y[i] - qy) < 1e-6
        assert h[i] == pytest.approx(qh, abs=1e-12)


@pytest.mark.parametrize(
    "k0, k1",
    [(0.02, 0.02 + 1e-13), (0.05, 0.05 + 1e-8), (0.0, 5e-324), (0.01, 0.01 + 1.3e-5), (-0.1, 0.1), (0.08, -0.03)],
)
def test_spiral_near_constant_curvature_and_sign_change(k0, k1):
    g = Geometry("spiral", 0.0, 5.0, 5.0, 0.2, 150.0, curv_start=k0, curv_end=k1)
    x, y, h = evaluate(g, np.array([150.0]))
    qx, qy, qh = quadrature_pose(5.0, 5.0, 0.2, k0, (k1 - k0) / 150.0, 150.0)
    assert math.hypot(x[0] - qx, y[0] - qy) < 1e-7
    assert h[0] == pytest.approx(qh, abs=1e-12)


# ---------------------------------------------------------------- poly3 and paramPoly3


@pytest.mark.parametrize("c", [0.02, -0.05])
def test_poly3_parabola_is_sampled_by_arc_length(c):
    u_end = 40.0
    length = float(parabola_length(c, np.array(u_end)))
    g = Geometry("poly3", 0.0, 0.0, 0.0, 0.0, length, c=c)
    ds = np.linspace(0.0, length, 33)
    x, y, h = evaluate(g, ds)
    np.testing.assert_allclose(y, c * x**2, atol=1e-12)
    np.testing.assert_allclose(parabola_length(c, x), ds, atol=1e-8)
    np.testing.assert_allclose(h, np.arctan(2.0 * c * x), atol=1e-12)
    assert x[-1] == pytest.approx(u_end, abs=1e-8)


def test_poly3_offset_and_rotation():
    g = Geometry("poly3", 0.0, 100.0, 50.0, math.pi / 2, 10.0, a=1.5)
    x, y, h = evaluate(g, np.array([0.0, 10.0]))
    # v = +1.5 is to the left of a north-going record: towards -x
    np.testing.assert_allclose(x, [98.5, 98.5], atol=1e-12)
    np.testing.assert_allclose(y, [50.0, 60.0], atol=1e-12)
    np.testing.assert_allclose(h, math.pi / 2, atol=1e-15)


@pytest.mark.parametrize("p_range", ["arcLength", "normalized"])
def test_param_poly3_straight_line_with_non_uniform_parameter_is_spaced_by_arc_length(p_range):
    length = 60.0
    # u(p) = L·(1.3 q - 0.3 q²) with q = p / p_end: monotone, not arc length in p
    q_end = 1.0 if p_range == "normalized" else length
    bu, cu = 1.3 * length / q_end, -0.3 * length / q_end**2
    g = Geometry("paramPoly3", 0.0, 1e6, 2e6, -0.4, length, bu=bu, cu=cu, p_range=p_range)
    ds = np.linspace(0.0, length, 25)
    x, y, h = evaluate(g, ds)
    np.testing.assert_allclose(x - 1e6, ds * math.cos(-0.4), atol=1e-7)
    np.testing.assert_allclose(y - 2e6, ds * math.sin(-0.4), atol=1e-7)
    np.testing.assert_allclose(h, -0.4, atol=1e-12)


@pytest.mark.parametrize("p_range", ["arcLength", "normalized"])
def test_param_poly3_parabola(p_range):
    c, u_end = 0.03, 25.0
    length = float(parabola_length(c, np.array(u_end)))
    if p_range == "normalized":
        g = Geometry("paramPoly3", 0.0, 0.0, 0.0, 0.0, length, bu=u_end, cv=c * u_end**2, p_range=p_range)
    else:
        # p in [0, length] with u = p·u_end/length: p is close to, but not, arc length
        k = u_end / length
        g = Geometry("paramPoly3", 0.0, 0.0, 0.0, 0.0, length, bu=k, cv=c * k * k, p_range=p_range)
    ds = np.linspace(0.0, length, 30)
    x, y, h = evaluate(g, ds)
    np.testing.assert_allclose(y, c * x**2, atol=1e-11)
    np.testing.assert_allclose(parabola_length(c, x), ds, atol=1e-7)
    np.testing.assert_allclose(h, np.arctan(2.0 * c * x), atol=1e-11)


# ---------------------------------------------------------------- properties of every kind


def geometries(x0: float = 0.0, y0: float = 0.0):
    """Strategy: a random record of every kind, starting at (x0, y0)."""
    coef = st.floats(-0.01, 0.01, allow_nan=False)
    tiny = st.floats(-1e-4, 1e-4, allow_nan=False)
    return st.one_of(
        st.builds(lambda h, l: Geometry("line", 0.0, x0, y0, h, l), headings, lengths),
        st.builds(lambda h, l, k: Geometry("arc", 0.0, x0, y0, h, l, curvature=k), headings, lengths, curvatures),
        st.builds(
            lambda h, l, a, b: Geometry("spiral", 0.0, x0, y0, h, l, curv_start=a, curv_end=b),
            headings, lengths, curvatures, curvatures,
        ),
        st.builds(
            lambda h, l, c, d: Geometry("poly3", 0.0, x0, y0, h, l, c=c, d=d * 1e-2),
            headings, lengths, coef, tiny,
        ),
        st.builds(
            lambda h, l, cv, dv, n: Geometry(
                "paramPoly3", 0.0, x0, y0, h, l,
                bu=l if n else 1.0, cv=cv * (l * l if n else 1.0), dv=dv * 1e-2 * (l**3 if n else 1.0),
                p_range="normalized" if n else "arcLength",
            ),
            headings, lengths, coef, tiny, st.booleans(),
        ),
    )


@settings(max_examples=80, deadline=None)
@given(geometries(), st.floats(0.05, 0.95))
def test_heading_is_direction_of_finite_difference_derivative(g, fraction):
    d = fraction * g.length
    h = 1e-4
    x, y, hdg = evaluate(g, np.array([d - h, d, d + h]))
    direction = math.atan2(y[2] - y[0], x[2] - x[0])
    assert math.remainder(direction - hdg[1], 2 * math.pi) == pytest.approx(0.0, abs=1e-6)
    # and ds is arc length: the chord over 2h is 2h up to curvature terms, times the
    # paramPoly3 scale (true curve length) / (length attribute)
    assert math.hypot(x[2] - x[0], y[2] - y[0]) == pytest.approx(2 * h * length_ratio(g), rel=1e-6)


@settings(max_examples=60, deadline=None)
@given(geometries(), st.floats(-3e6, 3e6), st.floats(-3e6, 3e6))
def test_far_from_origin_equals_translated_near_origin(g, dx, dy):
    far = replace(g, x=g.x + dx, y=g.y + dy)
    ds = np.linspace(0.0, g.length, 9)
    x0, y0, h0 = evaluate(g, ds)
    x1, y1, h1 = evaluate(far, ds)
    assert np.max(np.hypot(x1 - dx - x0, y1 - dy - y0)) < 1e-6
    np.testing.assert_array_equal(h0, h1)


@settings(max_examples=40, deadline=None)
@given(st.lists(geometries(), min_size=2, max_size=5))
def test_reference_line_is_continuous_across_records(chain):
    records, s = [], 0.0
    x, y, hdg = 1e5, -1e5, 0.0
    for g in chain:
        record = replace(g, s=s, x=x, y=y, hdg=hdg)
        records.append(record)
        ex, ey, eh = evaluate(record, np.array([record.length]))
        x, y, hdg, s = float(ex[0]), float(ey[0]), float(eh[0]), s + record.length
    road = road_of(*records)
    eps = 1e-7
    for record in records[1:]:
        px, py, ph = reference_pose(road, np.array([record.s - eps, record.s]))
        assert math.hypot(px[1] - px[0], py[1] - py[0]) < eps * max(length_ratio(g) for g in records) * 1.001
        assert math.remainder(ph[1] - ph[0], 2 * math.pi) == pytest.approx(0.0, abs=1e-6)


# ---------------------------------------------------------------- errors


def test_unknown_kind_and_non_positive_length_raise():
    with pytest.raises(ValueError, match="unknown kind 'clothoid'"):
        evaluate(Geometry("clothoid", 0.0, 0.0, 0.0, 0.0, 1.0), np.array([0.5]))  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="length must be > 0"):
        evaluate(Geometry("line", 0.0, 0.0, 0.0, 0.0, 0.0), np.array([0.0]))


def test_degenerate_param_poly3_raises():
    with pytest.raises(ValueError, match=r"paramPoly3 at s=3.0: .* \(zero arc length\)"):
        evaluate(Geometry("paramPoly3", 3.0, 0.0, 0.0, 0.0, 5.0, au=1.0, av=2.0), np.array([1.0]))


def test_reference_pose_rejects_s_off_the_road_and_nan():
    road = road_of(Geometry("line", 0.0, 0.0, 0.0, 0.0, 10.0), road_id="7")
    with pytest.raises(ValueError, match="road 7: s in"):
        reference_pose(road, np.array([5.0, 10.5]))
    with pytest.raises(ValueError, match="road 7: s contains NaN"):
        reference_pose(road, np.array([np.nan]))


def test_reference_pose_picks_the_record_by_s():
    road = road_of(
        Geometry("line", 0.0, 0.0, 0.0, 0.0, 10.0),
        Geometry("arc", 10.0, 10.0, 0.0, 0.0, 5 * math.pi, curvature=0.1),
    )
    x, y, h = reference_pose(road, np.array([4.0, 10.0, 10.0 + 5 * math.pi]))
    np.testing.assert_allclose(x, [4.0, 10.0, 20.0], atol=1e-12)
    np.testing.assert_allclose(y, [0.0, 0.0, 10.0], atol=1e-12)
    np.testing.assert_allclose(h, [0.0, 0.0, math.pi / 2], atol=1e-12)


def test_parameters_of_many_curves_at_once_equal_one_curve_at_a_time_bit_for_bit():
    from cold_maps.opendrive.geometry.cubic_curve import CubicCurve, arc_length_table, curve_stack, stacked_parameters

    rng = np.random.default_rng(3)
    tables = []
    for index in range(60):
        curve = CubicCurve(tuple(rng.normal(size=4) * [0, 10, 1, 0.1]), tuple(rng.normal(size=4) * [0, 1, 1, 0.1]),
                           float(rng.uniform(0.5, 3.0)) if index % 2 else 1.0)
        tables.append(arc_length_table(curve))
    which = rng.permutation(len(tables))[:45]  # some of the stack's curves, in another order
    blocks = [rng.uniform(-0.1, 1.05, size=int(rng.integers(0, 40))) * tables[i].total for i in which]
    together = stacked_parameters(curve_stack(tables), which, np.concatenate(blocks),
                                  np.array([len(block) for block in blocks]))
    assert together.tobytes() == np.concatenate([tables[i].parameter(b) for i, b in zip(which, blocks)]).tobytes()
