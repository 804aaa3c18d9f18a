"""The progress line: in a terminal it is redrawn in place with nothing stale left behind
(read back through a small terminal model), elsewhere it prints a line now and then."""

import logging

from campipe.study.run.progress import ERASE, Progress, format_seconds, logging_cleared


class Screen:
    """What a terminal shows after a stream of text with carriage returns, newlines and
    the erase-to-end-of-line sequence (the only controls the progress line writes)."""

    def __init__(self, columns: int = 80):
        self.rows = [""]
        self.col = 0
        self.columns = columns

    def write(self, text: str) -> None:
        i = 0
        while i < len(text):
            if text.startswith(ERASE, i):
                self.rows[-1] = self.rows[-1][: self.col]
                i += len(ERASE)
                continue
            ch = text[i]
            i += 1
            if ch == "\r":
                self.col = 0
            elif ch == "\n":
                self.rows.append("")
                self.col = 0
            else:
                if self.col >= self.columns:  # the terminal wraps: a new row
                    self.rows.append("")
                    self.col = 0
                row = self.rows[-1].ljust(self.col)
                self.rows[-1] = row[: self.col] + ch + row[self.col + 1 :]
                self.col += 1


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def test_a_shorter_line_leaves_no_trace_of_a_longer_one():
    screen, clock = Screen(), Clock()
    bar = Progress(1000, screen.write, terminal=True, clock=clock, columns=80)
    clock.t = 1.0
    bar.advance(1)
    long_line = screen.rows[-1]
    assert long_line.endswith("1/1000 cases  1 cases/s  16 min 39 s left")
    clock.t = 2.0
    bar.advance(499)
    assert screen.rows == [bar.line()] and len(bar.line()) < len(long_line)
    assert screen.rows[-1] == "[" + "#" * 12 + " " * 12 + "] 500/1000 cases  250 cases/s  2 s left"
    bar.advance(499)
    bar.advance(1)
    assert screen.rows == ["[" + "#" * 24 + "] 1000/1000 cases, writing the archive"]
    bar.close()
    assert screen.rows == [""] and screen.col == 0  # nothing left for the next line


def test_the_line_never_wraps_in_a_narrow_terminal():
    screen = Screen(columns=30)
    bar = Progress(117, screen.write, terminal=True, columns=30)
    for _ in range(117):
        bar.advance(1)
    assert len(screen.rows) == 1 and len(screen.rows[0]) == 29 and screen.rows[0].endswith("…")


def test_a_log_message_starts_on_a_clean_line(caplog):
    screen = Screen()
    bar = Progress(10, screen.write, terminal=True, columns=80)
    bar.advance(3)
    handler = logging.StreamHandler(type("S", (), {"write": screen.write, "flush": lambda s: 0})())
    root = logging.getLogger()
    root.addHandler(handler)
    try:
        with logging_cleared(lambda: bar):
            logging.getLogger("campipe.test").warning("case 7 failed")
        bar.advance(7)
    finally:
        root.removeHandler(handler)
    assert screen.rows[0] == "case 7 failed"
    assert screen.rows[1] == "[" + "#" * 24 + "] 10/10 cases, writing the archive"


def test_outside_a_terminal_a_line_every_interval_and_the_last():
    lines, clock = [], Clock()
    bar = Progress(4, lines.append, interval=2.0, clock=clock)
    for t in (0.5, 1.0, 2.6, 3.0):
        clock.t = t
        bar.advance(1)
    assert len(lines) == 3 and all(line.endswith("\n") for line in lines)
    assert lines[0].startswith("[######                  ] 1/4 cases  2 cases/s")
    assert lines[-1] == "[########################] 4/4 cases, writing the archive\n"
    bar.close()
    assert len(lines) == 3


def test_a_restart_leaves_what_came_before_out_of_the_rate():
    """campipe design draws its bar from before the kernels compile; restarted once they
    are, 30 s of compiling is not in the rate (campipe before: a design of 1.2 s said "8 min
    02 s left" after its first evaluation; found by a fresh pair of eyes)."""
    lines, clock = [], Clock()
    bar = Progress(33, lines.append, interval=0.0, clock=clock, unit="designs at most")
    clock.t = 30.0  # compiled
    bar.restart()
    clock.t = 30.1
    bar.advance(1)
    assert lines[0].startswith("[#                       ] 1/33 designs at most  10 designs/s")
    assert "3 s left" in lines[0]


def test_a_study_already_done_says_what_follows():
    lines = []
    Progress(8, lines.append, done=8, then="")
    assert lines == ["[########################] 8/8 cases, done\n"]


def test_format_seconds():
    assert [format_seconds(s) for s in (0.2, 12.4, 75.2, 7300)] == [
        "under a second",
        "12 s",
        "1 min 15 s",
        "2 h 01 min",
    ]
