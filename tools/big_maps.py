"""Seeded generator of two big, valid OpenDRIVE maps that stress the map commands and the
ground truth (issue 28), and a benchmark of ``cold-maps info`` against the ground-truth
preparation of ``cold-eval`` on them.

- ``chain``: ``--roads`` (default 100 000) one-metre roads linked end to end, each an arc
  (curvature drawn per block of ``BLOCK_ROADS`` roads, seeded) with ``--lanes`` (default 1)
  3.5 m driving lanes per direction: a 100 km drive through 100 000 road links. About
  1.2 kB of XML per road with one lane per side (a public 207 MB map has 1.1 kB per road),
  0.5 kB more per further lane per side.
- ``junction``: one junction of ``--arms``² (default 100² = 10 000) connections: ``--arms``
  incoming roads end on the west quarter of a circle of ``JUNCTION_RADIUS_M``, as many
  outgoing roads start on its east quarter, and every incoming road is joined to every
  outgoing one by a one-lane connecting road (a ``paramPoly3`` cubic Hermite curve, C¹ at
  both ends); every connection crosses most others. ``--parallel``: as many connections
  side by side, none crossing another.

The documents are written as text, road by road (an element tree of 100 000 roads needs
gigabytes). Same seed, same bytes.

    python tools/big_maps.py chain OUT.xodr [--roads 100000] [--lanes 1] [--seed 0]
    python tools/big_maps.py junction OUT.xodr [--arms 100] [--seed 0]
    python tools/big_maps.py bench MAP.xodr [...] [--routing-graph]   # info vs ground-truth preparation, CPU s
"""

from __future__ import annotations

import argparse
import math
import random
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from pathlib import Path
from typing import Final

PROJECT_ROOT: Final[Path] = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(PROJECT_ROOT))
sys.path.insert(0, str(PROJECT_ROOT / "tools"))

from make_maps import Pose, arc, end_pose, fmt, normalize_angle  # noqa: E402

LANE_WIDTH_M: Final[float] = 3.5
"""Width (m) of every lane."""

ROAD_LENGTH_M: Final[float] = 1.0
"""Length (m) of each road of the chain."""

BLOCK_ROADS: Final[int] = 200
"""Roads of the chain that share one curvature."""

MAX_CURVATURE: Final[float] = 0.004
"""Largest |curvature| (1/m) of the chain (radius 250 m)."""

JUNCTION_RADIUS_M: Final[float] = 30.0
"""Radius (m) of the circle the junction's arms end and start on."""

ARM_LENGTH_M: Final[float] = 20.0
"""Length (m) of each incoming and outgoing road of the junction."""

QUARTER_RAD: Final[float] = 0.5 * math.pi
"""Angle (rad) of the circle each set of arms spreads over."""

GAUSS_NODES: Final[int] = 8
"""Gauss-Legendre nodes per piece of a connecting road's arc length."""

GAUSS_PIECES: Final[int] = 64
"""Pieces of a connecting road's parameter range for its arc length."""

_HEADER: Final[str] = ('<?xml version="1.0" encoding="UTF-8"?>\n<OpenDRIVE>\n  <header revMajor="1" revMinor="6" '
                       'name="{name}" version="1.0" vendor="cold-maps tools/big_maps.py (seed {seed})"/>\n')
_MARK: Final[str] = '<roadMark sOffset="0" type="{kind}" weight="standard" color="standard" width="0.12"/>'
_WIDTH: Final[str] = f'<width sOffset="0" a="{fmt(LANE_WIDTH_M)}" b="0" c="0" d="0"/>'


def _lane(lane_id: int, predecessor: int | None, successor: int | None, mark: str) -> str:
    links = "".join(f'<{tag} id="{lane}"/>' for tag, lane in (("predecessor", predecessor), ("successor", successor))
                    if lane is not None)
    return (f'<lane id="{lane_id}" type="driving" level="false"><link>{links}</link>{_WIDTH}'
            + _MARK.format(kind=mark) + "</lane>")


def _road(road_id: str, length: float, geometry: str, lanes: str, *, junction: str = "-1",
          predecessor: str = "", successor: str = "") -> str:
    """One ``<road>`` (town type, 50 km/h, flat) with one lane section."""
    return (f'  <road name="" length="{fmt(length)}" id="{road_id}" junction="{junction}" rule="RHT">'
            f"<link>{predecessor}{successor}</link>"
            '<type s="0" type="town"><speed max="50" unit="km/h"/></type>'
            f"<planView>{geometry}</planView><elevationProfile/><lateralProfile/>"
            f'<lanes><laneSection s="0">{lanes}</laneSection></lanes></road>\n')


