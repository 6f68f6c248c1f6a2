"""A study file (YAML), read and validated: the template, label map and solve options every
subject shares, and per subject its static trial, walking trials (globs), measurements and
overrides. Paths are relative to the study file. Every rejection is one line naming the file and
the key path (``study.yaml: subjects[1].trials[0]: expected …``).

```yaml
name: example                              # default: the file's stem
template: configs/models/lower_limb.yaml   # default for every subject
map: lab.yaml                              # default label map (a file, or NAME: LABEL pairs)
options: {filter_cutoff: 6}                # SolveOptions keys, as a sweep cell's
measurements: from-c3d                     # default for every subject (see below)
subjects:
  - name: S01
    group: control                         # default: all
    static: S01/static.c3d
    frames: 0:100                          # the static's frame indices used (default: all)
    trials: [S01/walk*.c3d]
    mass: 67                               # kg
    measurements: from-c3d                 # the static's PROCESSING group (Vicon Nexus), or
                                           # {knee_width: 100, ankle_width: 70,
                                           #  marker_diameter: 14} in mm (Davis templates)
    map: lab.yaml                          # optional; template: optional override
```
"""

from __future__ import annotations

import glob
import math
import os
import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any, NoReturn

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import load_yaml, read_text
from fccgrb_cli.pipeline.options import SolveOptions, label_map_file

TOP_KEYS = ("name", "template", "map", "options", "measurements", "subjects")
SUBJECT_KEYS = ("name", "group", "static", "frames", "trials", "mass", "measurements", "map",
                "template")
WIDTHS = ("knee_width", "ankle_width", "marker_diameter")  # mm, as `fccgrb calibrate` takes
FROM_C3D = "from-c3d"
NAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]*")
DEFAULT_GROUP = "all"
MAX_MASS = 500.0  # kg


@dataclass(frozen=True)
class SubjectSpec:
    """One subject: its template, static trial (frame indices A:B or all), walking trials,
    body mass (kg, or None), measurements (``FROM_C3D``, a mapping of Davis' widths in mm, or
    None) and label map (model name → trial label)."""

    name: str
    group: str
    template: Path
    static: Path
    frames: tuple[int, int] | None
    trials: tuple[Path, ...]
    mass: float | None
    measurements: str | tuple[tuple[str, float], ...] | None
    mapping: tuple[tuple[str, str], ...]
    map_file: Path | None = None

    def trial_name(self, trial: Path) -> str:
        """A trial's run name in the study file: subject, then the trial file's stem."""
        return f"{self.name}-{trial.stem}"


@dataclass(frozen=True)
class Study:
    """A validated study: its name, file and text (kept in the results), the options every trial
    is solved with, and the subjects in the file's order."""

    name: str
    source: Path
    text: str
    options: SolveOptions
    subjects: tuple[SubjectSpec, ...]

    @property
    def inputs(self) -> tuple[Path, ...]:
        """Every file the study reads (none may be its output)."""
        out = [self.source]
        for s in self.subjects:
            out += [s.template, s.static, *s.trials, *([s.map_file] if s.map_file else [])]
        return tuple(out)

    def relative(self, path: Path) -> str:
        """A path as seen from the study file's folder (as the study names it)."""
        return os.path.relpath(path, self.source.parent)


