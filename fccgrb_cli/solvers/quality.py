"""Frames not to be trusted, whatever the solver said: no silent wrong answer.

A solver's own verdict (converged or not) says nothing of a frame that landed on the other
assembly branch, of a method whose per-frame optimum is not unique (goal attainment's minimax on
noisy markers) and so jumps from frame to frame, of a topology left broken, of markers that
cannot determine the model, of a model that does not fit its markers, or of angles no person
takes. Every run is checked after its solve, and each frame gets a bit mask (``FRAME_BITS``):

* ``UNCONVERGED``: the solver did not converge (or the frame was left unsolved);
* ``TOPOLOGY``: a method that keeps the model rigid (AD, CNO, MO) left max |Φ_top| above
  ``TOPOLOGY_PROMISE`` (NRM-LS/WLS relax the topology by design and are not judged on it);
* ``JUMP``: the model points' motion is rougher than the markers they follow allow. Joint
  moments rest on central-difference accelerations; jitter of δ in a frame's solution changes
  them by ~4δ/dt² there, while a smooth motion's second differences change slowly. So each
  frame's fourth difference of the model points (p[f−2] − 4p[f−1] + 6p[f] − 4p[f+1] + p[f+2],
  the change of the second differences, ≈ (ω dt)² times them for a smooth motion) is compared
  with the markers' largest over frames f−2…f+2: a fit to the markers cannot be rougher than the
  markers beyond a factor ``JUMP_RATIO`` (10). On the five-bar, NRM-WLS and CNO-SQP reach 4.1 at
  30 mm (0.8 without noise), goal attainment 18–12,000 (its per-frame optimum is not unique on
  noisy markers, and consecutive frames land anywhere on it); on the Qualisys gait trial
  NRM-WLS reaches 0.66 (its markers' own noise is rougher than any fit). The classical AD
  analysis is not judged on it: its drivers come from a pre-analysis, not from a fit of the
  model to the markers, and carry a segment's error down the chain with the lever arm (8× on the
  five-bar with P4 and P9 at 30 mm: inaccurate, but the pre-analysis's own). A frame on the
  other assembly branch shows as a jump where it leaves and where it rejoins the branch; the
  frames between are found by re-solving from a trusted neighbour (the parallel modes' repair,
  ``solvers/optimize/``). A frame whose neighbour jumps is flagged too: its central
  differences include the jump.
* ``NO_DATA``: the markers present cannot determine the model (left unsolved, by every method);
* ``SINGULAR``: the classical model's Φ_q is near a singular position (solvers/conditioning.py),
  or a paper-style angle (s1·s2 = cos θ) is within ``FLAT_DEG`` of 0° or 180°, where the
  relation loses θ's sign and the mixed Jacobian its rank;
* ``BRANCH``: a paper-style angle left (0°, 180°) — sin θ < 0, the mirror image whose moments
  have the opposite sign — or the classical model could not be solved from the mixed solution's
  configuration and may sit on another assembly branch (dynamics/convert.py);
* ``ANGLE_RANGE``: a clinical angle outside its physiological or declared range
  (model/ranges.py);
* ``POOR_FIT``: the model's points are far from the markers they follow: the frame's mean
  distance above ``FIT_MEAN_MM`` or one marker's above ``FIT_MARKER_MM`` (plus the largest
  artefact the run added itself, √3 times ``--perturb``); methods that fit the markers only
  (the AD baseline's pre-analysis is its own);
* ``CALIBRATION``: the model's calibration is implausible (``fccgrb calibrate`` warned) or the
  model is an uncalibrated template solved on a real trial (every frame).

A trusted frame has mask 0. ``converged`` in the results file means trusted. Joint moments carry
their own mask per frame and joint (``MOMENT_BITS``, dynamics/trust.py): where the kinematics
are trusted but the moment is not.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace

import numpy as np

from fccgrb_cli.solvers.result import KinematicResult

FLAG_DTYPE = np.uint16
(UNCONVERGED, TOPOLOGY, JUMP, NO_DATA, SINGULAR, BRANCH, ANGLE_RANGE, POOR_FIT,
 CALIBRATION) = (1 << k for k in range(9))
TOPOLOGY_PROMISE = 1e-6
JUMP_RATIO = 10.0
JUMP_FLOOR = 1e-5
EXACT_TOPOLOGY = ("ad", "cno", "mo")
FIT_MEAN_MM = 20.0
FIT_MARKER_MM = 50.0
FLAT_DEG = 5.0


@dataclass(frozen=True)
class Bit:
    """One reason a frame (or a frame's moment) is not trusted: its name in the results file,
    its value in the mask, and what it means, thresholds included."""

    name: str
    value: int
    meaning: str


FRAME_BITS = (
    Bit("unconverged", UNCONVERGED, "the solver did not converge, or the frame was left "
        "unsolved"),
    Bit("topology", TOPOLOGY, f"max |Φ_top| above {TOPOLOGY_PROMISE:g} m for a method that holds "
        "the topology (AD, CNO, MO)"),
    Bit("jump", JUMP, f"the model points' fourth difference more than {JUMP_RATIO:g}× the "
        "markers' (another assembly branch, or a per-frame optimum that is not unique), or a "
        "neighbour's"),
    Bit("no_data", NO_DATA, "the markers present cannot determine the model"),
    Bit("singular", SINGULAR, "near a singular position: the classical model's σ_min/σ_max "
        "under 1/10 of its well-conditioned value, or an angle (s1·s2 = cos θ) within "
        f"{FLAT_DEG:g}° of 0° or 180°"),
    Bit("branch", BRANCH, "an angle (s1·s2 = cos θ) outside (0°, 180°), or the classical model "
        "not solved from the mixed solution's assembly branch"),
    Bit("angle_range", ANGLE_RANGE, "a clinical angle outside its physiological or declared "
        "range (range_deg)"),
    Bit("poor_fit", POOR_FIT, f"mean model–marker distance above {FIT_MEAN_MM:g} mm or one "
        f"marker's above {FIT_MARKER_MM:g} mm (plus the run's own added artefact)"),
    Bit("calibration", CALIBRATION, "an implausible calibration, or an uncalibrated template "
        "on a real trial"),
)
BITS = {bit.name: bit.value for bit in FRAME_BITS}

# a joint moment's own reasons, per frame and joint (dynamics where the kinematics are trusted)
KINEMATICS, NO_DYNAMICS, CONTACT, NOISY = (1 << k for k in range(4))
NOISE_SHARE = 0.5
MOMENT_BITS = (
    Bit("kinematics", KINEMATICS, "the frame, or a neighbour its central differences reach, is "
        "flagged"),
    Bit("no_dynamics", NO_DYNAMICS, "outside the stretches where the inverse dynamics ran "
        "(frames outside the data; unsmoothed, also unsolved frames and solved stretches too "
        "short for the rates)"),
    Bit("contact", CONTACT, "a contact body beyond the joint may be on the ground where no "
        "force plate measures it (stance off the plates, a trial without plates)"),
    Bit("noisy_rates", NOISY, f"more than {100 * NOISE_SHARE:.0f} % of the angular "
        "accelerations' RMS above 15 Hz: differentiated marker noise (neither smoothed nor "
        "filtered)"),
)


def bit_summary(bits: tuple[Bit, ...], flags: np.ndarray, details: dict[str, str] | None = None
                ) -> str:
    """The bits as JSON for the results file (``flags`` attribute ``bits``): per bit its name,
    value, meaning, how many entries of ``flags`` carry it (frames, or frame × joint entries),
    the first frame and this run's explanation (``details`` by name, else '')."""
    out = []
    for bit in bits:
        hit = np.flatnonzero((np.asarray(flags) & bit.value).reshape(len(flags), -1).any(axis=1))
        out.append({"name": bit.name, "value": bit.value, "meaning": bit.meaning,
                    "frames": len(hit), "first": int(hit[0]) if len(hit) else -1,
                    "detail": (details or {}).get(bit.name, "")})
    return json.dumps(out, ensure_ascii=False)


def roughness(points: np.ndarray) -> np.ndarray:
    """max over points of the fourth difference ‖p[f−2] − 4p[f−1] + 6p[f] − 4p[f+1] + p[f+2]‖
    (frames × points × 3 → frames; the two frames at each end take the nearest value; NaN
    where no point is available)."""
    n = len(points)
    out = np.full(n, np.nan)
    if n < 5:
        return out
    d4 = np.linalg.norm(points[4:] - 4.0 * points[3:-1] + 6.0 * points[2:-2]
                        - 4.0 * points[1:-3] + points[:-4], axis=2)
    out[2:-2] = _nanmax(d4, axis=1)
    out[:2], out[-2:] = out[2], out[-3]
    return out


def _nanmax(a: np.ndarray, axis: int) -> np.ndarray:
    """np.nanmax without its warning: NaN where a slice holds no number."""
    known = np.isfinite(a)
    out = np.where(known, a, -np.inf).max(axis=axis)
    return np.where(known.any(axis=axis), out, np.nan)


def jump_ratio(points: np.ndarray, markers: np.ndarray) -> np.ndarray:
    """Per frame, the model points' roughness over the largest of the markers' in frames
    f−2…f+2 (plus ``JUMP_FLOOR`` m, the scale of the solver's and the markers' rounding); NaN
    where either is unknown."""
    data = roughness(markers)
    padded = np.concatenate([[np.nan] * 2, data, [np.nan] * 2])
    window = np.stack([padded[k:k + len(data)] for k in range(5)])
    return roughness(points) / (_nanmax(window, axis=0) + JUMP_FLOOR)


def flags_of(method: str, converged: np.ndarray, phi_top_max: np.ndarray, points: np.ndarray,
             markers: np.ndarray) -> np.ndarray:
    """The solver's bits (unconverged, topology, jump; see the module's docstring) of every
    frame of a run by ``method``, from the solver's verdict, max |Φ_top|, the model points and
    the input markers (frames × k × 3) they follow."""
    flags = np.where(converged, 0, UNCONVERGED).astype(FLAG_DTYPE)
    if method.startswith(EXACT_TOPOLOGY):
        flags[~(phi_top_max <= TOPOLOGY_PROMISE) & converged] |= TOPOLOGY
    if method != "ad":
        jumps = jump_ratio(points, markers) > JUMP_RATIO
        near = jumps.copy()  # a neighbour's jump is inside this frame's central differences
        near[1:] |= jumps[:-1]
        near[:-1] |= jumps[1:]
        flags[near] |= JUMP
    return flags


@dataclass(frozen=True)
class Finding:
    """Frames one check flags, and this run's explanation of them (empty when none)."""

    frames: np.ndarray
    detail: str = ""


def poor_fit(distances: np.ndarray, labels: tuple[str, ...], added_m: float = 0.0,
             static_mm: tuple[float, float] | None = None) -> Finding:
    """Frames whose model points are far from their markers (``distances``: frames × markers,
    m, NaN where a marker is missing): the frame's mean above ``FIT_MEAN_MM`` or a marker's
    above ``FIT_MARKER_MM``, each plus √3·``added_m`` (the largest artefact a run added itself:
    its markers are that far from any model). The explanation names the markers furthest from
    the model over the flagged frames, and the calibration's own fit (``static_mm``: mean and
    largest, mm) when the model records it."""
    mm = 1e3 * np.asarray(distances, dtype=float)
    n = len(mm)
    if not mm.size:
        return Finding(np.zeros(n, dtype=bool))
    allowance = 1e3 * np.sqrt(3.0) * added_m
    seen = np.isfinite(mm).any(axis=1)
    mean = np.where(seen, np.nanmean(np.where(np.isfinite(mm), mm, 0.0), axis=1)
                    * mm.shape[1] / np.maximum(np.isfinite(mm).sum(axis=1), 1), np.nan)
    largest = _nanmax(mm, axis=1)
    bad = seen & ((mean > FIT_MEAN_MM + allowance) | (largest > FIT_MARKER_MM + allowance))
    if not bad.any():
        return Finding(bad)
    per_marker = np.array([np.nanmean(col) if np.isfinite(col).any() else -np.inf
                           for col in mm[bad].T])
    worst = np.argsort(-per_marker)[:3]
    names = ", ".join(f"{labels[k]} {per_marker[k]:.0f} mm" for k in worst
                      if np.isfinite(per_marker[k]))
    static = (f"; the calibration's own markers were {static_mm[0]:.1f} mm (mean) from their "
              f"places" if static_mm is not None else "")
    return Finding(bad, f"mean distance up to {np.nanmax(mean[bad]):.0f} mm, largest "
                        f"{np.nanmax(largest[bad]):.0f} mm; furthest markers (mean over these "
                        f"frames): {names}{static}")


def out_of_range(clinical: np.ndarray, names: tuple[str, ...],
                 ranges: tuple[tuple[float, float] | None, ...], margin: float = 0.0,
                 units: tuple[str, ...] | None = None) -> Finding:
    """Frames where a clinical angle (frames × angles, deg) leaves its range (deg; None: not
    checked) by more than ``margin``; the explanation names the angle furthest outside and its
    values (``units`` per angle: '°' by default, 'mm' for a translation)."""
    bad = np.zeros(len(clinical), dtype=bool)
    worst, detail = 0.0, ""
    for k, extent in enumerate(ranges):
        if extent is None:
            continue
        low, high = extent
        values = clinical[:, k]
        outside = np.isfinite(values) & ((values < low - margin) | (values > high + margin))
        if not outside.any():
            continue
        bad |= outside
        excess = float(np.max(np.maximum(low - values[outside], values[outside] - high)))
        if excess > worst:
            worst = excess
            unit = "°" if units is None else units[k]
            detail = (f"{names[k]} reaches {np.nanmin(values[outside]):.4g}…"
                      f"{np.nanmax(values[outside]):.4g}{unit} on {int(outside.sum())} frames, "
                      f"outside its range {low:.4g}…{high:.4g}{unit}")
    return Finding(bad, detail)


def flat_or_mirrored(theta: np.ndarray, names: tuple[str, ...], half: np.ndarray
                     ) -> tuple[Finding, Finding]:
    """Paper-style angles (``half``: s1·s2 = cos θ, no sign of their own) within ``FLAT_DEG`` of
    0° or 180° (singular) and outside (0°, 180°) (mirrored: sin θ < 0, the other branch of the
    cosine, where the conjugate moment changes sign)."""
    n = len(theta)
    if not half.any():
        return Finding(np.zeros(n, dtype=bool)), Finding(np.zeros(n, dtype=bool))
    s = np.sin(theta[:, half])
    known = np.isfinite(s)
    flat = known & (np.abs(s) < np.sin(np.radians(FLAT_DEG)))
    mirrored = known & (s < 0) & ~flat
    half_names = [name for name, h in zip(names, half, strict=True) if h]

    def finding(mask: np.ndarray, what: str) -> Finding:
        frames = np.asarray(mask.any(axis=1))
        if not frames.any():
            return Finding(frames)
        k = int(np.argmax(mask.sum(axis=0)))
        return Finding(frames, f"{half_names[k]} {what} on {int(mask[:, k].sum())} frames")

    return (finding(flat, f"within {FLAT_DEG:g}° of 0° or 180°"),
            finding(mirrored, "outside (0°, 180°): sin θ < 0"))


def combined(flags: np.ndarray, found: dict[int, Finding]) -> np.ndarray:
    """``flags`` with each finding's bit set on its frames."""
    out = np.asarray(flags, dtype=FLAG_DTYPE).copy()
    for bit, finding in found.items():
        out[np.asarray(finding.frames, dtype=bool)] |= bit
    return out


def describe(flags: np.ndarray, time: np.ndarray, method: str,
             details: dict[int, str] | None = None) -> list[str]:
    """One warning per kind of flag (the solver's own failures are reported by the solver),
    naming how many frames, the first one and, where a check gave one, its explanation."""
    out = []
    reasons = {
        TOPOLOGY: f"the topology is violated by more than {TOPOLOGY_PROMISE:g} m, which "
                  f"{method} promises to hold",
        JUMP: "the model moves more roughly than its markers (fourth differences more than "
              f"{JUMP_RATIO:g}× the markers'): a frame on another assembly branch, or a "
              "per-frame optimum that is not unique",
        NO_DATA: "the markers present cannot determine the model; left unsolved (by every "
                 "method)",
        SINGULAR: "the mechanism is near a singular position, where the classical model "
                  "driven by the angles loses rank and joint moments blow up",
        BRANCH: "another assembly branch: the moments conjugate to the angles change sign "
                "there",
        ANGLE_RANGE: "a clinical angle leaves its physiological range: not a posture a "
                     "person takes (mislabelled or missing markers, a wrong calibration)",
        POOR_FIT: "the model fits its markers far worse than a calibrated model does "
                  "(mislabelled or moved markers, a wrong or uncalibrated model)",
        CALIBRATION: "the model's calibration is implausible or missing",
    }
    for bit, reason in reasons.items():
        hit = np.flatnonzero(flags & bit)
        if len(hit):
            f = int(hit[0])
            extra = (details or {}).get(bit, "")
            out.append(f"{len(hit)} frames flagged (first: frame index {f}, t = {time[f]:.3f} s):"
                       f" {reason}{'; ' + extra if extra else ''}; they are not counted as "
                       "converged, and velocities, accelerations and joint moments there are "
                       "not to be trusted")
    return out


def frame_flags(result: KinematicResult, points: np.ndarray,
                markers: np.ndarray) -> np.ndarray:
    """The solver's bits of every frame of a solved run."""
    return flags_of(result.method, result.converged, result.phi_top_max, points, markers)


def assessed(result: KinematicResult, points: np.ndarray, markers: np.ndarray,
             found: dict[int, Finding] | None = None) -> KinematicResult:
    """``result`` with its frames' flags (the solver's bits and the ``found`` ones, by bit)
    and a warning for each kind found."""
    found = found or {}
    flags = combined(frame_flags(result, points, markers), found)
    details = {bit: f.detail for bit, f in found.items() if f.detail}
    return replace(result, flags=flags, messages=result.messages + tuple(
        describe(flags, result.time, result.method, details)))


def with_findings(result: KinematicResult, found: dict[int, Finding]) -> KinematicResult:
    """An assessed ``result`` with more findings (a later stage's, e.g. the classical model's
    singular positions) set in its flags and explained, for the frames they newly flag."""
    before = result.flags if result.flags is not None else np.zeros(result.n_frames, FLAG_DTYPE)
    flags = combined(before, found)
    new = np.where(flags != before, flags & ~before, 0).astype(FLAG_DTYPE)
    details = {bit: f.detail for bit, f in found.items() if f.detail}
    return replace(result, flags=flags, messages=result.messages + tuple(
        describe(new, result.time, result.method, details)))
