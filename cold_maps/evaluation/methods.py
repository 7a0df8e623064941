"""Fusion methods for the gap: the paper's and the Hermite spline, and your own.

The protocol
------------
A fusion method is a callable ``method(ego, coop, params) -> fusion.FusionResult``:

- ``ego``, ``coop``: :class:`fusion.LaneDetection` (reported pose in the world frame,
  borders ``(N, 2)`` float64 in the sender's vehicle frame, ISO 8855, m, driving order);
  the coop drives ahead of the ego, its detection starts about d_s beyond the ego's end.
- ``params``: :class:`fusion.FusionParams` of the run (d_i, sampling step, thresholds).
- returns a :class:`fusion.FusionResult` with ``left``/``right`` in the *world* frame (m),
  one ``fusion.Source`` per point, ``kind`` ``"spline"`` (or ``"convoy"``) when it fused,
  or ``kind="none"`` with the ego lane and a ``reason`` when the pair is not fusible
  (counted under ``rejected``); malformed input may raise ``fusion.FusionError``.

The evaluation measures the returned borders against the ground truth exactly as it
does the built-in methods (errors, perception range, runtime, fusibility) and reports them
as ``fusion = "spline"``, ``interpolation = <method name>``.

Naming a method
---------------
- a registered name: an entry point of the ``cold_maps.fusion_methods`` group
  (``[project.entry-points."cold_maps.fusion_methods"] mine = "my_pkg.fusion:mine"`` in
  your package's ``pyproject.toml``); the built-ins ``paper`` and ``hermite`` are
  registered so too, and also resolve without installed metadata;
- ``package.module:function``: imported directly (``cold-eval --method my_pkg.fusion:mine``),
  from the installed packages or, as ``python -m`` would, the current folder (appended to
  ``sys.path`` for the lookup and left there for the worker processes).

The name (as given) is what ``metrics.json``, ``frames.csv`` and the sweep tables show,
and what worker processes resolve again, so a ``module:function`` must be importable there
(on a Dask cluster: installed on the workers).
"""

from __future__ import annotations

import functools
import importlib
import os
import sys
from importlib.metadata import entry_points
from typing import Final, Protocol

import fusion

ENTRY_POINT_GROUP: Final[str] = "cold_maps.fusion_methods"


class FusionMethod(Protocol):
    """``(ego, coop, params) -> FusionResult``; see the module docstring."""

    def __call__(self, ego: fusion.LaneDetection, coop: fusion.LaneDetection,
                 params: fusion.FusionParams) -> fusion.FusionResult: ...


class MethodError(ValueError):
    """A fusion method name that does not resolve to a callable; the message names it."""


def paper(ego: fusion.LaneDetection, coop: fusion.LaneDetection, params: fusion.FusionParams) -> fusion.FusionResult:
    """Spline fusion with the paper's natural cubic spline through the apex (sec. III)."""
    return fusion.fuse(ego, coop, mode="spline", interpolation="paper", params=params)


def hermite(ego: fusion.LaneDetection, coop: fusion.LaneDetection, params: fusion.FusionParams) -> fusion.FusionResult:
    """Spline fusion with the G1 line-and-arc Hermite variant."""
    return fusion.fuse(ego, coop, mode="spline", interpolation="hermite", params=params)


BUILTIN_METHODS: Final[dict[str, FusionMethod]] = {"paper": paper, "hermite": hermite}


def _import(spec: str) -> FusionMethod:
    """``package.module:function`` imported."""
    module_name, _, attribute = spec.partition(":")
    if not module_name or not attribute:
        raise MethodError(f"fusion method {spec!r}: expected package.module:function")
    folder = os.getcwd()
    if not any(os.path.abspath(entry or os.curdir) == folder for entry in sys.path):
        sys.path.append(folder)
    try:
        target = importlib.import_module(module_name)
    except Exception as exc:  # noqa: BLE001 - whatever the module raises while it loads is named, not a traceback
        missing = isinstance(exc, ModuleNotFoundError) and exc.name is not None and (
            module_name == exc.name or module_name.startswith(f"{exc.name}."))
        if not missing:
            raise MethodError(f"fusion method {spec!r}: importing {module_name} failed: "
                              f"{type(exc).__name__}: {exc}") from None
        raise MethodError(f"fusion method {spec!r}: no module {exc.name} in the installed packages nor in the "
                          f"current folder {folder}: run from the folder that holds "
                          f"{module_name.replace('.', os.sep)}.py, or install its package") from None
    for part in attribute.split("."):
        if not hasattr(target, part):
            raise MethodError(f"fusion method {spec!r}: {module_name} has no {attribute}")
        target = getattr(target, part)
    if not callable(target):
        raise MethodError(f"fusion method {spec!r}: {attribute} is not callable")
    return target  # type: ignore[return-value]


def registered_methods() -> dict[str, str]:
    """Names registered in the ``cold_maps.fusion_methods`` entry-point group → their
    ``module:function``, the built-ins included."""
    found = {name: f"{__name__}:{name}" for name in BUILTIN_METHODS}
    found.update({ep.name: ep.value for ep in entry_points(group=ENTRY_POINT_GROUP)})
    return found


@functools.lru_cache(maxsize=None)
def resolve_method(name: str) -> FusionMethod:
    """The fusion method named ``name``: ``module:function``, a registered entry point or a
    built-in; raises :class:`MethodError` naming it otherwise."""
    if ":" in name:
        return _import(name)
    for point in entry_points(group=ENTRY_POINT_GROUP, name=name):
        return _import(point.value)
    if name in BUILTIN_METHODS:
        return BUILTIN_METHODS[name]
    raise MethodError(f"fusion method {name!r}: not registered (known: {', '.join(sorted(registered_methods()))}); "
                      "name one as package.module:function")
