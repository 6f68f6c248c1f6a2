"""OpenSim's storage files (``.mot``, ``.sto``): a header, ``endheader``, a line of column
names whose first is ``time``, then one row of numbers per time.

Two header layouts are read. OpenSim 4 writes a name line, then ``key=value`` lines
(``version=1``, ``nRows=``, ``nColumns=`` counting the time column, ``inDegrees=yes|no``);
SIMM and OpenSim 1–3 files state ``name``, ``datarows``, ``datacolumns`` and ``range`` as
``key value`` lines. Either may hold free text. Columns are separated by tabs or spaces.

A file is refused in one line naming it and the line, row or column when it has no
``endheader``, a header count or flag that is not one, a row of a length other than the names
line's, a row count other than the header's, a number that is not finite or beyond
``MAX_MAGNITUDE``, a time that does not increase, or more than ``MAX_BYTES`` (read whole, at
about three times its size in memory). Time steps that
are not uniform are accepted and said in ``Storage.notes`` (OpenSim's resampled outputs end on
a shorter last step)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from fccgrb_cli.core.atomic import atomic_path
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import decode, read_bytes

__all__ = ["MAX_BYTES", "MAX_HEADER_LINES", "MAX_MAGNITUDE", "Storage", "read_storage",
           "storage_text", "write_storage"]

MAX_BYTES = 256 << 20        # a 10-minute, 1000 Hz table of 19 columns is ~0.15 GB
BLOCK = 20_000               # rows parsed at a time
MAX_HEADER_LINES = 1000      # OpenSim's headers are a dozen lines
MAX_MAGNITUDE = 1e12         # as the XML readers' numbers
UNIFORM = 0.05               # of a step: times farther from a uniform grid are not uniform
_COUNTS = {"nrows": "rows", "datarows": "rows", "ncolumns": "columns", "datacolumns": "columns"}


@dataclass(frozen=True)
class Storage:
    """One storage file: ``names`` of its data columns (time apart), ``time`` (rows, s),
    ``values`` (rows × columns, in the file's units), ``in_degrees`` as the header states it
    (None when it does not), ``header`` (its ``key=value`` / ``key value`` lines, keys as
    written), ``title`` (the first header line) and ``notes`` (what is accepted but unusual,
    e.g. a non-uniform time step)."""

    names: tuple[str, ...]
    time: np.ndarray
    values: np.ndarray
    in_degrees: bool | None = None
    header: Mapping[str, str] = field(default_factory=lambda: MappingProxyType({}))
    title: str = ""
    notes: tuple[str, ...] = ()
    source: str = "<storage>"

    def column(self, name: str) -> np.ndarray:
        """The column ``name`` (rows); an InputError naming the file when it has none, or more
        than one (a SIMM motion file repeats its plates' column names: which one is meant?)."""
        count = self.names.count(name)
        if count != 1:
            raise InputError(f"{self.source}: expected one column {name!r}, got {count}")
        return self.values[:, self.names.index(name)]

    def has(self, name: str) -> bool:
        return name in self.names


def read_storage(path: str | Path, missing: bool = False) -> Storage:
    """The storage file ``path``.

    Parameters
    ----------
    path
        A ``.mot`` or ``.sto`` file (OpenSim 4 or SIMM header; tab- or space-separated).
    missing
        Accept ``NaN`` as a missing value (OpenSim writes it for a marker out of view, fccgrb
        for a frame it could not solve); by default a NaN is refused like an infinity.

    Returns
    -------
    Storage
        Time (rows, s), values (rows × columns), column names, ``inDegrees`` and the header.

    Raises
    ------
    InputError
        One line naming the file and the line, row or column at fault.
    """
    source = str(path)
    text = decode(read_bytes(path, "storage file", MAX_BYTES), source, "storage file")
    lines = text.splitlines()
    end = _endheader(lines, source)
    header, title = _header(lines[:end], source)
    names_at = next((k for k in range(end + 1, len(lines)) if lines[k].strip()), None)
    if names_at is None:
        raise InputError(f"{source}: expected a line of column names after endheader "
                         f"(line {end + 1}), got the end of the file")
    names = _names(lines[names_at], names_at + 1, source)
    table = _table(lines[names_at + 1:], names_at + 2, len(names), source, missing)
    del lines, text
    counts = _counts(header, source)
    if "rows" in counts and counts["rows"] != len(table):
        raise InputError(f"{source}: header {counts['rows key']}: expected the number of data "
                         f"rows, {len(table)}, got {counts['rows']}")
    if "columns" in counts and counts["columns"] != len(names):
        raise InputError(f"{source}: header {counts['columns key']}: expected the number of "
                         f"columns with time, {len(names)}, got {counts['columns']}")
    time = table[:, 0]
    notes = _time_notes(time, source)
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:  # read, and refused where one of them is used
        notes += (f"{source}: columns named more than once (not usable): "
                  f"{', '.join(twice)[:200]}",)
    return Storage(tuple(names[1:]), time, table[:, 1:], _in_degrees(header, source),
                   MappingProxyType(header), title, notes, source)


def _endheader(lines: list[str], source: str) -> int:
    for k, line in enumerate(lines[:MAX_HEADER_LINES + 1]):
        if line.strip().lower() == "endheader":
            return k
    if not lines:
        raise InputError(f"{source}: expected an OpenSim storage file, got an empty file")
    raise InputError(f"{source}: expected an OpenSim storage header ending in a line "
                     f"'endheader' within {MAX_HEADER_LINES} lines, got none")


def _header(lines: list[str], source: str) -> tuple[dict[str, str], str]:
    """The ``key=value`` and SIMM ``key value`` lines (known keys only for the latter) and the
    title (the first line when it is neither)."""
    header: dict[str, str] = {}
    title = ""
    for k, line in enumerate(lines):
        text = line.strip()
        if "=" in text:
            key, _, value = text.partition("=")
            header[key.strip()] = value.strip()
            continue
        key, _, value = text.partition(" ")
        if key.lower() in ("name", "datarows", "datacolumns", "range", "otherdata"):
            header[key] = value.strip()
        elif k == 0:
            title = text
    if not title:
        title = header.get("name", "")
    return header, title


def _counts(header: Mapping[str, str], source: str) -> dict:
    out: dict = {}
    for key, value in header.items():
        kind = _COUNTS.get(key.lower())
        if kind is None:
            continue
        try:
            count = int(value)
        except ValueError:
            raise InputError(f"{source}: header {key}: expected a whole number, got "
                             f"{value!r:.40}") from None
        if kind in out and out[kind] != count:
            raise InputError(f"{source}: header {key}: expected {out[kind]} as "
                             f"{out[kind + ' key']} says, got {count}")
        out[kind], out[kind + " key"] = count, key
    return out


def _in_degrees(header: Mapping[str, str], source: str) -> bool | None:
    value = next((v for k, v in header.items() if k.lower() == "indegrees"), None)
    if value is None:
        return None
    flag = value.strip().lower()
    if flag not in ("yes", "no", "true", "false"):
        raise InputError(f"{source}: header inDegrees: expected yes or no, got {value!r:.40}")
    return flag in ("yes", "true")


def _names(line: str, number: int, source: str) -> list[str]:
    parts = line.split("\t") if "\t" in line else line.split()
    names = [p.strip() for p in parts if p.strip()]
    if not names or names[0].lower() != "time":
        first = names[0] if names else ""
        raise InputError(f"{source}: line {number}: expected column names starting with "
                         f"'time', got {first!r:.40}")
    return names


def _table(lines: list[str], first: int, width: int, source: str,
           missing: bool) -> np.ndarray:
    """The numbers of the non-blank ``lines`` (the ``first`` being line ``first`` of the file)
    as rows × width, each row ``width`` long, finite (or NaN when ``missing``) and bounded;
    read ``BLOCK`` lines at a time, so that the words of a large file are never all held."""
    blocks = []
    for start in range(0, len(lines), BLOCK):
        numbered = [(first + k, line) for k, line in
                    enumerate(lines[start:start + BLOCK], start=start) if line.strip()]
        if numbered:
            blocks.append(_block(numbered, width, source, missing))
    if not blocks:
        raise InputError(f"{source}: expected at least one data row after the column names, "
                         "got none")
    return np.vstack(blocks)


def _block(rows: list[tuple[int, str]], width: int, source: str,
           missing: bool) -> np.ndarray:
    words = [line.split() for _, line in rows]
    for (number, _), row in zip(rows, words, strict=True):
        if len(row) != width:
            raise InputError(f"{source}: line {number}: expected {width} numbers as the "
                             f"column names, got {len(row)}")
    try:
        table = np.array([w for row in words for w in row], dtype=float).reshape(-1, width)
    except ValueError:
        for (number, _), row in zip(rows, words, strict=True):
            for column, word in enumerate(row):
                try:
                    float(word)
                except ValueError:
                    raise InputError(f"{source}: line {number}, column {column + 1}: expected "
                                     f"a number, got {word!r:.40}") from None
        raise
    with np.errstate(invalid="ignore"):
        bad = ~np.isfinite(table) | (np.abs(table) > MAX_MAGNITUDE)
    if missing:
        bad[:, 1:] &= ~np.isnan(table[:, 1:])
    if bad.any():
        at, column = map(int, np.argwhere(bad)[0])
        raise InputError(f"{source}: line {rows[at][0]}, column {column + 1}: expected a "
                         f"finite number of magnitude at most {MAX_MAGNITUDE:g}, got "
                         f"{words[at][column]!r:.40}")
    return table


def _time_notes(time: np.ndarray, source: str) -> tuple[str, ...]:
    """A note when the times stray from a uniform grid (the least-squares line through them)
    by more than ``UNIFORM`` of a step: times are printed rounded, so a 600 Hz file's steps of
    0.0016 and 0.0017 s are uniform, a last step of 0.0455 among steps of 0.05 s is not."""
    step = np.diff(time)
    if (step <= 0).any():
        k = int(np.flatnonzero(step <= 0)[0])
        raise InputError(f"{source}: data row {k + 2}: expected a time after the previous "
                         f"row's {time[k]:.10g} s, got {time[k + 1]:.10g} s")
    if step.size < 2:
        return ()
    index = np.arange(len(time))
    slope, offset = np.polyfit(index, time, 1)
    stray = np.abs(time - (offset + slope * index))
    if stray.max() <= UNIFORM * slope:
        return ()
    k = int(np.argmax(np.abs(step - np.median(step))))
    return (f"{source}: time steps from {step.min():.6g} to {step.max():.6g} s (not uniform; "
            f"the step ending at data row {k + 2}, {time[k + 1]:.10g} s, differs most from "
            f"the median {np.median(step):.6g} s)",)


def storage_text(names: Sequence[str], time: np.ndarray, values: np.ndarray,
                 in_degrees: bool, title: str = "fccgrb",
                 header: Mapping[str, str] | None = None) -> str:
    """A table in OpenSim 4's storage layout: ``title``, ``version=1``, ``nRows``,
    ``nColumns`` (time included), ``inDegrees``, the ``header`` lines, ``endheader``, the
    tab-separated names (``time`` first) and rows (each number written to round-trip exactly).

    Parameters
    ----------
    names
        The data columns' names (columns), time apart.
    time
        Rows (s), increasing.
    values
        Rows × columns.
    in_degrees
        Whether the angles among the columns are in degrees.
    title, header
        The first line, and more ``key=value`` lines.

    Returns
    -------
    str
        The file's text.
    """
    values = np.asarray(values, dtype=float).reshape(len(time), len(names))
    for name in (title, *names, *(header or {}), *(header or {}).values()):
        if any(c in str(name) for c in "\t\r\n"):
            raise InputError(f"storage file: expected names without tabs or line breaks, got "
                             f"{name!r:.40}")
    lines = [title, "version=1", f"nRows={len(time)}", f"nColumns={1 + len(names)}",
             f"inDegrees={'yes' if in_degrees else 'no'}",
             *(f"{k}={v}" for k, v in (header or {}).items()), "endheader",
             "\t".join(["time", *names])]
    table = np.column_stack([np.asarray(time, dtype=float), values])
    lines += ["\t".join(_number(v) for v in row) for row in table.tolist()]
    return "\n".join(lines) + "\n"


def _number(value: float) -> str:
    return repr(value) if math.isfinite(value) else "NaN"


def write_storage(path: str | Path, names: Sequence[str], time: np.ndarray,
                  values: np.ndarray, in_degrees: bool, title: str = "fccgrb",
                  header: Mapping[str, str] | None = None) -> None:
    """:func:`storage_text` written to ``path`` whole or not at all."""
    text = storage_text(names, time, values, in_degrees, title, header)
    with atomic_path(path) as tmp:
        tmp.write_text(text, encoding="utf-8")
