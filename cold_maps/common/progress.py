"""A terminal progress bar over tqdm: drawn only when its stream is a TTY."""

from __future__ import annotations

import functools
import sys
from types import TracebackType
from typing import Final, Self, TextIO

BAR_WIDTH_CHARS: Final[int] = 30
REDRAW_INTERVAL_S: Final[float] = 0.1
ERASE_LINE_END: Final[str] = "\x1b[K"
"""ANSI erase to the end of the line: a bar never shows what a longer line left (tqdm
counts no width for it)."""


def is_terminal(stream: TextIO) -> bool:
    """Whether ``stream`` is a TTY (progress is drawn only there)."""
    return bool(getattr(stream, "isatty", lambda: False)())


class _ClosedOnExit:
    """A context manager whose exit calls :meth:`close`."""

    def close(self) -> None:
        raise NotImplementedError

    def __enter__(self) -> Self:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()


@functools.cache
def _unmonitored_tqdm() -> type:
    """tqdm without its monitor thread, which only lowers a bar's ``miniters`` after a
    stall (a :class:`ProgressBar` redraws at every step past its interval anyway, a
    :class:`Spinner` from its own thread): a process stays single-threaded for the workers
    it forks once its bar is closed."""
    from tqdm import tqdm

    return type("UnmonitoredTqdm", (tqdm,), {"monitor_interval": 0})


class ProgressBar(_ClosedOnExit):
    """``label [#####.....] 12/100  ETA 00:03`` on one line of ``stream`` (stderr by default).

    Silent when the stream is not a TTY (logs, CI, pipes). Use as a context manager or
    call :meth:`close`, which ends the line. Redraws at most every ``min_interval_s``
    seconds, and always at the last step. Drawn by ``tqdm`` (imported when a bar is made).
    """

    def __init__(self, total: int, label: str = "", stream: TextIO | None = None,
                 width: int = BAR_WIDTH_CHARS, min_interval_s: float = REDRAW_INTERVAL_S):
        if isinstance(total, bool) or not isinstance(total, int) or total <= 0:
            raise ValueError(f"ProgressBar total: expected an integer > 0, got {total!r}")
        if width <= 0:
            raise ValueError(f"ProgressBar width: expected > 0 characters, got {width!r}")
        self.total = total
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.done = 0
        enabled = is_terminal(self.stream)
        prefix = "{desc} " if label else ""
        self._bar = _unmonitored_tqdm()(total=total, desc=label, file=self.stream, disable=not enabled, ascii=".#",
                         bar_format=prefix + "[{bar:%d}] {n_fmt}/{total_fmt}  ETA {remaining}%s"
                         % (width, ERASE_LINE_END),
                         mininterval=min_interval_s, miniters=1, dynamic_ncols=False)

    def update(self, steps: int = 1) -> None:
        """Advances by ``steps`` (clamped to the total) and redraws when due."""
        steps = min(steps, self.total - self.done)
        self.done += steps
        self._bar.update(steps)
        if self.done == self.total:
            self._bar.refresh()

    def close(self) -> None:
        """Ends the bar's line (only if something was drawn)."""
        self._bar.close()


SPINNER_DELAY_S: Final[float] = 1.0
"""A step that ends sooner draws nothing."""
SPINNER_INTERVAL_S: Final[float] = 0.5


class Spinner(_ClosedOnExit):
    """``label  00:12`` (elapsed time) on one line of ``stream`` (stderr by default) while a
    step of unknown length runs (a map conversion), redrawn every ``interval_s`` seconds by
    a background thread once ``delay_s`` seconds have passed. Silent when the stream is not a TTY; the line is
    cleared when it ends. Drawn by ``tqdm``, so log records written through ``tqdm.write``
    (see :func:`cold_maps.cli.common.configure_logging`) pass above it. A context manager.
    """

    def __init__(self, label: str, stream: TextIO | None = None, delay_s: float = SPINNER_DELAY_S,
                 interval_s: float = SPINNER_INTERVAL_S):
        import threading

        self.stream = sys.stderr if stream is None else stream
        self.interval_s = interval_s
        enabled = is_terminal(self.stream)
        self._bar = _unmonitored_tqdm()(total=None, desc=label, file=self.stream, disable=not enabled, leave=False,
                         bar_format="{desc}  {elapsed}", delay=delay_s, mininterval=0.0, miniters=0,
                         dynamic_ncols=False)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._redraw, name="spinner", daemon=True)
        if enabled:
            self._thread.start()

    def _redraw(self) -> None:
        while not self._stop.wait(self.interval_s):
            self._bar.update(0)  # draws once ``delay_s`` has passed; close() then clears the line

    def close(self) -> None:
        """Stops redrawing and clears the line."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join()
        self._bar.close()
