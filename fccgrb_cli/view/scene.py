"""The scene the 3D view draws, built once in Python and drawn by the page's script and by the
still SVG alike: per layer (a run, or a model in its initial pose) every drawn point's lab
position per displayed frame, the lines between them, the measured markers with their model
points and distances, the frames' flags with their reasons, and the chosen curves.

Long trials are decimated for display only (:func:`display_frames`): the page shows every k-th
frame and says so; the flags and curves keep every frame; the results file is never changed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from fccgrb_cli.model import Model
from fccgrb_cli.solvers.quality import FIT_MARKER_MM
from fccgrb_cli.view.camera import LabAxes3, lab_axes
from fccgrb_cli.view.skeleton import Skeleton, pose_coordinates, skeleton

DISPLAY_BYTES = 8_000_000  # positions embedded per page at most (raw float32), before base64
FORCE_M_PER_N = 1e-3  # a plate's force drawn 1 m long per 1000 N
SOLID = frozenset({"origin", "point", "joint", "ground", "model_point", "marker", "cop"})


@dataclass(frozen=True)
class Curve:
    """One series drawn under the scene against the trial's clock, every frame kept.
    ``values`` and ``sd`` (its standard deviation, or None) are (frames,) in ``unit``;
    ``trusted`` (frames,) bool, False where the file does not trust the value."""

    name: str
    unit: str
    values: np.ndarray
    sd: np.ndarray | None
    trusted: np.ndarray


@dataclass(frozen=True)
class Bit:
    """A flag bit as the results file describes it: value, name, meaning, the run's detail."""

    value: int
    name: str
    meaning: str
    detail: str = ""


@dataclass(frozen=True)
class Layer:
    """One run (or one model) as drawn.

    ``positions`` (displayed frames, points, 3) m, NaN where a point is absent (a marker's
    gap, an unloaded plate); ``labels``/``kinds`` per point; ``lines`` (k, 2) point indices
    with ``line_kinds``/``line_labels``; ``markers``/``model_points`` (m,) the point indices of
    each measured marker and of the model point that follows it, ``distance`` (displayed frames,
    m) between them as the results file holds it (m), a marker drawn as untrusted beyond
    ``limit_m`` or where it is missing; ``flags`` (every frame) the file's bit mask, ``trusted``
    (every frame) the file's verdict, ``bits`` what each bit means.
    """

    name: str
    labels: tuple[str, ...]
    kinds: tuple[str, ...]
    positions: np.ndarray
    lines: np.ndarray
    line_kinds: tuple[str, ...]
    line_labels: tuple[str, ...]
    markers: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    model_points: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    distance: np.ndarray | None = None
    limit_m: float = math.inf
    flags: np.ndarray | None = None
    trusted: np.ndarray | None = None
    bits: tuple[Bit, ...] = ()
    curves: tuple[Curve, ...] = ()


@dataclass(frozen=True)
class Scene:
    """Everything drawn: ``time`` (every frame, s, on the trial's clock), ``frames`` the
    displayed frames' indices into it, the layers, the lab's axes, the floor's height along
    the vertical (m), the notes printed on the page (the vertical's origin, decimation), whether
    it is a model alone, and the vertical's name ('+z')."""

    title: str
    time: np.ndarray
    frames: np.ndarray
    layers: tuple[Layer, ...]
    axes: LabAxes3
    floor: float
    notes: tuple[str, ...] = ()
    model_view: bool = False
    vertical: str = ""

    @property
    def stride(self) -> int:
        """Every how many frames one is displayed (1: all)."""
        return int(self.frames[1] - self.frames[0]) if len(self.frames) > 1 else 1


def display_frames(n: int, bytes_per_frame: int, budget: int = DISPLAY_BYTES) -> np.ndarray:
    """The frames the page displays: every k-th, k the smallest stride that keeps the embedded
    positions within ``budget`` bytes, and always the first and the last frame.

    Parameters
    ----------
    n : the trial's frames.
    bytes_per_frame : the positions of one displayed frame, bytes.
    budget : bytes the page may embed.

    Returns
    -------
    (displayed,) int, increasing, from 0 to n − 1.
    """
    if n <= 0:
        return np.zeros(0, dtype=int)
    stride = max(1, math.ceil(n * bytes_per_frame / budget))
    frames = np.arange(0, n, stride)
    return frames if frames[-1] == n - 1 else np.append(frames, n - 1)


def skeleton_layer(name: str, s: Skeleton, x: np.ndarray, extra: dict | None = None) -> Layer:
    """A layer of a skeleton placed at body coordinates ``x`` (frames, bodies, 12)."""
    return Layer(name, tuple(s.labels), tuple(s.kinds), s.place(x),
                 np.asarray(s.lines, dtype=int).reshape(-1, 2), tuple(s.line_kinds),
                 tuple(s.line_labels), **(extra or {}))


def model_scene(model: Model) -> Scene:
    """A model alone in its file's initial pose, everything labelled (the paper's Figure 1:
    each body's point r and u, v, w; the joints and their axes; the tracked points and
    vectors)."""
    s = skeleton(model, labelled_points=True)
    tracked = {(t.body, t.point): t.marker for t in model.tracked_points}
    for k, label in enumerate(s.labels):
        body, _, point = label.partition(".")
        if s.kinds[k] == "point" and (body, point) in tracked:
            s.labels[k] = f"{label} ← {tracked[body, point]}"
            s.kinds[k] = "model_point"
    layer = skeleton_layer(model.name, s, pose_coordinates(model))
    up = -np.asarray(model.gravity, dtype=float)
    axes = lab_axes(up if np.linalg.norm(up) > 0 else np.array([0.0, 0.0, 1.0]))
    return Scene(f"{model.name}: initial pose", np.zeros(1), np.zeros(1, dtype=int), (layer,),
                 axes, floor_height([layer], axes),
                 (f"the lab's vertical: against the model's gravity {tuple(model.gravity)} "
                  "m/s²", "tracked points: 'body.point ← marker'"), model_view=True)


def floor_height(layers: list[Layer], axes: LabAxes3) -> float:
    """The floor along the vertical: the lab's 0, or lower where the model's points, the
    markers or a centre of pressure go below it (the drawn arrows do not count)."""
    lowest = 0.0
    for layer in layers:
        solid = [k for k, kind in enumerate(layer.kinds) if kind in SOLID]
        heights = layer.positions[:, solid] @ axes.up
        if np.isfinite(heights).any():
            lowest = min(lowest, float(np.nanmin(heights)))
    return lowest


def marker_limit_m(perturb_level_m: float) -> float:
    """The distance beyond which a marker is drawn as untrusted: the quality checks' limit
    for one marker (poor_fit), plus the artefact the run added itself (√3 × its level)."""
    return FIT_MARKER_MM * 1e-3 + math.sqrt(3.0) * perturb_level_m


def positions_bytes(layers: list[tuple[Skeleton, int, int]]) -> int:
    """Bytes of one displayed frame: per layer (skeleton, markers, loads) its float32 points
    (skeleton, markers, model points, a centre of pressure and a force tip per load) and
    distances."""
    return sum(4 * (3 * (len(s.labels) + 2 * m + 2 * loads) + m) for s, m, loads in layers)

