"""How the results files store arrays: a large one chunked and compressed, so that a long trial
(120,000 frames × 96 coordinates is 92 MB per array) is written and read a chunk at a time and
takes less disk; a small one contiguous, as HDF5 stores it by default. Lossless either way: what
is read back equals what was written bit for bit."""

from __future__ import annotations

import numpy as np

LARGE = 1 << 16  # bytes: an array at least this large is stored chunked and compressed


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
