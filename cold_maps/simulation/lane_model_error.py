"""Correlated lateral error of a camera lane detection: the cubic lane model.

Production lane sensors report each lane border as a cubic in the vehicle frame,
y(x) = c0 + c1·x + c2·x²/2 + c3·x³/6 (x forward, m). Their error is modelled the same way:
per frame and border, e(x) = δc0 + δc1·x + δc2·x²/2 + δc3·x³/6 with independent
δcᵢ ~ N(0, σᵢ²), plus white noise N(0, σ_w²) per point. The coefficients evolve from frame
to frame as AR(1) with time constant τ: δc(t + Δt) = ρ·δc(t) + √(1 − ρ²)·σ·N(0, 1),
ρ = exp(−Δt/τ), which keeps their variance and correlates frames by ρ.

Closed form of the lateral 1σ at distance x:
σ(x)² = σ0² + σ1²·x² + σ2²·x⁴/4 + σ3²·x⁶/36 + σ_w².

:class:`LaneModelErrorSampler` draws this error for the vehicles of one drive: x is each
point's forward coordinate in the vehicle frame (m), e(x) moves the point along its
border's left normal (vehicle frame; positive = to the left), and every vehicle has its own
generator (seeded from the run's seed, the drive and the vehicle's name) and its own
coefficients per border, evolved over the stamps at which it detects.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field
from typing import Final, Sequence

import numpy as np

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.simulation.sensor_errors import left_normals, left_normals_stacked

LANE_MODEL_STREAM: Final[int] = 13
"""Sub-stream of the run's seed that the lane-model errors draw from (the history and the
messages use 11 and 12, ``simulation.exchange``): the other error models' draws do not
depend on whether this one is on."""
_BORDERS: Final[tuple[str, str]] = ("left", "right")


@dataclass(frozen=True)
class LaneModelErrorParams:
    """Parameters of the cubic lane-model error (all 0: the ideal sensor).

    Fields:
        sigma_c0_m: 1σ of the lateral offset δc0 (m).
        sigma_c1_rad: 1σ of the heading error δc1 (rad).
        sigma_c2_per_m: 1σ of the curvature error δc2 (1/m).
        sigma_c3_per_m2: 1σ of the curvature-rate error δc3 (1/m²).
        white_m: 1σ of the independent noise of each point (m).
        tau_s: time constant of the coefficients' AR(1) evolution (s, > 0).
    """

    sigma_c0_m: float = 0.0
    sigma_c1_rad: float = 0.0
    sigma_c2_per_m: float = 0.0
    sigma_c3_per_m2: float = 0.0
    white_m: float = 0.0
    tau_s: float = 0.5

    def __post_init__(self) -> None:
        for name in ("sigma_c0_m", "sigma_c1_rad", "sigma_c2_per_m", "sigma_c3_per_m2", "white_m"):
            value = getattr(self, name)
            if not (np.isfinite(value) and value >= 0.0):
                raise ValueError(f"lane model error: {name} must be a finite value >= 0, got {value!r}")
        if not (np.isfinite(self.tau_s) and self.tau_s > 0.0):
            raise ValueError(f"lane model error: tau_s must be a finite time > 0 s, got {self.tau_s!r}")

    @property
    def is_zero(self) -> bool:
        """True when the model adds no error (the ideal sensor)."""
        return not (self.sigma_c0_m or self.sigma_c1_rad or self.sigma_c2_per_m or self.sigma_c3_per_m2
                    or self.white_m)

    def sigma_m(self, x_m: NDArrayFloat) -> NDArrayFloat:
        """Lateral 1σ (m) of the error at distances ``x_m`` (m, vehicle frame x)."""
        x = np.asarray(x_m, dtype=np.float64)
        x2 = x * x
        variance = (self.sigma_c0_m**2 + self.sigma_c1_rad**2 * x2 + self.sigma_c2_per_m**2 * x2 * x2 / 4.0
                    + self.sigma_c3_per_m2**2 * x2**3 / 36.0 + self.white_m**2)
        return np.sqrt(variance)

    @property
    def coefficient_sigmas(self) -> NDArrayFloat:
        """1σ of (δc0 m, δc1 rad, δc2 1/m, δc3 1/m²), shape (4,)."""
        return np.array([self.sigma_c0_m, self.sigma_c1_rad, self.sigma_c2_per_m, self.sigma_c3_per_m2])


def evolve(coefficients: NDArrayFloat | None, params: LaneModelErrorParams, dt_s: float, rng: np.random.Generator,
           chains: tuple[int, ...] = ()) -> NDArrayFloat:
    """The coefficients ``dt_s`` (s, >= 0) after ``coefficients`` (shape ``chains + (4,)``):
    the AR(1) step ρ·c + √(1 − ρ²)·σ·N(0, 1), ρ = exp(−dt_s/τ); None draws them from the
    stationary N(0, σ²). Coefficients with σ 0 stay 0; no draw when every σ is 0."""
    if not (math.isfinite(dt_s) and dt_s >= 0.0):
        raise ValueError(f"lane model error: time step must be a finite value >= 0 s, got {dt_s!r}")
    sigmas = params.coefficient_sigmas
    shape = (*chains, 4) if coefficients is None else np.shape(coefficients)
    if not sigmas.any():
        return np.zeros(shape)
    return _step(coefficients, params, dt_s, rng.standard_normal(shape))


def _step(coefficients: NDArrayFloat | None, params: LaneModelErrorParams, dt_s: float,
          normals: NDArrayFloat) -> NDArrayFloat:
    """:func:`evolve`'s step with its standard normals ``normals`` drawn."""
    fresh = normals * params.coefficient_sigmas
    if coefficients is None:
        return fresh
    rho = math.exp(-dt_s / params.tau_s)
    return rho * np.asarray(coefficients) + math.sqrt(1.0 - rho * rho) * fresh


