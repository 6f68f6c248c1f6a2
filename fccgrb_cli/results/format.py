"""What a results or sweep file must be before anything reads it (``core.datasets.open_results``
opens it), and the one-line errors when it is not: an HDF5 file of this format version whose
``/runs`` (results) or ``/cells`` (sweep) is a group of groups; a run whose datasets are missing
or of the wrong shape names the file, the run and what is missing.
"""

from __future__ import annotations

import contextlib
import re
from collections.abc import Iterator
from pathlib import Path

from fccgrb_cli.core.errors import InputError

FORMAT_VERSION = 2
DAMAGE = (KeyError, ValueError, TypeError, IndexError, AttributeError, OSError)


def check_version(h5, path: str | Path, where: str = "") -> None:
    """The file (or a sweep's cell, ``where``) was written in this format."""
    version = h5.attrs.get("format_version")
    if version != FORMAT_VERSION:
        inside = f"{where}: " if where else ""
        raise InputError(f"{path}: {inside}results format {version or 1} (written by another "
                         f"fccgrb); this one reads format {FORMAT_VERSION}: solve the trial "
                         "again to read it here")


def groups(h5, path: str | Path, key: str, what: str):
    """``h5[key]``, a group whose every member is a group (a run, a cell)."""
    import h5py

    if key not in h5:
        raise InputError(f"{path}: expected /{key} in a {what} file")
    group = h5[key]
    if not isinstance(group, h5py.Group):
        raise InputError(f"{path}: /{key}: expected a group of {what}s, got a dataset")
    for name, item in group.items():
        if not isinstance(item, h5py.Group):
            raise InputError(f"{path}: /{key}/{name}: expected a {what} (a group), got a "
                             "dataset")
    return group


def runs_group(h5, path: str | Path):
    """The ``/runs`` group of a results file of this format."""
    check_version(h5, path)
    return groups(h5, path, "runs", "run")


def cells_group(h5, path: str | Path):
    """The ``/cells`` group of a sweep file, every cell of this format holding its run."""
    cells = groups(h5, path, "cells", "cell")
    for key, cell in cells.items():
        check_version(cell, path, f"/cells/{key}")
        if "runs" in cell:
            groups(cell, path, "runs", "run")
    return cells


# a run's datasets as fccgrb writes them: name → number of dimensions (frames first)
RUN_DATASETS = {"time": 1, "q": 2, "qd": 2, "qdd": 2, "theta": 2, "theta_d": 2, "theta_dd": 2,
                "model_points": 3, "markers_input": 3, "reference": 3, "ed": 2, "ed_input": 2,
                "iterations": 1, "time_s": 1, "phi_norm": 1, "phi_top_max": 1,
                "converged": 1, "solver_converged": 1, "flags": 1}


def check_run(g, path: str | Path, where: str) -> None:
    """A run group holds every dataset fccgrb writes, each with the frames first and as many
    dimensions as written, the angle names and marker labels matching the columns."""
    import h5py

    frames = None
    for key, ndim in RUN_DATASETS.items():
        item = g.get(key)
        if not isinstance(item, h5py.Dataset):
            raise InputError(f"{path}: {where}: expected a run as fccgrb writes it (no dataset "
                             f"{key})")
        if item.ndim != ndim or (frames is not None and item.shape[0] != frames):
            raise InputError(f"{path}: {where}/{key}: expected {ndim} dimension(s), frames "
                             f"first ({frames if frames is not None else 'any'}), got shape "
                             f"{item.shape}")
        frames = item.shape[0] if frames is None else frames
    names = g["theta"].attrs.get("names")
    labels = g.attrs.get("labels")
    if names is None or len(names) != g["theta"].shape[1]:
        raise InputError(f"{path}: {where}/theta: expected one name per column (attribute "
                         "names)")
    if labels is None or isinstance(labels, (int, float)) or \
            len(labels) != g["model_points"].shape[1]:
        raise InputError(f"{path}: {where}: expected one label per model point (attribute "
                         "labels)")


def _why(error: Exception) -> str:
    text = str(error).splitlines()[0] if str(error) else error.__class__.__name__
    missing = re.search(r"object '([^']+)' doesn't exist", text)
    return f"no {missing.group(1)}" if missing else text.strip("'\"")


@contextlib.contextmanager
def reading(path: str | Path, where: str) -> Iterator[None]:
    """Turn a missing dataset, a wrong shape or type inside the block into one line naming the
    file and ``where`` ('/runs/x')."""
    try:
        yield
    except DAMAGE as error:
        raise InputError(f"{path}: {where}: expected a run as fccgrb writes it "
                         f"({_why(error)})") from None
