"""Subject measurements from a C3D's PROCESSING group (``io/processing.py``).

Expectations come from the values written into the files here (in Vicon's units: mm, rad, kg,
converted to SI by this file's own factors) and, for the shared Plug-in Gait trial, from the
numbers ``../shared/data/README.md`` states for it.
"""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.trial.processing import processing_measurements

ROOT = Path(__file__).resolve().parents[1]
STATIC = ROOT / ".." / "shared" / "data" / "c3d" / "plugin_gait" / "HC030A01.c3d"

# Vicon key → (field, side, factor to SI): written out here, not taken from the module.
KEYS = {
    "Bodymass": ("body_mass", None, 1.0),
    "Height": ("height", None, 1e-3),
    "MarkerDiameter": ("marker_diameter", None, 1e-3),
    "InterAsisDistance": ("inter_asis_distance", None, 1e-3),
    "LLegLength": ("leg_length", "left", 1e-3), "RLegLength": ("leg_length", "right", 1e-3),
    "LKneeWidth": ("knee_width", "left", 1e-3), "RKneeWidth": ("knee_width", "right", 1e-3),
    "LAnkleWidth": ("ankle_width", "left", 1e-3), "RAnkleWidth": ("ankle_width", "right", 1e-3),
    "LAsisTrocanterDistance": ("asis_trochanter_distance", "left", 1e-3),
    "RAsisTrocanterDistance": ("asis_trochanter_distance", "right", 1e-3),
    "LSoleDelta": ("sole_delta", "left", 1e-3), "RSoleDelta": ("sole_delta", "right", 1e-3),
    "LThighRotation": ("thigh_rotation", "left", 1.0),
    "RThighRotation": ("thigh_rotation", "right", 1.0),
    "LShankRotation": ("shank_rotation", "left", 1.0),
    "RShankRotation": ("shank_rotation", "right", 1.0),
    "LTibialTorsion": ("tibial_torsion", "left", 1.0),
    "RTibialTorsion": ("tibial_torsion", "right", 1.0),
}
# Plausible values in Vicon's units, drawn per case.
RANGES = {"Bodymass": (15, 120), "Height": (900, 2000), "MarkerDiameter": (8, 25),
          "InterAsisDistance": (150, 300), "LegLength": (500, 1100), "KneeWidth": (70, 130),
          "AnkleWidth": (50, 90), "AsisTrocanterDistance": (30, 90), "SoleDelta": (-10, 30),
          "ThighRotation": (-0.4, 0.4), "ShankRotation": (-0.4, 0.4),
          "TibialTorsion": (-0.5, 0.5)}


def _range(key: str) -> tuple[float, float]:
    return RANGES.get(key, RANGES.get(key[1:], (0, 1)))


def write_c3d(path: Path, processing: dict[str, float]) -> None:
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [100.0]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ["A"]
    c3d["data"]["points"] = np.ones((4, 1, 3))
    for key, value in processing.items():
        c3d.add_parameter("PROCESSING", key, [float(value)])
    c3d.write(str(path))


def value_of(m, field: str, side: str | None):
    value = getattr(m, field)
    return getattr(value, side) if side else value


@pytest.mark.parametrize("seed", range(4))
def test_generated_processing_groups_read_in_si(tmp_path, seed):
    rng = np.random.default_rng(seed)
    keys = [k for k in KEYS if rng.random() < 0.7]  # some keys absent in each case
    written = {k: float(np.float32(rng.uniform(*_range(k)))) for k in keys}
    path = tmp_path / "subject.c3d"
    write_c3d(path, {**written, "UnrelatedKey": 3.0})
    m = processing_measurements(path)
    for key, (field, side, factor) in KEYS.items():
        got = value_of(m, field, side)
        if key in written:
            assert got == pytest.approx(written[key] * factor, rel=1e-6), key
        else:
            assert got is None, key
    assert set(m.present) == set(written)
    assert str(path) in m.source


def test_zero_means_not_measured_where_vicon_writes_it_so(tmp_path):
    """Nexus writes 0 for an optional distance it should compute (InterAsisDistance,
    AsisTrocanterDistance); a zero rotation or torsion is a value."""
    path = tmp_path / "zeros.c3d"
    write_c3d(path, {"InterAsisDistance": 0.0, "LAsisTrocanterDistance": 0.0,
                     "LTibialTorsion": 0.0, "RThighRotation": 0.0})
    m = processing_measurements(path)
    assert m.inter_asis_distance is None and m.asis_trochanter_distance.left is None
    assert m.tibial_torsion.left == 0.0 and m.thigh_rotation.right == 0.0
    assert set(m.present) == {"LTibialTorsion", "RThighRotation"}


@pytest.mark.parametrize("key,value", [("LKneeWidth", 10.2), ("Bodymass", -3.0),
                                       ("RTibialTorsion", 120.0), ("Height", float("nan"))])
def test_implausible_values_are_refused_naming_file_and_key(tmp_path, key, value):
    """A knee width in cm, a negative mass, a torsion no unit makes plausible: one error
    naming both."""
    path = tmp_path / "bad.c3d"
    write_c3d(path, {key: value})
    with pytest.raises(InputError, match=rf"bad\.c3d: PROCESSING:{key}: expected"):
        processing_measurements(path)


