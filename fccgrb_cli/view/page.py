"""The self-contained HTML page of a scene: the scene as JSON with its arrays as base64 typed
arrays, the renderer (``viewer.js``, a canvas and this package's projection; no library, no
network) and the controls. The page opens offline in any current browser."""

from __future__ import annotations

import base64
import html
import json
import math
from importlib.resources import files

import numpy as np

from fccgrb_cli.view.camera import FOV_DEG, PRESETS, framing
from fccgrb_cli.view.scene import FORCE_M_PER_N, Layer, Scene
from fccgrb_cli.view.styles import (
    BAND_ALPHA,
    CURVE,
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

CSS = """
body{font:14px system-ui,sans-serif;margin:0;color:#202020;background:#fafafa}
header,footer,.bar{padding:6px 12px}
h1{font-size:17px;margin:4px 0}
#stage{position:relative}
#view{width:100%;height:560px;display:block;background:#fff;cursor:grab;touch-action:none}
#tip{position:absolute;background:#ffffe8;border:1px solid #999;padding:3px 6px;
  pointer-events:none;max-width:520px;font-size:12px}
#flags{width:100%;height:10px;display:block;cursor:pointer}
#curves{width:100%;height:220px;display:block;background:#fff;cursor:crosshair}
#frame{width:100%}
#status{white-space:pre-wrap;min-height:1.2em;font-size:13px}
#status.flagged{color:#d0021b}
button.on{background:#333;color:#fff}
.legend span{display:inline-block;margin-right:12px}
.legend i{display:inline-block;width:12px;height:12px;margin-right:4px;vertical-align:-2px}
.notes{font-size:12px;color:#555}
"""


def grid(scene: Scene) -> dict:
    """The floor's square grid in the lab's forward/lateral coordinates: its low corner, step
    (a 1-2-5 number, about a tenth of the drawn extent) and number of cells; and the vertical's
    drawn length."""
    ax = scene.axes
    points = np.concatenate([layer.positions.reshape(-1, 3) for layer in scene.layers])
    points = points[np.isfinite(points).all(axis=1)]
    plane = np.stack([points @ ax.forward, points @ ax.lateral], axis=1) if len(points) else \
        np.zeros((1, 2))
    low, high = plane.min(axis=0), plane.max(axis=0)
    extent = max(float((high - low).max()), 0.2)
    power = 10.0 ** math.floor(math.log10(extent / 10))
    step = next(power * m for m in (1, 2, 5, 10) if power * m >= extent / 10)
    start = np.floor(low / step) * step - step
    n = math.ceil((float((high - start).max()) + step) / step)
    return {"low": start.tolist(), "step": step, "n": n, "vertical": 0.25 * extent}


def _b64(values: np.ndarray | None, dtype) -> str | None:
    if values is None:
        return None
    return base64.b64encode(np.ascontiguousarray(values, dtype=dtype).tobytes()).decode("ascii")


def _layer(layer: Layer) -> dict:
    kinds = sorted(set(layer.kinds) | set(layer.line_kinds))
    index = {k: n for n, k in enumerate(kinds)}
    return {
        "name": layer.name, "labels": list(layer.labels), "kindNames": kinds,
        "kinds": [index[k] for k in layer.kinds], "nPoints": len(layer.labels),
        "positions": _b64(layer.positions, "<f4"), "lines": _b64(layer.lines, "<i4"),
        "lineKinds": [index[k] for k in layer.line_kinds], "lineLabels": list(layer.line_labels),
        "markers": layer.markers.tolist(), "modelPoints": layer.model_points.tolist(),
        "distance": _b64(layer.distance, "<f4"),
        "limit": layer.limit_m if math.isfinite(layer.limit_m) else 1e9,
        "flags": _b64(layer.flags, "<u2"),
        "trusted": _b64(layer.trusted, "u1"),
        "bits": [{"value": b.value, "name": b.name, "meaning": b.meaning, "detail": b.detail}
                 for b in layer.bits],
        "curves": [{"name": c.name, "unit": c.unit, "values": _b64(c.values, "<f4"),
                    "sd": _b64(c.sd, "<f4"), "trusted": _b64(c.trusted, "u1")}
                   for c in layer.curves],
    }


def scene_json(scene: Scene, camera: str) -> dict:
    """The scene as the page's script reads it."""
    target, distance = framing(scene.layers[0].positions)
    return {
        "title": scene.title, "modelView": scene.model_view, "nFrames": len(scene.time),
        "time": _b64(scene.time, "<f8"), "frames": _b64(scene.frames, "<i4"),
        "axes": {"forward": scene.axes.forward.tolist(), "lateral": scene.axes.lateral.tolist(),
                 "up": scene.axes.up.tolist()},
        "floor": scene.floor, "grid": grid(scene), "verticalLabel": f"up {scene.vertical}".strip(),
        "presets": PRESETS, "camera": camera, "fov": FOV_DEG,
        "target": target.tolist(), "distance": distance, "styles": STYLES,
        "overlayKinds": sorted(OVERLAY_KINDS), "overlayWiden": OVERLAY_WIDEN,
        "overlayAlpha": OVERLAY_ALPHA,
        "colors": {"overlay": OVERLAY, "flagged": FLAGGED, "untrusted": UNTRUSTED,
                   "floor": FLOOR, "vertical": VERTICAL, "curve": CURVE},
        "bandAlpha": BAND_ALPHA,
        "layers": [_layer(layer) for layer in scene.layers],
    }


def _legend(scene: Scene) -> str:
    items = [("model", STYLES["segment"]["color"]), ("u", STYLES["u"]["color"]),
             ("v", STYLES["v"]["color"]), ("w", STYLES["w"]["color"]),
             ("joint", STYLES["joint"]["color"]), ("joint axis", STYLES["axis"]["color"])]
    if not scene.model_view:
        items += [("model point", STYLES["model_point"]["color"]),
                  ("marker", STYLES["marker"]["color"]),
                  ("marker missing or too far", UNTRUSTED), ("frame not trusted", FLAGGED),
                  (f"force at the CoP (1 m = {1 / FORCE_M_PER_N:g} N)",
                   STYLES["force"]["color"])]
        if len(scene.layers) > 1:
            items.append((f"second run: {scene.layers[1].name}", OVERLAY))
    else:
        items.append(("tracked point", STYLES["model_point"]["color"]))
    return "".join(f'<span><i style="background:{c}"></i>{html.escape(t)}</span>'
                   for t, c in items)


def page(scene: Scene, camera: str = "orbit") -> str:
    """The HTML page of a scene, opened on the camera preset ``camera``."""
    data = json.dumps(scene_json(scene, camera), separators=(",", ":"), allow_nan=False)
    data = data.replace("</", "<\\/")  # a label cannot end the script element
    script = files("fccgrb_cli.view").joinpath("viewer.js").read_text(encoding="utf-8")
    buttons = "".join(f'<button data-camera="{n}">{n}</button>' for n in PRESETS)
    timeline = "" if scene.model_view else (
        '<div class="bar"><button id="play">▶ play</button> <button id="back">◀ step</button>'
        ' <button id="forth">step ▶</button> speed <select id="speed">'
        + "".join(f'<option value="{s}"{" selected" if s == 1 else ""}>{s}×</option>'
                  for s in (0.1, 0.25, 0.5, 1, 2, 4))
        + '</select> <span id="clock"></span>'
        '<input id="frame" type="range" min="0" value="0" step="1">'
        '<canvas id="flags" height="10" title="frames not trusted (red): hover for why, '
        'click to go there"></canvas></div>'
        '<canvas id="curves" height="220"></canvas>')
    if scene.model_view:  # the script's handles for the controls a model view has not
        timeline = ('<input id="frame" type="hidden"><span id="clock" hidden></span>'
                    '<canvas id="flags" hidden></canvas><canvas id="curves" hidden></canvas>')
    notes = "".join(f"<li>{html.escape(n)}</li>" for n in scene.notes)
    return f"""<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<title>{html.escape(scene.title)}</title><style>{CSS}</style></head>
<body><header><h1>{html.escape(scene.title)}</h1>
<div class="bar">camera {buttons} <label><input type="checkbox" id="labels"
{" checked" if scene.model_view else ""}> labels</label>
<span class="legend">{_legend(scene)}</span></div></header>
<div id="stage"><canvas id="view"></canvas><div id="tip" hidden></div></div>
<div class="bar" id="status"></div>
{timeline}
<footer><ul class="notes">{notes}<li>drag to orbit, wheel to zoom; hover a point for its name
and, for a marker, its distance to its model point</li></ul></footer>
<script type="application/json" id="scene">{data}</script>
<script>{script}</script>
</body></html>
"""
