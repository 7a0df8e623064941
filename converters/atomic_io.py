"""Atomic output files: written to a temporary file in the target folder, renamed into place.

The one atomic-write helper of the project: the converter's cache and ``-o`` files, the
exports and the evaluation reports all go through :func:`atomic_output`.

A reader never sees a half-written file, and a failure leaves the target as it was. The
finished file gets the ordinary mode of a new file (0666 less the umask), not the private
mode of a temporary file. A target that exists and is not a regular file (a device such as
``/dev/stdout``, a FIFO) is written in place: it is never replaced. A missing folder is an
error, never created on the way.
"""

from __future__ import annotations

import errno
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import IO, Literal


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


@contextmanager
def atomic_output(path: str | os.PathLike[str], mode: Literal["w", "wb"] = "w") -> Iterator[IO]:
    """A stream to write ``path`` through: text (UTF-8, no newline translation) or binary.

    On normal exit the data is flushed to disk and renamed onto ``path``; on any exception
    the temporary file is removed and the exception propagates.
    """
    path = Path(path)
    text = {"encoding": "utf-8", "newline": ""} if mode == "w" else {}
    if path.exists() and not path.is_file():
        with open(path, mode, **text) as stream:
            yield stream
        return
    if not path.parent.is_dir():
        raise FileNotFoundError(errno.ENOENT, "no such folder", str(path.parent))
    handle, temp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    try:
        with os.fdopen(handle, mode, **text) as stream:
            yield stream
            stream.flush()
            os.fsync(stream.fileno())
        os.chmod(temp, 0o666 & ~_umask())
        os.replace(temp, path)
    except BaseException:
        Path(temp).unlink(missing_ok=True)
        raise
