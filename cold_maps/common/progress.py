"""A terminal progress bar over tqdm: drawn only when its stream is a TTY."""

from __future__ import annotations

import sys
from types import TracebackType
from typing import Final, TextIO

BAR_WIDTH_CHARS: Final[int] = 30
REDRAW_INTERVAL_S: Final[float] = 0.1


class ProgressBar:
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
        from tqdm import tqdm

        self.total = total
        self.label = label
        self.stream = sys.stderr if stream is None else stream
        self.done = 0
        enabled = bool(getattr(self.stream, "isatty", lambda: False)())
        prefix = "{desc} " if label else ""
        self._bar = tqdm(total=total, desc=label, file=self.stream, disable=not enabled, ascii=".#",
                         bar_format=prefix + "[{bar:%d}] {n_fmt}/{total_fmt}  ETA {remaining}" % width,
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

    def __enter__(self) -> ProgressBar:
        return self

    def __exit__(self, exc_type: type[BaseException] | None, exc: BaseException | None,
                 tb: TracebackType | None) -> None:
        self.close()
