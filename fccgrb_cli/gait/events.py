"""Gait events — foot strike and foot off of each side — from three sources:

* ``c3d``: the trial's ``EVENT`` section, in both conventions in use: labels such as ``LHS``,
  ``RTO`` (Qualisys, older Vicon), or ``Foot Strike`` / ``Foot Off`` with ``Left`` / ``Right``
  in ``EVENT:CONTEXTS`` (Vicon Nexus). Event times count from the capture's start, frame 1 at
  t = 0, so a trial whose first frame is F starts at (F − 1)/rate.
* ``plates``: each force plate's force normal to it, where the inverse dynamics assigned a foot
  to it. A contact is detected where the force averaged over a frame exceeds the threshold
  (default 20 N, robust to the plate's noise), then its start and end are moved outwards, on
  the plate's analog samples, to where the force leaves the plate's own noise band (its
  unloaded level plus five standard deviations, at least 2 N), the crossing interpolated
  between samples, so that the event marks the first and last contact rather than the
  threshold's crossing, to a fraction of a sample rather than of a frame.
* ``kinematic``: Zeni, Richards and Higginson (2008), Gait & Posture 27:710–714: foot strike at
  each maximum of the heel's position relative to the pelvis along the direction of walking,
  foot off at each minimum of the toe's (markers low-passed at 6 Hz first).

``auto`` takes the file's events when it has some, else the plates' when they give both feet a
stride, else the markers'.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.trial.c3d_header import read_layout, read_parameters

SOURCES = ("c3d", "plates", "kinematic")
KINDS = ("strike", "off")
SIDES = ("left", "right")
_ABBREVIATIONS = {"HS": "strike", "FS": "strike", "IC": "strike", "TO": "off", "FO": "off"}


@dataclass(frozen=True)
class Events:
    """Events of one source, sorted by time: times (s from the trial's first frame), sides
    ('left'/'right') and kinds ('strike'/'off')."""

    source: str
    time: np.ndarray
    side: tuple[str, ...]
    kind: tuple[str, ...]

    def __len__(self) -> int:
        return len(self.time)

    def of(self, side: str, kind: str) -> np.ndarray:
        """The times of one side's events of one kind."""
        mask = np.array([s == side and k == kind for s, k in zip(self.side, self.kind,
                                                                  strict=True)], dtype=bool)
        return self.time[mask] if len(mask) else np.zeros(0)

    def has_strides(self) -> bool:
        """Two strikes of each foot: a stride per side."""
        return all(len(self.of(side, "strike")) >= 2 for side in SIDES)


def _sorted(source: str, items: list[tuple[float, str, str]]) -> Events:
    items.sort()
    return Events(source, np.array([t for t, _, _ in items], dtype=float),
                  tuple(s for _, s, _ in items), tuple(k for _, _, k in items))


def _parse(label: str, context: str) -> tuple[str, str] | None:
    """(side, kind) of one EVENT entry, or None for events that are not foot contacts."""
    text = label.strip().lower().replace("_", " ")
    words = context.strip().lower()
    kind = "strike" if ("strike" in text or "contact" in text) else \
        "off" if ("off" in text and "foot" in text) or text in ("toe off", "toeoff") else None
    if kind is not None:
        side = "left" if words.startswith("l") else "right" if words.startswith("r") else None
        if side is None:  # 'Left Foot Strike' with no context
            side = "left" if text.startswith("l") else "right" if text.startswith("r") else None
        return (side, kind) if side is not None else None
    compact = label.strip().upper().replace(" ", "").replace("_", "")
    if len(compact) == 3 and compact[0] in "LR" and compact[1:] in _ABBREVIATIONS:
        return ("left" if compact[0] == "L" else "right"), _ABBREVIATIONS[compact[1:]]
    return None


def _minutes_seconds(path: str | Path, values: np.ndarray, n: int) -> np.ndarray:
    """EVENT:TIMES as 2 × n (minutes; seconds), from either layout Vicon writes: a 2 × n array
    (Nexus 2) or 2n values in one dimension (Nexus 1.4), both stored as (minutes, seconds)
    pairs one after the other, the first dimension varying fastest."""
    if values.size != 2 * n:
        raise InputError(f"{path}: EVENT:TIMES: expected 2 × {n} values ((minutes, seconds) "
                         f"for each of EVENT:LABELS's {n}), got {values.size}")
    return np.asarray(values, dtype=float).reshape(n, 2).T


def c3d_events(path: str | Path, n_frames: int, rate: float) -> Events | None:
    """The foot events of a C3D's EVENT section within the trial (None when it has none), read
    from its parameter section alone (``c3d_header.read_parameters``: ezc3d would load every
    frame's points again, ~10 kB a frame)."""
    params = read_parameters(path)
    if "EVENT:LABELS" not in params or "EVENT:TIMES" not in params:
        return None
    labels = [str(v) for v in params["EVENT:LABELS"].values]
    times = _minutes_seconds(path, params["EVENT:TIMES"].values, len(labels))
    contexts = [str(v) for v in params["EVENT:CONTEXTS"].values] \
        if "EVENT:CONTEXTS" in params else []
    contexts += [""] * (len(labels) - len(contexts))
    start = (read_layout(path).first_frame - 1) / rate  # numbered from 1
    items = []
    for label, context, (minutes, seconds) in zip(labels, contexts, times.T, strict=True):
        parsed = _parse(label, context)
        t = 60.0 * minutes + seconds - start
        if parsed is not None and -0.5 / rate <= t <= (n_frames - 0.5) / rate:
            items.append((t, *parsed))
    return _sorted("c3d", items) if items else None


@dataclass(frozen=True)
class NormalForce:
    """One plate's force normal to it (N): per frame (the frame's analog samples averaged) and
    per analog sample (``per`` to a frame, the first at the frame's own instant)."""

    framed: np.ndarray
    samples: np.ndarray
    per: int


def _plate_normal_forces(path: str | Path, n_frames: int) -> list[NormalForce | None]:
    """Each plate's force normal to it (None for a plate whose corners do not give a normal,
    or with fewer samples than frames)."""
    from fccgrb_cli.trial.forceplates import plate_file

    out: list[NormalForce | None] = []
    for raw in plate_file(path).plates:
        corners = raw.corners.T
        normal = np.cross(corners[2] - corners[0], corners[3] - corners[1])
        force = raw.force
        per = force.shape[1] // n_frames if n_frames else 0
        if per < 1 or not np.isfinite(normal).all() or not np.linalg.norm(normal):
            out.append(None)
            continue
        samples = np.abs(normal @ force[:, : per * n_frames]) / np.linalg.norm(normal)
        out.append(NormalForce(samples.reshape(n_frames, per).mean(axis=1), samples, per))
    return out


def _widen(force: np.ndarray, start: int, stop: int, floor: float) -> tuple[float, float]:
    """A contact [start, stop) (sample indices) found at the threshold, its edges moved to the
    outermost samples above ``floor`` of the run of such samples they lie in (inwards first,
    where the frame that reached the threshold began or ended below the floor), with the
    crossing of ``floor`` interpolated linearly between samples."""
    a, b = start, stop - 1
    while a < b and force[a] <= floor:
        a += 1
    while b > a and force[b] <= floor:
        b -= 1
    while a > 0 and force[a - 1] > floor:
        a -= 1
    while b + 1 < len(force) and force[b + 1] > floor:
        b += 1
    t0 = a - (force[a] - floor) / (force[a] - force[a - 1]) if a > 0 else float(a)
    t1 = b + (force[b] - floor) / (force[b] - force[b + 1]) if b + 1 < len(force) else float(b)
    return float(np.clip(t0, a - 1, a)), float(np.clip(t1, b, b + 1))


def plate_events(path: str | Path, rate: float, stance: dict[str, np.ndarray],
                 threshold: float = 20.0) -> Events | None:
    """Foot strikes and offs from the plates, for the feet the dynamics put on them (``stance``:
    body name → loaded frames; a body's side from its name, e.g. foot_l). A contact is a run of
    frames whose mean force reaches ``threshold``; its edges are found on the analog samples
    (the first and last above the noise floor, the crossing interpolated between samples: a
    frame's mean would put an onset inside the frame up to a frame early). A contact already
    under way at the first frame, or not ended at the last, gives no event there."""
    sides = {body: side for body in stance if (side := side_of(body)) is not None}
    if not stance or len(sides) < len(stance):  # a body on no side
        return None
    n_frames = len(next(iter(stance.values())))
    items: list[tuple[float, str, str]] = []
    for plate in _plate_normal_forces(path, n_frames):
        if plate is None:
            continue
        loaded = plate.framed >= threshold
        quiet = ~_near(loaded, int(0.05 * rate))
        rest = plate.samples.reshape(n_frames, plate.per)[quiet].ravel() \
            if quiet.sum() >= 10 else np.zeros(10)
        floor = float(np.median(rest) + max(5.0 * 1.4826 * np.median(np.abs(rest -
                                                                            np.median(rest))),
                                            2.0))
        edges = np.flatnonzero(np.diff(np.concatenate([[0], loaded.astype(int), [0]])))
        sample_rate = rate * plate.per
        for start, stop in zip(edges[::2], edges[1::2], strict=True):
            body = max(stance, key=lambda b: int(stance[b][start:stop].sum()))
            if not stance[body][start:stop].any():
                continue
            first, last = _widen(plate.samples, start * plate.per, stop * plate.per, floor)
            if start > 0:
                items.append((first / sample_rate, sides[body], "strike"))
            if stop < n_frames:
                items.append((last / sample_rate, sides[body], "off"))
    return _sorted("plates", items) if items else None


def _near(mask: np.ndarray, half: int) -> np.ndarray:
    """Frames within ``half`` frames of a True frame of ``mask`` (any length, even shorter than
    the window)."""
    counts = np.concatenate([[0], np.cumsum(mask)])
    frames = np.arange(len(mask))
    return counts[np.minimum(frames + half + 1, len(mask))] - counts[np.maximum(frames - half,
                                                                                 0)] > 0


def side_of(name: str) -> str | None:
    """'left' or 'right' from a body's name (foot_l, left_foot, …), else None."""
    lower = name.lower()
    if lower.endswith(("_l", "_left")) or lower.startswith(("l_", "left_")):
        return "left"
    if lower.endswith(("_r", "_right")) or lower.startswith(("r_", "right_")):
        return "right"
    return None


def _extrema(signal: np.ndarray, rate: float, maxima: bool, spacing_s: float = 0.4
             ) -> np.ndarray:
    """Frames of the local maxima (or minima) of a smooth signal at least ``spacing_s`` apart
    (the larger one kept), excluding the first and last frames."""
    x = signal if maxima else -signal
    inner = np.flatnonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:])) + 1
    inner = inner[np.isfinite(x[inner])]
    kept: list[int] = []
    for f in inner[np.argsort(-x[inner])]:
        if all(abs(int(f) - k) >= spacing_s * rate for k in kept):
            kept.append(int(f))
    return np.array(sorted(kept), dtype=int)


