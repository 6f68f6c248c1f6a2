"""A run's flags as its results file declares them, read without knowing them in advance.

Every dataset of a run group named ``flags`` or ``…_flags`` (``flags`` per frame,
``moment_flags`` per frame and joint, ``classical/flags`` …) is a bit mask; each integer
attribute of it names a bit, and a JSON attribute ``bits`` (a list of ``{name, value, meaning,
detail, …}``), where present, says what each bit means and why this run has it. Flags that a
later version adds show in the study's tables and report without a change here.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from typing import Any

import numpy as np

DESCRIBED = "bits"  # the attribute holding the bits' descriptions (JSON)


@dataclass(frozen=True)
class Flag:
    """One bit of one flag dataset (``dataset``: its path in the run group), the frames that
    carry it (in any column), and what the file says it means and why this run has it."""

    dataset: str
    name: str
    bit: int
    frames: int
    meaning: str = ""
    detail: str = ""

    @property
    def label(self) -> str:
        """Its column's name: the bit's for the frame flags, else dataset:bit."""
        return self.name if self.dataset == "flags" else f"{self.dataset}:{self.name}"


def _descriptions(dataset) -> dict[str, dict]:
    text = dataset.attrs.get(DESCRIBED)
    if isinstance(text, bytes):
        text = text.decode()
    try:
        items = json.loads(text) if isinstance(text, str) else []
    except json.JSONDecodeError:
        return {}
    return {str(i["name"]): i for i in items if isinstance(i, dict) and "name" in i} \
        if isinstance(items, list) else {}


def _is_bit(value) -> bool:
    return isinstance(value, int | np.integer) and not isinstance(value, bool | np.bool_) \
        and bool(value > 0)


def run_flags(group) -> tuple[tuple[Flag, ...], tuple[tuple[str, str], ...]]:
    """Every bit of every flag dataset of a run group (the frame flags first, then the others
    by path; bits in order), and the datasets' other attributes as (dataset:attribute, text)."""
    names: list[str] = []

    def visit(name: str) -> None:
        stem = name.rsplit("/", 1)[-1]
        if stem == "flags" or stem.endswith("_flags"):
            names.append(name)

    # names first, objects only for those: opening every object of a run (visititems) took
    # ~20 ms a run, a second of a 50-trial study's merge
    group.visit(visit)
    datasets: list[tuple[str, Any]] = []  # (path, h5py dataset)
    for name in names:
        obj = group[name]
        if hasattr(obj, "dtype") and obj.dtype.kind in "iu":
            datasets.append((name, obj))
    datasets.sort(key=lambda item: (item[0] != "flags", item[0]))
    flags: list[Flag] = []
    notes: list[tuple[str, str]] = []
    for path, dataset in datasets:
        values = dataset[()]
        rows = values.reshape(len(values), -1)
        described = _descriptions(dataset)
        bits = []
        for key, value in dataset.attrs.items():
            if _is_bit(value):
                about = described.get(key, {})
                bits.append(Flag(path, key, int(value), int((rows & int(value)).any(axis=1).sum()),
                                 str(about.get("meaning", "")), str(about.get("detail", ""))))
            elif key not in (DESCRIBED, "names"):
                text = value.decode() if isinstance(value, bytes) else value
                notes.append((f"{path}:{key}", text if isinstance(text, str) else json.dumps(
                    np.asarray(text).tolist())))
        flags += sorted(bits, key=lambda f: f.bit)
    return tuple(flags), tuple(notes)
