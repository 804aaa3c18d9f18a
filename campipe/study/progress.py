"""A progress line for a running study: cases done, rate and time left.

It writes through a callable (the CLI gives it stderr), redrawing one line in a terminal and
printing a new line at most every ``interval`` seconds otherwise.
"""

from __future__ import annotations

import time
from collections.abc import Callable


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
    """Counts finished cases and draws ``[####....] 37/117 cases  12.3 cases/s  6 s left``."""

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
    ):
        self.total = total  # cases in the study
        self.done = done  # cases finished (reused ones included)
        self.start_done = done  # cases finished before this run
        self.write = write
        self.terminal = terminal  # redraw in place
        self.interval = interval  # [s] between lines when not a terminal
        self.width = width
        self.clock = clock
        self.started = clock()
        self._last = -float("inf")

    def line(self) -> str:
        elapsed = max(self.clock() - self.started, 1e-9)
        new = self.done - self.start_done
        rate = new / elapsed
        left = (self.total - self.done) / rate if rate > 0 else float("nan")
        frac = self.done / self.total if self.total else 1.0
        bar = "#" * int(round(frac * self.width))
        return (
            f"[{bar:<{self.width}}] {self.done}/{self.total} cases  {rate:.3g} cases/s  "
            f"{format_seconds(left) if self.done < self.total else 'done'}"
            + (" left" if self.done < self.total else "")
        )

    def advance(self, cases: int) -> None:
        self.done += cases
        now = self.clock()
        finished = self.done >= self.total
        if self.terminal:
            self.write("\r" + self.line() + ("\n" if finished else ""))
        elif finished or now - self._last >= self.interval:
            self.write(self.line() + "\n")
            self._last = now