def _vertex(signal: np.ndarray, f: int) -> float:
    """The extremum's sub-frame position (parabola through frames f−1, f, f+1)."""
    a, b, c = signal[f - 1], signal[f], signal[f + 1]
    denominator = a - 2 * b + c
    return float(f + (0.5 * (a - c) / denominator if denominator else 0.0))


def smoothed_markers(markers: dict[str, np.ndarray], rate: float,
                     where: str) -> dict[str, np.ndarray]:
    """Each marker (frames × 3) with its gaps bridged (:func:`bridged`), then, in a trial of
    more than 12 frames, low-passed forward and backward (2nd order, min(6 Hz, 0.4 × rate)):
    every marker in one pass of the filter, each column alone, so each marker is what a call
    of its own gives, to the bit, in C order. InputError for a marker never seen."""
    from fccgrb_cli.signals.butterworth import lowpass

    filled = {}
    for name, xyz in markers.items():
        bridge = bridged(xyz)
        if bridge is None:
            raise InputError(f"{where}: kinematic gait events: the {name} marker is never "
                             "seen")
        filled[name] = bridge
    if len(next(iter(filled.values()), ())) <= 12:
        return filled
    together = lowpass(np.concatenate(list(filled.values()), axis=1), rate,
                       min(6.0, 0.4 * rate), 2)
    return {name: np.ascontiguousarray(together[:, 3 * k:3 * k + 3])
            for k, name in enumerate(filled)}


