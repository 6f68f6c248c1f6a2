"""The layout of a C3D file read from its own bytes, to tell a complete file from a cut one.

ezc3d rewrites a file's frame count from the frames it finds, so a copy interrupted in the data
section reads as a shorter trial without a word. This module reads what the file announces and
counts what its bytes hold, following the C3D User Guide (c3d.org, "The C3D File Format"):

* the 512-byte header block: byte 1 is the parameter section's first block (1-based), byte 2 the
  key 0x50; then 16-bit words (1-based, counting bytes 1–2 as word 1): word 2 points per frame,
  word 3 analog values per frame (channels × samples), words 4–5 the first and last frame,
  words 7–8 the scale factor (a float; negative: the data are 32-bit floats, positive: 16-bit
  integers), word 9 the data section's first block, words 11–12 the frame rate;
* the parameter section: a 4-byte header whose byte 3 counts its 512-byte blocks and byte 4 is the
  processor type (84 Intel: little-endian IEEE; 85 DEC: little-endian words, VAX F floats; 86
  MIPS: big-endian IEEE), which decides how every word and float of the file is read; then group
  and parameter records. The parameters are the master copies of the header's values: POINT:USED,
  POINT:SCALE, ANALOG:USED × ANALOG:RATE / POINT:RATE, POINT:FRAMES (an unsigned 16-bit word, or a
  float; 65535 means "look further": POINT:LONG_FRAMES, a float, or TRIAL:ACTUAL_START_FIELD and
  ACTUAL_END_FIELD, two 16-bit words each, low word first).

A frame is the points (x, y, z and a residual word each) followed by the frame's analog values,
4 bytes each in float files, 2 in integer files; frames follow one another from the data block.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import NoReturn

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import regular_file
from fccgrb_cli.trial.rates import ANALOG_RATE_MAX, POINT_RATE_MAX, rate_problem

BLOCK = 512
KEY = 0x50
PROCESSORS = {84: "Intel", 85: "DEC", 86: "MIPS"}
WORD_LIMIT = 0xFFFF  # the largest frame count a 16-bit word holds
TRUNCATED = "the file is truncated (an interrupted copy?)"


def decode_floats(raw: bytes, processor: str) -> np.ndarray:
    """32-bit floats of a C3D file as float64: IEEE little- (Intel) or big-endian (MIPS), or
    DEC (VAX F: two little-endian words, the first holding sign, exponent with bias 128 and the
    high mantissa, a hidden leading bit worth one half)."""
    if processor == "Intel":
        return np.frombuffer(raw, "<f4").astype(float)
    if processor == "MIPS":
        return np.frombuffer(raw, ">f4").astype(float)
    words = np.frombuffer(raw, "<u2").reshape(-1, 2).astype(np.int64)
    bits = (words[:, 0] << 16) | words[:, 1]
    sign = np.where(bits >> 31, -1.0, 1.0)
    exponent = (bits >> 23) & 0xFF
    mantissa = (bits & 0x7FFFFF) / float(1 << 23)
    value = sign * (0.5 + mantissa / 2.0) * np.exp2(exponent - 128.0)
    return np.where(exponent == 0, 0.0, value)


@dataclass(frozen=True)
class Parameter:
    """One parameter: its C3D type (1 byte, 2 integer, 4 float; -1 text) and values (flat, the
    first dimension varying fastest; text: one string per column of the character array,
    without trailing blanks), with the dimensions as stored (text: the first is the length)."""

    kind: int
    values: np.ndarray
    dims: tuple[int, ...] = ()


@dataclass(frozen=True)
class C3DLayout:
    """What a C3D file announces and how its data section is laid out."""

    size: int                  # bytes in the file
    processor: str             # "Intel", "DEC" or "MIPS"
    float_data: bool           # 32-bit floats (negative scale), else 16-bit integers
    points: int                # 3D points per frame
    analog: int                # analog values per frame (channels × samples per frame)
    data_start: int            # the data section's first 512-byte block, 1-based
    frames: int                # frames announced
    first_frame: int           # the announced range, for messages
    last_frame: int
    frames_from: str           # where the count comes from ("header", "POINT:FRAMES", …)
    point_scale: float = -1.0  # POINT:SCALE (integer data: the unit of a stored word)

    @property
    def frame_bytes(self) -> int:
        """Bytes of one frame: 4 words per point, then the analog values."""
        return (4 * self.points + self.analog) * (4 if self.float_data else 2)

    @property
    def data_offset(self) -> int:
        return (self.data_start - 1) * BLOCK

    @property
    def frames_held(self) -> int:
        """Whole frames the file's bytes hold after the data start (the announced count when a
        frame has no bytes: no points and no analog values)."""
        if self.frame_bytes == 0:
            return self.frames
        return max(self.size - self.data_offset, 0) // self.frame_bytes

    @property
    def truncated(self) -> bool:
        return self.frames_held < self.frames

    def announced(self) -> str:
        """'the header announces 300 frames (1–300)', naming the parameter it comes from when
        that is not the header's own range."""
        where = "the header" if self.frames_from == "header" else self.frames_from
        return f"{where} announces {self.frames} frames ({self.first_frame}–{self.last_frame})"


