"""The camera of the 3D view: a perspective projection from the lab to the screen, the same
formulas in Python (the still SVG) and in the page's script (``viewer.js``, its ``project``).

The camera orbits a target in the lab's own axes: ``forward`` (the walking direction, or the
lab's x made horizontal), ``lateral`` = up × forward and ``up`` (the vertical the solve found).
At yaw ψ and pitch φ the eye sits at ``target + distance·b`` with
``b = cos φ (cos ψ f + sin ψ l) + sin φ u``; the screen's right is ``−sin ψ f + cos ψ l``
(horizontal, so looking straight down stays defined) and its up is ``b × right``. A lab point p
at ``d = p − eye`` lands at ``(W/2 + k x/z, H/2 − k y/z)`` with ``x = d·right``, ``y = d·up_s``,
``z = −d·b`` (its depth) and ``k = (H/2)/tan(fov/2)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

# the presets' yaw and pitch, degrees: sagittal from the subject's right (progression to the
# screen's right), frontal from the front, transverse from above (progression to the right)
PRESETS: dict[str, tuple[float, float]] = {
    "sagittal": (-90.0, 0.0), "frontal": (0.0, 0.0), "transverse": (-90.0, 90.0),
    "orbit": (-60.0, 20.0)}
FOV_DEG = 40.0


@dataclass(frozen=True)
class LabAxes3:
    """The lab's forward, lateral and up unit vectors (each (3,), right-handed)."""

    forward: np.ndarray
    lateral: np.ndarray
    up: np.ndarray


def lab_axes(up: np.ndarray, walking: np.ndarray | None = None) -> LabAxes3:
    """Forward, lateral, up from the vertical and the walking direction (either may be rough:
    forward is made horizontal; without a walking direction the lab axis most horizontal).

    Parameters
    ----------
    up : (3,) the lab's vertical, pointing up.
    walking : (3,) or None, the direction of progression.
    """
    up = np.asarray(up, dtype=float) / np.linalg.norm(up)
    forward = None if walking is None or not np.all(np.isfinite(walking)) else \
        np.asarray(walking, dtype=float)
    if forward is None or np.linalg.norm(forward - (forward @ up) * up) < 1e-6:
        forward = np.eye(3)[int(np.argmin(np.abs(up)))]
    forward = forward - (forward @ up) * up
    forward /= np.linalg.norm(forward)
    return LabAxes3(forward, np.cross(up, forward), up)


@dataclass(frozen=True)
class Camera:
    """Where the camera looks from: ``target`` (3,) m, ``yaw`` and ``pitch`` (rad, in the lab
    axes), ``distance`` (m) from the target, vertical field of view ``fov`` (rad)."""

    target: np.ndarray
    yaw: float
    pitch: float
    distance: float
    fov: float = np.radians(FOV_DEG)

    @classmethod
    def preset(cls, name: str, target: np.ndarray, distance: float) -> Camera:
        yaw, pitch = PRESETS[name]
        return cls(np.asarray(target, dtype=float), np.radians(yaw), np.radians(pitch), distance)


def view_basis(camera: Camera, axes: LabAxes3) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The eye's backward direction b, the screen's right and the screen's up (each (3,))."""
    cy, sy = np.cos(camera.yaw), np.sin(camera.yaw)
    cp, sp = np.cos(camera.pitch), np.sin(camera.pitch)
    horizontal = cy * axes.forward + sy * axes.lateral
    back = cp * horizontal + sp * axes.up
    right = -sy * axes.forward + cy * axes.lateral
    return back, right, np.cross(back, right)


def project(points: np.ndarray, camera: Camera, axes: LabAxes3, width: float, height: float
            ) -> np.ndarray:
    """Screen coordinates of lab points.

    Parameters
    ----------
    points : (..., 3) lab coordinates, m.
    camera, axes : the camera and the lab's axes.
    width, height : the picture's size, px.

    Returns
    -------
    (..., 3): x and y in px (y down, as SVG and canvas count), and the depth in m (positive in
    front of the eye; a point at or behind the eye is not drawable).
    """
    back, right, up = view_basis(camera, axes)
    d = np.asarray(points, dtype=float) - (camera.target + camera.distance * back)
    x, y, z = d @ right, d @ up, -(d @ back)
    k = 0.5 * height / np.tan(0.5 * camera.fov)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.stack([0.5 * width + k * x / z, 0.5 * height - k * y / z, z], axis=-1)


def framing(points: np.ndarray, fov: float = np.radians(FOV_DEG)) -> tuple[np.ndarray, float]:
    """A target and a distance that keep every finite point of ``points`` (..., 3) in view: the
    bounding box's centre, and the distance at which its enclosing sphere fills the field."""
    flat = np.asarray(points, dtype=float).reshape(-1, 3)
    flat = flat[np.isfinite(flat).all(axis=1)]
    if not len(flat):
        return np.zeros(3), 1.0
    low, high = flat.min(axis=0), flat.max(axis=0)
    radius = max(0.5 * float(np.linalg.norm(high - low)), 0.05)
    return 0.5 * (low + high), 1.1 * radius / np.sin(0.5 * fov)
