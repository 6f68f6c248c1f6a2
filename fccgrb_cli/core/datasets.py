"""How the results files store arrays: a large one chunked and compressed, so that a long trial
(120,000 frames × 96 coordinates is 92 MB per array) is written and read a chunk at a time and
takes less disk; a small one contiguous, as HDF5 stores it by default. Lossless either way: what
is read back equals what was written bit for bit. :func:`open_results` opens such a file to read."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import regular_file

# bytes: an array at least this large is stored chunked and compressed (a long trial's: 1,560
# frames of 84 coordinates). Below it, compressing costs more than it saves: a 340-frame gait
# trial's 13 arrays over 64 KiB took 55 ms of its 0.55 s to compress, for 8 % less file
LARGE = 1 << 20


def put(group, key: str, data) -> object:
    """``group[key] = data``, chunked in h5py's chunk shape (≤ 1 MiB) and compressed with gzip at
    level 1 after byte shuffling when it holds ≥ ``LARGE`` bytes (gzip: every HDF5 reader has
    it; level 1 with the shuffle filter compresses float64 results better than level 4 without,
    in half the time); the h5py dataset."""
    data = np.asarray(data)
    if data.nbytes >= LARGE:
        return group.create_dataset(key, data=data, chunks=True, compression="gzip",
                                    compression_opts=1, shuffle=True)
    return group.create_dataset(key, data=data)


def open_results(path: str | Path):
    """An existing results or sweep file, read-only (h5py.File); one-line errors otherwise."""
    import h5py

    path = regular_file(path, "results file")  # a FIFO would block h5py
    try:
        return h5py.File(path, "r")
    except OSError:
        raise InputError(f"{path}: not an HDF5 results file") from None
