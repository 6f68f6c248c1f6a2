"""A trial in stretches: runs of consecutive frames that a stage can take, solved apart and put
back together on the trial's frames.

Markers that cannot determine the model leave frames unsolved; the kinematic solve then runs on
each stretch the markers determine (a fresh initial guess after each gap, as after the trial's
start), and the inverse dynamics on each stretch of solved frames long enough for its rates:
central differences and the Butterworth filter within the stretch, never across a gap.
``SHORTEST`` frames is the least a stretch needs: the filter's forward-backward pass pads
3·(order + 1) samples at each end (9 for the default order 2), and below 10 frames one-sided
stencils are most of the stretch.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Sequence
from typing import Any

import numpy as np

SHORTEST = 10
PER_FRAME_TUPLES = frozenset({"status"})  # tuples with one entry per frame (by field name)


def shortest(order: int | None = None) -> int:
    """The fewest frames a stretch needs for rates and dynamics (with a filter of ``order``)."""
    return max(SHORTEST, 3 * (order + 1) + 1) if order is not None else SHORTEST


def runs(mask: np.ndarray, least: int = 1) -> list[tuple[int, int]]:
    """The runs [start, stop) of True in a per-frame mask, those of at least ``least`` frames."""
    edges = np.diff(np.concatenate([[0], np.asarray(mask, dtype=np.int8), [0]]))
    pairs = zip(np.flatnonzero(edges == 1).tolist(), np.flatnonzero(edges == -1).tolist(),
                strict=True)
    return [(a, b) for a, b in pairs if b - a >= least]


def spans(frames: np.ndarray) -> str:
    """Frame indices as 'a:b, c:d' runs (b excluded)."""
    mask = np.zeros(int(frames.max()) + 1 if len(frames) else 0, dtype=bool)
    mask[frames] = True
    return ", ".join(f"{a}:{b}" for a, b in runs(mask))


def _dataclass(value) -> bool:
    return dataclasses.is_dataclass(value) and not isinstance(value, type)


def take(value, part: slice, n: int, name: str = ""):
    """A dataclass (or array) cut to the frames of ``part``: every array whose first axis has
    the trial's ``n`` frames, the per-frame tuples (``PER_FRAME_TUPLES``), nested dataclasses
    and tuples of them alike."""
    if isinstance(value, np.ndarray):
        return value[part] if value.ndim and len(value) == n else value
    if name in PER_FRAME_TUPLES and isinstance(value, tuple) and len(value) == n:
        return value[part]
    if isinstance(value, tuple) and value and all(_dataclass(v) for v in value):
        return tuple(take(v, part, n) for v in value)
    if _dataclass(value):
        return dataclasses.replace(value, **{
            f.name: take(getattr(value, f.name), part, n, f.name)
            for f in dataclasses.fields(value) if f.init})
    return value


def merged(parts: Sequence[tuple[slice, Any]], n: int, like_time: np.ndarray | None = None):
    """Per-frame values of stretch results put back on the trial's ``n`` frames (the inverse of
    :func:`take`): arrays NaN (False, 0, '') outside the parts; fields that are not per frame
    from the first part; ``like_time`` replaces an array field named ``time``."""
    (first_part, first), *_ = parts
    length = first_part.stop - first_part.start

    def put(name: str, values: list):
        head = values[0]
        if isinstance(head, np.ndarray) and head.ndim and len(head) == length:
            if name == "time" and like_time is not None:
                return like_time
            if head.dtype.kind in "biu":  # booleans False, counts and masks 0
                out = np.zeros((n, *head.shape[1:]), dtype=head.dtype)
            else:
                out = np.full((n, *head.shape[1:]), np.nan,
                              dtype=np.result_type(head.dtype, float))
            for (part, _), v in zip(parts, values, strict=True):
                out[part] = v
            return out
        if name in PER_FRAME_TUPLES and isinstance(head, tuple) and len(head) == length:
            texts = [""] * n
            for (part, _), v in zip(parts, values, strict=True):
                texts[part] = list(v)
            return tuple(texts)
        if isinstance(head, tuple) and head and all(_dataclass(v) for v in head):
            return tuple(merged([(p, v[k]) for (p, _), v in zip(parts, values, strict=True)],
                                n, like_time) for k in range(len(head)))
        if _dataclass(head):
            return merged([(p, v) for (p, _), v in zip(parts, values, strict=True)], n,
                          like_time)
        return head

    return dataclasses.replace(first, **{
        f.name: put(f.name, [getattr(obj, f.name) for _, obj in parts])
        for f in dataclasses.fields(first) if f.init})


_FRAME = re.compile(r"(frame index |first frame index |frame indices )(\d+)")


def window(times: np.ndarray, start: float | None, stop: float | None) -> np.ndarray:
    """The samples whose ``times`` (s, evenly spaced) lie in [start, stop] (None: unbounded),
    each end widened by a millionth of a step for times printed rounded: OpenSim's time_range,
    ``--from``/``--to``."""
    keep = np.ones(len(times), dtype=bool)
    slack = 1e-6 * float(np.mean(np.diff(times))) if len(times) > 1 else 0.0
    if start is not None:
        keep &= times >= start - slack
    if stop is not None:
        keep &= times <= stop + slack
    return keep


_TIME = re.compile(r"\bt = (-?\d+\.\d+)(?:–(-?\d+\.\d+))? s\b")


def clocked(message: str, start: float) -> str:
    """A message's times (``t = 1.234 s``, ``t = 1.234–2.345 s``), counted from the trial's
    first frame where it was written, on the trial file's own clock (its first frame at
    ``start`` s: a C3D's first frame, a TRC's first Time), the clock of its events and of every
    export."""
    if not start:
        return message

    def moved(match: re.Match) -> str:
        first = f"t = {float(match.group(1)) + start:.3f}"
        if match.group(2) is None:
            return f"{first} s"
        return f"{first}–{float(match.group(2)) + start:.3f} s"

    return _TIME.sub(moved, message)


def shifted(message: str, offset: int) -> str:
    """A message of a stretch's solve with its frame indices counted from the trial's start."""
    if not offset:
        return message
    return _FRAME.sub(lambda m: f"{m.group(1)}{int(m.group(2)) + offset}", message)
