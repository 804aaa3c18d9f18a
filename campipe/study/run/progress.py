"""A progress line for a running study or replay: items done, the rate, the time left, then
what remains to be done once they are (writing the archive).

It writes through a callable (the CLI gives it stderr). In a terminal it redraws one line in
place, erasing what the previous drawing left and never wider than the terminal (a wrapped
line cannot be redrawn), and :meth:`Progress.close` erases it, so nothing stale stays on the
screen; elsewhere (a log file, a pipe) it prints a line at most every ``interval`` seconds.
While it is drawn, :func:`logging_cleared` lets a log message through on a clean line.
"""

from __future__ import annotations

import contextlib
import logging
import shutil
import time
from collections.abc import Callable, Iterator

#: Erase from the cursor to the end of the line (ANSI; every terminal campipe runs in).
ERASE = "\x1b[K"


def format_seconds(seconds: float) -> str:
    """``75.2`` → ``"1 min 15 s"``."""
    if seconds != seconds or seconds == float("inf"):
        return "?"
    if seconds < 1:
        return "under a second"
    s = int(round(seconds))
    if s < 60:
        return f"{s} s"
    if s < 3600:
        return f"{s // 60} min {s % 60:02d} s"
    return f"{s // 3600} h {s % 3600 // 60:02d} min"


class Progress:
    """Counts finished items and draws ``[####....] 37/117 cases  12.3 cases/s  6 s left``;
    once all are done, ``... 117/117 cases, writing the archive`` until :meth:`close`."""

    def __init__(
        self,
        total: int,
        write: Callable[[str], object],
        *,
        done: int = 0,
        terminal: bool = False,
        interval: float = 2.0,
        width: int = 24,
        clock: Callable[[], float] = time.monotonic,
        unit: str = "cases",
        then: str = "writing the archive",
        columns: int | None = None,
    ):
        self.total = total  # items in all
        self.done = done  # items finished (reused ones included)
        self.start_done = done  # items finished before this run
        self.write = write
        self.terminal = terminal  # redraw in place
        self.interval = interval  # [s] between lines when not a terminal
        self.width = width  # characters of the bar
        self.clock = clock
        self.unit = unit  # what is counted
        self.then = then  # what follows the last item, shown until close()
        self.columns = columns  # terminal width (default: asked of the terminal)
        self.started = clock()
        self._last = -float("inf")
        self._drawn = False  # a line is on the terminal, to be erased or ended
        if done >= total:
            self._draw()

    def line(self) -> str:
        elapsed = max(self.clock() - self.started, 1e-9)
        new = self.done - self.start_done
        rate = new / elapsed
        frac = self.done / self.total if self.total else 1.0
        bar = "#" * int(round(frac * self.width))
        head = f"[{bar:<{self.width}}] {self.done}/{self.total} {self.unit}"
        if self.done >= self.total:
            return f"{head}, {self.then}" if self.then else f"{head}, done"
        left = (self.total - self.done) / rate if rate > 0 else float("nan")
        per = self.unit.split()[0] if self.unit else ""
        return f"{head}  {rate:.3g} {per}/s  {format_seconds(left)} left"

    def restart(self) -> None:
        """Start the clock again: what came before (compiling the kernels, an estimate's
        timing) is not counted in the rate and the time left."""
        self.started = self.clock()

    def advance(self, items: int) -> None:
        self.done += items
        self._draw()

    def _draw(self) -> None:
        now = self.clock()
        finished = self.done >= self.total
        if self.terminal:
            self.write("\r" + self._fit(self.line()) + ERASE)
            self._drawn = True
        elif finished or now - self._last >= self.interval:
            self.write(self.line() + "\n")
            self._last = now

    def _fit(self, text: str) -> str:
        """``text`` cut to one character less than the terminal is wide (a line as wide as
        the terminal wraps on some, and a wrapped line cannot be redrawn)."""
        columns = self.columns or shutil.get_terminal_size((80, 24)).columns
        limit = max(columns - 1, 10)
        return text if len(text) <= limit else text[: limit - 1] + "…"

    def clear(self) -> None:
        """Erase the line (a terminal), so that other text starts on a clean line."""
        if self.terminal and self._drawn:
            self.write("\r" + ERASE)
            self._drawn = False

    def close(self) -> None:
        """The work is over: erase the line (a terminal); the caller reports the outcome."""
        self.clear()


@contextlib.contextmanager
def logging_cleared(current: Callable[[], Progress | None]) -> Iterator[None]:
    """While the block runs, a log record is written on a clean line: the progress line
    ``current()`` returns (None before there is one) is erased first, and drawn again at its
    next advance."""

    class _Clear(logging.Filter):
        def filter(self, record: logging.LogRecord) -> bool:
            progress = current()
            if progress is not None:
                progress.clear()
            return True

    handlers = logging.getLogger().handlers
    clear = _Clear()
    for handler in handlers:
        handler.addFilter(clear)
    try:
        yield
    finally:
        for handler in handlers:
            handler.removeFilter(clear)