def _link(tag: str, kind: str, element: str, contact: str | None = None) -> str:
    point = f' contactPoint="{contact}"' if contact else ""
    return f'<{tag} elementType="{kind}" elementId="{element}"{point}/>'


def _center(mark: str) -> str:
    return f'<center><lane id="0" type="none" level="false">{_MARK.format(kind=mark)}</lane></center>'


def _geometry(pose: Pose, length: float, shape: str) -> str:
    return (f'<geometry s="0" x="{fmt(pose.x)}" y="{fmt(pose.y)}" hdg="{fmt(normalize_angle(pose.hdg))}" '
            f'length="{fmt(length)}">{shape}</geometry>')


def chain(roads: int, seed: int, lanes_per_side: int = 1) -> Iterator[str]:
    """The chain map's text, piece by piece: ``lanes_per_side`` lanes each way, the outer
    ones marked solid, the others broken; the centre broken, solid with more than one lane
    per side."""
    rng = random.Random(seed)
    yield _HEADER.format(name=f"chain of {roads} roads", seed=seed)
    pose = Pose(0.0, 0.0, 0.0)
    curvature = 0.0
    centre = _center("broken" if lanes_per_side == 1 else "solid")
    for index in range(1, roads + 1):
        if (index - 1) % BLOCK_ROADS == 0:
            curvature = rng.uniform(-MAX_CURVATURE, MAX_CURVATURE)
        segment = arc(ROAD_LENGTH_M, curvature)
        side = [[_lane(sign * k, sign * k if index > 1 else None, sign * k if index < roads else None,
                       "solid" if k == lanes_per_side else "broken") for k in range(1, lanes_per_side + 1)]
                for sign in (1, -1)]
        lanes = "<left>" + "".join(reversed(side[0])) + "</left>" + centre + "<right>" + "".join(side[1]) + "</right>"
        yield _road(str(index), ROAD_LENGTH_M, _geometry(pose, ROAD_LENGTH_M, f'<arc curvature="{fmt(curvature)}"/>'),
                    lanes,
                    predecessor=_link("predecessor", "road", str(index - 1), "end") if index > 1 else "",
                    successor=_link("successor", "road", str(index + 1), "start") if index < roads else "")
        pose = end_pose(pose, segment)
    yield "</OpenDRIVE>\n"


def _gauss_length(speed: Callable[[float], float]) -> float:
    """∫₀¹ speed(p) dp, composite Gauss-Legendre (``GAUSS_PIECES`` × ``GAUSS_NODES``)."""
    import numpy as np

    nodes, weights = np.polynomial.legendre.leggauss(GAUSS_NODES)
    total = 0.0
    for piece in range(GAUSS_PIECES):
        low = piece / GAUSS_PIECES
        p = low + 0.5 * (nodes + 1.0) / GAUSS_PIECES
        total += float(np.sum(weights * np.array([speed(float(x)) for x in p]))) * 0.5 / GAUSS_PIECES
    return total


def hermite(start: Pose, end: Pose) -> tuple[str, float]:
    """The ``<paramPoly3>`` (normalised p) of the cubic Hermite curve from ``start`` to
    ``end`` with tangents as long as the chord, and its arc length (m)."""
    dx, dy = end.x - start.x, end.y - start.y
    chord = math.hypot(dx, dy)
    cos_h, sin_h = math.cos(start.hdg), math.sin(start.hdg)
    du, dv = dx * cos_h + dy * sin_h, -dx * sin_h + dy * cos_h
    turn = end.hdg - start.hdg
    t0u, t0v = chord, 0.0
    t1u, t1v = chord * math.cos(turn), chord * math.sin(turn)
    u = (0.0, t0u, 3.0 * du - 2.0 * t0u - t1u, -2.0 * du + t0u + t1u)
    v = (0.0, t0v, 3.0 * dv - 2.0 * t0v - t1v, -2.0 * dv + t0v + t1v)

    def speed(p: float) -> float:
        return math.hypot(u[1] + p * (2.0 * u[2] + 3.0 * p * u[3]), v[1] + p * (2.0 * v[2] + 3.0 * p * v[3]))

    names = "abcd"
    coefficients = " ".join(f'{names[k]}U="{fmt(u[k])}" {names[k]}V="{fmt(v[k])}"' for k in range(4))
    return f'<paramPoly3 {coefficients} pRange="normalized"/>', _gauss_length(speed)


