"""Parameter sweeps: a grid of cells (map × gap d_s × fusion method × sensor × error level ×
seed),
each one independent evaluation, run in this process, in local worker processes or on a
Dask cluster, stored cell by cell so that an interrupted sweep resumes.

A cell evaluates ``local``, ``convoy`` and ``spline`` with its method at its gap d_s on
its map (``routes`` drives of ``frames`` frames, seeded by its seed, its lane sensor
profile, sensor noise σ and coop pose σ from its error level). Its rows, one per fusion × boundary, are the
``metrics.json`` records flattened (``runtime_ms_mean``, ``fusibility_precision``, …,
``rejected`` as JSON text) plus the cell's parameters (``cell_*`` columns, with the version
that computed it and its sensor profile's every parameter, :func:`cell_provenance`). Each finished
cell is written atomically to ``DIR/cells/<key>.json``; the key is a hash of the cell's
parameters and its map's sha256, so a restarted sweep with the same arguments computes
only the missing cells, and a changed map file is never mixed with old results.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import logging
import tempfile
from concurrent.futures import Executor, Future, as_completed
from contextlib import AbstractContextManager, contextmanager, nullcontext
from dataclasses import dataclass
from dataclasses import fields as dataclass_fields
from pathlib import Path
from typing import Any, Callable, Final, Iterator, Sequence

from cold_maps.simulation.sensor_profile import IDEAL, SensorProfile
from converters.atomic_io import atomic_output

LOG = logging.getLogger("cold_maps.evaluation.sweep")

CELL_FORMAT_VERSION: Final[int] = 2
"""Version of the stored cell files; part of every cell key (2: cells have a sensor)."""
CELLS_DIR: Final[str] = "cells"
RESULTS_PARQUET: Final[str] = "results.parquet"
RESULTS_CSV: Final[str] = "results.csv"
MAPS_TEMP_DIR: Final[str] = "cold-maps-sweep-maps"
"""Folder under the worker's temporary directory where shipped maps are written."""


class SweepError(ValueError):
    """A sweep that cannot run as asked (bad map, bad grid); the message names the cause."""


@dataclass(frozen=True)
class Cell:
    """One work unit of a sweep.

    Fields:
        map_path: the map file on the machine that started the sweep.
        map_name: its name (file stem), the ``map`` column.
        map_sha256: hex sha256 of its bytes.
        d_s_m: spline gap (m).
        interpolation: fusion method across the gap (see :mod:`methods`).
        noise_sigma_m: sensor noise σ (m).
        pose_sigma_xy_m: coop pose error σ in x and y (m).
        seed: seed of routes and error models.
        frames: frames per drive.
        routes: drives on the map.
        sensor: the lane sensor's profile (``simulation.sensor_profile``).
    """

    map_path: str
    map_name: str
    map_sha256: str
    d_s_m: float
    interpolation: str
    noise_sigma_m: float
    pose_sigma_xy_m: float
    seed: int
    frames: int
    routes: int
    sensor: SensorProfile = IDEAL

    def params(self) -> dict[str, Any]:
        """The cell's parameters as ``cell_*`` columns (the map path left out: a moved file
        with the same bytes is the same cell; the sensor by its profile's name)."""
        fields = {f.name: getattr(self, f.name) for f in dataclass_fields(self) if f.name != "map_path"}
        fields["sensor"] = self.sensor.name
        return {f"cell_{name}": value for name, value in fields.items()}

    @property
    def key(self) -> str:
        """Hex sha256 of the parameters, every parameter of the sensor profile, the map's
        sha256 and the cell format (64 chars)."""
        text = json.dumps({"format": CELL_FORMAT_VERSION, **self.params(), "sensor_profile": self.sensor.describe()},
                          sort_keys=True)
        return hashlib.sha256(text.encode()).hexdigest()


@dataclass(frozen=True)
class SweepSpec:
    """The grid of a sweep; cells are the product of every axis, in this order.

    Fields:
        maps: map files.
        gaps_m: spline gaps d_s (m).
        interpolations: fusion method names.
        sensors: lane sensor profiles.
        noise_sigmas_m: sensor noise levels σ (m).
        pose_sigmas_xy_m: coop pose error levels σ (m).
        seeds: seeds.
        frames: frames per drive.
        routes: drives per map and cell.
    """

    maps: tuple[Path, ...]
    gaps_m: tuple[float, ...]
    interpolations: tuple[str, ...]
    noise_sigmas_m: tuple[float, ...]
    pose_sigmas_xy_m: tuple[float, ...]
    seeds: tuple[int, ...]
    frames: int
    routes: int
    sensors: tuple[SensorProfile, ...] = (IDEAL,)

    def cells(self) -> list[Cell]:
        """Every cell, maps read (and hashed) once; raises :class:`SweepError` for a map
        that cannot be read, two maps or two sensor profiles with one name."""
        sensors = [sensor.name for sensor in self.sensors]
        if len(set(sensors)) < len(sensors):
            raise SweepError(f"--sensor: two profiles share a name ({', '.join(sensors)}); the report keys results "
                             "by sensor name: give every TOML file its own name")
        names: dict[str, Path] = {}
        digests = []
        for path in self.maps:
            if path.stem in names:
                raise SweepError(f"--map {names[path.stem]} and --map {path} share the name {path.stem!r}")
            names[path.stem] = path
            try:
                digests.append(hashlib.sha256(path.read_bytes()).hexdigest())
            except OSError as exc:
                raise SweepError(f"{path}: cannot read the map: {exc.strerror or exc}") from None
        return [Cell(str(path), path.stem, digest, float(gap), method, float(noise), float(pose), int(seed),
                     self.frames, self.routes, sensor)
                for (path, digest), gap, method, sensor, noise, pose, seed in itertools.product(
                    zip(self.maps, digests), self.gaps_m, self.interpolations, self.sensors, self.noise_sigmas_m,
                    self.pose_sigmas_xy_m, self.seeds)]


