"""The largest per-frame arrays of a run, held on disk while the run is solved and written.

A 10-minute trial at 200 Hz (120,000 frames) makes q, q̇, q̈ of both models, the multipliers,
the markers and the model points ~1 GB of float64: more than the rest of the solve together.
``fccgrb solve`` therefore passes ``solve_trial`` a :class:`Spill`: as soon as a stage has
produced one of those arrays and the later stages no longer need it, it goes to a scratch HDF5
file beside the results (stored as the results file stores it, ``core.datasets.put``) and the Run
keeps a :class:`StoredArray` in its place; ``results.storage.write_run`` copies the stored dataset
into the results file as it is (HDF5's object copy: chunk by chunk, no decompression), so the
file is the same bit for bit, and from then on the StoredArray reads the results file and the
scratch file is deleted. Reading a StoredArray (``np.asarray``, indexing) loads the whole array.
"""

from __future__ import annotations

import glob
import os
import weakref
from pathlib import Path

import numpy as np

from fccgrb_cli.core import scratch
from fccgrb_cli.core.atomic import FULL, alive, reason
from fccgrb_cli.core.datasets import put
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.hdf5_writer import writing

PREFIX = ".fccgrb-spill-"


class Spill:
    """A scratch HDF5 file in ``folder`` (the results' folder: the same disk), deleted once its
    arrays are in the results file, when the Spill is collected, or when the process ends."""

    def __init__(self, folder: str | Path) -> None:
        remove_stale(folder)
        try:
            self.path = scratch.create(folder, f"{PREFIX}{os.getpid()}-", ".h5")
        except OSError as error:
            raise InputError(f"{folder}: expected a folder the results can be written to "
                             f"({error.strerror})") from None
        self.group = "/"  # where the stored arrays are: the scratch file's root, then the run's
        self._written = False
        self._remove = weakref.finalize(self, _unlink, self.path)

    def keep(self, key: str, values: np.ndarray) -> StoredArray:
        """Store ``values`` under ``key`` (the dataset's path in a run's group, e.g. 'qd' or
        'classical/q'); the placeholder that reads it back. A full disk is an InputError."""
        values = np.asarray(values)
        try:
            with writing(self.path, "r+" if self._written else "w") as h5:
                folder, _, name = key.rpartition("/")
                put(h5.require_group(folder) if folder else h5, name, values)
        except OSError as error:
            if error.errno not in FULL:
                raise
            raise InputError(f"{self.path.parent}: cannot keep the solve's arrays there "
                             f"({reason(error)}); nothing was written") from None
        self._written = True
        return StoredArray(self, key, values.shape, values.dtype)

    def discard(self) -> None:
        """Delete the scratch file now (its run failed)."""
        self._remove()

    def settled(self, results: str | Path, group: str) -> None:
        """The arrays are now the datasets of ``group`` in ``results``: read them there and
        delete the scratch file."""
        self._remove()
        self.path, self.group = Path(results), group


def _unlink(path: Path) -> None:
    path.unlink(missing_ok=True)
    scratch.release(path)


def remove_stale(folder: str | Path) -> None:
    """Delete the scratch files in ``folder`` of solves that no longer run (a kill -9)."""
    for name in glob.glob(os.path.join(glob.escape(str(folder)), f"{PREFIX}*-*.h5")):
        pid = Path(name).name[len(PREFIX):].split("-")[0]
        if pid.isdigit() and int(pid) != os.getpid() and not alive(int(pid)):
            Path(name).unlink(missing_ok=True)


class StoredArray:
    """An array held in a Spill's file: its shape and dtype, and its values on demand."""

    def __init__(self, spill: Spill, key: str, shape: tuple[int, ...], dtype: np.dtype) -> None:
        self.spill, self.key, self.shape, self.dtype = spill, key, shape, dtype

    @property
    def ndim(self) -> int:
        return len(self.shape)

    def __len__(self) -> int:
        return self.shape[0]

    def __repr__(self) -> str:
        return f"StoredArray({self.spill.path}:{self.spill.group}/{self.key}, {self.shape})"

    def dataset(self, h5):
        """The stored dataset in an open file of the spill (h5py)."""
        return h5[f"{self.spill.group.rstrip('/')}/{self.key}"]

    def __array__(self, dtype=None, copy=None) -> np.ndarray:
        import h5py

        with h5py.File(self.spill.path, "r") as h5:
            values = self.dataset(h5)[()]
        return values if dtype is None else values.astype(dtype)

    def __getitem__(self, index) -> np.ndarray:
        return np.asarray(self)[index]

    def copy_to(self, group, name: str) -> None:
        """The stored dataset as ``group[name]`` (h5py), as stored: same chunks, filters and
        bytes."""
        import h5py

        with h5py.File(self.spill.path, "r") as h5:
            h5.copy(self.dataset(h5), group, name=name)
