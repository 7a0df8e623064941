"""Calibration of the gap bridge's interpolation σ (``fusion.uncertainty.BRIDGE_SIGMA_PER_M``).

On noise-free pairs of the analytic road families (``fusion.analytic.FAMILIES``), every
interpolated point of a spline fusion gives its true error e (distance from the true
border), its distance d from the nearer end of the bridge and the bridge's bend F
(``fusion.uncertainty.bridge_bend`` of ``gap_bend`` of the pair's end fits, as the fusion
computes it; F = 1 for an interpolation whose term does not scale with the bend,
``BRIDGE_SCALES_WITH_BEND``). The model σ = k·F·d is fitted in the second moment on the tune seed,
k = sqrt(Σe² / Σ(F·d)²), per interpolation; printed with the coverage of e ≤ k·F·d and
e ≤ 2k·F·d (68 % / 95 % for Gaussian errors) on the tune and on the report seed, overall and
per family. No sensor noise and exact poses: the interpolation's own error only.

    .venv/bin/python tools/calibrate_bridge_sigma.py [--pairs 40] [--seed 123] [--report-seed 7]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fusion.analytic import FAMILIES, detect, family_case  # noqa: E402
from fusion.api import DEFAULT_PARAMS, ego_frame_borders, end_fits, fuse  # noqa: E402
from fusion.geometry import cumulative_length, distance_to_polyline  # noqa: E402
from fusion.types import Source  # noqa: E402
from fusion.uncertainty import BRIDGE_SCALES_WITH_BEND, bridge_bend, gap_bend  # noqa: E402

INTERPOLATIONS = ("paper", "hermite")
OFFSETS_M = (0.0, -4.0)
Sample = tuple[str, np.ndarray, np.ndarray]  # family, F·d [rad·m], e [m] of one bridge border's points


def samples(pairs: int, seed: int) -> dict[str, list[Sample]]:
    """Per interpolation: (family, F·d, e) of every bridge border of ``pairs`` pairs per family."""
    out: dict[str, list[Sample]] = {name: [] for name in INTERPOLATIONS}
    for family in FAMILIES:
        rng = np.random.default_rng(seed)
        for _ in range(pairs):
            road, s_end, s_coop = family_case(family, rng)
            ego = detect(road, s_end - 30.0, 30.0, *OFFSETS_M)
            coop = detect(road, s_coop, 30.0, *OFFSETS_M)
            borders, _ = ego_frame_borders(ego, coop)
            ends = gap_bend(end_fits(ego, coop, borders, DEFAULT_PARAMS).arcs())
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
                    bend = bridge_bend(*ends, float(s[-1])) if BRIDGE_SCALES_WITH_BEND[name] else 1.0
                    out[name].append((family, bend * d, distance_to_polyline(points[inside], road.border(offset))))
    return out


def coverage(rows: list[Sample], k: float) -> str:
    """Shares of points within k·F·d and 2k·F·d, overall and per family."""
    def shares(part: list[Sample]) -> str:
        z = np.concatenate([r[2] for r in part]) / np.maximum(k * np.concatenate([r[1] for r in part]), 1e-12)
        return f"{np.mean(z <= 1):.3f} / {np.mean(z <= 2):.3f}"
    return f"{shares(rows)} (" + ", ".join(f"{f} {shares([r for r in rows if r[0] == f])}" for f in FAMILIES) + ")"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=int, default=40, help="pairs per family (default 40)")
    parser.add_argument("--seed", type=int, default=123, help="seed of the road draws k is fitted on (default 123)")
    parser.add_argument("--report-seed", type=int, default=7, help="seed of the road draws reported (default 7)")
    args = parser.parse_args()
    tune, report = samples(args.pairs, args.seed), samples(args.pairs, args.report_seed)
    for name in INTERPOLATIONS:
        fd = np.concatenate([row[1] for row in tune[name]])
        e = np.concatenate([row[2] for row in tune[name]])
        k = math.sqrt(float((e * e).sum() / (fd * fd).sum()))
        unit = "m/(m·rad)" if BRIDGE_SCALES_WITH_BEND[name] else "m/m"
        print(f"{name}: k = {k:.4f} {unit} over {e.size} points")
        print(f"  within 1σ / 2σ, tune seed {args.seed}: {coverage(tune[name], k)}")
        print(f"  within 1σ / 2σ, report seed {args.report_seed}: {coverage(report[name], k)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
