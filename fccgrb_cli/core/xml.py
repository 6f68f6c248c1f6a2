"""XML from strangers, parsed without surprises.

OpenSim's models, external loads and setups are XML written by anyone. A document is refused, in
one line naming the file, when it declares a DOCTYPE (entity expansion — "billion laughs" — and
external entities both need one; OpenSim never writes one), nests deeper than ``MAX_DEPTH``, is
larger than ``MAX_BYTES`` or is not well formed up to the end of its root element (what follows
that end is not read, as OpenSim's parser does not: opensim-core's ``gait2354_IK_Tasks.xml``
closes an ``OpenSimDocument`` it never opened). Numbers are read by ``number``, which refuses
what is not finite or beyond ``MAX_MAGNITUDE``."""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from pathlib import Path
from xml.parsers.expat import ExpatError, ParserCreate

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import read_bytes

__all__ = ["MAX_BYTES", "MAX_DEPTH", "MAX_MAGNITUDE", "element_path", "number", "numbers",
           "parse", "parse_bytes"]

MAX_BYTES = 64 * 1024 * 1024
MAX_DEPTH = 64
MAX_MAGNITUDE = 1e12


class _Refused(Exception):
    pass


def parse(path: str | Path) -> ET.Element:
    """The root element of the XML file ``path``.

    Raises
    ------
    InputError
        Naming the file: missing, not a regular file (a FIFO would block the read), too large,
        not well formed, a DOCTYPE (entities), or nesting deeper than ``MAX_DEPTH``.
    """
    return parse_bytes(read_bytes(path, "XML file", MAX_BYTES), str(path))


def parse_bytes(data: bytes, name: str) -> ET.Element:
    """The root element of the XML document ``data``; ``name`` names it in errors."""
    depth, closed = 0, False

    def start(tag, attrs):
        nonlocal depth
        depth += 1
        if depth > MAX_DEPTH:
            raise _Refused(f"elements nested deeper than {MAX_DEPTH}")
        builder.start(tag, attrs)

    def end(tag):
        nonlocal depth, closed
        depth -= 1
        builder.end(tag)
        closed = depth == 0

    def doctype(*_):
        raise _Refused("a DOCTYPE declaration (entities are not accepted)")

    builder = ET.TreeBuilder()
    expat = ParserCreate()
    expat.buffer_text = True
    expat.StartElementHandler = start
    expat.EndElementHandler = end
    expat.StartDoctypeDeclHandler = doctype
    expat.EntityDeclHandler = doctype
    expat.ExternalEntityRefHandler = doctype
    expat.CharacterDataHandler = builder.data
    try:
        expat.Parse(data, True)
        root = builder.close()
    except _Refused as why:
        raise InputError(f"{name}: refused: {why}") from None
    except ExpatError as error:
        if not closed:
            raise InputError(f"{name}: not well-formed XML ({error})") from None
        root = builder.close()  # what follows the root element is not read (as OpenSim)
    return root


def element_path(parents: list[ET.Element], element: ET.Element) -> str:
    """``Model/BodySet/objects/Body[name=femur_r]``: where an element sits, for messages."""
    parts = []
    for node in [*parents, element]:
        name = node.get("name")
        parts.append(f"{node.tag}[name={name}]" if name else node.tag)
    return "/".join(parts)


def numbers(text: str | None, where: str, count: int | None = None) -> tuple[float, ...]:
    """The whitespace-separated numbers of an element's text, each finite and at most
    ``MAX_MAGNITUDE``; ``count`` of them when given. ``where`` names the element in errors."""
    words = (text or "").split()
    if count is not None and len(words) != count:
        raise InputError(f"{where}: expected {count} numbers, got {len(words)}")
    return tuple(number(word, where) for word in words)


def number(text: str | None, where: str) -> float:
    """One finite number of magnitude at most ``MAX_MAGNITUDE``."""
    try:
        value = float((text or "").strip())
    except ValueError:
        raise InputError(f"{where}: expected a number, got {text!r:.40}") from None
    if not math.isfinite(value) or abs(value) > MAX_MAGNITUDE:
        raise InputError(f"{where}: expected a finite number of magnitude at most "
                         f"{MAX_MAGNITUDE:g}, got {text!r:.40}")
    return value