def test_not_a_c3d_file(tmp_path):
    path = tmp_path / "notes.c3d"
    path.write_text("not a c3d")
    with pytest.raises(InputError, match=r"notes\.c3d: not a readable C3D file"):
        processing_measurements(path)
    with pytest.raises(InputError, match=r"missing\.c3d: C3D file not found"):
        processing_measurements(tmp_path / "missing.c3d")


@pytest.mark.skipif(not STATIC.exists(), reason="shared Plug-in Gait data absent")
def test_shared_plugin_gait_static():
    """The values ../shared/data/README.md gives for HC030A01: body mass 45.8 kg, knee widths
    L/R 102/104 mm, ankle widths 61/59 mm, marker diameter 10 mm."""
    m = processing_measurements(STATIC)
    assert m.body_mass == pytest.approx(45.8, abs=1e-5)
    assert (m.knee_width.left, m.knee_width.right) == pytest.approx((0.102, 0.104))
    assert (m.ankle_width.left, m.ankle_width.right) == pytest.approx((0.061, 0.059))
    assert m.marker_diameter == pytest.approx(0.010)
    assert m.missing(("leg_length", "knee_width", "ankle_width", "marker_diameter")) == []
    assert m.missing(("sole_delta",)) == ["LSoleDelta", "RSoleDelta"]


# --- other sources: a Vicon .vsk, a YAML subject section, the command line -------------------

def write_vsk(path: Path, values: dict[str, float]) -> None:
    rows = "\n".join(f'    <StaticParameter NAME="{k}" VALUE="{v!r}" PRIOR="0"/>'
                     for k, v in values.items())
    path.write_text(f'<?xml version="1.0"?>\n<KinematicModel>\n  <Parameters>\n{rows}\n'
                    "  </Parameters>\n</KinematicModel>\n", encoding="utf-8")


def test_vsk_spells_the_sides_left_and_right(tmp_path):
    from fccgrb_cli.trial.vsk import vsk_measurements

    path = tmp_path / "child.vsk"
    write_vsk(path, {"Bodymass": 31.5, "LeftLegLength": 702.0, "RightLegLength": 698.0,
                     "LeftKneeWidth": 88.5, "RightTibialTorsion": -0.21, "MarkerDiameter": 14.0,
                     "Theta": 0.5})
    m = vsk_measurements(path)
    assert m.body_mass == pytest.approx(31.5)
    assert (m.leg_length.left, m.leg_length.right) == pytest.approx((0.702, 0.698))
    assert m.knee_width.left == pytest.approx(0.0885) and m.knee_width.right is None
    assert m.tibial_torsion.right == pytest.approx(-0.21)
    assert set(m.present) == {"Bodymass", "LeftLegLength", "RightLegLength", "LeftKneeWidth",
                              "RightTibialTorsion", "MarkerDiameter"}
    write_vsk(path, {"LeftKneeWidth": "wide"})  # type: ignore[dict-item]
    path.write_text(path.read_text().replace("'wide'", "wide"))
    with pytest.raises(InputError, match=r"child\.vsk: StaticParameter LeftKneeWidth: expected"):
        vsk_measurements(path)
    path.write_text("not xml <")
    with pytest.raises(InputError, match=r"child\.vsk: not a readable Vicon subject file"):
        vsk_measurements(path)


def test_yaml_subject_file_in_model_units(tmp_path):
    from fccgrb_cli.trial.subject_files import read_measurements

    path = tmp_path / "subject.yaml"
    path.write_text("subject:\n  mass: 40\n  knee_width: {left: 0.095, right: 0.097}\n"
                    "  ankle_width: 0.06\n  thigh_rotation: {left: -6}\n", encoding="utf-8")
    m = read_measurements(path)
    assert m.body_mass == 40 and m.knee_width.right == pytest.approx(0.097)
    assert (m.ankle_width.left, m.ankle_width.right) == (0.06, 0.06)
    assert m.thigh_rotation.left == pytest.approx(np.radians(-6)) and \
        m.thigh_rotation.right is None
    path.write_text("subject:\n  knee_width: 102\n", encoding="utf-8")  # mm by mistake
    with pytest.raises(InputError, match=r"subject\.yaml: subject\.knee_width: expected"):
        read_measurements(path)
    path.write_text("subject:\n  knee_widht: 0.1\n", encoding="utf-8")
    with pytest.raises(InputError, match="expected only the keys"):
        read_measurements(path)


def test_typed_values_and_their_precedence():
    from fccgrb_cli.model.subject import Sided, SubjectMeasurements, from_flags

    typed = from_flags({"knee_width": "102,104", "ankle_width": "61", "body_mass": None})
    assert (typed.knee_width.left, typed.knee_width.right) == pytest.approx((0.102, 0.104))
    assert (typed.ankle_width.left, typed.ankle_width.right) == pytest.approx((0.061, 0.061))
    base = SubjectMeasurements(body_mass=45.0, knee_width=Sided(0.1, None),
                               leg_length=Sided(0.8, 0.81), source="base")
    merged = typed.merged_over(base)
    assert merged.knee_width.right == pytest.approx(0.104) and merged.body_mass == 45.0
    assert merged.leg_length.right == 0.81 and merged.source == "the command line; base"
    for text, message in (("10,104", "--knee-width: expected 20–250 mm"),
                          ("1,2,3", "--knee-width: expected one or two numbers"),
                          ("wide", "--knee-width: expected a number")):
        with pytest.raises(InputError, match=message):
            from_flags({"knee_width": text})