def junction(arms: int, seed: int, parallel: bool = False) -> Iterator[str]:
    """The junction map's text, piece by piece (the seed turns the arms' spread). With
    ``parallel``: arms² incoming roads side by side, each joined to the outgoing road
    straight ahead only (the same number of connections, none crossing another)."""
    rng = random.Random(seed)
    yield _HEADER.format(name=f"junction of {arms * arms} connections", seed=seed)
    turn = rng.uniform(-0.1, 0.1)
    one_lane = _center("none") + "<right>{lane}</right>"
    entries, exits = [], []
    count = arms * arms if parallel else arms
    for index in range(count):
        if parallel:
            across = Pose(-math.sin(turn), math.cos(turn), turn)
            entry = Pose(index * LANE_WIDTH_M * across.x, index * LANE_WIDTH_M * across.y, turn)
            exit_ = Pose(entry.x + ARM_LENGTH_M * math.cos(turn), entry.y + ARM_LENGTH_M * math.sin(turn), turn)
        else:
            fraction = (index + 0.5) / arms - 0.5
            west = math.pi + turn + QUARTER_RAD * fraction
            east = turn - QUARTER_RAD * fraction
            entry = Pose(JUNCTION_RADIUS_M * math.cos(west), JUNCTION_RADIUS_M * math.sin(west), west + math.pi)
            exit_ = Pose(JUNCTION_RADIUS_M * math.cos(east), JUNCTION_RADIUS_M * math.sin(east), east)
        far = Pose(entry.x - ARM_LENGTH_M * math.cos(entry.hdg), entry.y - ARM_LENGTH_M * math.sin(entry.hdg), entry.hdg)
        yield _road(f"in{index}", ARM_LENGTH_M, _geometry(far, ARM_LENGTH_M, "<line/>"),
                    one_lane.format(lane=_lane(-1, None, None, "solid")), successor=_link("successor", "junction", "J"))
        yield _road(f"out{index}", ARM_LENGTH_M, _geometry(exit_, ARM_LENGTH_M, "<line/>"),
                    one_lane.format(lane=_lane(-1, None, None, "solid")), predecessor=_link("predecessor", "junction", "J"))
        entries.append(entry)
        exits.append(exit_)
    connections = []
    for i, entry in enumerate(entries):
        for j, exit_ in enumerate(exits):
            if parallel and i != j:
                continue
            road_id = f"c{i}_{j}"
            shape, length = hermite(entry, exit_)
            yield _road(road_id, length, _geometry(entry, length, shape),
                        one_lane.format(lane=_lane(-1, -1, -1, "none")), junction="J",
                        predecessor=_link("predecessor", "road", f"in{i}", "end"),
                        successor=_link("successor", "road", f"out{j}", "start"))
            connections.append(f'    <connection id="{len(connections)}" incomingRoad="in{i}" connectingRoad="{road_id}" '
                               'contactPoint="start"><laneLink from="-1" to="-1"/></connection>\n')
    yield '  <junction id="J" name="big">\n' + "".join(connections) + "  </junction>\n</OpenDRIVE>\n"


def write(pieces: Iterator[str], path: Path) -> None:
    """Write the pieces to ``path`` (UTF-8) through a temporary file, then rename."""
    partial = path.with_name(f".{path.name}.partial")
    with partial.open("w", encoding="utf-8") as handle:
        for piece in pieces:
            handle.write(piece)
    partial.replace(path)


def _cpu(action: Callable[[], object]) -> tuple[float, object]:
    start = time.process_time()
    result = action()
    return time.process_time() - start, result


