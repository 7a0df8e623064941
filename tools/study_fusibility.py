"""Default fusibility on analytic 90° bends: same lane rejected, neighbour lanes accepted.

Roads: a straight, a 90° bend of radius 15–60 m (plain, or with clothoids of 10 / 20 m at
both ends), a straight; lane width 3.5 m; 30 m noise-free detections; the ego detection ends
every 3 m from 20 m before the bend to 10 m after it; the coop detection starts d_s = 10 /
20 / 40 m later in the ego lane, its left or its right neighbour. Prints how often the same
lane is rejected and a neighbour accepted (``fusion.is_fusible``, default parameters with
d_i = 51 m).

Usage: .venv/bin/python tools/study_fusibility.py [--noise 0.05 --seeds 2]
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import fusion  # noqa: E402
from fusion.analytic import AnalyticRoad, Segment, bend_segments, detect  # noqa: E402

WIDTH_M = 3.5
STRAIGHT_M = 100.0
RADII_M = (15.0, 20.0, 30.0, 40.0, 60.0)
ENTRIES_M = (0.0, 10.0, 20.0)
GAPS_M = (10.0, 20.0, 40.0)
PARAMS = fusion.FusionParams(d_i_m=51.0)


def bend(radius: float, sign: int, entry_m: float) -> tuple[AnalyticRoad, float]:
    """The road and the length of its bend [m]."""
    pieces = bend_segments(sign / radius, math.pi / 2, entry_m)
    return AnalyticRoad([Segment(STRAIGHT_M), *pieces, Segment(STRAIGHT_M)]), sum(p.length_m for p in pieces)


def lane(road: AnalyticRoad, s_from: float, index: int, noise_m: float, seed: int) -> fusion.LaneDetection:
    offset = index * WIDTH_M
    return detect(road, s_from, 30.0, WIDTH_M / 2 + offset, -WIDTH_M / 2 + offset, noise_m=noise_m,
                  rng=np.random.default_rng(seed))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--noise", type=float, default=0.0, help="detection noise σ [m]")
    parser.add_argument("--seeds", type=int, default=1, help="noise seeds per placement")
    args = parser.parse_args()
    same = same_rejected = neighbour = neighbour_accepted = 0
    for radius in RADII_M:
        for sign in (1, -1):
            for entry in ENTRIES_M:
                road, length = bend(radius, sign, entry)
                for gap in GAPS_M:
                    for s_end in np.arange(STRAIGHT_M - 20.0, STRAIGHT_M + length + 10.0, 3.0):
                        for seed in range(args.seeds):
                            ego = lane(road, s_end - 30.0, 0, args.noise, seed)
                            for index in (0, 1, -1):
                                ok, _ = fusion.is_fusible(ego, lane(road, s_end + gap, index, args.noise, seed + 1),
                                                          PARAMS)
                                if index == 0:
                                    same, same_rejected = same + 1, same_rejected + (not ok)
                                else:
                                    neighbour, neighbour_accepted = neighbour + 1, neighbour_accepted + ok
    print(f"noise {args.noise:.2f} m: same lane rejected {same_rejected} of {same}; "
          f"neighbour lanes accepted {neighbour_accepted} of {neighbour}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
