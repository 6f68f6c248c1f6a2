"""The lab's axes: which way is up, and which way the subject walks, read from the trial.

A model whose ground takes part in it (a joint, an angle or a distance on the ground: a
mechanism) defines the lab frame itself: its gravity is the model file's, and a ``--vertical``
that says otherwise is an error. A model of floating bodies only (a subject: the lower-limb
templates and the models ``calibrate`` writes) is placed in the lab by its markers, so nothing in
the model says which of the lab's axes is up; the trial does. Its cues:

* **force plates**: each plate's normal (from its corners), signed by the force it measures on
  the subject over its loaded frames: the ground pushes a standing or walking subject up
  (ezc3d's platform force is that reaction, the load the inverse dynamics applies);
* **markers**: the model's pose (the template's upright subject, a calibrated model's calibration
  frame, both with gravity along the model's own vertical) fitted rigidly to the tracked markers
  (Söderkvist & Wedin 1993) on up to ``FIT_FRAMES`` frames carries the model's up, −gravity,
  into the lab; the cue is their mean when the frames agree (the mean of the unit vectors at
  least ``AGREEMENT`` long);
* **POINT:Y_SCREEN**, the axis the capture software draws upwards: reported beside the data,
  never used alone (Qualisys writes −Z into files whose +z is up).

A cue counts when its direction lies within ``SNAP_DEG`` of a lab axis, and the plates and the
markers must agree (an error otherwise, asking for ``--vertical``). The model's gravity is kept
exactly as written when it already points down that axis (the axis nearest to it), and turned
onto it, with the file's magnitude, when it does not. With no cue, the model's gravity stays
and a warning says so. ``--vertical`` (``SolveOptions.vertical``) overrides the cues, which are
still reported where they disagree with it.

The direction of walking is the tracked markers' mean velocity, its horizontal part, when faster
than ``WALKING`` m/s (the gait analysis measures strides along the pelvis's own travel).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import GROUND, Model
from fccgrb_cli.model.spatial import JointCoordinate
from fccgrb_cli.trial.record import Trial

AXES = ("+x", "-x", "+y", "-y", "+z", "-z")
VERTICALS = ("auto", *AXES)
SNAP_DEG = 25.0      # a cue within this angle of a lab axis names that axis
LEANING_DEG = 45.0   # a weaker one, confirmed by POINT:Y_SCREEN naming the same axis
AGREEMENT = 0.9      # least length of the mean of the frames' unit up vectors (markers)
FIT_FRAMES = 200     # frames the model's pose is fitted to, evenly spread over the trial
WALKING = 0.15       # m/s: the least mean marker speed that gives a direction of walking
MIN_SPREAD = 0.02    # m: the fitted markers' second principal spread (not on one line)


def axis_vector(label: str) -> np.ndarray:
    """'+y' → (0, 1, 0)."""
    out = np.zeros(3)
    out["xyz".index(label[1])] = 1.0 if label[0] == "+" else -1.0
    return out


def nearest_axis(direction: np.ndarray) -> tuple[str, float]:
    """The lab axis nearest to a non-zero ``direction`` and the angle between them (deg)."""
    unit = direction / np.linalg.norm(direction)
    k = int(np.argmax(np.abs(unit)))
    label = ("+" if unit[k] > 0 else "-") + "xyz"[k]
    return label, float(np.degrees(np.arccos(np.clip(abs(unit[k]), -1.0, 1.0))))


def _vector_text(v: np.ndarray | tuple[float, ...]) -> str:
    return "(" + ", ".join(f"{x:.3g}" for x in np.asarray(v, dtype=float) + 0.0) + ")"


def _direction_text(v: np.ndarray) -> str:
    label, off = nearest_axis(v)
    return label if off < 0.5 else f"{_vector_text(v)} ({off:.0f}° from {label})"


@dataclass(frozen=True)
class Cue:
    """What one source says: ``axis`` up (None when it cannot tell) and why; ``leaning``: the
    axis a cue too weak to tell on its own is nearest to (within ``LEANING_DEG``), which
    POINT:Y_SCREEN naming the same axis confirms."""

    source: str
    axis: str | None
    detail: str
    leaning: str | None = None


@dataclass(frozen=True)
class LabAxes:
    """The run's lab axes: ``up`` (unit; zeros when gravity is zero and nothing tells), its
    ``vertical`` label ('+z'), the ``gravity`` the dynamics uses (m/s²), who chose it
    (``chosen_by``: 'ground' for a model tied to its ground, 'model' when nothing in the file
    tells, 'option' or 'file'), ``why`` (the cues, for the summary and the
    results file), the direction of walking (unit, or None) and ``warnings``."""

    vertical: str
    up: np.ndarray
    gravity: tuple[float, float, float]
    chosen_by: str
    why: str
    forward: np.ndarray | None = None
    warnings: tuple[str, ...] = ()

    def note(self) -> str:
        """One line for the summary: the vertical, why, gravity, the direction of walking."""
        walking = "not walking" if self.forward is None else \
            f"walking along {_direction_text(self.forward)}"
        return (f"lab axes: vertical {self.vertical} ({self.why}); gravity "
                f"{_vector_text(self.gravity)} m/s²; {walking}")


def model_defines_lab(model: Model) -> str | None:
    """What ties the model to its ground (a joint, angle or distance naming it), or None for a
    model of floating bodies only."""
    for joint in model.joints:
        if GROUND in joint.bodies:
            return f"joint {joint.name}"
    for moving in model.moving_joints:
        if moving.parent == GROUND:
            return f"joint {moving.name}"
    for coordinate in model.angles:
        if isinstance(coordinate, JointCoordinate):  # held by a moving joint, named above
            continue
        ends = (coordinate.body1, coordinate.body2)
        axis = getattr(coordinate, "axis", None)
        if GROUND in ends or (isinstance(axis, tuple) and axis[0] == GROUND):
            return f"{coordinate.kind} {coordinate.name}"
    return None


def _up_of(gravity: tuple[float, float, float]) -> np.ndarray | None:
    g = np.asarray(gravity, dtype=float)
    norm = np.linalg.norm(g)
    return -g / norm if norm > 0 else None


def screen_cue(path: str) -> Cue | None:
    """POINT:Y_SCREEN of a C3D, the axis its software draws upwards (None without one)."""
    if not path.lower().endswith(".c3d") or not Path(path).is_file():
        return None
    from fccgrb_cli.trial.c3d_header import read_parameters

    value = read_parameters(path).get("POINT:Y_SCREEN")
    text = str(value.values[0]).strip().lower() if value is not None and value.values.size \
        else ""
    if len(text) != 2 or text[0] not in "+-" or text[1] not in "xyz":
        return None
    return Cue("POINT:Y_SCREEN", text, f"POINT:Y_SCREEN {text.upper()}")


def plate_cue(model: Model, trial: Trial) -> Cue | None:
    """The plates' normals signed by the force on the subject over their loaded frames."""
    if not trial.path.lower().endswith(".c3d") or not Path(trial.path).is_file():
        return None  # a trial made in memory has no plates
    from fccgrb_cli.trial.c3d_header import WORD_LIMIT, read_layout, read_parameters
    from fccgrb_cli.trial.forceplates import plate_normal, read_force_plates

    used = read_parameters(trial.path).get("FORCE_PLATFORM:USED")
    if used is None or not used.values.size or not used.values[0] or \
            read_layout(trial.path).frames > WORD_LIMIT:
        return None
    try:
        plates = read_force_plates(trial.path, trial.n_frames, model.plate_threshold)
    except InputError:
        return None  # the dynamics stage says why, when it needs them
    found: dict[int, np.ndarray] = {}
    refused = [str(plate.number) for plate in plates if plate.problem is not None]
    for plate in plates:
        loaded = np.abs(plate.force).any(axis=1)
        if plate.problem is not None or not loaded.any():
            continue
        normal = plate_normal(plate.corners)
        push = float(np.sum(plate.force[loaded] @ normal))
        found[plate.number] = np.sign(push) * normal * loaded.sum()
    if not found:
        why = f" ({', '.join(refused)} implausible)" if refused else ""
        return Cue("force plates", None, f"force plates: none loaded{why}")
    axes = {number: nearest_axis(v) for number, v in found.items()}
    labels = {label for label, _ in axes.values()}
    names = ", ".join(str(n) for n in found)
    if len(labels) > 1:
        each = ", ".join(f"{n} {label}" for n, (label, _) in axes.items())
        return Cue("force plates", None, f"force plates disagree ({each})")
    label, off = nearest_axis(sum(found.values(), np.zeros(3)))
    if off > SNAP_DEG:
        return Cue("force plates", None, f"force plates {names}: normal {off:.0f}° from "
                                         f"the nearest axis {label}")
    return Cue("force plates", label,
               f"force plate{'s' if len(found) > 1 else ''} {names}: the normal force on the "
               f"subject along {label}")


