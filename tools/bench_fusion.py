"""Latency of fusion.fuse on 300-point borders, side by side with a scipy baseline.

The baseline implements the same steps straightforwardly (world-frame borders, nearest-point
overlap search, arc-length pairing, scipy.interpolate.CubicSpline with natural boundary
conditions, dense evaluation and arc-length resampling) without fusibility checks; for the
Hermite rows it still runs the paper's spline, so its |Δ| column there is the difference of
the two interpolations. Two timings per row, both in one run so that the library and the
baseline see the same machine load: *steady* — blocks of 50 consecutive calls of one, then
50 of the other (each call timed; the usual warm-loop latency, as timeit measures it); and
*cold* — single calls strictly alternating, so every call of one runs right after the other
has evicted its code and data from the CPU caches (the worst case for short calls). Also
prints the Bézier exchange cost.

With ``--families N`` it prints instead the accuracy of the gap interpolations on N random
roads of each held-out family of :func:`fusion.analytic.family_case`, without and with 5 cm
noise: max and mean error of ``paper``, ``hermite`` and the largest-arc Hermite (``arc``).

Usage: .venv/bin/python tools/bench_fusion.py [--repeats 2000] [--json out.json] [--families N]
"""

from __future__ import annotations

import argparse
import gc
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import fusion  # noqa: E402
from fusion import bezier  # noqa: E402
from fusion.analytic import FAMILIES, AnalyticRoad, Segment, detect, family_case, gap_errors, with_history  # noqa: E402
from fusion.geometry import cumulative_length, distance_to_polyline, to_world  # noqa: E402

RADIUS_M = 20.0
BLOCK = 50  # consecutive calls per block in the steady timing
LENGTH_M = 29.9  # 300 points at 0.1 m


def baseline_convoy(ego: fusion.LaneDetection, coop: fusion.LaneDetection, w_coop: float = 0.75) -> list[np.ndarray]:
    """Convoy fusion written plainly: per border, world frame, brute-force overlap start."""
    out = []
    for e_v, c_v in ((ego.left, coop.left), (ego.right, coop.right)):
        e, c = to_world(e_v, ego.pose), to_world(c_v, coop.pose)
        s_e, s_c = cumulative_length(e), cumulative_length(c)
        k = int(np.argmin(np.linalg.norm(e - c[0], axis=1)))
        s0 = s_e[k]
        keep = s_e < s0
        overlap = (s_e >= s0) & (s_e - s0 <= s_c[-1])
        u = s_e[overlap] - s0
        paired = np.column_stack((np.interp(u, s_c, c[:, 0]), np.interp(u, s_c, c[:, 1])))
        fused = (1 - w_coop) * e[overlap] + w_coop * paired
        tail = c[s_c > s_e[-1] - s0]
        out.append(np.vstack((e[keep], fused, tail)))
    return out


def baseline_spline(ego: fusion.LaneDetection, coop: fusion.LaneDetection) -> list[np.ndarray]:
    """The paper's spline fusion with scipy.interpolate.CubicSpline (chord-length knots)."""
    from scipy.interpolate import CubicSpline

    out = []
    for e_v, c_v in ((ego.left, coop.left), (ego.right, coop.right)):
        e, c = to_world(e_v, ego.pose), to_world(c_v, coop.pose)
        de, dc = e[-1] - e[-3], c[2] - c[0]
        de, dc = de / np.linalg.norm(de), dc / np.linalg.norm(dc)
        knots = [e[-3], e[-1]]
        if abs(math.atan2(de[0] * dc[1] - de[1] * dc[0], de @ dc)) > math.radians(10.0):
            a, b = np.linalg.solve(np.column_stack((de, dc)), c[0] - e[-1])
            p_i = e[-1] + a * de
            chord = c[0] - e[-1]
            p_j = e[-1] + chord * ((p_i - e[-1]) @ chord) / (chord @ chord)
            knots.append(p_i + 0.4 * (p_j - p_i))
        knots += [c[0], c[2]]
        q = np.array(knots)
        t = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(q, axis=0), axis=1))))
        spline = CubicSpline(t, q, bc_type="natural")
        dense_t = np.linspace(t[1], t[-2], 2000)
        s = cumulative_length(spline(dense_t))
        n = math.ceil(s[-1] / 0.1)
        gap = spline(np.interp(np.linspace(0.0, s[-1], n + 1)[1:-1], s, dense_t))
        out.append(np.vstack((e, gap, c)))
    return out


def baseline_chain(ego: fusion.LaneDetection, coops: list[fusion.LaneDetection]) -> None:
    """The scipy spline fusion of every link (ego, coop 1), (coop 1, coop 2), …: the same
    interpolation work as a chain without history (output not stitched: no |Δ| for it)."""
    for a, b in zip([ego, *coops], coops):
        baseline_spline(a, b)


def baseline_spline_unstitched(ego: fusion.LaneDetection, coop: fusion.LaneDetection) -> None:
    """The scipy spline fusion of the pair, for a result the history replaced (no |Δ| for it)."""
    baseline_spline(ego, coop)


