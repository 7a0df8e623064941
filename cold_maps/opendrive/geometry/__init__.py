"""Reference-line geometry records, one module per OpenDRIVE element, vectorised over ds.

``evaluate(geom, ds)`` dispatches on ``geom.kind``; every module returns inertial x, y (m)
and heading (rad) at arc length ds (m) from the record start, ds in [0, geom.length].
"""

from __future__ import annotations

from typing import Callable, Final, Mapping

import numpy as np

from cold_maps.opendrive.cubic_poly import NDArrayFloat
from cold_maps.opendrive.geometry import arc, line, param_poly3, poly3, spiral
from cold_maps.opendrive.model import Geometry

Evaluator = Callable[[Geometry, NDArrayFloat], tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]]

EVALUATORS: Final[Mapping[str, Evaluator]] = {
    "line": line.evaluate,
    "arc": arc.evaluate,
    "spiral": spiral.evaluate,
    "poly3": poly3.evaluate,
    "paramPoly3": param_poly3.evaluate,
}


def evaluate(geom: Geometry, ds: NDArrayFloat) -> tuple[NDArrayFloat, NDArrayFloat, NDArrayFloat]:
    """Inertial x, y (m) and heading (rad) at arc length ds (m) along one record; ValueError
    naming the record and s where they are not finite."""
    try:
        evaluator = EVALUATORS[geom.kind]
    except KeyError:
        raise ValueError(f"geometry at s={geom.s}: unknown kind {geom.kind!r}") from None
    if not geom.length > 0.0:
        raise ValueError(f"{geom.kind} geometry at s={geom.s}: length must be > 0, got {geom.length}")
    with np.errstate(over="ignore", invalid="ignore"):  # a non-finite pose is refused just below
        x, y, hdg = evaluator(geom, ds)
    bad = ~(np.isfinite(x) & np.isfinite(y) & np.isfinite(hdg))
    if np.any(bad):
        where = float(np.broadcast_to(ds, bad.shape)[bad].flat[0])
        raise ValueError(f"{geom.kind} geometry at s={geom.s:.6g}: the reference line is not finite at "
                         f"s={geom.s + where:.6g} m")
    return x, y, hdg
