"""Plug-in Gait's upper body (the full-body model): its segments from the markers, frame by
frame, and its angle outputs ``LThoraxAngles``, ``LSpineAngles``, ``LNeckAngles``,
``LHeadAngles``, ``LShoulderAngles``, ``LElbowAngles``, ``LWristAngles`` and the right side's
(X, Y, Z in degrees), as Vicon's Plug-in Gait computes them.

Segments (Vicon's Plug-in Gait Reference Guide; pyCGM's ``thoraxJC``, ``headJC``,
``findshoulderJC``, ``elbowJointCenter``, ``wristJointCenter``, ``handJointCenter``), each as
Plug-in Gait's own axes (columns x, y, z; frames × 3 × 3) and origin:

* thorax: z from the midpoint of CLAV and C7 down to that of STRN and T10; x from the back
  midpoint (C7, T10) to the front one (CLAV, STRN), made perpendicular to z; y = z × x (to the
  subject's right); origin CLAV moved back along x by the marker radius. Its z points down
  and its y right, as Vicon's TRX bone;
* head: x from the back head markers' midpoint to the front ones', y from the right
  markers' midpoint to the left ones' made perpendicular to x, z = x × y (up); turned about y
  by the static's head offset (``HeadOffset``: Vicon's x' = x cos h − z sin h); origin the
  front midpoint;
* shoulder centre: the chord construction (``segments.chord``) from the thorax origin and a
  wand normal to the thorax's x and the shoulder marker, at the shoulder offset plus the
  marker radius from SHO;
* elbow centre: the chord construction from the shoulder centre and the elbow marker, at half
  the elbow width plus the marker radius, towards the normal of the plane of the shoulder
  centre, ELB and the wrist bar's midpoint (+ on the right, − on the left); wrist centre: the
  wrist bar's midpoint moved by half the wrist width plus the marker radius along the forearm's
  y (built from WRA − WRB and the elbow centre; + on the right, − on the left);
* humerus: z from the elbow centre to the shoulder centre, y = x × z normal to the plane of z
  and the elbow → wrist centre direction (x), x = y × z; origin the elbow centre;
* radius: y the humerus's (the elbow's flexion axis), z from the wrist centre to the elbow
  centre made perpendicular to it, x = y × z; origin the wrist centre;
* hand: its centre by the chord construction from the wrist centre and the wrist bar's
  midpoint to the finger marker at half the hand thickness plus the marker radius; z from it to
  the wrist centre, y along the wrist bar (WRB → WRA on the right, WRA → WRB on the left) made
  perpendicular, x = y × z; origin the hand centre.

The axes are Vicon's; the head's and hand's origins are not where Vicon puts its bones'
origins (further along their axes, by its bone lengths), which no angle uses.

Angles: Cardan angles of one segment's axes relative to another's, R = R_proximalᵀ R_distal =
R_i(a) R_j(b) R_k(c) in the sequence (i, j, k), then per output the components and signs
Plug-in Gait gives each side (``UPPER``): the thorax and head in the progression frame
(``angles.progression_frame``), the spine as the pelvis relative to the thorax and the neck as
the thorax relative to the head (Vicon's order, as pyCGM2 defines them), the shoulder as the
humerus relative to the thorax in the sequence x–y–z, the elbow and wrist y–x–z. Continuous over
the frames as Vicon writes them (``angles._continuous`` with the output component that holds
the sequence's middle angle). These reproduce Vicon's outputs from Vicon's own segment axes (the
bones it writes into the C3D) to rounding (tests/test_plugin_gait_upper.py covers each on
generated poses with known rotations).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.plugin_gait.angles import _continuous
from fccgrb_cli.plugin_gait.segments import chord

SIDES = {"l": "L", "r": "R"}
SIDE_SIGN = {"r": 1.0, "l": -1.0}
UPPER_JOINTS = ("Thorax", "Spine", "Neck", "Head", "Shoulder", "Elbow", "Wrist")
AXES = {"x": 0, "y": 1, "z": 2}
MARKERS = ("CLAV", "STRN", "C7", "T10", "LFHD", "RFHD", "LBHD", "RBHD",
           *(p + k for p in "LR" for k in ("SHO", "ELB", "WRA", "WRB", "FIN")))


@dataclass(frozen=True)
class Output:
    """One angle output's definition: the proximal and distal segments (``{s}`` for the side;
    'lab' the progression frame), the Cardan sequence, and per output component X, Y, Z the
    index of the Cardan angle it takes, its sign and its offset (deg) on the left and right."""

    proximal: str
    distal: str
    sequence: str
    index: tuple[int, int, int]
    left: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]
    right: tuple[tuple[float, float], tuple[float, float], tuple[float, float]]

    def middle(self) -> int:
        """The output component holding the sequence's middle angle."""
        return self.index.index(1)