def _pose_points(model: Model) -> np.ndarray:
    """Each tracked point where the model's pose puts it (markers × 3, model frame)."""
    out = []
    for tp in model.tracked_points:
        pose = model.body(tp.body).pose
        local = model.body(tp.body).points[tp.point].local
        out.append(np.asarray(pose.r) + local[0] * np.asarray(pose.u)
                   + local[1] * np.asarray(pose.v) + local[2] * np.asarray(pose.w))
    return np.array(out).reshape(-1, 3)


def marker_cue(model: Model, markers: np.ndarray, model_up: np.ndarray | None) -> Cue | None:
    """The model's up carried into the lab by its pose fitted to the tracked markers (frames ×
    tracked points × 3, NaN where unseen)."""
    from fccgrb_cli.solvers.initial import rigid_fits

    if model_up is None or not model.tracked_points:
        return None
    local = _pose_points(model)
    seen = np.isfinite(markers).all(axis=2)
    usable = np.flatnonzero(seen.sum(axis=1) >= 3)
    if not len(usable):
        return Cue("markers", None, "markers: no frame with three tracked markers")
    frames = usable[np.unique(np.linspace(0, len(usable) - 1, FIT_FRAMES).astype(int))]
    fitted = np.full((len(frames), 3), np.nan)
    # the frames that see the same markers are fitted together (rigid_fits)
    masks, group = np.unique(seen[frames], axis=0, return_inverse=True)
    for g, mask in enumerate(masks):
        centred = local[mask] - local[mask].mean(axis=0)
        if np.linalg.svd(centred, compute_uv=False)[1] < MIN_SPREAD:
            continue
        members = np.flatnonzero(group.ravel() == g)
        rotations = rigid_fits(local[mask], markers[frames[members]][:, mask])
        fitted[members] = rotations @ model_up
    ups = fitted[np.isfinite(fitted).all(axis=1)]
    if not len(ups):
        return Cue("markers", None, "markers: the tracked markers seen lie on a line")
    mean = np.mean(ups, axis=0)
    agreement = float(np.linalg.norm(mean))
    label, off = nearest_axis(mean) if agreement > 0 else ("", 180.0)
    leaning = label if off <= LEANING_DEG else None
    if agreement < AGREEMENT:
        return Cue("markers", None, f"markers: the model's pose fitted to them turns its up "
                                    f"from frame to frame (agreement {agreement:.2f})", leaning)
    if off > SNAP_DEG:
        return Cue("markers", None, f"markers: the model's pose fitted to them puts its up "
                                    f"{off:.0f}° from the nearest axis {label}", leaning)
    return Cue("markers", label, f"markers: the model's pose fitted on {len(ups)} frames puts "
                                 f"its up {off:.0f}° from {label}")


