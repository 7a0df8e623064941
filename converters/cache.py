"""On-disk cache of converted maps, keyed by content hash and converter version.

One file per (map content, crdesigner version, our format version), written atomically
(temporary file in the same folder, then ``os.replace``), so a concurrent reader sees
either nothing or the whole file. Temporary files are hidden (``.…tmp``) and never read.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path
from typing import Final

from converters import frame
from converters.errors import ConversionError

CACHE_DIR_ENV: Final[str] = "COLD_MAPS_CACHE_DIR"
"""Environment variable overriding the cache folder."""

CACHE_SUFFIX: Final[str] = ".osm"


def cache_root(cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """The cache folder: ``cache_dir``, else $COLD_MAPS_CACHE_DIR, else
    $XDG_CACHE_HOME/cold-maps, else ~/.cache/cold-maps."""
    if cache_dir is not None:
        return Path(cache_dir)
    if os.environ.get(CACHE_DIR_ENV):
        return Path(os.environ[CACHE_DIR_ENV])
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "cold-maps"


def cache_path(content: bytes, converter_version: str, cache_dir: str | os.PathLike[str] | None = None) -> Path:
    """Cache file of a map with this content converted by this crdesigner version."""
    digest = hashlib.sha256(content).hexdigest()
    name = f"{digest}-crdesigner{converter_version}-format{frame.FORMAT_VERSION}{CACHE_SUFFIX}"
    return cache_root(cache_dir) / name


def atomic_write(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder + os.replace.

    Raises ConversionError naming ``path`` when the folder cannot be created or written.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    except OSError as exc:
        raise ConversionError(str(path), f"cannot write: {exc.strerror or exc}") from exc
    try:
        with os.fdopen(handle, "wb") as stream:
            stream.write(data)
            stream.flush()
            os.fsync(stream.fileno())
        os.replace(temporary, path)
    except BaseException as exc:
        Path(temporary).unlink(missing_ok=True)
        if isinstance(exc, OSError):
            raise ConversionError(str(path), f"cannot write: {exc.strerror or exc}") from exc
        raise


def clear_cache(cache_dir: str | os.PathLike[str] | None = None) -> int:
    """Delete the cached conversions (and stray temporary files); return how many files."""
    root = cache_root(cache_dir)
    if not root.is_dir():
        return 0
    removed = 0
    for entry in root.iterdir():
        ours = entry.name.endswith(CACHE_SUFFIX) or (entry.name.startswith(".") and entry.name.endswith(".tmp"))
        if ours and entry.is_file():
            entry.unlink(missing_ok=True)
            removed += 1
    return removed
