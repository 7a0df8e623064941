"""On-disk cache of converted maps, keyed by content hash and converter version.

One file per (map content, converter kind and version, our format version), written atomically
(temporary file in the same folder, then ``os.replace``), so a concurrent reader sees
either nothing or the whole file. Temporary files are hidden (``.…tmp``) and never read.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Final

from converters import frame
from converters.atomic_io import atomic_output
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


def cache_path(
    content: bytes, converter_version: str, cache_dir: str | os.PathLike[str] | None = None, *, kind: str = "crdesigner"
) -> Path:
    """Cache file of a map with this content converted by this converter (kind and version)."""
    digest = hashlib.sha256(content).hexdigest()
    name = f"{digest}-{kind}{converter_version}-format{frame.FORMAT_VERSION}{CACHE_SUFFIX}"
    return cache_root(cache_dir) / name


def atomic_write(path: Path, data: bytes, *, create_folder: bool = False) -> None:
    """Write ``data`` to ``path`` atomically (:func:`converters.atomic_io.atomic_output`:
    mode 0666 less the umask); ``create_folder`` creates missing folders (the cache's own),
    else a missing folder is an error. Raises ConversionError naming ``path``."""
    try:
        if create_folder:
            path.parent.mkdir(parents=True, exist_ok=True)
        with atomic_output(path, "wb") as stream:
            stream.write(data)
    except OSError as exc:
        raise ConversionError(str(path), f"cannot write: {exc.strerror or exc}") from exc


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
