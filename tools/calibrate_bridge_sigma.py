"""Calibration of the gap bridge's interpolation σ (``fusion.uncertainty.BRIDGE_SIGMA_PER_M``
k₁ and ``BRIDGE_SIGMA_FLOOR_PER_M`` k₀; the term's variance is (k₀·d)² + (k₁·F·d_t)², d the
distance from the bridge's nearer end, d_t from the nearer end of the part that turns
(``fusion.spline.hermite_turns``; the whole bridge for ``paper``), F =
``fusion.uncertainty.interpolation_bend``).

With ``--drives MAP ...`` (the constants' source, for ``--interpolation paper`` or
``hermite``): ``cold-eval --sensor camera --pose-xy 0.05 --pose-yaw 0.002 --interpolation
INTERPOLATION --seed DRIVE_SEED`` on each map and each drive seed, every interpolated point of a correct fusion
(truly fusible) with its error, d, d_t, F and the variance its ends carry in (the bridge's σ²
without the interpolation term); (k₀, k₁) on a grid (steps 0.0025 m/m, 0.0025 m/(m·rad)) with
the least squared deviation of the share within 1σ and 2σ from 68.3 % and 95.4 % over six
equally filled bins of F (fewer where many points share one F, e.g. hermite's F = 0).

Without ``--drives`` (a cross-check of ``hermite`` on the analytic road families,
``fusion.analytic.FAMILIES``, noise-free pairs, exact poses: the interpolation's own error):
every interpolated point gives its true error e (distance from the true border), d, d_t and
the bridge's bend F (of ``gap_bend`` of the pair's end fits, as the fusion computes it); prints
the second-moment k₁ = sqrt(Σe² / Σ(F·d_t)²) on the tune seed and the share of points within
1σ and 2σ of the module's interpolation term on the tune and on the report seed, overall and
per family.

    .venv/bin/python tools/calibrate_bridge_sigma.py --drives ../shared/maps/carla/Town01.xodr \\
        ../shared/maps/carla/Town04.xodr maps/rural.xodr [--interpolation hermite] [--drive-seed 2 3 4]
    .venv/bin/python tools/calibrate_bridge_sigma.py [--pairs 40] [--seed 123] [--report-seed 7]
"""

from __future__ import annotations

import argparse
import contextlib
import math
import sys
import tempfile
from pathlib import Path
from typing import Any, Iterator

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from fusion.analytic import FAMILIES, detect, family_case  # noqa: E402
from fusion.api import DEFAULT_PARAMS, ego_frame_borders, end_fits, fuse  # noqa: E402
from fusion.geometry import cumulative_length, distance_to_polyline  # noqa: E402
from fusion.types import Source  # noqa: E402
from fusion.spline import hermite_turns  # noqa: E402
from fusion.uncertainty import (BRIDGE_SIGMA_FLOOR_PER_M, BRIDGE_SIGMA_PER_M, bridge_distances,  # noqa: E402
                                bridge_ends_variance, bridge_fraction, gap_bend, interpolation_bend)

