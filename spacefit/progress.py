"""A small progress display on stderr for long work (renders, sweeps, fits)."""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable

ProgressCallback = Callable[[int, int], None]


class Progress:
    """Prints ``label [#####.....] done/total elapsed`` on stderr, redrawn in place on a terminal.

    Call the instance with ``(done, total)``; it stays silent for work shorter than ``delay`` s.
    Where stderr is not a terminal (a log file), it writes a line at most every ``interval`` s,
    and at the end.
    """

    def __init__(self, label: str, delay: float = 0.5, width: int = 30, interval: float = 30.0) -> None:
        self.label, self.delay, self.width, self.interval = label, delay, width, interval
        self.start = time.perf_counter()
        self.shown = False
        self.last_line = -math.inf

    def __call__(self, done: int, total: int) -> None:
        elapsed = time.perf_counter() - self.start
        if elapsed < self.delay and done < total and not self.shown:
            return
        if done == total and not self.shown and elapsed < self.delay:
            return
        filled = int(self.width * done / max(total, 1))
        line = f"{self.label} [{'#' * filled}{'.' * (self.width - filled)}] {done}/{total} {elapsed:.1f} s"
        tty = sys.stderr.isatty()
        if tty:
            sys.stderr.write("\r" + line + ("\n" if done == total else ""))
        elif done == total or elapsed - self.last_line >= self.interval:
            sys.stderr.write(line + "\n")
            self.last_line = elapsed
        sys.stderr.flush()
        self.shown = True