def walking_direction(markers: np.ndarray, rate: float, up: np.ndarray) -> np.ndarray | None:
    """The markers' mean velocity made horizontal (unit), None when slower than ``WALKING``:
    each marker's travel from the first frame it is seen to the last, over that time."""
    seen = np.isfinite(markers).all(axis=2)
    velocities = []
    for k in range(markers.shape[1]):
        frames = np.flatnonzero(seen[:, k])
        if len(frames) > 1 and frames[-1] > frames[0]:
            travel = markers[frames[-1], k] - markers[frames[0], k]
            velocities.append(travel * rate / (frames[-1] - frames[0]))
    if not velocities:
        return None
    mean = np.mean(velocities, axis=0)
    mean = mean - (mean @ up) * up
    speed = float(np.linalg.norm(mean))
    return mean / speed if speed >= WALKING else None


def lab_axes(model: Model, trial: Trial, markers: np.ndarray, vertical: str = "auto"
             ) -> LabAxes:
    """The lab's axes for solving ``trial`` with ``model`` (its tracked points' markers:
    frames × points × 3, m, NaN in gaps) and the gravity the run uses; ``vertical``: 'auto'
    (the cues), or an axis ('+y') the user states."""
    if vertical not in VERTICALS:
        raise InputError(f"vertical: expected one of {', '.join(VERTICALS)}, got {vertical!r}")
    model_up = _up_of(model.gravity)
    own = nearest_axis(model_up)[0] if model_up is not None else ""
    tie = model_defines_lab(model)
    if tie is not None:
        if vertical not in ("auto", own):
            raise InputError(f"--vertical {vertical}: {model.source} ties its bodies to the "
                             f"ground ({tie}), so its frame is the lab's and its gravity "
                             f"{_vector_text(model.gravity)} gives the vertical {own or 'none'};"
                             f" expected --vertical auto{' or ' + own if own else ''}, or edit "
                             "its gravity")
        return LabAxes(own, model_up if model_up is not None else np.zeros(3), model.gravity,
                       "ground", f"the model's ground ({tie}) is the lab's frame")
    cues = [c for c in (plate_cue(model, trial), marker_cue(model, markers, model_up),
                        screen_cue(trial.path)) if c is not None]
    chosen, chosen_by, why, warnings = _decide(cues, vertical, trial.path)
    if chosen is None:
        chosen, chosen_by = own, "model"
        reasons = "; ".join(c.detail for c in cues) or "no force plate, no tracked marker"
        warnings.append(f"{trial.path}: nothing tells the lab's vertical ({reasons}); gravity "
                        f"stays the model's {_vector_text(model.gravity)}: pass --vertical if "
                        "the lab's up is another axis")
        why = "the model's gravity: nothing in the file tells"
    up = axis_vector(chosen) if chosen else np.zeros(3)
    gravity = model.gravity
    if chosen and own != chosen:
        magnitude = float(np.linalg.norm(model.gravity))
        turned = -magnitude * up
        gravity = (float(turned[0]) + 0.0, float(turned[1]) + 0.0, float(turned[2]) + 0.0)
        why += f"; the model's gravity {_vector_text(model.gravity)} turned onto it"
    elif model_up is not None and chosen:
        up = model_up  # kept as written: its exact direction
    forward = walking_direction(markers, trial.rate, up) if up.any() else None
    return LabAxes(chosen, up, gravity, chosen_by, why, forward, tuple(warnings))


