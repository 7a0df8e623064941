"""fusion.geometry.fit_ends against a plain numpy.linalg.lstsq implementation of the same rule.

The reference fits every window of every border separately by least squares on a
Vandermonde matrix of the point index (no precomputed filters, no batching), takes the noise
gains from (VᵀV)⁻¹ of the same matrix, the arc bias from least-squares fits of t³ and t⁴, and
walks the windows in a loop: the fast path must give the same fits to 1e-9 relative.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from fusion.geometry import EndFit, fit_ends

WINDOWS_M = (2.0, 3.0, 4.5, 6.0)
NOISE_WINDOW_M = 5.0
REL = 1e-9


def lstsq_fit(t: np.ndarray, values: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients (increasing powers) of the least-squares polynomial and diag((VᵀV)⁻¹)."""
    vander = np.vander(t, degree + 1, increasing=True)
    coef = np.linalg.lstsq(vander, values, rcond=None)[0]
    return coef, np.diag(np.linalg.inv(vander.T @ vander))


def corrected(z: np.ndarray, t: np.ndarray) -> tuple[complex, complex, float]:
    """(p0, p1, κ) of the quadratic fit of complex points ``z`` at ``t`` with an arc's cubic and
    quartic terms (−κ²v³/6 along, −κ³v⁴/24 across the tangent) removed."""
    (p0, p1, p2), _ = lstsq_fit(t, z, 2)
    speed = abs(p1)
    tangent = p1 / speed
    kappa = (np.conj(p1) * p2).imag * 2.0 / speed ** 3
    bias = (lstsq_fit(t, t ** 3, 2)[0] * (-kappa ** 2 * speed ** 3 / 6.0) * tangent
            + lstsq_fit(t, t ** 4, 2)[0] * (-kappa ** 3 * speed ** 4 / 24.0) * 1j * tangent)
    p0, p1, p2 = np.array((p0, p1, p2)) - bias
    return p0, p1, (np.conj(p1) * p2).imag * 2.0 / abs(p1) ** 3


def reference_fits(borders: list[np.ndarray], at_end: list[bool]) -> list[EndFit]:
    """The documented rule of :func:`fusion.geometry.fit_ends`, one window at a time."""
    ordered = [(b[::-1] if end else b) @ np.array((1.0, 1j)) for b, end in zip(borders, at_end)]
    counts = []
    for z in ordered:
        span = min(z.shape[0] - 1, 20)
        step = abs(z[span] - z[0]) / span
        counts.append([min(z.shape[0] - 1, round(w / step)) + 1 for w in WINDOWS_M])
    n_noise = min(min(b.shape[0] for b in borders), round(NOISE_WINDOW_M / 0.1))
    d2 = np.concatenate([np.diff(z[:min(n_noise, c[-1])], 2) for z, c in zip(ordered, counts)])
    sigma = max(0.002, math.sqrt(float(np.vdot(d2, d2).real) / (12.0 * d2.shape[0])))
    fits = []
    for z, c, end in zip(ordered, counts, at_end):
        lo, hi, chosen = -math.inf, math.inf, None
        for k in c:
            if k < 4:
                break
            t = np.arange(k, dtype=float)
            (_, p1, _), var = lstsq_fit(t, z[:k], 2)
            heading = np.angle(p1 / np.exp(1j * np.angle(lstsq_fit(np.arange(c[0], dtype=float), z[:c[0]], 2)[0][1])))
            half = 2.5 * sigma * math.sqrt(var[1]) / abs(p1)
            lo, hi = max(lo, heading - half), min(hi, heading + half)
            if lo > hi:
                break
            chosen = k
        assert chosen is not None
        t = np.arange(chosen, dtype=float)
        p0, p1, kappa = corrected(z[:chosen], t)
        speed = abs(p1)
        kappa_sigma = 2.0 * sigma * math.sqrt(lstsq_fit(t, z[:chosen], 2)[1][2]) / speed ** 2
        t_long = np.arange(c[-1], dtype=float)
        (_, _, _, p3), var3 = lstsq_fit(t_long, z[:c[-1]], 3)
        arc_p3 = lstsq_fit(t_long, t_long ** 4, 3)[0][3] * (-kappa ** 3 * speed ** 4 / 24.0)
        normal_p3 = (p3 * np.conj(1j * p1 / speed)).real
        if abs(normal_p3 - arc_p3) > 3.0 * sigma * math.sqrt(var3[3]) + 0.05 * abs(arc_p3):
            kappa_sigma = math.inf
        direction = (-p1 if end else p1) / speed
        fits.append(EndFit(np.array((p0.real, p0.imag)), (direction.real, direction.imag), -kappa if end else kappa,
                           kappa_sigma))
    return fits


def border(rng: np.random.Generator, kappa: float, rate: float, noise_m: float, n: int, step: float = 0.1) -> np.ndarray:
    """A clothoid piece (curvature ``kappa`` + ``rate``·s) sampled every ``step`` [m], with noise."""
    s = np.arange(n) * step
    heading = rng.uniform(-math.pi, math.pi) + kappa * s + 0.5 * rate * s * s
    points = np.cumsum(step * np.column_stack((np.cos(heading), np.sin(heading))), axis=0) + rng.uniform(-80, 80, 2)
    return points + rng.normal(0.0, noise_m, points.shape)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), kappa=st.floats(-1 / 15.0, 1 / 15.0), rate=st.sampled_from([0.0, 1e-3, -4e-3]),
       noise_m=st.sampled_from([0.0, 0.01, 0.05]), n=st.integers(40, 300),
       steps=st.lists(st.sampled_from([0.1, 0.12, 0.25]), min_size=4, max_size=4))
def test_fit_ends_matches_lstsq_reference(seed: int, kappa: float, rate: float, noise_m: float, n: int,
                                          steps: list[float]) -> None:
    """Four borders of mixed lengths and spacings (several window sets in one call)."""
    rng = np.random.default_rng(seed)
    borders = [border(rng, kappa, rate, noise_m, n + 13 * i, step) for i, step in enumerate(steps)]
    at_end = [True, True, False, False]
    fast, ref = fit_ends(borders, at_end, WINDOWS_M, NOISE_WINDOW_M), reference_fits(borders, at_end)
    for got, want in zip(fast, ref):
        assert np.allclose(got.point, want.point, rtol=REL, atol=REL)
        assert np.allclose(got.direction, want.direction, rtol=REL, atol=REL)
        assert math.isclose(got.curvature, want.curvature, rel_tol=REL, abs_tol=REL * 1e-3)
        assert math.isinf(got.curvature_sigma) == math.isinf(want.curvature_sigma)
        if math.isfinite(want.curvature_sigma):
            assert math.isclose(got.curvature_sigma, want.curvature_sigma, rel_tol=REL)


def test_reference_sees_curvature_and_clothoid() -> None:
    """The reference itself: a noise-free arc's curvature within 0.2 % (the bias of a quadratic over
    6 m, about 3 % at this radius, is removed), a clothoid flagged as no arc."""
    rng = np.random.default_rng(3)
    arc = reference_fits([border(rng, 1 / 20.0, 0.0, 0.0, 300)], [True])[0]
    assert math.isclose(arc.curvature, 1 / 20.0, rel_tol=0.002) and math.isfinite(arc.curvature_sigma)
    clothoid = reference_fits([border(rng, 0.0, 1 / 100.0, 0.0, 300)], [False])[0]
    assert math.isinf(clothoid.curvature_sigma)