def fuse_any(ego: fusion.LaneDetection, coop: fusion.LaneDetection, kwargs: dict) -> object:
    """``fusion.fuse``, or ``fusion.fuse_chain`` of ego, coop and ``kwargs["chain"]``."""
    if "chain" in kwargs:
        rest = {k: v for k, v in kwargs.items() if k != "chain"}
        return fusion.fuse_chain(ego, [coop, *kwargs["chain"]], **rest)
    return fusion.fuse(ego, coop, **kwargs)


def scenarios() -> dict[str, tuple[fusion.LaneDetection, fusion.LaneDetection, dict, object]]:
    straight = AnalyticRoad([Segment(300.0)])
    curve = AnalyticRoad([Segment(60.0), Segment(math.pi / 2 * RADIUS_M, -1 / RADIUS_M), Segment(200.0)])
    apex = 60.0 + math.pi / 4 * RADIUS_M
    lane = (0.0, -4.0)
    return {
        "convoy, straight, 10 m overlap": (detect(straight, 10.0, LENGTH_M, *lane), detect(straight, 30.0, LENGTH_M, *lane),
                                           {}, baseline_convoy),
        "convoy, 90° curve, 10 m overlap": (detect(curve, apex - 30.0, LENGTH_M, *lane),
                                            detect(curve, apex - 10.0, LENGTH_M, *lane), {}, baseline_convoy),
        "spline paper, straight, d_s 20 m": (detect(straight, 10.0, LENGTH_M, *lane),
                                             detect(straight, 60.0, LENGTH_M, *lane), {}, baseline_spline),
        "spline paper, 90° curve, d_s 20 m": (detect(curve, apex - 40.0, LENGTH_M, *lane),
                                              detect(curve, apex + 10.0, LENGTH_M, *lane), {}, baseline_spline),
        "spline paper, 90° curve, paper check": (detect(curve, apex - 40.0, LENGTH_M, *lane),
                                                 detect(curve, apex + 10.0, LENGTH_M, *lane),
                                                 {"params": fusion.FusionParams(fusibility="paper", t_psi_rad=math.pi)},
                                                 baseline_spline),
        "spline hermite, straight, d_s 20 m": (detect(straight, 10.0, LENGTH_M, *lane),
                                               detect(straight, 60.0, LENGTH_M, *lane), {"interpolation": "hermite"},
                                               baseline_spline),
        "spline hermite, 90° curve, d_s 20 m": (detect(curve, apex - 40.0, LENGTH_M, *lane),
                                                detect(curve, apex + 10.0, LENGTH_M, *lane),
                                                {"interpolation": "hermite"}, baseline_spline),
        "pair, 100 m history, 90° curve, d_s 20 m": (
            detect(curve, apex - 40.0, LENGTH_M, *lane),
            with_history(curve, detect(curve, apex + 10.0, LENGTH_M, *lane), apex + 10.0, 100.0, *lane),
            {"chain": []}, baseline_spline_unstitched),
        "chain of 3, 100 m history, 90° curve, d_s 20 m": (
            detect(curve, apex - 40.0, LENGTH_M, *lane),
            with_history(curve, detect(curve, apex + 10.0, LENGTH_M, *lane), apex + 10.0, 100.0, *lane),
            {"chain": [with_history(curve, detect(curve, apex + 60.0, LENGTH_M, *lane), apex + 60.0, 100.0, *lane)]},
            lambda ego, coop: baseline_chain(ego, [coop, detect(curve, apex + 60.0, LENGTH_M, *lane)])),
    }


def stats(samples_ns: list[int]) -> dict[str, float]:
    ms = np.array(samples_ns) / 1e6
    return {"mean": float(ms.mean()), "sigma": float(ms.std()), "median": float(np.median(ms)), "max": float(ms.max())}