def read_layout(path: str | Path) -> C3DLayout:
    """Read a C3D file's header and parameter section; InputError (one line naming the file)
    when the file is not C3D, ends inside its header or parameter section, or counts 65535
    frames (a 16-bit word's limit) with more data after them and nothing giving the count."""
    path = regular_file(path, "C3D file")  # a FIFO would block the read
    try:
        with path.open("rb") as f:
            size = path.stat().st_size
            header = f.read(BLOCK)
            if size == 0:
                raise InputError(f"{path}: not a readable C3D file (the file is empty)")
            if len(header) >= 2 and header[1] != KEY:
                raise InputError(f"{path}: not a readable C3D file (byte 2 is {header[1]:#04x}, "
                                 f"expected {KEY:#04x}, the C3D key)")
            if header[0] == 0:
                raise InputError(f"{path}: not a readable C3D file (byte 1, the parameter "
                                 "section's first block, is 0)")
            if len(header) < BLOCK:
                raise InputError(f"{path}: the file ends at byte {size}, inside its "
                                 f"{BLOCK}-byte header: {TRUNCATED}")
            param_start = (header[0] - 1) * BLOCK
            f.seek(param_start)
            head = f.read(4)
            if len(head) < 4:
                where = (f"before its parameter section (byte {param_start})" if not head else
                         f"inside its parameter section's header (bytes {param_start}–"
                         f"{param_start + 3})")
                raise InputError(f"{path}: the file ends at byte {size}, {where}: {TRUNCATED}")
            processor = PROCESSORS.get(head[3])
            if processor is None:
                raise InputError(f"{path}: not a readable C3D file (processor type {head[3]} at "
                                 f"byte {param_start + 4}, expected 84 Intel, 85 DEC or 86 MIPS)")
            section = head + f.read(max(head[2], 1) * BLOCK - 4)
    except OSError as exc:
        raise InputError(f"{path}: cannot read the C3D file ({exc.__class__.__name__})") from None
    words = np.frombuffer(header[:24], "<u2" if processor != "MIPS" else ">u2").astype(int)
    scale = decode_floats(header[12:16], processor)[0]
    first, last, data_start = int(words[3]), int(words[4]), int(words[8])
    if data_start <= header[0]:
        raise InputError(f"{path}: not a readable C3D file (header word 9, the data section's "
                         f"first block, is {data_start}; expected a block after the parameter "
                         f"section's first, {header[0]})")
    data_offset = (data_start - 1) * BLOCK
    section_end = min(param_start + max(head[2], 1) * BLOCK, data_offset)
    if size < data_offset:
        where = (f"inside its parameter section (bytes {param_start}–{section_end - 1})"
                 if size < section_end else f"before its data section (byte {data_offset})")
        count = f"{last - first + 1} frames ({first}–{last})" if last >= first else "frames"
        raise InputError(f"{path}: the file ends at byte {size}, {where}, with none of the "
                         f"{count} its header announces: {TRUNCATED}")
    _check_records(section, processor, path)
    params = _parameters(section, processor)

    def number(key: str, default: float) -> float:
        p = params.get(key)
        return float(p.values[0]) if p is not None and p.values.size else default

    points = int(number("POINT:USED", words[1]))
    point_scale = number("POINT:SCALE", scale)
    rate = number("POINT:RATE", 0.0)
    _check_values(path, points, point_scale, rate, params)
    analog = int(words[2])
    if "ANALOG:USED" in params and rate > 0:
        analog = int(number("ANALOG:USED", 0)) * round(number("ANALOG:RATE", 0.0) / rate)
    frames, first, last, source = _frame_count(params, first, last)
    layout = C3DLayout(size, processor, point_scale < 0, points, analog, data_start,
                       frames, first, last, source, point_scale)
    beyond = size - data_offset - frames * layout.frame_bytes  # bytes after the last frame
    # writers pad the data to a whole block, ezc3d with up to one block more: past that, the
    # data hold frames the count leaves out
    if frames != WORD_LIMIT and layout.frame_bytes and beyond > max(BLOCK, layout.frame_bytes):
        raise InputError(f"{path}: {layout.announced()}, but the data section goes on "
                         f"{beyond} bytes after them ({beyond // layout.frame_bytes} frames; "
                         f"expected at most a {BLOCK}-byte block's padding): the count is "
                         "wrong or the file damaged")
    if frames == WORD_LIMIT and source in ("header", "POINT:FRAMES") and beyond >= BLOCK:
        raise InputError(f"{path}: POINT:FRAMES is {WORD_LIMIT}, the most a 16-bit word counts, "
                         "and neither POINT:LONG_FRAMES nor TRIAL:ACTUAL_START_FIELD/"
                         f"ACTUAL_END_FIELD gives the true count, while the data go on {beyond} "
                         f"bytes past frame {WORD_LIMIT}: those frames would be lost; split the "
                         f"trial into files of at most {WORD_LIMIT} frames")
    return layout


