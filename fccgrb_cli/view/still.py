"""A still picture of one displayed frame of a scene as SVG, drawn with the page's rules (the
same styles, the same projection: ``camera.project``), for reports and papers. PNG is left to
the browser (a screenshot of the page) so that no image library is needed."""

from __future__ import annotations

import html

import numpy as np

from fccgrb_cli.view.camera import Camera, project
from fccgrb_cli.view.camera import framing as frame_points
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
)

WIDTH, HEIGHT = 900, 560


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
    target, distance = frame_points(scene.layers[0].positions)
    cam = Camera.preset(camera, target, distance)
    ax = scene.axes
    out = [f'<svg xmlns="http://www.w3.org/2000/svg" width="{width}" height="{height}" '
           f'viewBox="0 0 {width} {height}" font-family="sans-serif" font-size="12">',
           f'<rect width="{width}" height="{height}" fill="#ffffff"/>']

    def segment(a: np.ndarray, b: np.ndarray, color: str, w: float, css: str = "") -> None:
        (x0, y0, z0), (x1, y1, z1) = project(np.stack([a, b]), cam, ax, width, height)
        if z0 > 0 and z1 > 0:
            out.append(f'<line class="{css}" x1="{x0:.1f}" y1="{y0:.1f}" x2="{x1:.1f}" '
                       f'y2="{y1:.1f}" stroke="{color}" stroke-width="{w:g}"/>')

    g = grid(scene)
    low, step, n = np.asarray(g["low"]), g["step"], g["n"]
    corner = low[0] * ax.forward + low[1] * ax.lateral + scene.floor * ax.up
    for a in range(n + 1):
        segment(corner + a * step * ax.forward, corner + a * step * ax.forward
                + n * step * ax.lateral, FLOOR, 1)
        segment(corner + a * step * ax.lateral, corner + a * step * ax.lateral
                + n * step * ax.forward, FLOOR, 1)
    segment(corner, corner + g["vertical"] * ax.up, "#000000", 2, "vertical")
    for n_layer in reversed(range(len(scene.layers))):  # the second run under the first
        overlay = n_layer > 0
        out.append(f'<g opacity="{OVERLAY_ALPHA if overlay else 1:g}">')
        _layer(out, scene.layers[n_layer], k, overlay, scene, cam, width, height, segment)
        out.append("</g>")
    t = scene.time[scene.frames[k]]
    out.append(f'<text x="8" y="{height - 8}">{html.escape(scene.title)} · t = {t:.3f} s · '
               f"frame {int(scene.frames[k])}</text></svg>")
    return "\n".join(out)


def _layer(out: list[str], layer: Layer, k: int, overlay: bool, scene: Scene, cam: Camera,
           width: int, height: int, segment) -> None:
    f = int(scene.frames[k])
    flagged = layer.trusted is not None and not layer.trusted[f]
    points = layer.positions[k]

    def color(kind: str) -> str:
        if overlay and kind != "marker":
            return OVERLAY
        if flagged and kind in ("segment", "origin"):
            return FLAGGED
        return str(STYLES[kind]["color"])

    for (i, j), kind in zip(layer.lines, layer.line_kinds, strict=True):
        if overlay and kind not in OVERLAY_KINDS:
            continue
        if np.isfinite(points[[i, j]]).all():
            segment(points[i], points[j], color(kind),
                    float(STYLES[kind]["width"]) + (OVERLAY_WIDEN if overlay else 0.0), kind)
    screen = project(points, cam, scene.axes, width, height)
    bad = _untrusted_markers(layer, k)
    for i, (kind, label) in enumerate(zip(layer.kinds, layer.labels, strict=True)):
        x, y, z = screen[i]
        if not np.isfinite(screen[i]).all() or z <= 0:
            continue
        radius = float(STYLES[kind]["radius"]) + (OVERLAY_WIDEN / 2 if overlay else 0.0)
        fill = UNTRUSTED if i in bad else color(kind)
        if radius > 0 and (not overlay or kind in OVERLAY_KINDS):
            out.append(f'<circle class="{kind}" cx="{x:.1f}" cy="{y:.1f}" r="{radius:g}" '
                       f'fill="{fill}"><title>{html.escape(label)}</title></circle>')
        if label and not overlay and (scene.model_view or kind == "origin"):
            below = y + 15 if kind == "joint" else y - 5
            out.append(f'<text x="{x + 5:.1f}" y="{below:.1f}">{html.escape(label)}</text>')


def _untrusted_markers(layer: Layer, k: int) -> set[int]:
    """The point indices of markers missing or beyond the layer's limit at displayed frame k."""
    if layer.distance is None:
        return set()
    missing = ~np.isfinite(layer.positions[k, layer.markers]).all(axis=1)
    far = layer.distance[k] > layer.limit_m
    return {int(i) for i in layer.markers[missing | far]}
