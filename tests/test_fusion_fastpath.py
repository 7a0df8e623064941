"""The vectorised gap sampling against straightforward references (dense curves, per-sample masks)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from fusion.geometry import cumulative_length, distance_to_polyline, project_point
from fusion.spline import hermite_gap, sample_pieces, transition_tangent


def bezier(p0: complex, d0: complex, p3: complex, d1: complex, arm0: float, arm1: float) -> list[complex]:
    """Power-basis coefficients of the cubic Bézier p0, p0 + arm0·d0, p3 − arm1·d1, p3."""
    c1, c2 = p0 + arm0 * d0, p3 - arm1 * d1
    return [p0, 3.0 * (c1 - p0), 3.0 * (c2 - 2.0 * c1 + p0), p3 - 3.0 * c2 + 3.0 * c1 - p0]


def dense(chain: list[list[complex]], n: int = 20_000) -> np.ndarray:
    """The chain evaluated at n + 1 parameters per piece, as an (M, 2) polyline."""
    tau = np.linspace(0.0, 1.0, n + 1)
    z = np.concatenate([np.polynomial.polynomial.polyval(tau, piece) for piece in chain])
    return np.column_stack((z.real, z.imag))


def random_chain(rng: np.random.Generator, n_pieces: int) -> list[list[complex]]:
    """Bézier pieces joined end to start, each turning at most ~60° over 5–25 m, with unequal arms
    (a speed that is not symmetric along the piece)."""
    chain, p, heading = [], complex(*rng.uniform(-50.0, 50.0, 2)), rng.uniform(-math.pi, math.pi)
    for _ in range(n_pieces):
        length, turn = rng.uniform(5.0, 25.0), rng.uniform(-1.0, 1.0)
        d0, d1 = np.exp(1j * heading), np.exp(1j * (heading + turn))
        end = p + length * np.exp(1j * (heading + 0.5 * turn))
        chain.append(bezier(p, d0, end, d1, *(length * rng.uniform(0.2, 0.5, 2))))
        p, heading = end, heading + turn
    return chain


@pytest.mark.parametrize("seed", range(6))
def test_chains_are_sampled_on_the_curve_at_equal_arc_length(seed: int) -> None:
    rng = np.random.default_rng(seed)
    chains = [random_chain(rng, k) for k in (1, 3, 2)] + [[]]
    spacing = 0.1
    out = sample_pieces(chains, spacing)
    assert len(out) == len(chains) and out[-1].shape == (0, 2)
    for chain, points in zip(chains, out):
        if not chain:
            continue
        curve = dense(chain)
        s = cumulative_length(curve)
        n_steps = math.ceil(s[-1] / spacing * (1.0 + 1e-3))
        assert points.shape == (n_steps - 1, 2)
        assert distance_to_polyline(points, curve).max() < 1e-6  # exact points of the cubics
        # sample j at j·L/n of arc length (the 128-step chord grid per piece: ≤ 5e-4 m on 30 seeds)
        foot = [project_point(p, curve, s)[0] for p in points[::7]]
        np.testing.assert_allclose(foot, s[-1] / n_steps * np.arange(1, n_steps)[::7], rtol=0.0, atol=1e-3)
        steps = np.hypot(*np.diff(np.vstack((curve[:1], points, curve[-1:])), axis=0).T)
        assert steps.max() <= spacing + 1e-3  # as in test_fusion_properties (grid: ≤ 3e-4 m here)


def test_long_chain_after_a_short_one_is_evenly_spaced() -> None:
    short = [bezier(0j, 1 + 0j, 3 + 0j, 1 + 0j, 1.0, 1.0)]  # a 3 m straight, then 700 m: 7000 samples
    long = [bezier(0j, 1j, 700j, 1j, 700.0 / 3.0, 700.0 / 3.0)]
    for points, length in zip(sample_pieces([short, long], 0.1), (3.0, 700.0)):
        n = math.ceil(length / 0.1 * (1.0 + 1e-3))
        np.testing.assert_allclose(np.hypot(*points.T), length / n * np.arange(1, n), atol=1e-9)


def reference_gap(p0: np.ndarray, d0: np.ndarray, p3: np.ndarray, d1: np.ndarray, spacing: float,
                  share: float) -> np.ndarray:
    """Line–turn–line of hermite_gap, every sample from its own stretch by masks; the clothoids'
    heading integrated densely (1 mm) instead of by the midpoint rule on the samples."""
    a, b = np.linalg.solve(np.column_stack((d0, d1)), p3 - p0)
    turn = math.atan2(d0[0] * d1[1] - d0[1] * d1[0], d0 @ d1)
    m = min(a, b)
    radius = m / (transition_tangent(turn, share) if share else math.tan(abs(turn) / 2.0))
    spiral, along = share * abs(turn) * radius, (1.0 - share) * abs(turn) * radius
    arc = 2.0 * spiral + along
    lead, total = a - m, a - m + arc + b - m
    n = math.ceil(total / spacing * (1.0 + 1e-9))
    u = np.arange(1, n) * (total / n)
    s = np.linspace(0.0, arc, max(2, round(arc / 1e-3)) + 1)
    if share:
        kappa = np.interp(s, [0.0, spiral, spiral + along, arc], [0.0, 1.0, 1.0, 0.0]) / radius
        heading = np.concatenate(([0.0], np.cumsum(0.5 * (kappa[1:] + kappa[:-1]) * np.diff(s))))
    else:
        heading = s / radius
    heading *= math.copysign(1.0, turn)
    mid = 0.5 * (heading[1:] + heading[:-1])
    bend = np.concatenate(([0.0], np.cumsum(np.exp(1j * mid) * np.diff(s))))
    inside = (u >= lead) & (u <= lead + arc)
    z0, dz0, dz1 = complex(*p0), complex(*d0), complex(*d1)
    z = np.where(u < lead, z0 + u * dz0, complex(*p3) + (u - total) * dz1)
    ua = u[inside] - lead
    z[inside] = z0 + lead * dz0 + dz0 * (np.interp(ua, s, bend.real) + 1j * np.interp(ua, s, bend.imag))
    return np.column_stack((z.real, z.imag))


@pytest.mark.parametrize("share", [0.0, 0.5, 1.0])
@pytest.mark.parametrize("seed", range(5))
def test_hermite_gap_matches_the_stretches_sampled_one_by_one(share: float, seed: int) -> None:
    rng = np.random.default_rng(seed)
    turn = rng.choice((-1.0, 1.0)) * rng.uniform(0.2, 1.8)
    a, b = rng.uniform(4.0, 25.0, 2)  # straight on the longer leg, before or after the turn
    corner = np.array([a, 0.0])
    d1 = np.array([math.cos(turn), math.sin(turn)])
    p3 = corner + b * d1
    pts = hermite_gap(np.zeros(2), np.array([1.0, 0.0]), p3, d1, 0.1, share)
    ref = reference_gap(np.zeros(2), np.array([1.0, 0.0]), p3, d1, 0.1, share)
    assert pts.shape == ref.shape
    # the arc in closed form (the reference's 1 mm integration: 3e-8 m); the clothoids by the
    # midpoint rule on the 0.1 m sample steps (1.3e-4 m on 40 seeds)
    assert np.abs(pts - ref).max() < (1e-6 if share == 0.0 else 3e-4)