# (sign, offset) per component; the right side mirrors the left in Y and Z.
UPPER = {
    "Thorax": Output("lab", "thorax", "yxz", (0, 1, 2),
                     ((1, 180), (-1, 0), (1, 180)), ((1, 180), (1, 0), (-1, 180))),
    "Spine": Output("thorax", "pelvis", "yxz", (0, 1, 2),
                    ((1, 180), (-1, 0), (-1, 180)), ((1, 180), (1, 0), (1, 180))),
    "Neck": Output("head", "thorax", "yxz", (0, 1, 2),
                   ((-1, 180), (-1, 0), (1, 180)), ((-1, 180), (1, 0), (-1, 180))),
    "Head": Output("lab", "head", "yxz", (0, 1, 2),
                   ((-1, 0), (1, 0), (-1, 0)), ((-1, 0), (-1, 0), (1, 0))),
    "Shoulder": Output("thorax", "humerus_{s}", "xyz", (1, 0, 2),
                       ((-1, 0), (1, 180), (-1, 180)), ((-1, 0), (-1, 180), (1, 180))),
    "Elbow": Output("humerus_{s}", "radius_{s}", "yxz", (0, 1, 2),
                    ((1, 0), (1, 0), (1, 0)), ((1, 0), (1, 0), (1, 0))),
    "Wrist": Output("radius_{s}", "hand_{s}", "yxz", (0, 1, 2),
                    ((1, 0), (-1, 0), (-1, 0)), ((1, 0), (1, 0), (1, 0))),
}


def output_names() -> tuple[str, ...]:
    """The upper body's angle outputs, left side first: LThoraxAngles ... RWristAngles."""
    return tuple(f"{SIDES[s]}{j}Angles" for s in ("l", "r") for j in UPPER_JOINTS)


def cardan(proximal: np.ndarray, distal: np.ndarray, sequence: str) -> np.ndarray:
    """(a, b, c) in radians with proximalᵀ distal = R_i(a) R_j(b) R_k(c) for the sequence
    (i, j, k) of distinct axes ('yxz', 'xyz', ...), per frame (axes as columns, frames × 3 ×
    3); b in [−90°, 90°]."""
    i, j, k = (AXES[a] for a in sequence)
    parity = 1.0 if (j - i) % 3 == 1 else -1.0  # +1 for the cyclic orders xyz, yzx, zxy
    r = np.einsum("fji,fjk->fik", proximal, distal)
    b = np.arcsin(np.clip(parity * r[:, i, k], -1.0, 1.0))
    a = np.arctan2(-parity * r[:, j, k], r[:, k, k])
    c = np.arctan2(-parity * r[:, i, j], r[:, i, i])
    return np.stack([a, b, c], axis=1)


def _continuous_about(degrees: np.ndarray, middle: int) -> np.ndarray:
    """``angles._continuous`` for outputs whose sequence's middle angle is component
    ``middle``: the other Cardan reading adds 180° to the two other components and takes the
    middle one to 180° − itself, whichever component holds it."""
    order = [k for k in range(3) if k != middle]
    order.insert(1, middle)
    back = np.argsort(order)
    return _continuous(np.asarray(degrees)[:, order])[:, back]


def upper_angles(frames: dict[str, np.ndarray], progression: np.ndarray
                 ) -> dict[str, np.ndarray]:
    """Plug-in Gait's upper-body angles (name → frames × 3, deg) from segment axes in Plug-in
    Gait's convention (``frames``: name → frames × 3 × 3, columns x, y, z: 'pelvis' (x
    anterior, y left, z up), 'thorax' (x anterior, y right, z down), 'head', and per side s
    'humerus_s', 'radius_s', 'hand_s', as :func:`segments` builds them) and the progression
    frame (3 × 3); an output whose segments are absent is left out."""
    n = len(next(iter(frames.values())))
    axes = dict(frames, lab=np.broadcast_to(progression, (n, 3, 3)))
    out: dict[str, np.ndarray] = {}
    for s, prefix in SIDES.items():
        for joint in UPPER_JOINTS:
            d = UPPER[joint]
            proximal, distal = d.proximal.format(s=s), d.distal.format(s=s)
            if proximal not in axes or distal not in axes:
                continue
            angles = np.degrees(cardan(axes[proximal], axes[distal], d.sequence))
            signs = d.left if s == "l" else d.right
            value = np.column_stack([sign * angles[:, d.index[k]] + offset
                                     for k, (sign, offset) in enumerate(signs)])
            out[f"{prefix}{joint}Angles"] = _continuous_about(value, d.middle())
    return out


