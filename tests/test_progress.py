"""Progress on stderr for long trials: quiet for short runs, one line per ``log_every``
seconds into a log, a rewritten line on a terminal, and the time left at the pace so far."""

from __future__ import annotations

import io

from fccgrb_cli.core import progress as module
from fccgrb_cli.core.progress import Progress


class Clock:
    """time.perf_counter under the test's control."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


class Stream(io.StringIO):
    def __init__(self, terminal: bool) -> None:
        super().__init__()
        self.terminal = terminal

    def isatty(self) -> bool:
        return self.terminal


def run(monkeypatch, terminal: bool, seconds_per_frame: float, total: int) -> str:
    """Report every frame of a run of ``total`` frames at a steady pace (a power of two, so
    that the clock's sums are exact); what stderr got."""
    clock, stream = Clock(), Stream(terminal)
    monkeypatch.setattr(module.time, "perf_counter", clock)
    monkeypatch.setattr(module.sys, "stderr", stream)
    report = Progress("solve", delay=1.0, every=0.5, log_every=10.0)
    start = clock.now
    for done in range(1, total + 1):
        clock.now = start + done * seconds_per_frame
        report(done, total)
    return stream.getvalue()


def test_a_short_run_prints_nothing(monkeypatch):
    assert run(monkeypatch, False, 2**-10, 1000) == ""  # 0.98 s < delay
    assert run(monkeypatch, True, 2**-10, 1000) == ""
    # into a log, a run that ends before its first 10-s line adds no line at all
    assert run(monkeypatch, False, 2**-10, 5 * 1024) == ""


def test_a_long_run_into_a_log_adds_a_line_every_ten_seconds_and_a_last_one(monkeypatch):
    text = run(monkeypatch, False, 2**-10, 120 * 1024)  # 2 minutes
    lines = text.splitlines()
    assert "\r" not in text
    assert len(lines) == 12  # at 10, 20, …, 110 s, then the end
    assert lines[0] == "solve: frame 10240/122880 (8 %, 10 s, ~1.8 min left)"
    assert lines[1] == "solve: frame 20480/122880 (17 %, 20 s, ~1.7 min left)"
    assert lines[-1] == "solve: frame 122880/122880 (100 %, 2.0 min)"


def test_the_time_left_is_the_pace_so_far(monkeypatch):
    lines = run(monkeypatch, False, 2**-4, 1600).splitlines()  # 100 s at 16 frames/s
    # at 60 s: 960 frames done, 640 to go at 1/16 s each
    assert lines[5] == "solve: frame 960/1600 (60 %, 1.0 min, ~40 s left)"


def test_a_terminal_gets_one_line_rewritten_in_place(monkeypatch):
    text = run(monkeypatch, True, 2**-10, 5 * 1024)
    updates = text.split("\r")[1:]
    assert len(updates) == 9  # every 0.5 s from 1 s to 5 s
    assert updates[0] == "solve: frame 1024/5120 (20 %, 1 s, ~4 s left)\033[K"
    assert text.endswith("\rsolve: frame 5120/5120 (100 %, 5 s)\033[K\n")
    assert text.count("\n") == 1
