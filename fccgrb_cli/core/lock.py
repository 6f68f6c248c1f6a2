"""One writer at a time per output file.

Adding a run to a results file reads the file, adds the run and renames the new file into
place; two solves doing that at once would each add their run to the old file, and the second
rename would drop the first run. So a writer holds an exclusive ``flock`` on a lock file beside
the output, ``.NAME.lock`` (holding its pid, for the message of whoever waits), for the whole
read-add-rename. The lock file is deleted when released; a writer that locked a lock file
since deleted (its path now names another file, or none) locks again. The kernel releases a
lock when its process ends, however it ends, so a killed writer never blocks the next one.
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import time
from collections.abc import Callable, Iterator
from pathlib import Path

from fccgrb_cli.core import scratch
from fccgrb_cli.core.errors import InputError

WAIT = 600.0  # seconds a writer waits for another before giving up


def lock_path(target: str | Path) -> Path:
    target = Path(target)
    return target.with_name(f".{target.name}.lock")


def _holder(fd: int) -> str:
    try:
        text = os.pread(fd, 32, 0).decode("ascii", "replace").strip()
    except OSError:
        text = ""
    return f"pid {text}" if text.isdigit() else "another process"


@contextlib.contextmanager
def exclusive(target: str | Path, wait: float = WAIT,
              waiting: Callable[[str], None] | None = None) -> Iterator[None]:
    """Hold the lock of ``target`` for the block; wait up to ``wait`` seconds for another
    writer (``waiting`` is told once, with a line naming it), then an InputError."""
    path = lock_path(target)
    deadline = time.monotonic() + wait
    told = False
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o666)
        except OSError as error:
            raise InputError(f"{target}: cannot lock it for writing ({error.strerror})") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            holder = _holder(fd)
            os.close(fd)
            if time.monotonic() >= deadline:
                raise InputError(f"{target}: {holder} is writing it (lock {path.name}); try "
                                 "again when it has finished") from None
            if waiting is not None and not told:
                waiting(f"{target}: waiting for {holder}, which is writing it")
                told = True
            time.sleep(0.05)
            continue
        try:
            current = os.stat(path)
        except FileNotFoundError:
            current = None
        mine = os.fstat(fd)
        if current is None or (current.st_ino, current.st_dev) != (mine.st_ino, mine.st_dev):
            os.close(fd)  # released and deleted while we waited: lock the new one
            continue
        break
    scratch.register(path)
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, str(os.getpid()).encode(), 0)
    except OSError:
        pass  # a full disk: the lock holds without the pid
    try:
        yield
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
        scratch.release(path)
        os.close(fd)