class _Reader:
    """One-line errors naming the study file and the key path."""

    def __init__(self, source: Path):
        self.source = source
        self.folder = source.parent

    def fail(self, where: str, expected: str, got: Any = None) -> NoReturn:
        raise InputError(f"{self.source}: {where}: expected {expected}"
                         + ("" if got is None else f", got {got!r}"))

    def mapping(self, value: Any, where: str, allowed: tuple[str, ...]) -> dict:
        if not isinstance(value, dict):
            self.fail(where, "a mapping", value)
        unknown = sorted(str(k) for k in value if k not in allowed)
        if unknown:
            prefix = f"{where}." if where != "(top level)" else ""
            self.fail(f"{prefix}{unknown[0]}", f"one of the keys {', '.join(allowed)}")
        return value

    def name(self, value: Any, where: str) -> str:
        if not isinstance(value, str | int) or isinstance(value, bool) or \
                not NAME.fullmatch(str(value)) or len(str(value)) > 100:
            self.fail(where, "a name of letters, digits and _ . + - (starting with a letter or "
                             "digit, at most 100 characters)", value)
        return str(value)

    def file(self, value: Any, where: str, what: str) -> Path:
        """An existing regular file, relative to the study file; a glob matching one file."""
        if not isinstance(value, str) or not value.strip():
            self.fail(where, f"the path of {what}", value)
        found = self.matches(value, where, what)
        if len(found) != 1:
            self.fail(where, f"one {what}, found {len(found)} matching", value)
        return found[0]

    def matches(self, pattern: str, where: str, what: str) -> list[Path]:
        """The regular files a path or glob names, relative to the study file, sorted."""
        path = self.folder / pattern
        if any(c in pattern for c in "*?[") and not path.exists():
            found = [Path(p) for p in sorted(glob.glob(str(path)))]
            found = [p for p in found if p.is_file()]
            if not found:
                self.fail(where, f"{what} matching the pattern, found none", pattern)
            return [p.resolve() for p in found]
        if not path.is_file():
            self.fail(where, f"an existing {what}" + (", got a folder" if path.is_dir() else
                                                      f" ({path} not found)"))
        return [path.resolve()]

    def mapping_pairs(self, value: Any, where: str
                      ) -> tuple[tuple[tuple[str, str], ...], Path | None]:
        """A label map: a YAML file of NAME: LABEL lines (and its path), or those pairs
        inline."""
        if isinstance(value, dict):
            if not all(isinstance(k, str) and isinstance(v, str) for k, v in value.items()):
                self.fail(where, "NAME: LABEL pairs of strings")
            return tuple(value.items()), None
        path = self.file(value, where, "label map file")
        return tuple(label_map_file(str(path))), path

    def frames(self, value: Any, where: str) -> tuple[int, int]:
        text = "" if value is None else str(value)
        match = re.fullmatch(r"\s*(\d+)\s*:\s*(\d+)\s*", text)
        if isinstance(value, list) and len(value) == 2 and all(
                isinstance(v, int) and not isinstance(v, bool) for v in value):
            start, stop = value
        elif match:
            start, stop = int(match[1]), int(match[2])
        else:
            self.fail(where, "A:B, frame indices from 0 with B excluded", value)
        if not 0 <= start < stop:
            self.fail(where, "A:B with 0 ≤ A < B", value)
        return start, stop

    def mass(self, value: Any, where: str) -> float:
        if isinstance(value, bool) or not isinstance(value, int | float) or \
                not math.isfinite(value) or not 0 < value <= MAX_MASS:
            self.fail(where, f"a body mass in kg, above 0 and at most {MAX_MASS:g}", value)
        return float(value)

    def measurements(self, value: Any, where: str) -> str | tuple[tuple[str, float], ...]:
        if value == FROM_C3D:
            return FROM_C3D
        if not isinstance(value, dict):
            self.fail(where, f"{FROM_C3D} or a mapping of {', '.join(WIDTHS)} (mm)", value)
        self.mapping(value, where, WIDTHS)
        out = []
        for key, number in value.items():
            if isinstance(number, bool) or not isinstance(number, int | float) or \
                    not math.isfinite(number):
                self.fail(f"{where}.{key}", "a number of mm", number)
            out.append((str(key), float(number)))
        return tuple(out)


def _load_text(path: Path) -> tuple[str, Any]:
    text = read_text(path, "study file")
    return text, load_yaml(text, str(path))


