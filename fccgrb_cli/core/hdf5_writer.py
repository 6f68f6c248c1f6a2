"""HDF5 files written so that a full disk is an error, never a crash.

When a write of HDF5's own file driver fails (ENOSPC on a full disk, EFBIG past ``ulimit -f``),
closing the dataset being written fails too (its chunk cache cannot be flushed), and the
half-destroyed dataset stays in HDF5's table of open objects; closing the file then flushes
every open dataset and dereferences that one: SIGSEGV in ``H5D__flush_all_cb`` under
``H5F__dest`` (h5py 3.16, HDF5 2.0; gdb's backtrace of a five-line script on a 2 MB tmpfs). So
HDF5 is never shown a failed write: the file is opened through h5py's file-object driver on a
``GuardedFile``, whose ``write`` always "succeeds". The first write the disk refuses is recorded,
and that write and every later one are kept in memory instead (reads see them), so that HDF5
finishes and closes a consistent file; ``writing`` then raises the recorded OSError, which
``core.atomic`` turns into one line naming the output. Until a write fails nothing is held in
memory: the file goes to disk as HDF5's own driver would write it, at the same speed.
"""

from __future__ import annotations

import contextlib
import errno
import os
from collections.abc import Iterator
from pathlib import Path

FULL = {errno.ENOSPC, errno.EFBIG, errno.EDQUOT}


class GuardedFile:
    """A binary file (read, write, seek, tell, truncate, flush) whose writes do not fail when
    the disk is full: see the module's docstring."""

    def __init__(self, path: str | Path, create: bool) -> None:
        flags = os.O_RDWR | (os.O_CREAT | os.O_TRUNC if create else 0)
        self.fd = os.open(path, flags, 0o666)
        self.position = 0
        self.size = os.fstat(self.fd).st_size
        self.error: OSError | None = None
        self.kept: list[tuple[int, bytes]] = []  # (offset, bytes) written after the failure

    def seek(self, offset: int, whence: int = 0) -> int:
        base = {0: 0, 1: self.position, 2: self.size}[whence]
        self.position = base + offset
        return self.position

    def tell(self) -> int:
        return self.position

    def read(self, count: int = -1) -> bytes:
        if count < 0:
            count = max(self.size - self.position, 0)
        count = min(count, max(self.size - self.position, 0))
        data = bytearray(os.pread(self.fd, count, self.position))
        data.extend(bytes(count - len(data)))
        end = self.position + count
        for offset, chunk in self.kept:
            low, high = max(offset, self.position), min(offset + len(chunk), end)
            if low < high:
                data[low - self.position:high - self.position] = chunk[low - offset:high - offset]
        self.position = end
        return bytes(data)

    def readinto(self, buffer) -> int:
        data = self.read(len(buffer))
        buffer[:len(data)] = data
        return len(data)

    def write(self, data) -> int:
        data = bytes(data)
        done = 0
        if self.error is None:
            try:
                while done < len(data):
                    done += os.pwrite(self.fd, data[done:], self.position + done)
            except OSError as error:
                if error.errno not in FULL:
                    raise
                self.error = error
        if done < len(data):
            self.kept.append((self.position + done, data[done:]))
        self.position += len(data)
        self.size = max(self.size, self.position)
        return len(data)

    def truncate(self, size: int | None = None) -> int:
        size = self.position if size is None else size
        if self.error is None:
            try:
                os.ftruncate(self.fd, size)
            except OSError as error:
                if error.errno not in FULL:
                    raise
                self.error = error
        self.size = size
        return size

    def flush(self) -> None:
        """Nothing is buffered here."""

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


@contextlib.contextmanager
def writing(path: str | Path, mode: str = "w") -> Iterator:
    """An h5py File on ``path`` ('w': created or emptied; 'r+': an existing file changed) whose
    failed writes are raised as an OSError once the file is closed."""
    import h5py

    raw = GuardedFile(path, create=mode == "w")
    try:
        with h5py.File(raw, mode) as h5:
            yield h5
    finally:
        raw.close()
    if raw.error is not None:
        raise raw.error