@dataclass(frozen=True)
class UpperGeometry:
    """What Plug-in Gait's upper body needs of the subject (m, rad): the marker radius, the
    head offset, and per side ('l', 'r') the shoulder offset, elbow width, wrist width and hand
    thickness."""

    marker_radius: float
    head_offset: float
    shoulder_offset: dict[str, float]
    elbow_width: dict[str, float]
    wrist_width: dict[str, float]
    hand_thickness: dict[str, float]


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _frame(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    return np.stack([x, y, z], axis=-1)


def thorax(clav: np.ndarray, strn: np.ndarray, c7: np.ndarray, t10: np.ndarray,
           marker_radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Plug-in Gait's thorax (origin, axes; x anterior, y right, z down)."""
    z = _unit(0.5 * (strn + t10) - 0.5 * (clav + c7))
    forward = 0.5 * (clav + strn) - 0.5 * (c7 + t10)
    y = _unit(np.cross(z, forward))
    x = np.cross(y, z)
    return clav - marker_radius * x, _frame(x, y, z)


def head(lfhd: np.ndarray, rfhd: np.ndarray, lbhd: np.ndarray, rbhd: np.ndarray,
         offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Plug-in Gait's head (origin the front midpoint; x anterior, y left, z up), turned by
    the head offset (rad) about its y axis."""
    front = 0.5 * (lfhd + rfhd)
    x = _unit(front - 0.5 * (lbhd + rbhd))
    z = _unit(np.cross(x, 0.5 * (lfhd + lbhd) - 0.5 * (rfhd + rbhd)))
    y = np.cross(z, x)
    c, s = np.cos(offset), np.sin(offset)
    return front, _frame(c * x - s * z, y, s * x + c * z)


def segments(markers: dict[str, np.ndarray], g: UpperGeometry) -> tuple[
        dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Plug-in Gait's upper-body segments per frame from its markers (Vicon's labels: CLAV,
    STRN, C7, T10, LFHD, RFHD, LBHD, RBHD, and per side SHO, ELB, WRA, WRB, FIN; frames × 3,
    metres): (axes, origins) by name — 'thorax', 'head' and per side s 'humerus_s',
    'radius_s', 'hand_s' — plus the joint centres as origins 'shoulder_s', 'elbow_s',
    'wrist_s'."""
    m = markers
    r = g.marker_radius
    t_origin, t_axes = thorax(m["CLAV"], m["STRN"], m["C7"], m["T10"], r)
    h_origin, h_axes = head(m["LFHD"], m["RFHD"], m["LBHD"], m["RBHD"], g.head_offset)
    axes = {"thorax": t_axes, "head": h_axes}
    origins = {"thorax": t_origin, "head": h_origin}
    tx = t_axes[:, :, 0]
    for s, p in SIDES.items():
        sign = SIDE_SIGN[s]
        sho, elb, wra, wrb, fin = (m[p + k] for k in ("SHO", "ELB", "WRA", "WRB", "FIN"))
        wand = t_origin + sign * _unit(np.cross(_unit(sho - t_origin), tx))
        shoulder = chord(t_origin, wand, sho, g.shoulder_offset[s] + r)
        wri = 0.5 * (wra + wrb)
        normal = _unit(np.cross(_unit(shoulder - elb), _unit(wri - elb)))
        elbow = chord(shoulder, elb - sign * normal, elb, 0.5 * g.elbow_width[s] + r)
        fz = _unit(elbow - wri)
        fy = _unit(np.cross(fz, wra - wrb))
        wrist = wri + sign * (0.5 * g.wrist_width[s] + r) * fy
        uz = _unit(shoulder - elbow)
        uy = _unit(np.cross(wrist - elbow, uz))
        axes[f"humerus_{s}"] = _frame(np.cross(uy, uz), uy, uz)
        rx = _unit(np.cross(uy, elbow - wrist))
        axes[f"radius_{s}"] = _frame(rx, uy, np.cross(rx, uy))
        hand = chord(wrist, wri, fin, 0.5 * g.hand_thickness[s] + r)
        hz = _unit(wrist - hand)
        hx = _unit(np.cross(sign * (wra - wri), hz))
        axes[f"hand_{s}"] = _frame(hx, np.cross(hz, hx), hz)
        origins.update({f"humerus_{s}": elbow, f"radius_{s}": wrist, f"hand_{s}": hand,
                        f"shoulder_{s}": shoulder, f"elbow_{s}": elbow, f"wrist_{s}": wrist})
    return axes, origins