def bench(path: Path, frames: int, routing: bool = False) -> None:
    """CPU seconds of ``cold-maps info`` (read + ``map_info``) and of the ground-truth
    preparation of ``cold-eval`` (read, engine conversion to Lanelet2 without cache — which
    builds the lane graph it needs, as in ``Evaluator.prepare`` —, ``lanelet2.io.load``,
    ``GroundTruth``, whose routing relations are computed per lanelet when frames reach
    it), then, with ``routing``, lanelet2's
    ``RoutingGraph`` of the converted map (what a user of ``cold-maps convert`` builds;
    not part of ``cold-eval``), and with ``frames`` > 0 a small ``cold-eval`` (one route
    of ``frames`` frames) end to end."""
    import tempfile

    import lanelet2.io

    from cold_maps.cli.maps import map_info
    from cold_maps.groundtruth.lanelet2_from_engine import engine_converter
    from cold_maps.opendrive.parser import load_opendrive
    from converters import convert, frame, routing_graph
    from gt_matching import GroundTruth

    info_read, odr_map = _cpu(lambda: load_opendrive(path))
    info_rest, _ = _cpu(lambda: map_info(odr_map))
    info = info_read + info_rest
    print(f"{path.name} ({path.stat().st_size / 1e6:.1f} MB, {len(odr_map.roads)} roads)", flush=True)
    print(f"  cold-maps info: read {info_read:.2f} s + summary {info_rest:.2f} s = {info:.2f} s CPU", flush=True)
    with tempfile.TemporaryDirectory(prefix="big-maps-") as folder:
        osm = Path(folder) / "gt.osm"
        stages = {}
        stages["read"], gt_map = _cpu(lambda: load_opendrive(path))
        stages["convert"], _ = _cpu(lambda: convert(path, osm, cache=False, converter=engine_converter(gt_map)))
        print("  ground truth: " + ", ".join(f"{k} {v:.2f} s" for k, v in stages.items()), end="", flush=True)
        stages["lanelet2 load"], lanelet_map = _cpu(lambda: lanelet2.io.load(str(osm), frame.projector()))
        print(f", lanelet2 load {stages['lanelet2 load']:.2f} s", end="", flush=True)
        stages["GroundTruth"], _ = _cpu(lambda: GroundTruth(lanelet_map, prepare_all=False))
        total = sum(stages.values())
        print(f", GroundTruth {stages['GroundTruth']:.2f} s = {total:.2f} s CPU = {total / info:.2f} x info", flush=True)
        if routing:
            graph_s, _ = _cpu(lambda: routing_graph(lanelet_map))
            print(f"  lanelet2 RoutingGraph of the converted map: {graph_s:.2f} s CPU", flush=True)
        if frames > 0:
            from cold_maps.cli import evaluate

            eval_s, status = _cpu(lambda: evaluate.main([
                "--map", str(path), "--routes", "1", "--frames", str(frames), "--workers", "1", "--no-mcap",
                "--no-plots", "-q", "--out", str(Path(folder) / "eval")]))
            print(f"  cold-eval --routes 1 --frames {frames}: exit {status}, {eval_s:.2f} s CPU", flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest="command", required=True)
    chain_parser = commands.add_parser("chain", help="one-metre roads linked end to end")
    chain_parser.add_argument("out", type=Path)
    chain_parser.add_argument("--roads", type=int, default=100_000)
    chain_parser.add_argument("--lanes", type=int, default=1, help="driving lanes per direction")
    chain_parser.add_argument("--seed", type=int, default=0)
    junction_parser = commands.add_parser("junction", help="a junction of arms² connections")
    junction_parser.add_argument("out", type=Path)
    junction_parser.add_argument("--arms", type=int, default=100)
    junction_parser.add_argument("--seed", type=int, default=0)
    junction_parser.add_argument("--parallel", action="store_true",
                                 help="arms² side-by-side arms, each joined straight ahead (no crossing connections)")
    bench_parser = commands.add_parser("bench", help="cold-maps info vs ground-truth preparation (CPU time)")
    bench_parser.add_argument("maps", nargs="+", type=Path)
    bench_parser.add_argument("--frames", type=int, default=20, help="frames of the cold-eval run (0: none)")
    bench_parser.add_argument("--routing-graph", action="store_true",
                              help="also time lanelet2's RoutingGraph of the converted map (not part of cold-eval)")
    args = parser.parse_args(argv)
    if args.command == "chain":
        if args.roads < 1 or args.lanes < 1:
            parser.error("--roads and --lanes must be at least 1")
        write(chain(args.roads, args.seed, args.lanes), args.out)
    elif args.command == "junction":
        if args.arms < 1:
            parser.error("--arms must be at least 1")
        write(junction(args.arms, args.seed, args.parallel), args.out)
    else:
        for path in args.maps:
            bench(path, args.frames, args.routing_graph)
    return 0


if __name__ == "__main__":
    sys.exit(main())
