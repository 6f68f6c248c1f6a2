"""The flags a run group declares, as the results file's contract states them (written here
from the contract, for the tests to compare the study's tables and report with): every integer
dataset named ``flags`` or ``*_flags`` is a bit mask, each of its positive integer attributes a
bit; a frame carries a bit when any of its entries has it."""

from __future__ import annotations

import numpy as np


def declared(run) -> dict[str, tuple[str, int, int]]:
    """label → (dataset path, bit, frames carrying it); labels as the report names them:
    the bit's name for ``flags``, ``path:name`` for the other datasets."""
    found: dict[str, tuple[str, int, int]] = {}

    def visit(name: str, obj) -> None:
        stem = name.split("/")[-1]
        if not hasattr(obj, "dtype") or obj.dtype.kind not in "iu":
            return
        if stem != "flags" and not stem.endswith("_flags"):
            return
        values = obj[()].reshape(len(obj), -1)
        for key, value in obj.attrs.items():
            if isinstance(value, np.integer) and value > 0:
                label = key if name == "flags" else f"{name}:{key}"
                found[label] = (name, int(value), int((values & int(value)).any(axis=1).sum()))

    run.visititems(visit)
    return found
