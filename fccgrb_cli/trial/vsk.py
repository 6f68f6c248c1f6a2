"""A subject's measurements from a Vicon subject file (``.vsk``, XML): Plug-in Gait's
``<StaticParameter NAME="LeftKneeWidth" VALUE="102" QUANTITY="length" .../>`` entries (and plain
``<Parameter>`` ones), lengths in mm, angles in rad, the mass in kg, the sides spelt ``Left`` /
``Right``."""

from __future__ import annotations

import xml.etree.ElementTree as ElementTree
from pathlib import Path

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model.subject import SubjectMeasurements, from_vicon


def vsk_measurements(path: str | Path) -> SubjectMeasurements:
    """The measurements a ``.vsk`` file holds (SI; the keys found in ``present``). A file that
    is not XML, or a parameter whose VALUE is not a number, is an InputError naming the file
    and the parameter."""
    path = Path(path)
    try:
        root = ElementTree.parse(path).getroot()
    except FileNotFoundError:
        raise InputError(f"{path}: subject file not found") from None
    except (ElementTree.ParseError, OSError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: not a readable Vicon subject file (XML: {exc})") from None
    values: dict[str, float] = {}
    for element in root.iter():
        if element.tag not in ("StaticParameter", "Parameter") or "NAME" not in element.attrib:
            continue
        name, text = element.attrib["NAME"], element.attrib.get("VALUE")
        if text is None:
            continue
        try:
            value = float(text)
        except ValueError:
            raise InputError(f"{path}: {element.tag} {name}: expected a number VALUE, got "
                             f"{text!r}") from None
        values[name] = value

    def fail(key: str, expected: str, got: float) -> None:
        raise InputError(f"{path}: StaticParameter {key}: expected {expected}, got {got:g}")

    return from_vicon(values, str(path), fail, prefixes=("Left", "Right"))
