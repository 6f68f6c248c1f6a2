"""Upper-body segment frames and joint centres from landmark trajectories (frames × 3, metres).

Every frame follows the ISB recommendations for the upper body (Wu et al. 2005, J Biomech
38:981–992) in this project's body order (u = X anterior, v = Y superior along the segment's
long axis, w = Z to the subject's right, for both sides):

* thorax: v from the midpoint of the xiphoid (PX) and T8 to the midpoint of the suprasternal
  notch (IJ) and C7; w perpendicular to the plane of IJ, C7 and that lower midpoint, to the
  right; u = v × w anterior. Origin IJ.
* head: w from the left to the right head markers' midpoints, u from the back markers' midpoint
  to the front markers' perpendicular to w, v = w × u. Origin the four markers' centroid.
* upper arm (humerus, Wu et al.'s first option): origin at the glenohumeral centre, v from the
  elbow centre (mid-epicondyles) to it, u perpendicular to the plane of v and the epicondyles;
  the thigh's construction (``frames.thigh_frames``).
* forearm: v from the wrist centre (mid-styloids) to the elbow centre, u perpendicular to the
  plane of v and the styloids (radial lateral, ulnar medial in the anatomical posture); origin
  the elbow centre: the shank's construction (``frames.shank_frames``). In pronation the frame
  turns with the radius, as Wu et al.'s forearm frame does.
* hand: v from the midpoint of the 2nd and 5th metacarpal heads to the wrist centre, u
  perpendicular to the plane of v and those heads; origin the wrist centre.

Joint centres: the glenohumeral centre below the acromion marker along the thorax's long axis
by 17 % of the acromion–lateral epicondyle distance (Rab et al. 2002, Gait Posture 15:113–119);
the elbow and wrist centres midway between the epicondyles and the styloids (Wu et al. 2005);
the cervicothoracic joint midway between C7 and IJ.
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.anatomy.frames import Frames, shank_frames, thigh_frames

SHOULDER_DROP = 0.17  # Rab et al. (2002): GH centre below the acromion, × upper-arm length


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def thorax_frames(ij: np.ndarray, px: np.ndarray, c7: np.ndarray, t8: np.ndarray) -> Frames:
    """ISB thorax from the suprasternal notch, the xiphoid, C7 and T8 (Wu et al. 2005 §2.3.1)."""
    upper, lower = 0.5 * (ij + c7), 0.5 * (px + t8)
    v = _unit(upper - lower)
    w = _unit(np.cross(c7 - ij, lower - ij))  # the sagittal plane's normal, to the right
    u = np.cross(v, w)
    return Frames(ij, np.stack([u, v, w], axis=2))


def head_frames(left_front: np.ndarray, right_front: np.ndarray, left_back: np.ndarray,
                right_back: np.ndarray) -> Frames:
    """The head from a head band's four markers (front and back, left and right)."""
    origin = 0.25 * (left_front + right_front + left_back + right_back)
    w = _unit(right_front + right_back - left_front - left_back)
    forward = right_front + left_front - right_back - left_back
    u = _unit(forward - np.sum(forward * w, axis=1, keepdims=True) * w)
    return Frames(origin, np.stack([u, np.cross(w, u), w], axis=2))


def shoulder_centre(acromion: np.ndarray, thorax: Frames, upper_arm_length: float
                    ) -> np.ndarray:
    """The glenohumeral centre (frames × 3): ``SHOULDER_DROP`` × the upper arm's length
    (acromion to lateral epicondyle) below the acromion marker along the thorax's v (Rab et al.
    2002)."""
    return acromion - SHOULDER_DROP * upper_arm_length * thorax.axes[:, :, 1]


def upper_arm_frames(shoulder: np.ndarray, lateral_epicondyle: np.ndarray,
                     medial_epicondyle: np.ndarray, side: str) -> Frames:
    """ISB humerus (Wu et al. 2005 §2.4.3, first option), origin the glenohumeral centre."""
    return thigh_frames(shoulder, lateral_epicondyle, medial_epicondyle, side)


def forearm_frames(elbow: np.ndarray, radial_styloid: np.ndarray, ulnar_styloid: np.ndarray,
                   side: str) -> Frames:
    """ISB forearm (Wu et al. 2005 §2.4.4) with the origin at the elbow centre: the radial
    styloid is lateral and the ulnar medial in the anatomical posture."""
    return shank_frames(elbow, radial_styloid, ulnar_styloid, side)


def hand_frames(wrist: np.ndarray, second_metacarpal: np.ndarray, fifth_metacarpal: np.ndarray,
                side: str) -> Frames:
    """The hand from the wrist centre and the 2nd (radial) and 5th (ulnar) metacarpal heads,
    origin the wrist centre."""
    return shank_frames(wrist, second_metacarpal, fifth_metacarpal, side)
