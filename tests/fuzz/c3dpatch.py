"""Where a C3D file (Intel, as ezc3d writes it) keeps its header words and parameter values,
found by walking its bytes independently of fccgrb_cli.trial.c3d_header, so that a case can
overwrite one value and nothing else."""

from __future__ import annotations

import struct
from dataclasses import dataclass

BLOCK = 512
# header fields: byte offset and struct format (16-bit words, 1-based word n at bytes 2n-2..2n-1)
HEADER = {"parameter_block": (0, "B"), "key": (1, "B"), "points": (2, "<H"),
          "analog_per_frame": (4, "<H"), "first_frame": (6, "<H"), "last_frame": (8, "<H"),
          "max_gap": (10, "<H"), "scale": (12, "<f"), "data_block": (16, "<H"),
          "analog_samples": (18, "<H"), "rate": (20, "<f")}


@dataclass(frozen=True)
class Value:
    """A parameter's data: where it starts, its type (1, 2, 4; -1 text) and dimensions."""

    offset: int
    kind: int
    dims: tuple[int, ...]

    @property
    def size(self) -> int:
        count = 1
        for d in self.dims:
            count *= d
        return abs(self.kind) * count


def parameters(data: bytes) -> dict[str, Value]:
    """'GROUP:NAME' → where its value is."""
    start = (data[0] - 1) * BLOCK
    pos = start + 4
    groups: dict[int, str] = {}
    found: dict[tuple[int, str], Value] = {}
    while pos + 2 < len(data):
        length, group = struct.unpack_from("bb", data, pos)
        length = abs(length)
        if length == 0:
            break
        name = data[pos + 2:pos + 2 + length].decode("ascii", "replace").upper()
        (step,) = struct.unpack_from("<h", data, pos + 2 + length)
        if group < 0:
            groups[-group] = name
        else:
            kind, n_dims = struct.unpack_from("bB", data, pos + 4 + length)
            dims = tuple(data[pos + 6 + length:pos + 6 + length + n_dims])
            found[group, name] = Value(pos + 6 + length + n_dims, kind, dims)
        if step == 0:
            break
        pos = pos + 2 + length + step
    return {f"{groups[g]}:{n}": v for (g, n), v in found.items() if g in groups}


def set_header(data: bytes, field: str, value: float) -> bytes:
    offset, fmt = HEADER[field]
    out = bytearray(data)
    struct.pack_into(fmt, out, offset, value)
    return bytes(out)


def set_parameter(data: bytes, key: str, value: float | str) -> bytes:
    """The first value of parameter ``key`` replaced (a number in the parameter's own type; a
    text padded or cut to the stored width)."""
    where = parameters(data)[key]
    out = bytearray(data)
    if where.kind == -1:
        width = where.dims[0] if where.dims else 1
        raw = str(value).encode("latin-1")[:width].ljust(width)
        out[where.offset:where.offset + width] = raw
    else:
        fmt = {1: "<B", 2: "<h", 4: "<f"}[where.kind]
        struct.pack_into(fmt, out, where.offset, value)
    return bytes(out)


def data_offset(data: bytes) -> int:
    return (struct.unpack_from("<H", data, 16)[0] - 1) * BLOCK