def kinematic_events(markers: dict[str, np.ndarray], rate: float, vertical: np.ndarray,
                     where: str) -> Events:
    """Zeni et al. (2008) from marker trajectories (frames × 3, m): ``markers`` holds
    ``pelvis`` (e.g. the mean of the ASIS and PSIS or sacrum markers), ``left_heel``,
    ``right_heel``, ``left_toe`` and ``right_toe``; ``vertical`` is the unit vector up."""
    absent = [k for k in ("pelvis", "left_heel", "right_heel", "left_toe", "right_toe")
              if k not in markers]
    if absent:
        raise InputError(f"{where}: kinematic gait events need heel, toe and pelvis markers; "
                         f"expected the landmarks {', '.join(absent)}")
    smooth = smoothed_markers(markers, rate, where)
    travel = smooth["pelvis"][-1] - smooth["pelvis"][0]
    travel -= (travel @ vertical) * vertical
    if np.linalg.norm(travel) < 0.1:
        raise InputError(f"{where}: kinematic gait events need a walking trial; the pelvis "
                         f"moves {1e3 * np.linalg.norm(travel):.0f} mm horizontally")
    forward = travel / np.linalg.norm(travel)
    items: list[tuple[float, str, str]] = []
    for side in SIDES:
        heel = (smooth[f"{side}_heel"] - smooth["pelvis"]) @ forward
        toe = (smooth[f"{side}_toe"] - smooth["pelvis"]) @ forward
        items += [(_vertex(heel, f) / rate, side, "strike") for f in _extrema(heel, rate, True)]
        items += [(_vertex(toe, f) / rate, side, "off") for f in _extrema(toe, rate, False)]
    return _sorted("kinematic", items)


def bridged(xyz: np.ndarray) -> np.ndarray | None:
    """Gaps (NaN) bridged linearly; None when the marker is never seen."""
    seen = np.isfinite(xyz).all(axis=1)
    if not seen.any():
        return None
    frames = np.arange(len(xyz))
    return np.column_stack([np.interp(frames, frames[seen], xyz[seen, k]) for k in range(3)])


def agreement(a: Events, b: Events, window_s: float = 0.15) -> list[tuple[str, str, float,
                                                                          float | None]]:
    """Each event of ``a`` with the nearest of ``b`` of the same side and kind within
    ``window_s``: (side, kind, time in a, time in b − time in a in s or None)."""
    out = []
    for t, side, kind in zip(a.time, a.side, a.kind, strict=True):
        other = b.of(side, kind)
        near = other[np.abs(other - t) <= window_s] if len(other) else other
        delta = float(near[np.argmin(np.abs(near - t))] - t) if len(near) else None
        out.append((side, kind, float(t), delta))
    return out