def _decide(cues: list[Cue], vertical: str, path: str
            ) -> tuple[str | None, str, str, list[str]]:
    """The vertical from the cues (or the option), who chose it, why, and warnings."""
    data = [c for c in cues if c.source != "POINT:Y_SCREEN" and c.axis is not None]
    screen = next((c for c in cues if c.source == "POINT:Y_SCREEN"), None)
    warnings: list[str] = []
    if vertical != "auto":
        against = [c for c in data if c.axis != vertical]
        warnings += [f"{path}: --vertical {vertical}, but {c.detail}" for c in against]
        return vertical, "option", "--vertical " + vertical, warnings
    axes = {c.axis for c in data}
    if len(axes) > 1:
        raise InputError(f"{path}: the lab's vertical is ambiguous: "
                         + "; ".join(c.detail for c in data)
                         + f"; expected one; pass --vertical {'|'.join(AXES)}")
    if not axes:
        weak = [c for c in cues if c.axis is None and c.leaning is not None]
        if screen is not None and weak and all(c.leaning == screen.axis for c in weak):
            # two cues, neither decisive alone, that agree
            return screen.axis, "file", "; ".join(
                [f"{screen.detail}, confirmed by the {c.source}" for c in weak[:1]]
                + [c.detail for c in weak]), warnings
        return None, "model", "", warnings
    chosen = axes.pop()
    parts = [c.detail for c in data]
    if screen is not None:
        parts.append(f"{screen.detail} {'agrees' if screen.axis == chosen else 'ignored: it '}"
                     + ("" if screen.axis == chosen else "disagrees with the data"))
    return chosen, "file", "; ".join(parts), warnings

