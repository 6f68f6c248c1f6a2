"""How each kind of drawn point and line looks, one table for the page and the still SVG."""

from __future__ import annotations

from typing import TypedDict


class Style(TypedDict):
    """A kind's colour, line width (px) and dot radius (px; 0: not drawn as a dot)."""

    color: str
    width: float
    radius: float


STYLES: dict[str, Style] = {
    "segment": {"color": "#3c3c3c", "width": 3.0, "radius": 0},
    "u": {"color": "#d62728", "width": 2.0, "radius": 0},
    "v": {"color": "#2ca02c", "width": 2.0, "radius": 0},
    "w": {"color": "#1f77b4", "width": 2.0, "radius": 0},
    "axis": {"color": "#9467bd", "width": 2.0, "radius": 0},
    "tracked_vector": {"color": "#8c564b", "width": 2.5, "radius": 0},
    "gap": {"color": "#8a8a8a", "width": 1.0, "radius": 0},
    "force": {"color": "#a0522d", "width": 3.0, "radius": 0},
    "origin": {"color": "#000000", "width": 0.0, "radius": 4.0},
    "point": {"color": "#3c3c3c", "width": 0.0, "radius": 2.5},
    "joint": {"color": "#ff7f0e", "width": 0.0, "radius": 5.5},
    "ground": {"color": "#000000", "width": 0.0, "radius": 4.0},
    "model_point": {"color": "#1f5fbf", "width": 0.0, "radius": 3.5},
    "marker": {"color": "#00a0a0", "width": 0.0, "radius": 3.5},
    "cop": {"color": "#a0522d", "width": 0.0, "radius": 4.0},
    "hidden": {"color": "#000000", "width": 0.0, "radius": 0.0},
}
OVERLAY = "#b000b0"  # the second run's model, drawn under the first, wider and translucent
OVERLAY_WIDEN, OVERLAY_ALPHA = 3.0, 0.55
FLAGGED = "#d0021b"  # a frame the file does not trust: its model drawn in this colour
UNTRUSTED = "#e8a000"  # a marker missing or too far from its model point
FLOOR = "#d8d8d8"
VERTICAL = "#000000"
# the kinds the second run draws (its frames' arrows and labels would hide the first run)
OVERLAY_KINDS = frozenset({"segment", "axis", "gap", "force", "origin", "joint",
                           "model_point", "marker", "cop"})
CURVE, BAND_ALPHA = "#1f5fbf", 0.18  # the first run's curves and their ±sd band