MAX_DIMS = 7  # the C3D User Guide: a parameter has at most 7 dimensions


def _check_records(section: bytes, processor: str, path: Path) -> None:
    """Every group and parameter record of the parameter section lies inside it and inside its
    own record (the next record's offset), a parameter of type -1, 1, 2 or 4 with at most 7
    dimensions; else an InputError. ezc3d trusts these sizes: a parameter claiming 161
    dimensions makes it read (and segfault) far past the section."""
    endian = ">" if processor == "MIPS" else "<"
    pos, end = 4, len(section)

    def fail(what: str) -> NoReturn:
        raise InputError(f"{path}: not a readable C3D file (the parameter record at byte "
                         f"{pos} of the parameter section {what})")

    while pos + 2 <= end:
        length, group = struct.unpack_from("bb", section, pos)
        length = abs(length)
        if length == 0:
            return  # the end of the records
        if group == 0:
            fail("belongs to group 0")
        if pos + 4 + length > end:
            fail("runs past the section")
        (offset,) = struct.unpack_from(endian + "h", section, pos + 2 + length)
        limit = end if offset == 0 else pos + 2 + length + offset
        if offset != 0 and not pos < limit <= end:
            fail(f"points to the next record at {limit}, outside the section or backwards")
        at = pos + 4 + length  # a parameter's type and dimensions; a group's description
        if group > 0:
            if at + 2 > limit:
                fail("ends before its type and dimensions")
            kind, n_dims = struct.unpack_from("bB", section, at)
            if kind not in (-1, 1, 2, 4) or n_dims > MAX_DIMS:
                fail(f"has type {kind} and {n_dims} dimensions, expected a type of -1, 1, 2 "
                     f"or 4 and at most {MAX_DIMS} dimensions")
            dims = section[at + 2:at + 2 + n_dims]
            at += 2 + n_dims + abs(kind) * math.prod(dims)
        if at >= limit or at + 1 + section[at] > limit:
            fail("holds more data than its size")
        if offset == 0:
            return
        pos = limit


def _check_values(path: Path, points: int, point_scale: float, rate: float,
                  params: dict[str, Parameter]) -> None:
    """The parameters the layout rests on: finite, and in range (a NaN POINT:SCALE would
    read float data as integers, an infinite rate divide by zero)."""
    def fail(key: str, expected: str, value: float) -> None:
        raise InputError(f"{path}: {key}: expected {expected}, got {value:g}")

    if points < 0:
        fail("POINT:USED", "a number of points ≥ 0", points)
    if not (math.isfinite(point_scale) and point_scale != 0):
        fail("POINT:SCALE", "a finite, non-zero scale (negative: float data)", point_scale)
    problem = rate_problem(rate, POINT_RATE_MAX, zero_ok=points == 0)
    if problem is not None:
        fail("POINT:RATE", problem, rate)
    analog = params.get("ANALOG:RATE")
    used = params.get("ANALOG:USED")
    if analog is not None and analog.values.size:
        value = float(analog.values[0])
        in_use = bool(used is not None and used.values.size and used.values[0] > 0)
        problem = rate_problem(value, ANALOG_RATE_MAX, zero_ok=not in_use)
        if problem is not None:
            fail("ANALOG:RATE", problem, value)


def _frame_count(params: dict[str, Parameter], first: int,
                 last: int) -> tuple[int, int, int, str]:
    """Frames announced, the first and last frame numbers, and the source of the count."""
    start, end = params.get("TRIAL:ACTUAL_START_FIELD"), params.get("TRIAL:ACTUAL_END_FIELD")
    p = params.get("POINT:FRAMES")
    if p is None or not p.values.size:
        return max(last - first + 1, 0), first, last, "header"
    # a float, or an unsigned word (often written as a signed one)
    count = round(p.values[0]) if p.kind == 4 else int(p.values[0]) & WORD_LIMIT
    if p.kind != 4 and count == WORD_LIMIT:
        long = params.get("POINT:LONG_FRAMES")
        if long is not None and long.kind == 4 and long.values.size:
            count = round(long.values[0])
            return count, first, first + count - 1, "POINT:LONG_FRAMES"
        if start is not None and end is not None and start.values.size >= 2 \
                and end.values.size >= 2:
            low, high = (int(v) & WORD_LIMIT for v in start.values[:2])
            a = low + (high << 16)
            low, high = (int(v) & WORD_LIMIT for v in end.values[:2])
            b = low + (high << 16)
            return b - a + 1, a, b, "TRIAL:ACTUAL_START_FIELD/ACTUAL_END_FIELD"
    if count == 0:  # some writers leave POINT:FRAMES at 0 (no points): the header decides
        return max(last - first + 1, 0), first, last, "header"
    if last - first + 1 == count:
        return count, first, last, "header"
    return count, first, first + count - 1, "POINT:FRAMES"


