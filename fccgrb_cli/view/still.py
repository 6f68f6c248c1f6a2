"""A still picture of one displayed frame of a scene as SVG, drawn with the page's rules (the
same styles, the same projection: ``camera.project``), for reports and papers. PNG is left to
the browser (a screenshot of the page) so that no image library is needed."""

from __future__ import annotations

import html
from dataclasses import dataclass, field

import numpy as np

from fccgrb_cli.view.camera import Camera, LabAxes3, framing, project
from fccgrb_cli.view.page import grid
from fccgrb_cli.view.scene import Layer, Scene
from fccgrb_cli.view.styles import (
    FLAGGED,
    FLOOR,
    OVERLAY,
    OVERLAY_ALPHA,
    OVERLAY_KINDS,
    OVERLAY_WIDEN,
    STYLES,
    UNTRUSTED,
    VERTICAL,
)

WIDTH, HEIGHT = 900, 560


@dataclass
class _Picture:
    """The SVG elements drawn so far, through one camera onto a width × height picture."""

    camera: Camera
    axes: LabAxes3
    width: int
    height: int
    out: list[str] = field(default_factory=list)

    def segment(self, a: np.ndarray, b: np.ndarray, color: str, w: float, css: str = "") -> None:
        (x0, y0, z0), (x1, y1, z1) = project(np.stack([a, b]), self.camera, self.axes,
                                             self.width, self.height)
        if z0 > 0 and z1 > 0:
            self.out.append(f'<line class="{css}" x1="{x0:.1f}" y1="{y0:.1f}" x2="{x1:.1f}" '
                            f'y2="{y1:.1f}" stroke="{color}" stroke-width="{w:g}"/>')

    def layer(self, layer: Layer, k: int, overlay: bool, scene: Scene) -> None:
        """One layer at displayed frame k, with the page's colours (viewer.js ``draw``)."""
        f = int(scene.frames[k])
        flagged = layer.trusted is not None and not layer.trusted[f]
        points = layer.positions[k]
        widen = OVERLAY_WIDEN if overlay else 0.0

        def color(kind: str) -> str:
            if overlay and kind != "marker":
                return OVERLAY
            if flagged and kind in ("segment", "origin"):
                return FLAGGED
            return str(STYLES[kind]["color"])

        for (i, j), kind in zip(layer.lines, layer.line_kinds, strict=True):
            if (not overlay or kind in OVERLAY_KINDS) and np.isfinite(points[[i, j]]).all():
                self.segment(points[i], points[j], color(kind),
                             float(STYLES[kind]["width"]) + widen, kind)
        screen = project(points, self.camera, self.axes, self.width, self.height)
        bad = _untrusted_markers(layer, k)
        for i, (kind, label) in enumerate(zip(layer.kinds, layer.labels, strict=True)):
            x, y, z = screen[i]
            if not np.isfinite(screen[i]).all() or z <= 0:
                continue
            radius = float(STYLES[kind]["radius"])
            if radius > 0 and (not overlay or kind in OVERLAY_KINDS):
                fill = UNTRUSTED if i in bad else color(kind)
                self.out.append(f'<circle class="{kind}" cx="{x:.1f}" cy="{y:.1f}" '
                                f'r="{radius + widen / 2:g}" fill="{fill}"><title>'
                                f"{html.escape(label)}</title></circle>")
            if label and not overlay and (scene.model_view or kind == "origin"):
                below = y + 15 if kind == "joint" else y - 5
                self.out.append(f'<text x="{x + 5:.1f}" y="{below:.1f}">'
                                f"{html.escape(label)}</text>")


def svg(scene: Scene, k: int = 0, camera: str = "orbit", width: int = WIDTH,
        height: int = HEIGHT) -> str:
    """The SVG of displayed frame ``k`` of ``scene`` seen from the camera preset ``camera``.

    Parameters
    ----------
    scene : the scene (its first layer frames the camera, as the page does).
    k : index into ``scene.frames``.
    camera : a preset name (``camera.PRESETS``).
    width, height : the picture's size, px.
    """
    target, distance = framing(scene.layers[0].positions)
    ax = scene.axes
    picture = _Picture(Camera.preset(camera, target, distance), ax, width, height)
    picture.out += [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" '
                    f'height="{height}" viewBox="0 0 {width} {height}" '
                    'font-family="sans-serif" font-size="12">',
                    f'<rect width="{width}" height="{height}" fill="#ffffff"/>']
    g = grid(scene)
    low, step, n = np.asarray(g["low"]), g["step"], g["n"]
    corner = low[0] * ax.forward + low[1] * ax.lateral + scene.floor * ax.up
    for a in range(n + 1):
        for along, across in ((ax.forward, ax.lateral), (ax.lateral, ax.forward)):
            start = corner + a * step * along
            picture.segment(start, start + n * step * across, FLOOR, 1)
    picture.segment(corner, corner + g["vertical"] * ax.up, VERTICAL, 2, "vertical")
    for n_layer in reversed(range(len(scene.layers))):  # the second run under the first
        picture.out.append(f'<g opacity="{OVERLAY_ALPHA if n_layer else 1:g}">')
        picture.layer(scene.layers[n_layer], k, n_layer > 0, scene)
        picture.out.append("</g>")
    t = scene.time[scene.frames[k]]
    picture.out.append(f'<text x="8" y="{height - 8}">{html.escape(scene.title)} · '
                       f"t = {t:.3f} s · frame {int(scene.frames[k])}</text></svg>")
    return "\n".join(picture.out)


def _untrusted_markers(layer: Layer, k: int) -> set[int]:
    """The point indices of markers missing or beyond the layer's limit at displayed frame k."""
    if layer.distance is None:
        return set()
    missing = ~np.isfinite(layer.positions[k, layer.markers]).all(axis=1)
    far = layer.distance[k] > layer.limit_m
    return {int(i) for i in layer.markers[missing | far]}
