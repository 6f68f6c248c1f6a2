"""Marker trials in: C3D (ezc3d) and OpenSim TRC; out: TRC. SI (metres) inside.

Gaps are NaN: a C3D point whose residual is negative, or an empty TRC field.

A trial whose data end before the last frame its header announces (a C3D whose bytes hold fewer
frames than POINT:FRAMES, see ``c3d_header``; a TRC with fewer rows than NumFrames) is an
InputError naming the file and both counts, unless the caller accepts it: then the frames present
are read and the trial carries a warning saying so.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fccgrb_cli.core.atomic import atomic_path
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import decode, read_bytes, regular_file
from fccgrb_cli.core.stretches import window
from fccgrb_cli.trial.c3d import ARTEFACT_PARAMETER, ARTEFACT_TRC_KEY, UNIT_SCALE, write_markers
from fccgrb_cli.trial.c3d_file import ezc3d_read
from fccgrb_cli.trial.c3d_header import (
    TRUNCATED,
    WORD_LIMIT,
    C3DLayout,
    read_layout,
    read_parameters,
    read_points,
)
from fccgrb_cli.trial.rates import POINT_RATE_MAX, rate_problem

TRIAL_ENDINGS = (".c3d", ".trc")
TRC_MAX = 4 << 30  # bytes: a TRC is read whole (a 10-minute trial of 55 markers is ~0.3 GB)


@dataclass(frozen=True)
class Trial:
    """Marker positions (frames × markers × 3, metres, NaN in gaps) sampled at ``rate`` Hz;
    ``warnings`` says what the reader let through (a truncated file accepted); ``start`` the
    first frame's time on the file's clock (s: a C3D's first frame F counts from the capture's
    frame 1, so (F − 1) / rate; a TRC's first Time); ``artefact_m`` the soft-tissue-artefact
    level ``fccgrb perturb`` recorded in the file (m; 0 for a file it did not perturb)."""

    path: str
    labels: tuple[str, ...]
    markers: np.ndarray
    rate: float
    warnings: tuple[str, ...] = ()
    start: float = 0.0
    artefact_m: float = 0.0

    @property
    def n_frames(self) -> int:
        return self.markers.shape[0]

    @property
    def time(self) -> np.ndarray:
        return np.arange(self.n_frames) / self.rate

    def find(self, name: str) -> str | None:
        """The file label for a marker name: the name itself, else a label 'Subject:NAME'."""
        if name in self.labels:
            return name
        return next((label for label in self.labels if label.split(":")[-1] == name), None)

    def between(self, start: float | None, stop: float | None) -> Trial:
        """The frames whose times on the file's clock (``start`` + frame / rate) lie in
        [start, stop] (s; None: unbounded), as OpenSim's time_range selects them; an InputError
        naming the file when none does."""
        if start is None and stop is None:
            return self
        clock = self.start + self.time
        keep = window(clock, start, stop)
        if not keep.any():
            raise InputError(f"{self.path}: --from/--to: expected a time range within the "
                             f"trial's {clock[0]:.6g}–{clock[-1]:.6g} s, got "
                             f"{'…' if start is None else f'{start:g}'}–"
                             f"{'…' if stop is None else f'{stop:g}'} s")
        first = int(np.argmax(keep))
        last = first + int(keep[first:].sum())
        return replace(self, markers=self.markers[first:last],
                       start=float(clock[first]))

    def select(self, labels: list[str]) -> np.ndarray:
        """The markers with these file labels, in that order (frames × len(labels) × 3)."""
        index = {label: k for k, label in enumerate(self.labels)}
        return self.markers[:, [index[label] for label in labels]]


def _unit_scale(units: str, path: Path, key: str) -> float:
    scale = UNIT_SCALE.get(units.strip().lower())
    if scale is None:
        raise InputError(f"{path}: {key}: expected a length unit {sorted(UNIT_SCALE)}, got "
                         f"{units!r}")
    return scale


def _complete(path: Path, announced: str, held: int, accept_truncated: bool) -> tuple[str, ...]:
    """The data hold fewer frames than announced: an InputError, or (accepted, and some frames
    held) the warning the trial carries."""
    if held == 0:
        raise InputError(f"{path}: {announced}, the data hold none: {TRUNCATED}")
    if not accept_truncated:
        raise InputError(f"{path}: {announced}, the data hold {held}: {TRUNCATED}; pass "
                         f"--accept-truncated to use the {held} frames")
    return (f"{path}: {announced}, the data hold only {held}: the file is truncated; its first "
            f"{held} frames were read (--accept-truncated)",)


def read_c3d(path: Path, accept_truncated: bool = False) -> Trial:
    """A C3D trial; its layout is read first, so that a cut file is not read as a short one."""
    layout = read_layout(path)
    warnings: tuple[str, ...] = ()
    frames = layout.frames
    if layout.truncated:
        frames = layout.frames_held
        warnings = _complete(path, layout.announced(), frames, accept_truncated)
    if frames > WORD_LIMIT:  # ezc3d counts frames in a 16-bit word: read the file's bytes
        return _read_long_c3d(path, layout, frames, warnings)
    try:
        c3d = ezc3d_read(path, False)  # shared with the platforms' read: trial.c3d_file
    except Exception as exc:  # ezc3d raises bare RuntimeError/IOError on bad files
        reason = str(exc).strip() or exc.__class__.__name__
        raise InputError(f"{path}: not a readable C3D file ({reason})") from None
    point = c3d["parameters"]["POINT"]
    labels = tuple(str(label).strip() for label in point_labels(point))
    units = point.get("UNITS", {}).get("value") or ["mm"]
    scale = _unit_scale(str(units[0]), path, "POINT:UNITS")
    rate = _rate(float(point["RATE"]["value"][0]), path)
    xyz = np.transpose(c3d["data"]["points"][:3], (2, 1, 0)) * scale
    residuals = c3d["data"]["meta_points"].get("residuals")
    if residuals is not None and residuals.size:
        xyz[np.transpose(residuals[0], (1, 0)) < 0] = np.nan
    if xyz.shape[0] != frames:
        raise InputError(f"{path}: ezc3d read {xyz.shape[0]} frames where the file holds "
                         f"{frames} ({layout.announced()})")
    labels = labels[: xyz.shape[1]]
    _finite(xyz, labels, path)
    group, name = ARTEFACT_PARAMETER.split(":")
    recorded = c3d["parameters"].get(group, {}).get(name, {}).get("value")
    artefact = _artefact(None if recorded is None or not len(recorded) else recorded[0], path,
                         ARTEFACT_PARAMETER)
    return Trial(str(path), labels, xyz, rate, warnings, (layout.first_frame - 1) / rate,
                 artefact)


def _artefact(value: object, path: Path, where: str) -> float:
    """The artefact level a file records (mm in the file, m returned; 0 when not recorded);
    anything but a number in [0, 1000] mm is an InputError naming the file and ``where``."""
    if value is None:
        return 0.0
    try:
        level = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        raise InputError(f"{path}: {where}: expected the artefact level in mm, got "
                         f"{value!r}") from None
    if not (np.isfinite(level) and 0.0 <= level <= 1000.0):
        raise InputError(f"{path}: {where}: expected an artefact level of 0–1000 mm, got "
                         f"{level:g}")
    return 1e-3 * level


def point_labels(point: dict) -> list[str]:
    """Every point label of an ezc3d POINT group: LABELS, then LABELS2, LABELS3, … (a file
    with more than 255 points continues its labels there)."""
    labels = list(point["LABELS"]["value"])
    k = 2
    while f"LABELS{k}" in point:
        labels += list(point[f"LABELS{k}"]["value"])
        k += 1
    return labels


def _finite(xyz: np.ndarray, labels: tuple[str, ...], path: Path) -> None:
    """Coordinates are numbers or gaps (NaN): an infinite one (a float32 overflow, a damaged
    file) is an InputError naming the first frame and label."""
    bad = np.isinf(xyz)
    if bad.any():
        frame, marker, _ = np.argwhere(bad)[0]
        label = labels[marker] if marker < len(labels) else f"point {marker + 1}"
        raise InputError(f"{path}: frame index {frame}, {label}: expected finite coordinates "
                         "or a gap, got an infinite one")


def _rate(rate: float, path: Path, key: str = "POINT:RATE") -> float:
    problem = rate_problem(rate, POINT_RATE_MAX)
    if problem is not None:
        raise InputError(f"{path}: {key}: expected {problem}, got {rate:g}")
    return rate


def _read_long_c3d(path: Path, layout: C3DLayout, frames: int,
                   warnings: tuple[str, ...]) -> Trial:
    """A C3D past 65,535 frames, whose points ezc3d stops short of: labels, units and rate from
    its parameter section, the points from its data section in chunks (``c3d_header``), with
    nothing else of the file in memory (ezc3d's objects would take ~10 kB a frame)."""
    params = read_parameters(path)
    if "POINT:LABELS" not in params or "POINT:RATE" not in params:
        raise InputError(f"{path}: expected the parameters POINT:LABELS and POINT:RATE")
    units = params.get("POINT:UNITS")
    unit = str(units.values[0]) if units is not None and units.values.size else "mm"
    scale = _unit_scale(unit, path, "POINT:UNITS")
    rate = _rate(float(params["POINT:RATE"].values[0]), path)
    xyz = read_points(path, layout, frames)
    xyz *= scale
    labels = tuple(str(label).strip() for key in sorted(
        (k for k in params if k.startswith("POINT:LABELS")), key=lambda k: (len(k), k))
        for label in params[key].values)
    labels = labels[: xyz.shape[1]]
    _finite(xyz, labels, path)
    recorded = params.get(ARTEFACT_PARAMETER)
    artefact = _artefact(None if recorded is None or not recorded.values.size
                         else recorded.values.ravel()[0], path, ARTEFACT_PARAMETER)
    return Trial(str(path), labels, xyz, rate, warnings, (layout.first_frame - 1) / rate,
                 artefact)


def read_trc(path: Path, accept_truncated: bool = False) -> Trial:
    """OpenSim TRC: header line 3 holds DataRate … NumFrames … Units; line 4 the labels; data
    from line 6. A last line without its newline is a cut row when rows are missing."""
    text = decode(read_bytes(path, "TRC file", limit=TRC_MAX), path, "TRC file")
    lines = text.splitlines()
    if len(lines) < 5 or not lines[0].startswith("PathFileType"):
        raise InputError(f"{path}: line 1: expected a TRC header starting with 'PathFileType'")
    # OpenSim's TRC reader skips empty fields in the header's two lines (several tabs between
    # values, as in opensim-models' Rajagopal walk); its data rows keep them (a missing marker)
    keys, values = ([f.strip() for f in line.split("\t") if f.strip()] for line in lines[1:3])
    header = dict(zip(keys, values, strict=False))
    rate = _rate(_header_number(header, "DataRate", float, path), path, "line 3: DataRate")
    n_markers = _header_number(header, "NumMarkers", int, path)
    if n_markers < 1:
        raise InputError(f"{path}: line 3: NumMarkers: expected at least 1, got {n_markers}")
    announced = _header_number(header, "NumFrames", int, path) if header.get("NumFrames") \
        else None
    if announced is not None and announced < 0:
        raise InputError(f"{path}: line 3: NumFrames: expected a count ≥ 0, got {announced}")
    scale = _unit_scale(header.get("Units", "mm"), path, "line 3: Units")
    names = [n.strip() for n in lines[3].split("\t")[2:]]
    labels = tuple(n for n in names if n)
    if len(labels) != n_markers:
        raise InputError(f"{path}: line 4: expected {n_markers} marker labels (NumMarkers), "
                         f"got {len(labels)}")
    data = lines[5:]
    complete = [line for line in data if line.strip()]
    if announced is not None and len(complete) < announced and not text.endswith("\n") \
            and complete:
        data = data[:-1]  # the cut last row: its values may be cut too
    rows = []
    start = None
    clock: list[tuple[int, float, float]] = []  # (line, Time, its rounding) per row
    for number, line in enumerate(data, start=6):
        if not line.strip():
            continue
        fields = line.rstrip("\r\n").split("\t")
        if start is None and len(fields) > 1:
            try:
                start = float(fields[1])
            except ValueError:
                start = 0.0  # no time column: the trial's clock starts at 0
        if len(fields) > 1:
            with contextlib.suppress(ValueError):  # a row without its Time: no clock check
                clock.append((number, float(fields[1]), _rounding(fields[1])))
        coords = fields[2:]
        while len(coords) > 3 * n_markers and not coords[-1].strip():
            coords.pop()
        if len(coords) != 3 * n_markers:
            raise InputError(f"{path}: line {number}: expected {3 * n_markers} marker columns "
                             f"(x y z for {n_markers} markers) after frame and time, "
                             f"got {len(coords)}")
        try:
            row = [float(c) if c.strip() else np.nan for c in coords]
        except ValueError:
            raise InputError(f"{path}: line {number}: expected numbers in every marker column") \
                from None
        if any(np.isinf(row)):
            raise InputError(f"{path}: line {number}: expected finite coordinates or a blank "
                             "(a gap), got an infinite one")
        rows.append(row)
    warnings: tuple[str, ...] = ()
    if announced is not None and len(rows) < announced:
        warnings = _complete(path, f"the header announces {announced} frames (NumFrames, line 3)",
                             len(rows), accept_truncated)
    if announced is not None and len(rows) > announced:
        raise InputError(f"{path}: line 3: NumFrames: the header announces {announced} frames, "
                         f"the file holds {len(rows)} rows of data")
    if not rows:
        raise InputError(f"{path}: expected at least one frame of data after the header")
    if len(clock) == len(rows):
        _uniform_clock(clock, rate, path)
    xyz = np.array(rows).reshape(len(rows), n_markers, 3) * scale
    artefact = _artefact(header.get(ARTEFACT_TRC_KEY), path, f"line 3: {ARTEFACT_TRC_KEY}")
    return Trial(str(path), labels, xyz, rate, warnings, start or 0.0, artefact)


def _rounding(text: str) -> float:
    """Half a unit of the last decimal a number is written with (0.0005 for '0.417')."""
    mantissa = text.strip().lower().split("e")[0]
    decimals = len(mantissa.split(".")[1]) if "." in mantissa else 0
    return 0.5 * 10.0 ** -decimals if "e" not in text.lower() else 0.0


def _uniform_clock(clock: list[tuple[int, float, float]], rate: float, path: Path) -> None:
    """Each row's Time on the first one's clock at DataRate, to a quarter frame beside the
    rounding of the Times as written: a file with rows removed (and NumFrames made to agree)
    is refused, naming the first line off it, rather than read as frames 1/rate apart."""
    first, first_rounding = clock[0][1], clock[0][2]
    for k, (number, time, rounding) in enumerate(clock):
        expected = first + k / rate
        if not abs(time - expected) <= 0.25 / rate + rounding + first_rounding:  # NaN fails
            raise InputError(f"{path}: line {number}: Time: expected {expected:.6g} s (row "
                             f"{k + 1} at DataRate {rate:g} Hz from {first:.6g} s: a uniform "
                             f"clock), got {time:.6g} s: rows missing, times edited, or a "
                             "DataRate other than the rows' rate")


def _header_number(header: dict[str, str], key: str, kind: type, path: Path):
    """A number of the TRC header's line 3 (an int: written as a whole number)."""
    if key not in header:
        raise InputError(f"{path}: lines 2-3: expected a {key} value")
    text = header[key]
    try:
        value = kind(text)
    except ValueError:
        what = "a whole number" if kind is int else "a number"
        raise InputError(f"{path}: line 3: {key}: expected {what}, got {text!r}") from None
    return value


def read_trial(path: str | Path, accept_truncated: bool = False) -> Trial:
    """Read a C3D or TRC marker file (by its ending). A file whose data end before the last
    frame its header announces is an InputError, or with ``accept_truncated`` is read with the
    frames it holds, the trial's ``warnings`` saying so."""
    path = regular_file(path, "trial file")
    suffix = path.suffix.lower()
    if suffix == ".trc":
        return read_trc(path, accept_truncated)
    if suffix == ".c3d":
        return read_c3d(path, accept_truncated)
    raise InputError(f"{path}: expected a .c3d or .trc trial file")


def write_trc(path: str | Path, trial_labels: list[str], markers_m: np.ndarray, rate: float,
              units: str = "mm", artefact_mm: float = 0.0) -> None:
    """Write markers (frames × markers × 3, metres) as an OpenSim TRC file in ``units``; an
    ``artefact_mm`` other than 0 (the level ``fccgrb perturb`` added) is one more header key,
    ``ARTEFACT_TRC_KEY``."""
    n_frames, n_markers, _ = markers_m.shape
    data = markers_m / UNIT_SCALE[units]
    name = Path(path).name
    extra_key, extra_value = (f"\t{ARTEFACT_TRC_KEY}", f"\t{artefact_mm:.12g}") if artefact_mm \
        else ("", "")
    out = [
        f"PathFileType\t4\t(X/Y/Z)\t{name}",
        "DataRate\tCameraRate\tNumFrames\tNumMarkers\tUnits\tOrigDataRate\tOrigDataStartFrame"
        f"\tOrigNumFrames{extra_key}",
        f"{rate:.12g}\t{rate:.12g}\t{n_frames}\t{n_markers}\t{units}\t{rate:.12g}\t1"
        f"\t{n_frames}{extra_value}",
        "Frame#\tTime\t" + "\t".join(f"{label}\t\t" for label in trial_labels).rstrip("\t"),
        "\t\t" + "\t".join(f"X{k}\tY{k}\tZ{k}" for k in range(1, n_markers + 1)),
        "",
    ]
    for f in range(n_frames):
        values = "\t".join("" if np.isnan(x) else f"{x:.9g}" for x in data[f].ravel())
        out.append(f"{f + 1}\t{f / rate:.6f}\t{values}")
    with atomic_path(path) as tmp:
        tmp.write_text("\n".join(out) + "\n", encoding="utf-8")


def write_trial(path: str | Path, labels: list[str], markers_m: np.ndarray, rate: float,
                units: str = "mm", description: str = "", artefact_mm: float = 0.0) -> None:
    """Write a C3D or TRC file, chosen by the ending of ``path`` (``description``: C3D's
    FCCGRB:SOURCE; ``artefact_mm``: the artefact level added to the markers, recorded in the
    file when not 0)."""
    suffix = Path(path).suffix.lower()
    if suffix == ".trc":
        write_trc(path, labels, markers_m, rate, units, artefact_mm)
    elif suffix == ".c3d":
        write_markers(path, labels, markers_m, rate, units, description, artefact_mm)
    else:
        raise InputError(f"{path}: expected an output ending in .c3d or .trc")