def load_study(path: str | Path) -> Study:
    """Read and validate a study file (the files it names must exist; their contents are read
    when each subject is calibrated and each trial solved)."""
    path = Path(path)
    text, doc = _load_text(path)
    r = _Reader(path)
    doc = r.mapping(doc, "(top level)", TOP_KEYS)
    if "subjects" not in doc:
        r.fail("subjects", "this key: a list of subjects")
    options = doc.get("options") or {}
    if not isinstance(options, dict):
        r.fail("options", "a mapping of solve options", options)
    for key in ("name", "map"):
        if key in options:
            r.fail(f"options.{key}", "no run name or label map here (runs are named after "
                                     "subject and trial; the map is the study's or a "
                                     "subject's 'map')")
    solve = SolveOptions.from_mapping(options, where=f"{path}: options")
    defaults = {key: doc[key] for key in ("template", "map", "measurements") if key in doc}
    subjects = doc["subjects"]
    if not isinstance(subjects, list) or not subjects:
        r.fail("subjects", "a non-empty list of subjects", subjects)
    out: list[SubjectSpec] = []
    for k, item in enumerate(subjects):
        out.append(_subject(r, f"subjects[{k}]", item, defaults))
    names = [s.name for s in out]
    runs: list[str] = []
    for k, s in enumerate(out):
        if s.name in names[:k]:
            r.fail(f"subjects[{k}].name", "a name no other subject has", s.name)
        for trial in s.trials:
            if s.trial_name(trial) in runs:
                r.fail(f"subjects[{k}].trials", "run names (subject-trial) no other subject's "
                                                "trial has", s.trial_name(trial))
            runs.append(s.trial_name(trial))
    return Study(r.name(doc.get("name", path.stem), "name"), path.resolve(), text, solve,
                 tuple(out))


def _subject(r: _Reader, where: str, item: Any, defaults: dict) -> SubjectSpec:
    item = r.mapping(item, where, SUBJECT_KEYS)
    for key in ("name", "static", "trials"):
        if key not in item:
            r.fail(f"{where}.{key}", "this key to be present")
    spec = defaults | item
    if "template" not in spec:
        r.fail(f"{where}.template", "a template here or at the top of the study")
    template_where = f"{where}.template" if "template" in item else "template"
    template = r.file(spec["template"], template_where, "template model file")
    try:
        method = _calibration_method(template)
    except InputError as error:
        raise InputError(f"{r.source}: {template_where}: {error}") from None
    patterns = item["trials"] if isinstance(item["trials"], list) else [item["trials"]]
    if not patterns:
        r.fail(f"{where}.trials", "a trial file or glob, or a non-empty list of them", [])
    trials: list[Path] = []
    for j, pattern in enumerate(patterns):
        if not isinstance(pattern, str) or not pattern.strip():
            r.fail(f"{where}.trials[{j}]", "a trial file or glob", pattern)
        trials += [p for p in r.matches(pattern, f"{where}.trials[{j}]", "trial files")
                   if p not in trials]
    stems = [t.stem for t in trials]
    twice = sorted({s for s in stems if stems.count(s) > 1})
    if twice:
        r.fail(f"{where}.trials", "trials with different file names (each run is named after "
                                  "its subject and trial)", twice[0])
    map_where = f"{where}.map" if "map" in item else "map"
    mapping, map_file = r.mapping_pairs(spec["map"], map_where) \
        if spec.get("map") is not None else ((), None)
    measurements_where = f"{where}.measurements" if "measurements" in item else "measurements"
    measurements = r.measurements(spec["measurements"], measurements_where) \
        if spec.get("measurements") is not None else None
    if isinstance(measurements, tuple) and method != "davis":
        r.fail(measurements_where, f"{FROM_C3D} or nothing: {template.name} maps the medial "
                                   "markers, whose midpoints are the joint centres (knee and "
                                   "ankle widths serve Helen Hayes/Davis templates)")
    return SubjectSpec(
        name=r.name(item["name"], f"{where}.name"),
        group=r.name(item.get("group", DEFAULT_GROUP), f"{where}.group"),
        template=template,
        static=r.file(item["static"], f"{where}.static", "static trial file"),
        frames=r.frames(item["frames"], f"{where}.frames") if "frames" in item else None,
        trials=tuple(trials),
        mass=r.mass(item["mass"], f"{where}.mass") if item.get("mass") is not None else None,
        measurements=measurements,
        mapping=mapping, map_file=map_file)


@lru_cache(maxsize=16)
def _calibration_method(path: Path) -> str:
    """The calibration method of a template that loads and maps a method's landmarks (a
    one-line error from the model's own reader otherwise), checked before anything runs."""
    from fccgrb_cli.anatomy.calibrate import calibration_method
    from fccgrb_cli.model import load_model

    return calibration_method(load_model(path))
