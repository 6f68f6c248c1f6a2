"""Progress on stderr for runs longer than a second."""

from __future__ import annotations

import sys
import time


class Progress:
    """A callable ``(done, total)`` that reports on stderr once the run passes ``delay`` s."""

    def __init__(self, label: str, delay: float = 1.0, every: float = 0.5):
        self.label = label
        self.delay = delay
        self.every = every
        self.start = time.perf_counter()
        self.last = self.start
        self.shown = False

    def __call__(self, done: int, total: int) -> None:
        now = time.perf_counter()
        finished = done >= total
        if now - self.start < self.delay or (now - self.last < self.every and not finished):
            return
        if not self.shown and finished:
            return
        self.last = now
        self.shown = True
        end = "\n" if finished or not sys.stderr.isatty() else ""
        sys.stderr.write(f"\r{self.label}: frame {done}/{total} ({now - self.start:.1f} s){end}")
        sys.stderr.flush()
