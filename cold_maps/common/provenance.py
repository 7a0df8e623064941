"""How an output was made: one block for ``summary.md``, ``metrics.json``, the sweep's summary
and the recording's ``cold.run`` parameters.

:func:`recorded_params` turns a command's parsed options into the parameter mapping the
recording stores; :func:`make_provenance` adds the command line, the version and the input
files with their sha256. Nothing in it depends on the worker count or the clock, except the
command line itself (which says ``--workers`` when given).
"""

from __future__ import annotations

import hashlib
import shlex
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Final, Mapping, Sequence

READ_CHUNK_BYTES: Final[int] = 1 << 20
"""Bytes read at a time while hashing an input file."""


def file_sha256(path: str | Path) -> str:
    """Hex sha256 of a file's bytes."""
    digest = hashlib.sha256()
    with open(path, "rb") as stream:
        for chunk in iter(lambda: stream.read(READ_CHUNK_BYTES), b""):
            digest.update(chunk)
    return digest.hexdigest()


def recorded_params(options: Mapping[str, Any], unrecorded: frozenset[str] = frozenset()) -> dict[str, str]:
    """The options as text, sorted by name, without ``unrecorded``; an object with a
    ``describe()`` method (a sensor profile), or a sequence of them, by its description."""
    return {name: _text(value) for name, value in sorted(options.items()) if name not in unrecorded}


def _text(value: Any) -> str:
    """An option's value as text; described objects (and tuples of them) by ``describe()``."""
    if callable(getattr(value, "describe", None)):
        return str(value.describe())
    if isinstance(value, (tuple, list)) and value and all(callable(getattr(v, "describe", None)) for v in value):
        return "; ".join(str(v.describe()) for v in value)
    if isinstance(value, (tuple, list)):
        return ",".join(f"{v:g}" if isinstance(v, float) else str(v) for v in value)
    return str(value)


@dataclass(frozen=True)
class InputFile:
    """One file a run read.

    Fields:
        role: what it is ("map", "input").
        name: its file name; path: as given on the command line; sha256: hex digest of its bytes.
    """

    role: str
    name: str
    path: str
    sha256: str

    @classmethod
    def of(cls, role: str, path: str | Path) -> InputFile:
        """The record of the file at ``path``."""
        return cls(role, Path(path).name, str(path), file_sha256(path))


@dataclass(frozen=True)
class Provenance:
    """How an output was made.

    Fields:
        program: the command ("cold-eval", "cold-eval sweep", "cold-fuse").
        command: its command line, shell-quoted.
        version: the cold-maps version.
        seed: the seed(s) as given ("" when the command has none).
        sensor: the lane sensor profile's description (``SensorProfile.describe``), "" when none.
        inputs: the files read, in command-line order.
        params: every option as text (:func:`recorded_params`).
    """

    program: str
    command: str
    version: str
    seed: str
    sensor: str
    inputs: tuple[InputFile, ...]
    params: Mapping[str, str]

    def to_dict(self) -> dict[str, Any]:
        """The ``provenance`` object of ``metrics.json``."""
        return {"program": self.program, "command": self.command, "version": self.version, "seed": self.seed,
                "sensor": self.sensor,
                "inputs": [{"role": f.role, "name": f.name, "path": f.path, "sha256": f.sha256} for f in self.inputs],
                "params": dict(self.params)}

    def markdown(self) -> str:
        """The block at the top of a ``summary.md`` (the sensor once, on its own line)."""
        lines = ["## How this was made\n", f"- command: `{self.command}`", f"- version: cold-maps {self.version}"]
        if self.seed:
            lines.append(f"- seed: {self.seed}")
        lines += [f"- {f.role}: `{f.name}` sha256 `{f.sha256}`" for f in self.inputs]
        if self.sensor:
            lines.append(f"- {self.sensor}")
        lines.append("- parameters: " + ", ".join(f"`{name}={value}`" for name, value in self.params.items()
                                                  if name != "sensor" or not self.sensor))
        return "\n".join(lines) + "\n"


def make_provenance(program: str, argv: Sequence[str], params: Mapping[str, str], *,
                    inputs: Sequence[tuple[str, str | Path]] = ()) -> Provenance:
    """The provenance of a run of ``program`` with the arguments ``argv`` (after the program
    name), its :func:`recorded_params` and the files it read as (role, path); the seed and the
    sensor come from ``params["seed"]`` / ``params["seeds"]`` and ``params["sensor"]``."""
    from cold_maps import __version__

    return Provenance(program, shlex.join([*program.split(), *argv]), __version__,
                      params.get("seed", params.get("seeds", "")), params.get("sensor", ""),
                      tuple(InputFile.of(role, path) for role, path in inputs), dict(params))
