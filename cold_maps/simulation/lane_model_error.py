"""Correlated lateral error of a camera lane detection: the cubic lane model.

Production lane sensors report each lane border as a cubic in the vehicle frame,
y(x) = c0 + c1·x + c2·x²/2 + c3·x³/6 (x forward, m). Their error is modelled the same way:
per frame and border, e(x) = δc0 + δc1·x + δc2·x²/2 + δc3·x³/6 with independent
δcᵢ ~ N(0, σᵢ²), plus white noise N(0, σ_w²) per point. The coefficients evolve from frame
to frame as AR(1) with time constant τ: δc(t + Δt) = ρ·δc(t) + √(1 − ρ²)·σ·N(0, 1),
ρ = exp(−Δt/τ), which keeps their variance and correlates frames by ρ.

Closed form of the lateral 1σ at distance x:
σ(x)² = σ0² + σ1²·x² + σ2²·x⁴/4 + σ3²·x⁶/36 + σ_w².
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from cold_maps.opendrive.cubic_poly import NDArrayFloat


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
