"""C3D trials carried into another lab: the same capture rotated, or cut short.

``rotated_c3d`` writes a C3D whose lab frame is the original's turned by ``rotation`` (3 × 3,
new = R · old): every POINT's coordinates and every FORCE_PLATFORM's corners. What a plate
measures needs nothing more for types 1–4: their analog channels are forces and moments in
the plate's own frame, which ezc3d (and every reader) places in the lab by the corners (its
axes are corner 1 − corner 2 and corner 1 − corner 4; ezc3d/src/modules/ForcePlatforms.cpp,
computePfReferenceFrame), and ORIGIN, the transducer's offset, is in that frame too. So the
analogs and origins are left as they are, and the rotated file's platform forces, moments and
centres of pressure are R times the original's (``test_lab_axes`` checks this on ezc3d's own
output). ``screen`` sets POINT:X_SCREEN / Y_SCREEN as another lab's software would write them.
"""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np

Y_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # z → +y, x stays
# z → −z (the lab's z points down), walking +x → −y
Z_DOWN_WALK_MINUS_Y = np.array([[0.0, -1.0, 0.0], [-1.0, 0.0, 0.0], [0.0, 0.0, -1.0]])
X_UP = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])  # z → +x, x → −z


def rotated_c3d(source: Path, target: Path, rotation: np.ndarray,
                screen: tuple[str, str] | None = None) -> Path:
    """``source`` turned by ``rotation`` into ``target`` (points, plate corners)."""
    assert np.allclose(rotation @ rotation.T, np.eye(3)) and np.isclose(np.linalg.det(rotation), 1)
    c3d = ezc3d.c3d(str(source))
    points = c3d["data"]["points"]
    gaps = c3d["data"]["meta_points"]["residuals"][0] < 0
    points[:3] = np.einsum("ij,jmf->imf", rotation, points[:3])
    points[:3, gaps] = 0.0  # a gap stays a gap (its residual says so)
    c3d["data"]["points"] = points
    platforms = c3d["parameters"]["FORCE_PLATFORM"]
    if "CORNERS" in platforms and np.size(platforms["CORNERS"]["value"]):  # plates
        corners = np.asarray(platforms["CORNERS"]["value"], dtype=float)  # 3 × 4 × plates
        c3d["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"] = np.einsum(
            "ij,jcp->icp", rotation, corners)
    if screen is not None:
        c3d["parameters"]["POINT"]["X_SCREEN"]["value"] = [screen[0]]
        c3d["parameters"]["POINT"]["Y_SCREEN"]["value"] = [screen[1]]
    c3d.write(str(target))
    return target


def cut_c3d(source: Path, target: Path, start: int, stop: int) -> Path:
    """Frames [start, stop) of ``source``, with their analog samples, into ``target``."""
    c3d = ezc3d.c3d(str(source))
    per = c3d["data"]["analogs"].shape[2] // c3d["data"]["points"].shape[2]
    c3d["data"]["points"] = c3d["data"]["points"][:, :, start:stop]
    for key in list(c3d["data"]["meta_points"].keys()):
        c3d["data"]["meta_points"][key] = c3d["data"]["meta_points"][key][:, :, start:stop]
    c3d["data"]["analogs"] = c3d["data"]["analogs"][:, :, start * per:stop * per]
    c3d.write(str(target))
    return target
