"""One ezc3d read of a C3D file per process: the markers (``trial.record.read_c3d``) and the
force platforms (``trial.forceplates.plate_file``, computed from the analog channels by
``trial.plate_analogs``) come from the same read.

ezc3d reads a 340-frame gait trial with two plates in 45 ms, and in 155 ms with its platforms'
extraction; a solve of it asks for the markers, then for the platforms (the lab's axes, the
loads and the gait events). Keyed by the file's identity (resolved path, inode, size,
modification time), so a file rewritten in between is read again. The ezc3d object is shared:
callers copy what they change.
"""

from __future__ import annotations

import os
from functools import lru_cache
from pathlib import Path
from typing import Any

__all__ = ["ezc3d_read"]


def ezc3d_read(path: str | Path, platforms: bool) -> Any:
    """ezc3d's object of the file at ``path``, with its platforms extracted when
    ``platforms``; ezc3d's own exception where it cannot read it (not kept: the next call
    tries again)."""
    real = os.path.realpath(path)
    stat = os.stat(real)
    return _read(real, (stat.st_ino, stat.st_size, stat.st_mtime_ns), platforms)


@lru_cache(maxsize=2)
def _read(real: str, identity: tuple[int, int, int], platforms: bool) -> Any:
    """``identity`` is in the key only."""
    import ezc3d

    return ezc3d.c3d(real, extract_forceplat_data=platforms)
