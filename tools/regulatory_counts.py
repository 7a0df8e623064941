"""Regulatory elements and tag-check findings of the converted ground truth, per map and
converter (engine and crdesigner), side by side.

Per map and converter: lanelets, regulatory elements by subtype (speed_limit,
traffic_light, right_of_way, traffic_sign), stop lines, lanelets that reference a
regulatory element, and the findings of ``converters.validation.validate_osm`` (the
lanelet2_validation checks): errors, warnings outside the namespaced tags
(``outside_namespaces``) and all warnings.

    python tools/regulatory_counts.py MAP.xodr ... [--converter engine --converter crdesigner]
"""

from __future__ import annotations

import argparse
import sys
import tempfile
from collections import Counter
from pathlib import Path
from typing import Final, Sequence

PROJECT_ROOT: Final[Path] = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(PROJECT_ROOT))


def counts(xodr: Path, converter_name: str, folder: Path) -> str:
    """One line of counts for ``xodr`` converted by ``converter_name`` (no cache)."""
    import lanelet2.io

    from cold_maps.groundtruth.lanelet2_from_engine import converter_named
    from converters import convert, frame
    from converters.validation import outside_namespaces, validate_osm

    osm = folder / f"{xodr.stem}-{converter_name}.osm"
    convert(xodr, osm, cache=False, converter=converter_named(converter_name))
    lanelet_map = lanelet2.io.load(str(osm), frame.projector())
    subtypes = Counter(str(element.attributes["subtype"]) for element in lanelet_map.regulatoryElementLayer)
    stop_lines = sum(1 for line in lanelet_map.lineStringLayer if line.attributes["type"] == "stop_line")
    governed = sum(1 for lanelet in lanelet_map.laneletLayer if len(lanelet.regulatoryElements))
    issues = validate_osm(osm)
    errors = [issue for issue in issues if issue.severity == "error"]
    warnings = [issue for issue in issues if issue.severity == "warning"]
    outside = [issue for issue in outside_namespaces(issues) if issue.severity == "warning"]
    by_subtype = ", ".join(f"{name} {count}" for name, count in sorted(subtypes.items())) or "-"
    return (f"{xodr.name} {converter_name}: {len(lanelet_map.laneletLayer)} lanelets; "
            f"{sum(subtypes.values())} regulatory elements ({by_subtype}); {stop_lines} stop lines; "
            f"{governed} lanelets with a regulatory element; tag checks: {len(errors)} errors, "
            f"{len(outside)} warnings outside the opendrive:/commonroad: tags, {len(warnings)} warnings in all")


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("maps", nargs="+", type=Path)
    parser.add_argument("--converter", action="append", choices=("engine", "crdesigner"),
                        help="converter (repeatable; default both)")
    args = parser.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="regulatory-counts-") as folder:
        for xodr in args.maps:
            for name in args.converter or ("engine", "crdesigner"):
                print(counts(xodr, name, Path(folder)), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