def read_parameters(path: str | Path) -> dict[str, Parameter]:
    """Every parameter of a C3D file, numbers and text, keyed 'GROUP:NAME', from its parameter
    section alone (the data section is not read: ezc3d would build an object per point of every
    frame, ~10 kB a frame for 55 markers); for a file ``read_layout`` accepted."""
    with Path(path).open("rb") as f:
        header = f.read(BLOCK)
        f.seek((header[0] - 1) * BLOCK)
        head = f.read(4)
        section = head + f.read(max(head[2], 1) * BLOCK - 4)
    return _parameters(section, PROCESSORS[head[3]], text=True)


def _parameters(section: bytes, processor: str, text: bool = False) -> dict[str, Parameter]:
    """The numeric parameters of a parameter section (and the text ones if ``text``), keyed
    'GROUP:NAME' (upper case). The walk stops at the end marker, at a record that runs past the
    section, or at a loop."""
    endian = ">" if processor == "MIPS" else "<"
    groups: dict[int, str] = {}
    found: dict[tuple[int, str], Parameter] = {}
    pos, end = 4, len(section)
    while pos + 4 <= end:
        length, group = struct.unpack_from("bb", section, pos)
        length = abs(length)
        if length == 0 or pos + 4 + length > end:
            break
        name = section[pos + 2:pos + 2 + length].decode("ascii", errors="replace").upper()
        (offset,) = struct.unpack_from(endian + "h", section, pos + 2 + length)
        if group < 0:
            groups[-group] = name
        elif group > 0 and pos + 6 + length <= end:
            kind, n_dims = struct.unpack_from("bB", section, pos + 4 + length)
            at = pos + 6 + length
            dims = section[at:at + n_dims]
            count = math.prod(dims) if n_dims else 1
            raw = section[at + n_dims:at + n_dims + abs(kind) * count]
            if kind in (1, 2, 4) and len(dims) == n_dims and len(raw) == kind * count:
                if kind == 1:
                    values = np.frombuffer(raw, np.uint8).astype(float)
                elif kind == 2:
                    values = np.frombuffer(raw, endian + "i2").astype(float)
                else:
                    values = decode_floats(raw, processor)
                found[group, name] = Parameter(kind, values, tuple(dims))
            elif text and kind == -1 and len(dims) == n_dims and len(raw) == count:
                width = dims[0] if n_dims else 1
                strings = [raw[k * width:(k + 1) * width].decode("latin-1").rstrip(" \x00")
                           for k in range(math.prod(dims[1:]))]
                found[group, name] = Parameter(kind, np.array(strings, dtype=object),
                                               tuple(dims))
        following = pos + 2 + length + offset
        if offset == 0 or following <= pos:
            break
        pos = following
    return {f"{groups[g]}:{name}": p for (g, name), p in found.items() if g in groups}


def read_points(path: str | Path, layout: C3DLayout, frames: int,
                chunk: int = 8192) -> np.ndarray:
    """The 3D points of the first ``frames`` frames (frames × points × 3, the file's units, NaN
    where the residual word is negative), read from the data section itself in chunks of
    frames (a memory map: nothing else of the file is loaded). For files past ezc3d's 65535
    frames; 32-bit floats of any processor, or 16-bit integers times |POINT:SCALE|."""
    size = 4 if layout.float_data else 2
    words = layout.frame_bytes // size
    if layout.float_data:
        dtype = {"Intel": "<f4", "MIPS": ">f4", "DEC": "<u4"}[layout.processor]
    else:
        dtype = ">i2" if layout.processor == "MIPS" else "<i2"
    raw = np.memmap(path, dtype=dtype, mode="r", offset=layout.data_offset,
                    shape=(frames, words))
    out = np.empty((frames, layout.points, 3))
    for start in range(0, frames, chunk):
        block = np.asarray(raw[start:start + chunk, :4 * layout.points])
        values: np.ndarray
        if layout.processor == "DEC" and layout.float_data:
            values = decode_floats(block.tobytes(), "DEC").reshape(block.shape)
        else:
            values = block.astype(float)
        if not layout.float_data:
            values *= abs(layout.point_scale)
        values = values.reshape(len(block), layout.points, 4)
        xyz = values[..., :3]
        xyz[values[..., 3] < 0] = np.nan
        out[start:start + len(block)] = xyz
    del raw
    return out