OFFSETS_M = (0.0, -4.0)
COVERAGE = (0.683, 0.954)
Sample = tuple[str, np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # family, d, d_t [m], F [rad], e [m] per point


def samples(pairs: int, seed: int) -> list[Sample]:
    """(family, d, d_t, F, e) of every ``hermite`` bridge border of ``pairs`` pairs per family."""
    out: list[Sample] = []
    for family in FAMILIES:
        rng = np.random.default_rng(seed)
        for _ in range(pairs):
            road, s_end, s_coop = family_case(family, rng)
            ego = detect(road, s_end - 30.0, 30.0, *OFFSETS_M)
            coop = detect(road, s_coop, 30.0, *OFFSETS_M)
            borders, _ = ego_frame_borders(ego, coop)
            fits = end_fits(ego, coop, borders, DEFAULT_PARAMS)
            ends, turns = gap_bend(fits.arcs()), hermite_turns(fits())
            result = fuse(ego, coop, mode="spline", interpolation="hermite")
            if result.kind != "spline":
                continue
            for points, source, offset, turn in ((result.left, result.left_source, OFFSETS_M[0], turns[0]),
                                                 (result.right, result.right_source, OFFSETS_M[1], turns[1])):
                inside = np.flatnonzero(source == Source.INTERPOLATED)
                if inside.size == 0:
                    continue
                s = cumulative_length(points[inside[0] - 1: inside[-1] + 2])
                d, d_turn = bridge_distances(s[1:-1] / s[-1], float(s[-1]), turn)
                bend = interpolation_bend("hermite", ends, float(s[-1]))
                out.append((family, d, d_turn, np.full(d.size, bend),
                            distance_to_polyline(points[inside], road.border(offset))))
    return out


def coverage(rows: list[Sample], k0: float, k1: float) -> str:
    """Shares of points within sqrt((k₀·d)² + (k₁·F·d_t)²) and twice that, overall and per family."""
    def shares(part: list[Sample]) -> str:
        d, d_turn, bend, e = (np.concatenate([r[i] for r in part]) for i in (1, 2, 3, 4))
        z = e / np.maximum(np.hypot(k0 * d, k1 * bend * d_turn), 1e-12)
        return f"{np.mean(z <= 1):.3f} / {np.mean(z <= 2):.3f}"
    return f"{shares(rows)} (" + ", ".join(f"{f} {shares([r for r in rows if r[0] == f])}" for f in FAMILIES) + ")"


@contextlib.contextmanager
def recorded_bridges(interpolation: str) -> Iterator[list[tuple[np.ndarray, ...]]]:
    """While open, every ``interpolation`` bridge border the evaluator records as a correct fusion:
    (e, d, d_t, F, variance of the ends) per interpolated point."""
    import fusion
    import fusion.api as api
    from cold_maps.evaluation import evaluator

    rows: list[tuple[np.ndarray, ...]] = []
    pending: list[tuple[np.ndarray, ...]] = []
    fused: dict[int, tuple[Any, np.ndarray, tuple[np.ndarray, ...] | None]] = {}
    bridge, fuse_pair, record = api.bridge_variance, fusion.fuse, evaluator.MapEvaluator._record

    def bridge_parts(gap, start, stop, ego_end, coop_start, kind, bend, turn=(0.0, 1.0)):  # type: ignore[no-untyped-def]
        tau, length = bridge_fraction(gap, start, stop)
        d, d_turn = bridge_distances(tau, length, turn)
        ends = bridge_ends_variance(tau, length, ego_end, coop_start)
        pending.append((d, d_turn, np.full(d.size, interpolation_bend(kind, bend, length)), ends))
        return bridge(gap, start, stop, ego_end, coop_start, kind, bend, turn)

    def fuse_and_keep(*args, **kwargs):  # type: ignore[no-untyped-def]
        pending.clear()
        result = fuse_pair(*args, **kwargs)
        calls = list(pending)
        for index, side in enumerate(("left", "right")):
            sigma = getattr(result, f"{side}_sigma")
            inside = getattr(result, f"{side}_source") == Source.INTERPOLATED
            if sigma is not None and kwargs.get("interpolation") == interpolation and len(calls) == 2:
                fused[id(sigma)] = (sigma, inside, calls[index] if calls[index][0].size == inside.sum() else None)
        return result

    def record_bridges(self, collector, scenario, keys, measured, *args, **kwargs):  # type: ignore[no-untyped-def]
        truth = args[6]
        for errors, sigma in zip((measured.left_errors_m, measured.right_errors_m), kwargs.get("sigmas", ())):
            found = fused.pop(id(sigma), None) if sigma is not None else None
            if truth and found is not None and found[0] is sigma and found[2] is not None:
                rows.append((errors[found[1]], *found[2]))
        return record(self, collector, scenario, keys, measured, *args, **kwargs)

    api.bridge_variance, fusion.fuse, evaluator.MapEvaluator._record = bridge_parts, fuse_and_keep, record_bridges
    try:
        yield rows
    finally:
        api.bridge_variance, fusion.fuse, evaluator.MapEvaluator._record = bridge, fuse_pair, record


def drive_samples(maps: list[Path], seeds: list[int], interpolation: str) -> tuple[np.ndarray, ...]:
    """(e, d, d_t, F, ends' variance) of every interpolated point of the correct ``interpolation``
    fusions of ``cold-eval`` camera drives on ``maps``, one run per map and drive seed."""
    from cold_maps.cli import evaluate

    with recorded_bridges(interpolation) as rows, tempfile.TemporaryDirectory() as folder:
        for index, (path, seed) in enumerate((path, seed) for seed in seeds for path in maps):
            status = evaluate.main(["--map", str(path), "--sensor", "camera", "--pose-xy", "0.05", "--pose-yaw",
                                    "0.002", "--interpolation", interpolation, "--seed", str(seed), "--workers", "1",
                                    "--no-mcap", "--no-plots", "-q", "--out", str(Path(folder) / str(index))])
            if status != 0:
                raise SystemExit(f"cold-eval failed on {path} (seed {seed})")
    return tuple(np.concatenate(column) for column in zip(*rows))


def fit_drives(e: np.ndarray, d: np.ndarray, d_turn: np.ndarray, bend: np.ndarray,
               ends: np.ndarray) -> tuple[float, float, str]:
    """(k₀, k₁) of the grid with the least squared deviation from :data:`COVERAGE` over up to
    six equally filled bins of F (tied quantiles merged), and the shares per bin. A point lies
    within kσ at k₀ when k₁² ≥ t = (e²/k² − ends − (k₀·d)²) / (F·d_t)², so each k₀ sorts t once
    per bin and counts it at every k₁ of the grid."""
    edges = np.unique(np.quantile(bend, np.linspace(0.0, 1.0, 7)))
    bins = max(1, edges.size - 1)
    index = np.clip(np.searchsorted(edges, bend, side="right") - 1, 0, bins - 1)
    counts = np.bincount(index, minlength=bins)
    k1_grid = np.arange(0.0, 0.25, 0.0025)
    scale = (bend * d_turn) ** 2
    best: tuple[float, float, float, np.ndarray, np.ndarray] | None = None
    for k0 in np.arange(0.0, 0.08, 0.0025):
        within = []
        for k in (1.0, 2.0):
            need = e * e / (k * k) - ends - (k0 * d) ** 2
            t = np.full(e.shape, np.inf)
            np.divide(need, scale, out=t, where=scale > 0.0)
            t[(scale == 0.0) & (need <= 0.0)] = -np.inf
            within.append(np.array([np.searchsorted(np.sort(t[index == b]), k1_grid * k1_grid, side="right")
                                    for b in range(bins)]) / counts[:, None])
        cost = sum((w - c) ** 2 for w, c in zip(within, COVERAGE)).sum(axis=0)
        j = int(np.argmin(cost))
        if best is None or cost[j] < best[0]:
            best = (float(cost[j]), float(k0), float(k1_grid[j]), within[0][:, j], within[1][:, j])
    assert best is not None
    _, k0, k1, one, two = best
    shares = ", ".join(f"F {lo:.3f}–{hi:.3f}: {a:.3f} / {b:.3f}" for lo, hi, a, b in zip(edges[:-1], edges[1:], one, two))
    return k0, k1, shares


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--pairs", type=int, default=40, help="pairs per family (default 40)")
    parser.add_argument("--seed", type=int, default=123, help="seed of the road draws of the tune set (default 123)")
    parser.add_argument("--report-seed", type=int, default=7, help="seed of the road draws reported (default 7)")
    parser.add_argument("--drives", type=Path, nargs="+", metavar="MAP", help="fit k₀, k₁ on these maps' drives")
    parser.add_argument("--interpolation", choices=("paper", "hermite"), default="paper",
                        help="--drives: the interpolation fitted (default paper)")
    parser.add_argument("--drive-seed", type=int, nargs="+", default=[0],
                        help="cold-eval --seed of the drives, one run per map and seed (default 0)")
    args = parser.parse_args()
    if args.drives:
        e, d, d_turn, bend, ends = drive_samples(args.drives, args.drive_seed, args.interpolation)
        k0, k1, bins = fit_drives(e, d, d_turn, bend, ends)
        z = e / np.sqrt(ends + (k0 * d) ** 2 + (k1 * bend * d_turn) ** 2)
        print(f"{args.interpolation}: k0 = {k0:.4f} m/m, k1 = {k1:.4f} m/(m·rad) over {e.size} points; "
              f"within 1σ / 2σ {np.mean(z <= 1):.3f} / {np.mean(z <= 2):.3f}")
        print(f"  per bin: {bins}")
        return 0
    tune, report = samples(args.pairs, args.seed), samples(args.pairs, args.report_seed)
    fd = np.concatenate([row[2] * row[3] for row in tune])
    e = np.concatenate([row[4] for row in tune])
    k = math.sqrt(float((e * e).sum() / (fd * fd).sum()))
    k0, k1 = BRIDGE_SIGMA_FLOOR_PER_M["hermite"], BRIDGE_SIGMA_PER_M["hermite"]
    print(f"hermite: second-moment k1 = {k:.4f} m/(m·rad) over {e.size} points of seed {args.seed}")
    print(f"  within 1σ / 2σ of k0 = {k0} m/m, k1 = {k1} m/(m·rad), tune seed {args.seed}: {coverage(tune, k0, k1)}")
    print(f"  within 1σ / 2σ, report seed {args.report_seed}: {coverage(report, k0, k1)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