def lateral_error(coefficients: NDArrayFloat, x_m: NDArrayFloat, params: LaneModelErrorParams,
                  rng: np.random.Generator) -> NDArrayFloat:
    """e(x) (m) at distances ``x_m`` (shape (N,)) for coefficients of shape ``chains + (4,)``:
    δc0 + δc1·x + δc2·x²/2 + δc3·x³/6 plus white noise N(0, σ_w²) per point (drawn only when
    σ_w > 0); shape ``chains + (N,)``."""
    c = np.asarray(coefficients)[..., None, :]
    x = np.asarray(x_m, dtype=np.float64)
    error = c[..., 0] + x * (c[..., 1] + x * (c[..., 2] / 2.0 + x * c[..., 3] / 6.0))
    if params.white_m > 0.0:
        error = error + rng.normal(0.0, params.white_m, error.shape)
    return error


@dataclass
class _Chain:
    """One vehicle's state: its generator, the coefficients of its (left, right) borders
    (shape (2, 4)) and the stamp they belong to (s)."""

    rng: np.random.Generator
    coefficients: NDArrayFloat
    stamp_s: float


@dataclass
class LaneModelErrorSampler:
    """The lane-model errors of the vehicles of one drive (module docstring).

    Fields:
        params: the model (the ideal sensor, all zero, needs no sampler).
        seed: the run's seed.
        drive: the drive's index in its map's evaluation.
    """

    params: LaneModelErrorParams
    seed: int
    drive: int
    _chains: dict[str, _Chain] = field(default_factory=dict, init=False, repr=False)

    def perturb(self, vehicle: str, stamp_s: float, left: NDArrayFloat,
                right: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat]:
        """The ``(left, right)`` borders (vehicle frame, m) of ``vehicle``'s detection at
        ``stamp_s`` (s) with the lane-model error; stamps of a vehicle must not decrease."""
        chain = self._chains.get(vehicle)
        if chain is None:
            rng = np.random.default_rng([self.seed, LANE_MODEL_STREAM, self.drive, zlib.crc32(vehicle.encode())])
            chain = self._chains[vehicle] = _Chain(rng, evolve(None, self.params, 0.0, rng, (2,)), stamp_s)
        elif stamp_s < chain.stamp_s:
            raise ValueError(f"lane model error: {vehicle} detects at {stamp_s!r} s, before its last detection at "
                             f"{chain.stamp_s!r} s")
        else:
            chain.coefficients = evolve(chain.coefficients, self.params, stamp_s - chain.stamp_s, chain.rng)
            chain.stamp_s = stamp_s
        moved = [border + lateral_error(c, border[:, 0], self.params, chain.rng)[:, None] * left_normals(border, name)
                 for name, border, c in zip(_BORDERS, (left, right), chain.coefficients)]
        return moved[0], moved[1]

    def perturb_many(self, vehicle: str, stamps_s: Sequence[float],
                     borders: Sequence[tuple[NDArrayFloat, NDArrayFloat]]) -> list[tuple[NDArrayFloat, NDArrayFloat]]:
        """:meth:`perturb` of ``vehicle``'s detections with ``borders`` at ``stamps_s`` (s,
        in order), as arrays: the vehicle's normal draws of all of them taken at once, in
        the order :meth:`perturb` takes them, and the errors evaluated over all points at
        once; the same borders."""
        if not borders:
            return []
        params = self.params
        counts = np.array([len(border) for pair in borders for border in pair])
        coefficients, white = self._coefficients(vehicle, stamps_s, counts.tolist())
        stacked = np.concatenate([border for pair in borders for border in pair])
        offsets = np.concatenate(([0], np.cumsum(counts)))
        c = np.repeat(coefficients.reshape(-1, 4), counts, axis=0)
        x = stacked[:, 0]
        error = c[:, 0] + x * (c[:, 1] + x * (c[:, 2] / 2.0 + x * c[:, 3] / 6.0))
        if params.white_m > 0.0:
            error = error + (0.0 + params.white_m * white)
        moved = stacked + error[:, None] * left_normals_stacked(stacked, offsets, _BORDERS * len(borders))
        parts = np.split(moved, offsets[1:-1])
        return [(parts[2 * k], parts[2 * k + 1]) for k in range(len(borders))]

    def _coefficients(self, vehicle: str, stamps_s: Sequence[float],
                      points: Sequence[int]) -> tuple[NDArrayFloat, NDArrayFloat]:
        """(D, 2, 4) coefficients of ``vehicle``'s D detections at ``stamps_s`` (their
        borders having ``points`` points, left and right in turn), evolved as :meth:`perturb`
        evolves them, and the standard normals of their points' white noise, all from one
        draw in :meth:`perturb`'s order."""
        params = self.params
        coefficient_draws = 8 if params.coefficient_sigmas.any() else 0
        white = params.white_m > 0.0
        chain = self._chains.get(vehicle)
        fresh = chain is None
        if chain is None:
            rng = np.random.default_rng([self.seed, LANE_MODEL_STREAM, self.drive, zlib.crc32(vehicle.encode())])
            chain = self._chains[vehicle] = _Chain(rng, np.zeros((2, 4)), stamps_s[0])
        total = len(stamps_s) * coefficient_draws + (sum(points) if white else 0)
        draws = chain.rng.standard_normal(total)
        out = np.empty((len(stamps_s), 2, 4))
        whites = []
        at = 0
        for k, stamp_s in enumerate(stamps_s):
            if stamp_s < chain.stamp_s:
                raise ValueError(f"lane model error: {vehicle} detects at {stamp_s!r} s, before its last detection at "
                                 f"{chain.stamp_s!r} s")
            previous = None if fresh and k == 0 else chain.coefficients
            chain.coefficients = (_step(previous, params, stamp_s - chain.stamp_s,
                                        draws[at: at + coefficient_draws].reshape(2, 4))
                                  if coefficient_draws else np.zeros((2, 4)))
            chain.stamp_s = stamp_s
            at += coefficient_draws
            out[k] = chain.coefficients
            if white:
                count = points[2 * k] + points[2 * k + 1]
                whites.append(draws[at: at + count])
                at += count
        return out, np.concatenate(whites) if whites else np.empty(0)
