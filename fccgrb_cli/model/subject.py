"""A subject's measurements: what a clinical gait model (Plug-in Gait, the Conventional Gait Model
CGM 1.0) needs besides the markers, per side where the body has two.

SI inside (kg, m, rad). The same quantities come from three places, each read elsewhere into this
one type: a C3D's ``PROCESSING`` group as Vicon Nexus writes it (``io/processing.py``), a Vicon
``.vsk`` subject file (``io/vsk.py``), and a model file's ``subject:`` section (the loader).
Vicon's own spelling (``PIG_KEYS``) names each quantity in both of Vicon's files: lengths in mm,
angles in rad, the mass in kg; one key per side, ``L``/``R`` + name in a C3D, ``Left``/``Right`` +
name in a ``.vsk``.

``present`` lists the source's keys that were found and used (its own spelling), so that a
personalized model can say what it was built from; a quantity the source lacks is None.

Keys are read by what they mean, not by their spelling: case, spaces, underscores and hyphens
are ignored (``Marker Diameter``, ``MARKER_DIAMETER`` and ``MarkerDiameter`` are one key). An
angle Vicon stores in radians whose size only degrees explain (|value| > π/2, a Workstation
export's ``StaticPlantFlex`` of 12.7, say) is read as degrees and said in ``notes``; a static
foot offset a calibration computes itself (``StaticPlantFlex``, ``StaticRotOff``) is never
required, and one no unit makes plausible is left out with a note rather than refused.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Any, NoReturn

from fccgrb_cli.core.errors import InputError

SIDE_NAMES = {"l": "left", "r": "right"}


@dataclass(frozen=True)
class Sided:
    """One quantity for each side (None where not measured)."""

    left: float | None = None
    right: float | None = None

    def side(self, s: str) -> float | None:
        """The value of side ``s`` ('l' or 'r')."""
        return self.left if s == "l" else self.right


@dataclass(frozen=True)
class Quantity:
    """How one measurement reads: its Vicon name (without the side prefix), its kind ('length',
    'angle' or 'mass'), whether it has a value per side, the plausible range in Vicon's units (a
    value outside it is refused: a typo, or a value in another unit), whether Vicon writes 0
    for 'not measured' (then 0 reads as absent and the model computes it), and whether it is
    a result a calibration computes again (``derived``: never refused, left out when
    implausible)."""

    vicon: str
    kind: str
    sided: bool
    low: float
    high: float
    zero_is_absent: bool = False
    derived: bool = False


# Field name → how Vicon spells and scales it. Ranges cover children to tall adults (mm, rad, kg).
PIG_KEYS: dict[str, Quantity] = {
    "body_mass": Quantity("Bodymass", "mass", False, 0.5, 400.0, True),
    "height": Quantity("Height", "length", False, 300.0, 2600.0, True),
    "marker_diameter": Quantity("MarkerDiameter", "length", False, 0.0, 50.0),
    "inter_asis_distance": Quantity("InterAsisDistance", "length", False, 50.0, 500.0, True),
    "leg_length": Quantity("LegLength", "length", True, 200.0, 1500.0, True),
    "knee_width": Quantity("KneeWidth", "length", True, 20.0, 250.0, True),
    "ankle_width": Quantity("AnkleWidth", "length", True, 15.0, 200.0, True),
    "asis_trochanter_distance": Quantity("AsisTrocanterDistance", "length", True, 5.0, 250.0,
                                         True),
    "sole_delta": Quantity("SoleDelta", "length", True, -100.0, 100.0),
    "thigh_rotation": Quantity("ThighRotation", "angle", True, -math.pi / 2, math.pi / 2),
    "shank_rotation": Quantity("ShankRotation", "angle", True, -math.pi / 2, math.pi / 2),
    "tibial_torsion": Quantity("TibialTorsion", "angle", True, -math.pi / 2, math.pi / 2),
    "static_plantar_flexion": Quantity("StaticPlantFlex", "angle", True, -math.pi / 2,
                                       math.pi / 2, derived=True),
    "static_rotation_offset": Quantity("StaticRotOff", "angle", True, -math.pi / 2, math.pi / 2,
                                       derived=True),
    # the full body's arms and head (plugin_gait/upper.py)
    "shoulder_offset": Quantity("ShoulderOffset", "length", True, 5.0, 200.0, True),
    "elbow_width": Quantity("ElbowWidth", "length", True, 20.0, 200.0, True),
    "wrist_width": Quantity("WristWidth", "length", True, 10.0, 150.0, True),
    "hand_thickness": Quantity("HandThickness", "length", True, 5.0, 100.0, True),
    "head_offset": Quantity("HeadOffset", "angle", False, -math.pi / 2, math.pi / 2),
}
VICON_SCALE = {"length": 1e-3, "angle": 1.0, "mass": 1.0}  # Vicon's unit → SI


@dataclass(frozen=True)
class SubjectMeasurements:
    """A subject's measurements, SI: body mass (kg), height, leg length (ASIS to medial
    malleolus), knee width (across the femoral epicondyles), ankle width (across the malleoli),
    the markers' diameter, the inter-ASIS distance, the ASIS–greater trochanter distance, the sole
    delta (heel minus toe sole thickness of the static trial's shoes), all m; thigh and shank
    rotation offsets (the thigh and shank wands' angles off the knee and ankle flexion axes) and
    tibial torsion, rad. ``static_plantar_flexion`` and ``static_rotation_offset`` are the foot
    offsets a static trial gave Vicon's Plug-in Gait (its results, stored for comparison:
    calibration computes its own). The full body's: shoulder offset (the shoulder marker to the
    shoulder centre), elbow and wrist widths, hand thickness (m), head offset (rad; the
    static's head tilt Plug-in Gait takes out). ``source`` names where the values came from,
    ``present`` the keys found there, ``notes`` what was read otherwise than written (an angle
    in degrees, a derived value left out)."""

    body_mass: float | None = None
    height: float | None = None
    marker_diameter: float | None = None
    inter_asis_distance: float | None = None
    leg_length: Sided = field(default_factory=Sided)
    knee_width: Sided = field(default_factory=Sided)
    ankle_width: Sided = field(default_factory=Sided)
    asis_trochanter_distance: Sided = field(default_factory=Sided)
    sole_delta: Sided = field(default_factory=Sided)
    thigh_rotation: Sided = field(default_factory=Sided)
    shank_rotation: Sided = field(default_factory=Sided)
    tibial_torsion: Sided = field(default_factory=Sided)
    static_plantar_flexion: Sided = field(default_factory=Sided)
    static_rotation_offset: Sided = field(default_factory=Sided)
    shoulder_offset: Sided = field(default_factory=Sided)
    elbow_width: Sided = field(default_factory=Sided)
    wrist_width: Sided = field(default_factory=Sided)
    hand_thickness: Sided = field(default_factory=Sided)
    head_offset: float | None = None
    source: str = ""
    present: tuple[str, ...] = ()
    notes: tuple[str, ...] = ()

    def merged_over(self, base: SubjectMeasurements) -> SubjectMeasurements:
        """These measurements where given (per side), ``base``'s elsewhere; sources joined."""
        values: dict[str, Any] = {}
        for name in PIG_KEYS:
            mine, theirs = getattr(self, name), getattr(base, name)
            if isinstance(mine, Sided):
                values[name] = Sided(theirs.left if mine.left is None else mine.left,
                                     theirs.right if mine.right is None else mine.right)
            else:
                values[name] = theirs if mine is None else mine
        source = "; ".join(s for s in (self.source, base.source) if s)
        return replace(self, **values, source=source,
                       present=tuple(dict.fromkeys(self.present + base.present)),
                       notes=tuple(dict.fromkeys(base.notes + self.notes)))

    def missing(self, names: tuple[str, ...]) -> list[str]:
        """The Vicon keys of the named quantities not given (per side for sided ones)."""
        out = []
        for name in names:
            value, q = getattr(self, name), PIG_KEYS[name]
            if isinstance(value, Sided):
                out += [f"{p}{q.vicon}" for p, s in (("L", "l"), ("R", "r"))
                        if value.side(s) is None]
            elif value is None:
                out.append(q.vicon)
        return out


def vicon_key_names(prefixes: tuple[str, str] = ("L", "R")) -> dict[str, tuple[str, str]]:
    """Every Vicon key (with ``prefixes`` for the left and right sides) → (field, side), side
    '' for a quantity of the whole body."""
    out: dict[str, tuple[str, str]] = {}
    for name, q in PIG_KEYS.items():
        if q.sided:
            out[f"{prefixes[0]}{q.vicon}"] = (name, "l")
            out[f"{prefixes[1]}{q.vicon}"] = (name, "r")
        else:
            out[q.vicon] = (name, "")
    return out


def spelling(key: str) -> str:
    """A key as its meaning reads it: upper case, without spaces, underscores or hyphens."""
    return "".join(c for c in key.upper() if c not in " _-")


def _as_degrees(value: float, q: Quantity) -> bool:
    """Whether an angle outside its range in radians lies inside it read as degrees."""
    return q.kind == "angle" and q.low <= math.radians(value) <= q.high


def from_vicon(values: dict[str, float], source: str, fail: Callable[[str, str, float], None],
               prefixes: tuple[str, str] = ("L", "R")) -> SubjectMeasurements:
    """Measurements from Vicon's keys and units (``values``: key → number, keys matched by
    :func:`spelling`; others ignored). A value that is not finite or lies outside its plausible
    range calls ``fail(key, expected, got)``, which raises, except an angle that reads plausibly
    in degrees (converted, and said in ``notes``) and a ``derived`` value (left out, said);
    0 where Vicon writes it for 'not measured' reads as absent. ``present`` holds the keys in
    Vicon's spelling."""
    by_meaning = {spelling(k): v for k, v in values.items()}
    collected: dict[str, Any] = {}
    present, notes = [], []
    for key, (name, side) in vicon_key_names(prefixes).items():
        if spelling(key) not in by_meaning:
            continue
        value = by_meaning[spelling(key)]
        q = PIG_KEYS[name]
        unit = {"length": "mm", "angle": "rad", "mass": "kg"}[q.kind]
        if value == 0 and q.zero_is_absent:
            continue
        si = value * VICON_SCALE[q.kind]
        if not (math.isfinite(value) and q.low <= value <= q.high):
            if math.isfinite(value) and _as_degrees(value, q):
                si = math.radians(value)
                notes.append(f"{source}: {key} {value:g} read as degrees ({si:.4f} rad): "
                             f"beyond ±{q.high:.4g} rad, only degrees make it plausible")
            elif q.derived:
                notes.append(f"{source}: {key} {value:g} left out (expected "
                             f"{q.low:g}–{q.high:g} {unit}); the calibration computes it")
                continue
            else:
                fail(key, f"{q.low:g}–{q.high:g} {unit}", value)
        present.append(key)
        if side:
            old = collected.get(name, Sided())
            collected[name] = replace(old, **{SIDE_NAMES[side]: si})
        else:
            collected[name] = si
    return SubjectMeasurements(**collected, source=source, present=tuple(present),
                               notes=tuple(notes))


YAML_UNITS = {"length": "m", "angle": "the file's angle unit", "mass": "kg"}


def from_yaml(spec: dict[str, Any], angle_scale: float,
              fail: Callable[[str, str, Any], None]) -> SubjectMeasurements:
    """Measurements from a model file's ``subject:`` section (``mass`` in kg; lengths in m;
    angles in the file's angle unit, ``angle_scale`` to radians; a per-side quantity as
    ``{left: .., right: ..}`` or one number for both; ``source`` free text). ``fail(path,
    expected, got)`` raises with the key path."""
    names = {"mass": "body_mass", **{name: name for name in PIG_KEYS if name != "body_mass"}}
    collected: dict[str, Any] = {}
    for key, value in spec.items():
        if key == "source":
            continue
        name = names[key]
        q = PIG_KEYS[name]
        scale = angle_scale if q.kind == "angle" else 1.0
        to_vicon = scale / VICON_SCALE[q.kind]

        def read(v: Any, path: str, q: Quantity = q, scale: float = scale,
                 to_vicon: float = to_vicon) -> float:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
                fail(path, "a finite number", v)
            low, high = q.low / to_vicon, q.high / to_vicon
            if q.kind == "mass" and not 0 < v <= high:
                fail(path, f"a positive body mass (kg), at most {high:g}", v)
            if not low <= v <= high:
                fail(path, f"{low:g}–{high:g} ({YAML_UNITS[q.kind]})", v)
            return float(v) * scale

        path = f"subject.{key}"
        if not q.sided:
            collected[name] = read(value, path)
        elif isinstance(value, dict):
            extra = set(value) - {"left", "right"}
            if extra:
                fail(path, "the keys left and right", sorted(extra))
            collected[name] = Sided(*(read(value[side], f"{path}.{side}")
                                      if side in value else None
                                      for side in ("left", "right")))
        else:
            both = read(value, path)
            collected[name] = Sided(both, both)
    source = spec.get("source", "")
    if not isinstance(source, str):
        fail("subject.source", "text", source)
    return SubjectMeasurements(**collected, source=source,
                               present=tuple(k for k in spec if k != "source"))


def yaml_keys() -> set[str]:
    """The keys a model file's ``subject:`` section may hold."""
    return {"mass", "source", *(name for name in PIG_KEYS if name != "body_mass")}


def from_flags(flags: dict[str, str | None]) -> SubjectMeasurements:
    """Measurements typed on the command line (``--knee-width 102,104``: field name → text in
    Vicon's units, mm or kg, one value for both sides or ``left,right``); an InputError names
    the flag."""
    values: dict[str, float] = {}
    for name, text in flags.items():
        if text is None:
            continue
        flag = f"--{name.replace('_', '-')}"
        try:
            numbers = [float(x) for x in text.split(",")]
        except ValueError:
            raise InputError(f"{flag}: expected a number or two (left,right), got "
                             f"{text!r}") from None
        q = PIG_KEYS[name]
        if len(numbers) not in ((1, 2) if q.sided else (1,)):
            wanted = "one or two numbers (left,right)" if q.sided else "one number"
            raise InputError(f"{flag}: expected {wanted}, got {text!r}")
        if q.sided:
            left, right = numbers if len(numbers) == 2 else numbers * 2
            values.update({f"L{q.vicon}": left, f"R{q.vicon}": right})
        else:
            values[q.vicon] = numbers[0]

    def fail(key: str, expected: str, got: float) -> NoReturn:
        name = next(n for n, q in PIG_KEYS.items() if key.endswith(q.vicon))
        raise InputError(f"--{name.replace('_', '-')}: expected {expected}, got {got:g}")

    return from_vicon(values, "the command line", fail)
