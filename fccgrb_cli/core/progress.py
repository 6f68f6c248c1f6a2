"""Progress on stderr for runs longer than a second."""

from __future__ import annotations

import sys
import time


def _duration(seconds: float) -> str:
    """'42 s', '3.5 min' or '1.2 h'."""
    if seconds < 60:
        return f"{seconds:.0f} s"
    if seconds < 3600:
        return f"{seconds / 60:.1f} min"
    return f"{seconds / 3600:.1f} h"


class Progress:
    """A callable ``(done, total)`` that reports on stderr once the run passes ``delay`` s:
    the frame, the share done, the time so far and the time left at the pace so far. On a
    terminal one line is rewritten every ``every`` s; into a file or a pipe (a log) a line is
    added every ``log_every`` s, so that a long trial's log stays short (a 10-minute solve:
    about 60 lines), and a last line when the run ends. ``unit`` names what is counted
    (frames; a batch's trials); ``bar`` draws a bar of that many characters before it; a third
    argument ``(done, total, what)`` names the last item done."""

    def __init__(self, label: str, delay: float = 1.0, every: float = 0.5,
                 log_every: float = 10.0, unit: str = "frame", bar: int = 0):
        self.label = label
        self.unit = unit
        self.bar = bar
        self.delay = delay
        self.every = every
        self.log_every = log_every
        self.start = time.perf_counter()
        self.last = self.start
        self.shown = False

    def __call__(self, done: int, total: int, what: str = "") -> None:
        now = time.perf_counter()
        finished = done >= total
        terminal = sys.stderr.isatty()
        interval = self.every if terminal else self.log_every
        if now - self.start < self.delay or (now - self.last < interval and not finished):
            return
        if not self.shown and finished:
            return
        self.last = now
        self.shown = True
        elapsed = now - self.start
        filled = self.bar * done // max(total, 1)
        bar = f"[{'#' * filled}{'.' * (self.bar - filled)}] " if self.bar else ""
        line = f"{self.label}: {bar}{self.unit} {done}/{total} " \
               f"({100 * done / max(total, 1):.0f} %, {_duration(elapsed)}"
        if not finished and done > 0:
            line += f", ~{_duration(elapsed * (total - done) / done)} left"
        line += ")" + (f" {what}" if what else "")
        if terminal:
            sys.stderr.write(f"\r{line}\033[K" + ("\n" if finished else ""))
        else:
            sys.stderr.write(line + "\n")
        sys.stderr.flush()