def cell_plan(cell: Cell, path: Path) -> Any:
    """The :class:`MapPlan` of ``cell`` on the map file ``path``."""
    from cold_maps.evaluation.scenarios import MapPlan, params_for_gaps, scenarios_for
    from cold_maps.simulation.sensor_errors import SensorErrorModel

    errors = SensorErrorModel(noise_sigma_m=cell.noise_sigma_m, pose_sigma_xy_m=cell.pose_sigma_xy_m)
    return MapPlan(path, scenarios_for([cell.d_s_m], [cell.interpolation]), frames=cell.frames, routes=cell.routes,
                   seed=cell.seed, errors=errors, params=params_for_gaps([cell.d_s_m]), sensor=cell.sensor)


def _shipped_map(cell: Cell, data: bytes) -> Path:
    """``data`` (the cell's map) as a file named like the map, in this machine's temporary
    folder under its sha256 (written once, atomically)."""
    if hashlib.sha256(data).hexdigest() != cell.map_sha256:
        raise SweepError(f"{cell.map_name}: the map bytes received do not match its sha256")
    path = Path(tempfile.gettempdir()) / MAPS_TEMP_DIR / cell.map_sha256 / f"{cell.map_name}.xodr"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_output(path, "wb") as stream:
            stream.write(data)
    return path


def _local_map(cell: Cell) -> Path:
    """The cell's map file, checked to still hold the bytes the cell was keyed by."""
    path = Path(cell.map_path)
    if hashlib.sha256(path.read_bytes()).hexdigest() != cell.map_sha256:
        raise SweepError(f"{path}: the map changed during the sweep")
    return path


def flat_record(record: dict[str, Any]) -> dict[str, Any]:
    """A ``metrics.json`` record as one flat row: nested numbers as ``<key>_<name>``,
    the rejection counts and any deeper structure (counts by kind, precision-recall
    points) as JSON text, so every column is a scalar."""
    row = {}
    for name, value in record.items():
        if name == "rejected":
            row[name] = json.dumps(value, sort_keys=True)
        elif isinstance(value, dict):
            row.update({f"{name}_{part}": json.dumps(item, sort_keys=True) if isinstance(item, (dict, list)) else item
                        for part, item in value.items()})
        else:
            row[name] = value
    return row


def run_cell(cell: Cell, map_bytes: bytes | None = None) -> list[dict[str, Any]]:
    """Evaluates one cell (in any process or on any Dask worker); ``map_bytes``: the map
    shipped with the cell, else it is read from ``cell.map_path``. Returns its rows."""
    from cold_maps.evaluation.collector import Collector
    from cold_maps.evaluation.parallel import cached_evaluator
    from cold_maps.evaluation.report import scenario_results

    path = _local_map(cell) if map_bytes is None else _shipped_map(cell, map_bytes)
    collector = Collector()
    try:
        cached_evaluator(cell_plan(cell, path)).run(collector)
        made = cell_provenance(cell)
        return [{**flat_record(result.to_dict()), **cell.params(), **made}
                for result in scenario_results(collector.accumulators.values())]
    finally:
        collector.spool.close()  # its records' files: a long sweep leaves none behind


def cell_provenance(cell: Cell) -> dict[str, str]:
    """The columns saying how a cell's rows were made beside its ``cell_*`` parameters: the
    cold-maps version that computed it and every parameter of its sensor profile."""
    from cold_maps import __version__

    return {"cell_version": __version__, "cell_sensor_profile": cell.sensor.describe()}


def _cell_file(out: Path, cell: Cell) -> Path:
    return out / CELLS_DIR / f"{cell.key}.json"


def load_cell(out: Path, cell: Cell) -> list[dict[str, Any]] | None:
    """The stored rows of ``cell``, or None when it was not finished (or its file is not
    a cell file of this format for this cell)."""
    path = _cell_file(out, cell)
    try:
        document = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(document, dict) or document.get("cell") != cell.params() or "rows" not in document:
        LOG.warning("%s: not a stored result of this cell; computing it again", path)
        return None
    return document["rows"]


