"""Progress displays for long work: a small one on stderr (renders, fits), and :func:`progress_bar`
(sweeps, sensitivity runs): tqdm with time left in terminals and notebooks, periodic lines in logs; and a job's
messages beside them (:func:`say`)."""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Callable
from typing import Any

ProgressCallback = Callable[[int, int], None]


def say(message: str, quiet: bool) -> None:
    """Print ``message`` on stderr at once, unless ``quiet``: what a job says beside its progress display."""
    if not quiet:
        print(message, file=sys.stderr, flush=True)


class Progress:
    """Prints ``label [#####.....] done/total elapsed`` on stderr, redrawn in place on a terminal.

    Call the instance with ``(done, total)``; it stays silent for work shorter than ``delay`` s.
    Where stderr is not a terminal (a log file), it writes a line at most every ``interval`` s,
    and at the end.
    """

    def __init__(self, label: str, delay: float = 0.5, width: int = 30, interval: float = 30.0, initial: int = 0) -> None:
        self.label, self.delay, self.width, self.interval, self.initial = label, delay, width, interval, initial
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
        if self.initial < done < total:
            line += f", about {elapsed / (done - self.initial) * (total - done):.0f} s left"
        tty = sys.stderr.isatty()
        if tty:
            sys.stderr.write("\r" + line + ("\n" if done == total else ""))
        elif done == total or elapsed - self.last_line >= self.interval:
            sys.stderr.write(line + "\n")
            self.last_line = elapsed
        sys.stderr.flush()
        self.shown = True


class _LogBar:
    """tqdm's ``update`` / ``close`` over :class:`Progress`: a line at most every ``interval`` s, with time left."""

    def __init__(self, total: int, label: str, initial: int, interval: float) -> None:
        self.total, self.n = total, initial
        self.progress = Progress(label, delay=0.0, interval=interval, initial=initial)

    def update(self, n: int = 1) -> None:
        self.n += n
        self.progress(self.n, self.total)

    def close(self) -> None:
        pass


def progress_bar(total: int, label: str, *, initial: int = 0, quiet: bool = False, interval: float = 30.0) -> Any:
    """A progress bar of ``total`` steps, ``initial`` of them already done (a resumed sweep):
    tqdm's with time left on a terminal, its widget in a notebook (with ipywidgets, else its text
    bar), and where stderr is a log file a line every ``interval`` s and at the end. Call
    ``update()`` after each step and ``close()`` at the end; ``quiet`` shows nothing."""
    from tqdm import tqdm  # here: only a long job shows a bar (tqdm takes 0.1 s to import)

    if quiet:
        return tqdm(total=total, initial=initial, disable=True)
    notebook = "ipykernel" in sys.modules
    if notebook or sys.stderr.isatty():
        try:
            import ipywidgets  # noqa: F401  (tqdm's notebook widget needs it)
            from tqdm.auto import tqdm as auto
        except ImportError:
            auto = tqdm
        return (auto if notebook else tqdm)(total=total, initial=initial, desc=label, unit="render", file=sys.stderr)
    return _LogBar(total, label, initial, interval)