def accuracy(n_roads: int) -> dict[str, dict[str, float]]:
    """Print and return the per-family max / mean gap errors [m] of paper, hermite and arc."""
    print(f"# Gap accuracy on {n_roads} random roads per family (seed 11): max / mean error [m] of the fused "
          "ones; 'rejected' = not fused (e.g. turns above 100°)\n")
    print("| family | noise [m] | fused | rejected | arc (old hermite) | hermite | paper | hermite > paper + 1 cm |")
    print("|---|---|---|---|---|---|---|---|")
    report = {}
    for family in FAMILIES:
        for noise in (0.0, 0.05):
            rng = np.random.default_rng(11)
            cases = [gap_errors(*family_case(family, rng), noise_m=noise, rng=rng) for _ in range(n_roads)]
            fused = [c for c in cases if c is not None]
            if not fused:
                continue
            err = {k: np.array([c[k] for c in fused]) for k in ("arc", "hermite", "paper")}
            worse = int((err["hermite"] > err["paper"] + 0.01).sum())
            cells = " | ".join(f"{v.max():.2f} / {v.mean():.2f}" for v in err.values())
            print(f"| {family} | {noise:.2f} | {len(fused)} | {n_roads - len(fused)} | {cells} | {worse} |")
            report[f"{family}, noise {noise}"] = {k: float(v.max()) for k, v in err.items()}
    return report


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=2000, help="timed calls per scenario and implementation")
    parser.add_argument("--json", type=Path, help="also write the figures as JSON")
    parser.add_argument("--families", type=int, metavar="N", help="gap accuracy on N roads per family instead")
    args = parser.parse_args()
    if args.families:
        report = accuracy(args.families)
        if args.json:
            args.json.write_text(json.dumps(report, indent=2))
        return 0
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    print(f"# fusion.fuse latency: {args.repeats} calls per row and timing, Python {platform.python_version()}, "
          f"numpy {np.__version__}, {os.cpu_count()} cores, load average {load:.2f}")
    print(f"Steady: blocks of {BLOCK} consecutive calls, library and baseline in turn; cold: single calls "
          "alternating. Wall-clock per call [ms]; CPU = CPU time of the calling thread (excludes time the "
          "scheduler gives to other processes); garbage collection off while timing, as in timeit.\n")
    print("| scenario | points out | steady mean | σ | median | max | steady CPU mean | cold mean | cold max "
          "| baseline steady mean | σ | max | baseline cold mean | max |Δ| to baseline [m] |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    report = {}
    for name, (ego, coop, kwargs, baseline) in scenarios().items():
        result = fuse_any(ego, coop, kwargs)
        assert getattr(result, "kind", "chain") != "none" and not result.reason, result.reason
        reference = baseline(ego, coop)
        delta = None if reference is None else max(
            float(distance_to_polyline(mine, ref).max()) for mine, ref in zip((result.left, result.right), reference))
        timings = {key: [] for key in ("steady", "steady_cpu", "cold", "baseline", "baseline_cold")}
        for _ in range(50):
            fuse_any(ego, coop, kwargs)
            baseline(ego, coop)
        gc.disable()  # as timeit does: no collector pauses inside the timed calls
        for _ in range(max(1, args.repeats // BLOCK)):
            for _ in range(BLOCK):
                c0, t0 = time.thread_time_ns(), time.perf_counter_ns()
                fuse_any(ego, coop, kwargs)
                c1, t1 = time.thread_time_ns(), time.perf_counter_ns()
                timings["steady"].append(t1 - t0)
                timings["steady_cpu"].append(c1 - c0)
            for _ in range(BLOCK):
                t0 = time.perf_counter_ns()
                baseline(ego, coop)
                timings["baseline"].append(time.perf_counter_ns() - t0)
        for _ in range(args.repeats):
            t0 = time.perf_counter_ns()
            fuse_any(ego, coop, kwargs)
            t1 = time.perf_counter_ns()
            baseline(ego, coop)
            t2 = time.perf_counter_ns()
            timings["cold"].append(t1 - t0)
            timings["baseline_cold"].append(t2 - t1)
        gc.enable()
        st = {key: stats(values) for key, values in timings.items()}
        report[name] = {**st, "points": int(result.left.shape[0] + result.right.shape[0]), "max_delta_m": delta}
        m, b = st["steady"], st["baseline"]
        print(f"| {name} | {report[name]['points']} | {m['mean']:.3f} | {m['sigma']:.3f} | {m['median']:.3f} | "
              f"{m['max']:.3f} | {st['steady_cpu']['mean']:.3f} | {st['cold']['mean']:.3f} | {st['cold']['max']:.3f} | "
              f"{b['mean']:.3f} | {b['sigma']:.3f} | {b['max']:.3f} | {st['baseline_cold']['mean']:.3f} | {'–' if delta is None else f'{delta:.4f}'} |")
    chain = report["chain of 3, 100 m history, 90° curve, d_s 20 m"]["steady"]["mean"]
    print(f"\nChain of 3 with history / pair: {chain / report['spline paper, 90° curve, d_s 20 m']['steady']['mean']:.2f}× "
          f"the spline pair, {chain / report['pair, 100 m history, 90° curve, d_s 20 m']['steady']['mean']:.2f}× the "
          "pair with history (steady means).")
    print("\n# Bézier exchange (tolerance 0.05 m)\n| lane (30 m) | Bézier bytes | payload | sampled bytes | "
          "segments | max decode error [m] |\n|---|---|---|---|---|---|")
    for name, (ego, _, _, _) in list(scenarios().items())[:2]:
        ex = bezier.exchange_stats(ego.left, ego.right)
        report[f"bezier {name}"] = ex.__dict__
        print(f"| {name.split(', ')[1]} | {ex.bezier_bytes} | {ex.payload_bytes} | {ex.sampled_bytes} | "
              f"{ex.segments[0]}+{ex.segments[1]} | {ex.max_error_m:.4f} |")
    if args.json:
        args.json.write_text(json.dumps(report, indent=2, default=list))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