def store_cell(out: Path, cell: Cell, rows: list[dict[str, Any]]) -> None:
    """Writes the rows of a finished cell atomically."""
    path = _cell_file(out, cell)
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_output(path) as stream:
        json.dump({"format": CELL_FORMAT_VERSION, "cell": cell.params(), "rows": rows}, stream)


@contextmanager
def dask_executor(address: str) -> Iterator[Executor]:
    """A ``concurrent.futures`` executor on the Dask cluster at ``address``
    (``tcp://HOST:PORT``); pending cells are cancelled on an exception."""
    from distributed import Client

    try:
        client = Client(address, timeout="20s")
    except OSError as exc:
        raise SweepError(f"--scheduler {address}: cannot connect: {exc}") from None
    executor = client.get_executor(pure=False)
    try:
        yield executor
    except BaseException:
        executor.shutdown(wait=False)
        raise
    finally:
        client.close()


@dataclass(frozen=True)
class SweepResult:
    """What a sweep did.

    Fields:
        cells: every cell of the grid.
        rows: the rows of the finished cells, in grid order.
        computed: cells computed in this run.
        reused: cells found finished from an earlier run.
        error: the exception that ended it early (Ctrl-C included), or None.
    """

    cells: list[Cell]
    rows: list[dict[str, Any]]
    computed: int
    reused: int
    error: BaseException | None

    @property
    def partial(self) -> bool:
        """True when cells are missing."""
        return self.error is not None


def check_cells(cells: Sequence[Cell]) -> None:
    """Before any cell runs: every method resolves, every map parses, its drives fit the
    longest gap and its ground truth converts (cached for the workers)."""
    from cold_maps.evaluation.methods import resolve_method
    from cold_maps.evaluation.parallel import cached_evaluator

    for name in dict.fromkeys(cell.interpolation for cell in cells):
        resolve_method(name)
    longest: dict[str, Cell] = {}
    for cell in cells:
        if cell.map_name not in longest or cell.d_s_m > longest[cell.map_name].d_s_m:
            longest[cell.map_name] = cell
    for cell in longest.values():
        path = Path(cell.map_path)
        LOG.info("%s: checking the drives and preparing ground truth", path)
        cached_evaluator(cell_plan(cell, path))


def run_sweep(spec: SweepSpec, out: Path, *, executor: AbstractContextManager[Executor] | None = None,
              ship_maps: bool = False, on_cells: Callable[[int], None] | None = None,
              cells: Sequence[Cell] | None = None) -> SweepResult:
    """Runs the missing cells of ``spec`` (in this process without ``executor``), stores
    each as it finishes and returns the rows of all finished cells in grid order.
    ``ship_maps``: send each map's bytes with its cells (workers without the maps' path).
    Bad input raises before any cell runs; an exception during the run (Ctrl-C included)
    ends it, returned in the result with the cells finished so far. ``cells``: ``spec.cells()``
    when the caller has them already (each reads and hashes every map)."""
    cells = spec.cells() if cells is None else list(cells)
    done = {cell.key: rows for cell in cells if (rows := load_cell(out, cell)) is not None}
    todo = [cell for cell in cells if cell.key not in done]
    reused = len(done)
    LOG.info("%d cells, %d finished before, %d to compute", len(cells), reused, len(todo))
    if todo:
        check_cells(todo)
    if on_cells is not None and reused:
        on_cells(reused)
    data = {cell.map_sha256: Path(cell.map_path).read_bytes() for cell in todo} if ship_maps else {}
    error: BaseException | None = None

    def finish(cell: Cell, rows: list[dict[str, Any]]) -> None:
        store_cell(out, cell, rows)
        done[cell.key] = rows
        if on_cells is not None:
            on_cells(1)

    try:
        with executor if executor is not None else nullcontext() as pool:
            if pool is None:
                for cell in todo:
                    finish(cell, run_cell(cell))
            else:
                futures: dict[Future[list[dict[str, Any]]], Cell] = {
                    pool.submit(run_cell, cell, data.get(cell.map_sha256)): cell for cell in todo}
                for future in as_completed(futures):
                    finish(futures[future], future.result())
    except (KeyboardInterrupt, Exception) as exc:  # noqa: BLE001 - finished cells are kept, the rest resumes later
        error = exc
        LOG.debug("sweep ended early", exc_info=True)
    rows = [row for cell in cells if cell.key in done for row in done[cell.key]]
    return SweepResult(cells, rows, len(done) - reused, reused, error)


def write_tables(out: Path, rows: Sequence[dict[str, Any]]) -> None:
    """``results.parquet`` and ``results.csv`` (one row per cell × fusion × boundary),
    each written atomically; columns are the union of the rows' keys in first-seen order."""
    import csv

    import pyarrow as pa
    import pyarrow.parquet as pq

    columns = list(dict.fromkeys(name for row in rows for name in row))
    table = pa.Table.from_pylist([{name: row.get(name) for name in columns} for row in rows])
    with atomic_output(out / RESULTS_PARQUET, "wb") as stream:
        pq.write_table(table, stream)
    with atomic_output(out / RESULTS_CSV) as stream:
        writer = csv.DictWriter(stream, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        writer.writerows(rows)
