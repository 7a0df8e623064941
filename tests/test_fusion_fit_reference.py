"""fusion.geometry.fit_ends against a plain numpy.linalg.lstsq implementation of the same rule.

The reference fits every window separately by least squares on a Vandermonde matrix (no
power sums, no normal equations), takes the covariances from (VᵀV)⁻¹ of the same matrix and
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


def lstsq_fit(x: np.ndarray, y: np.ndarray, degree: int) -> tuple[np.ndarray, np.ndarray]:
    """Coefficients (increasing powers) of the least-squares polynomial and diag((VᵀV)⁻¹)."""
    vander = np.vander(x, degree + 1, increasing=True)
    coef = np.linalg.lstsq(vander, y, rcond=None)[0]
    return coef, np.diag(np.linalg.inv(vander.T @ vander))


def reference_fits(borders: list[np.ndarray], at_end: list[bool]) -> list[EndFit]:
    """The documented rule of :func:`fusion.geometry.fit_ends`, one window at a time."""
    ordered = [b[::-1] if end else b for b, end in zip(borders, at_end)]
    counts = []
    for b in ordered:
        step = np.linalg.norm(b[-1] - b[0]) / (b.shape[0] - 1)
        counts.append([min(b.shape[0] - 1, round(w / step)) + 1 for w in WINDOWS_M])
    n_noise = min(max(c[-1] for c in counts), min(b.shape[0] for b in borders), round(NOISE_WINDOW_M / 0.1))
    d2 = np.concatenate([np.diff(b[:n_noise], 2, axis=0).ravel() for b in ordered])
    sigma = max(0.002, math.sqrt(float(d2 @ d2) / (12.0 * len(borders) * (n_noise - 2))))
    fits = []
    for b, c in zip(ordered, counts):
        chord = b[max(1, c[0] - 1)] - b[0]
        chord /= np.linalg.norm(chord)
        if at_end[len(fits)]:
            chord = -chord
        normal = np.array((-chord[1], chord[0]))
        x, y = (b - b[0]) @ chord, (b - b[0]) @ normal
        lo, hi, chosen = -math.inf, math.inf, None
        for k in c:
            coef, var = lstsq_fit(x[:k], y[:k], 2)
            half = 2.5 * sigma * math.sqrt(var[1])
            lo, hi = max(lo, coef[1] - half), min(hi, coef[1] + half)
            if lo > hi:
                break
            chosen = coef, var
        assert chosen is not None
        (a, slope, quad), var = chosen
        scale = 2.0 / math.hypot(1.0, slope) ** 3
        curvature, curvature_sigma = scale * quad, scale * sigma * math.sqrt(var[2])
        cubic, cubic_var = lstsq_fit(x[:c[-1]], y[:c[-1]], 3)
        x_far = x[c[-1] - 1]
        if abs(cubic[3] - curvature ** 3 * x_far / 6.0) > (3.0 * sigma * math.sqrt(cubic_var[3])
                                                          + 0.05 * abs(curvature) ** 3 * abs(x_far)):
            curvature_sigma = math.inf
        tangent = (chord + slope * normal) / math.hypot(1.0, slope)
        fits.append(EndFit(b[0] + a * normal, (float(tangent[0]), float(tangent[1])), curvature, curvature_sigma))
    return fits


def border(rng: np.random.Generator, kappa: float, rate: float, noise_m: float, n: int) -> np.ndarray:
    """A clothoid piece (curvature ``kappa`` + ``rate``·s) sampled every 0.1 m, with noise."""
    s = np.arange(n) * 0.1
    heading = rng.uniform(-math.pi, math.pi) + kappa * s + 0.5 * rate * s * s
    points = np.cumsum(0.1 * np.column_stack((np.cos(heading), np.sin(heading))), axis=0) + rng.uniform(-80, 80, 2)
    return points + rng.normal(0.0, noise_m, points.shape)


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), kappa=st.floats(-1 / 15.0, 1 / 15.0), rate=st.sampled_from([0.0, 1e-3, -4e-3]),
       noise_m=st.sampled_from([0.0, 0.01, 0.05]), n=st.integers(40, 300))
def test_fit_ends_matches_lstsq_reference(seed: int, kappa: float, rate: float, noise_m: float, n: int) -> None:
    rng = np.random.default_rng(seed)
    borders = [border(rng, kappa, rate, noise_m, n) for _ in range(4)]
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
    """The reference itself: a noise-free arc's curvature within the 2 % bias of a quadratic over 6 m,
    a clothoid flagged as no arc."""
    rng = np.random.default_rng(3)
    arc = reference_fits([border(rng, 1 / 20.0, 0.0, 0.0, 300)], [True])[0]
    assert math.isclose(arc.curvature, 1 / 20.0, rel_tol=0.025) and math.isfinite(arc.curvature_sigma)
    clothoid = reference_fits([border(rng, 0.0, 1 / 100.0, 0.0, 300)], [False])[0]
    assert math.isinf(clothoid.curvature_sigma)
