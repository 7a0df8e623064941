"""Calibration of the gap bridge's interpolation σ (``fusion.uncertainty.BRIDGE_SIGMA_PER_M``).

On noise-free pairs of the analytic road families (``fusion.analytic.FAMILIES``), every
interpolated point of a spline fusion gives its true error e (distance from the true
border) and its distance d from the nearer end of the bridge. The model σ = k·d is fitted
in the second moment, k = sqrt(Σe² / Σd²), per interpolation; printed with the coverage
of e ≤ k·d and e ≤ 2k·d (68 % / 95 % for Gaussian errors) and, per family, the RMS and
maximum error. No sensor noise and exact poses: the interpolation's own error only.

    .venv/bin/python tools/calibrate_bridge_sigma.py [--pairs 40] [--seed 123]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fusion.analytic import FAMILIES, detect, family_case  # noqa: E402
from fusion.api import fuse  # noqa: E402
from fusion.geometry import cumulative_length, distance_to_polyline  # noqa: E402
from fusion.types import Source  # noqa: E402

INTERPOLATIONS = ("paper", "hermite")
OFFSETS_M = (0.0, -4.0)


def samples(pairs: int, seed: int) -> dict[str, list[tuple[str, np.ndarray, np.ndarray]]]:
    """Per interpolation: (family, d [m], e [m]) of every bridge border of ``pairs`` pairs per family."""
    out: dict[str, list[tuple[str, np.ndarray, np.ndarray]]] = {name: [] for name in INTERPOLATIONS}
    for family in FAMILIES:
        rng = np.random.default_rng(seed)
        for _ in range(pairs):
            road, s_end, s_coop = family_case(family, rng)
            ego = detect(road, s_end - 30.0, 30.0, *OFFSETS_M)
            coop = detect(road, s_coop, 30.0, *OFFSETS_M)
            for name in INTERPOLATIONS:
                result = fuse(ego, coop, mode="spline", interpolation=name)
                if result.kind != "spline":
                    continue
                for points, source, offset in ((result.left, result.left_source, OFFSETS_M[0]),
                                               (result.right, result.right_source, OFFSETS_M[1])):
                    inside = np.flatnonzero(source == Source.INTERPOLATED)
                    if inside.size == 0:
                        continue
                    s = cumulative_length(points[inside[0] - 1: inside[-1] + 2])
                    d = np.minimum(s, s[-1] - s)[1:-1]
                    out[name].append((family, d, distance_to_polyline(points[inside], road.border(offset))))
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=int, default=40, help="pairs per family (default 40)")
    parser.add_argument("--seed", type=int, default=123, help="seed of the road draws (default 123)")
    args = parser.parse_args()
    for name, rows in samples(args.pairs, args.seed).items():
        d = np.concatenate([row[1] for row in rows])
        e = np.concatenate([row[2] for row in rows])
        k = math.sqrt(float((e * e).sum() / (d * d).sum()))
        z = e / np.maximum(k * d, 1e-12)
        print(f"{name}: k = {k:.4f} m/m over {e.size} points; within 1σ {np.mean(z <= 1):.3f}, "
              f"within 2σ {np.mean(z <= 2):.3f}")
        for family in FAMILIES:
            errors = np.concatenate([row[2] for row in rows if row[0] == family])
            print(f"  {family:<16} RMS error {math.sqrt(float(np.mean(errors ** 2))):.3f} m, "
                  f"max {errors.max():.3f} m")
    return 0


if __name__ == "__main__":
    sys.exit(main())
