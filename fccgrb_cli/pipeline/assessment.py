"""A solved run's checks put together: which frames the kinematics cannot be trusted on, and
where a joint moment cannot be trusted although the kinematics can (docs/formulation.md §11; the
bits are those of ``solvers/quality.py``; README, "What fccgrb checks for you").

Frames: the markers fit (``quality.poor_fit``), the clinical angles' ranges
(``model/ranges.py``), paper-style angles near 0°/180° or beyond (``quality.flat_or_mirrored``),
the model's calibration (``anatomy/plausibility.py``, an uncalibrated template), and with the
dynamics the classical model's singular positions (``solvers/conditioning.py``) and branch.

Moments, per frame and joint (``MOMENT_BITS``): the frame or a neighbour its central differences
reach is flagged; the inverse dynamics did not run there (no solved stretch long enough); a
contact body beyond the joint may be on the ground where no force plate measures it; the
accelerations are mostly noise (unfiltered markers).
"""

from __future__ import annotations

from itertools import pairwise

import numpy as np

from fccgrb_cli.anatomy.clinical import clinical_series, distal_contact
from fccgrb_cli.dynamics.convert import Dynamics
from fccgrb_cli.gait.analysis import FoundEvents
from fccgrb_cli.gait.events import Events, side_of
from fccgrb_cli.model import Model
from fccgrb_cli.model.elements import AngularCoordinate, Coordinate, in_metres
from fccgrb_cli.model.spatial import JointCoordinate
from fccgrb_cli.pipeline.options import SolveOptions
from fccgrb_cli.signals.butterworth import NOISE_BAND_HZ, noise_share
from fccgrb_cli.solvers.conditioning import conditioning
from fccgrb_cli.solvers.quality import (
    ANGLE_RANGE,
    BRANCH,
    CALIBRATION,
    CONTACT,
    FLAG_DTYPE,
    KINEMATICS,
    MOMENT_BITS,
    NO_DYNAMICS,
    NOISE_SHARE,
    NOISY,
    POOR_FIT,
    SINGULAR,
    Finding,
    flat_or_mirrored,
    out_of_range,
    poor_fit,
)
from fccgrb_cli.solvers.result import KinematicResult


def dynamic_findings(model: Model, dynamics: Dynamics) -> dict[int, Finding]:
    """The frame checks of the classical model the dynamics drove: its singular positions
    (``solvers.conditioning``) and the frames it could not solve from the mixed solution's
    configuration (its own BRANCH bits, set by the classical solve)."""
    classical = dynamics.kinematics
    condition = conditioning(model, classical.q)
    found = {SINGULAR: Finding(condition.singular, condition.describe()
                               if condition.singular.any() else "")}
    if classical.flags is not None and (classical.flags & BRANCH).any():
        found[BRANCH] = Finding((classical.flags & BRANCH) > 0, "the classical model did not "
                                "converge from the mixed solution's configuration there and was "
                                "solved from the previous frame's, which may lie on another "
                                "assembly branch")
    return found


def calibration_finding(model: Model, n: int, synthesized: bool) -> Finding:
    """Every frame when the model is an uncalibrated template solved on a real trial (a
    synthesized one is exact for its model) or its calibration warned."""
    if model.template and not synthesized:
        return Finding(np.ones(n, dtype=bool), f"{model.source} is a template (it names "
                       "calibration landmarks but was not personalized by `fccgrb calibrate`): "
                       "its segments and markers are a generic adult's, not this subject's; "
                       "calibrate it from a static trial first")
    record = model.calibrated
    if record is not None and record.warnings:
        return Finding(np.ones(n, dtype=bool), f"{model.source}: calibrated from "
                       f"{record.trial} with implausibilities: {'; '.join(record.warnings)}")
    return Finding(np.zeros(n, dtype=bool))


CLAMP_MARGIN = 1.0  # ° or mm beyond a clamped coordinate's range before a frame is flagged


def _clamped_range(coordinate: Coordinate) -> tuple[float, float]:
    """The range of a coordinate OpenSim clamps: only an imported joint's coordinate is."""
    assert isinstance(coordinate, JointCoordinate)
    return coordinate.range


def clamped_range(model: Model, theta: np.ndarray, clamped: list[int]) -> Finding:
    """Frames where an imported coordinate OpenSim clamps (``clamped``: its IK keeps it inside
    its range) lies more than ``CLAMP_MARGIN`` (° or mm) outside that range: the solve found
    another branch (an arm turned over, a mirrored elbow) or the markers are swapped, and the
    answer is not the one OpenSim gives."""
    scale = [1e3 if in_metres(model.angles[k]) else np.degrees(1.0) for k in clamped]
    values = np.column_stack([theta[:, k] * f for k, f in zip(clamped, scale, strict=True)])
    bounds = [_clamped_range(model.angles[k]) for k in clamped]
    ranges = tuple((low * f, high * f) for (low, high), f in zip(bounds, scale, strict=True))
    units = tuple("mm" if in_metres(model.angles[k]) else "°" for k in clamped)
    return out_of_range(values, tuple(model.angles[k].name for k in clamped), ranges,
                        CLAMP_MARGIN, units)


def kinematic_findings(model: Model, result: KinematicResult, fit: np.ndarray,
                       options: SolveOptions, synthesized: bool, recorded_m: float = 0.0
                       ) -> dict[int, Finding]:
    """The frame checks that need the kinematics only, by bit: the markers' fit (``fit``:
    frames × markers, m; every method whose answer comes from the markers, the angular-driver
    analysis with angles from the markers included: driven through a change point it may
    continue on the other assembly branch, its points then far from their markers; allowed
    the artefact the run adds and the one its trial file records, ``recorded_m``), the clinical
    ranges, paper-style angles flat (singular) or mirrored (another branch), and the
    calibration."""
    n = result.n_frames
    found: dict[int, Finding] = {}
    if result.method != "ad" or options.ad_drivers == "markers":
        record = model.calibrated
        found[POOR_FIT] = poor_fit(fit, model.marker_labels,
                                   options.perturb_level_m + recorded_m,
                                   record.fit_mm if record is not None else None)
    clinical = [k for k, a in enumerate(model.angles) if a.clinical_sign is not None]
    if clinical:
        values = np.column_stack([clinical_series(model.angles[k], result.theta[:, k])
                                  for k in clinical])
        found[ANGLE_RANGE] = out_of_range(values, tuple(model.angles[k].name for k in clinical),
                                          tuple(model.angles[k].clinical_range
                                                for k in clinical))
    clamped = [k for k, a in enumerate(model.angles) if getattr(a, "clamped", False)]
    if clamped and not clinical:
        found[ANGLE_RANGE] = clamped_range(model, result.theta, clamped)
    half = np.array([isinstance(a, AngularCoordinate) and not a.full for a in model.angles],
                    dtype=bool)
    found[SINGULAR], found[BRANCH] = flat_or_mirrored(result.theta, result.angle_names, half)
    found[CALIBRATION] = calibration_finding(model, n, synthesized)
    return found


CONTACT_MARGIN_S = 0.02  # a plate's contact counts this long beyond its loaded frames


def possible_contact(events: Events | None, side: str | None, n: int, rate: float
                     ) -> np.ndarray:
    """Per frame, whether a foot may be on the ground by gait events that do not come from the
    plates themselves (the file's, else the markers'): from each strike to the next off, and
    before the side's first event and after its last (unknown there); every frame when its
    side or events are unknown (a standing trial, a model without sides)."""
    if events is None or side is None:
        return np.ones(n, dtype=bool)
    marks = sorted((t, kind) for t, s, kind in zip(events.time, events.side, events.kind,
                                                    strict=True) if s == side)
    if not marks:
        return np.ones(n, dtype=bool)
    time = np.arange(n) / rate
    out = (time <= marks[0][0]) | (time >= marks[-1][0])
    for (t, kind), (later, _) in pairwise(marks):
        if kind == "strike":  # down until the next event (its off; or an off missed)
            out[(time >= t) & (time <= later)] = True
    return out


def contact_events(found: FoundEvents | None) -> Events | None:
    """The events that tell a foot's stance independently of the plates: the file's, else the
    markers' (the plates' own events cover only the contacts the plates measure)."""
    if found is None:
        return None
    return found.found.get("c3d") or found.found.get("kinematic")


def moment_flags(model: Model, result: KinematicResult, dynamics: Dynamics,
                 stance: dict[str, np.ndarray], events: Events | None,
                 rate: float) -> tuple[np.ndarray, dict[int, str]]:
    """Each joint moment's bits (frames × angles, ``MOMENT_BITS``) and the run's explanation of
    each bit found: the frame's flags (and its neighbours', which its central differences
    reach), the frames the dynamics did not cover, contacts no plate measures (``stance``: the
    frames a plate loads each body; ``events``: the gait events, when known), accelerations that
    are mostly noise."""
    moments = dynamics.inverse.joint_moments
    n, k = moments.shape
    out = np.zeros((n, k), dtype=FLAG_DTYPE)
    details: dict[int, str] = {}
    flagged = ~result.trusted
    reach = flagged.copy()
    reach[1:] |= flagged[:-1]
    reach[:-1] |= flagged[1:]
    out[reach] |= KINEMATICS
    out[~np.isfinite(moments)] |= NO_DYNAMICS
    margin = round(CONTACT_MARGIN_S * rate)
    unmeasured: dict[str, np.ndarray] = {}
    for j, angle in enumerate(model.angles):
        body = distal_contact(model, angle)
        if body is None:
            continue
        if body not in unmeasured:
            loaded = stance.get(body, np.zeros(n, dtype=bool))
            if margin and loaded.any():
                loaded = np.convolve(loaded, np.ones(2 * margin + 1), "same") > 0
            unmeasured[body] = possible_contact(events, side_of(body), n, rate) & ~loaded
        out[unmeasured[body], j] |= CONTACT
    gone = {body: int(mask.sum()) for body, mask in unmeasured.items() if mask.any()}
    if gone:
        details[CONTACT] = ("no force plate measures the ground's reaction on " + ", ".join(
            f"{body} ({frames} frames)" for body, frames in gone.items())
            + (" while the gait events (the file's or the markers') do not put it off the ground"
               if events is not None else " and no gait events say when it is off the ground"))
    share = noise_share(dynamics.kinematics.theta, rate)
    if np.isfinite(share).any() and np.nanmedian(share) > NOISE_SHARE:
        out[:] |= NOISY
        details[NOISY] = (f"{100 * np.nanmedian(share):.0f} % of the angular accelerations' "
                          f"RMS lies above {min(NOISE_BAND_HZ, 0.3 * rate):g} Hz (median over "
                          f"the angles; flagged above {100 * NOISE_SHARE:.0f} %): "
                          "differentiated marker noise; smooth the trial (--smooth auto) or "
                          "low-pass the angles "
                          "(--filter-cutoff 6, the gait standard)")
    return out, details


def describe_moments(flags: np.ndarray, details: dict[int, str], time: np.ndarray,
                     trusted: np.ndarray) -> list[str]:
    """One warning per moment bit on frames whose kinematics are trusted (the frames' own
    flags are explained already)."""
    out = []
    for bit in MOMENT_BITS:
        if bit.value == KINEMATICS:
            continue
        hit = np.flatnonzero((flags & bit.value).any(axis=1) & trusted)
        if len(hit):
            f = int(hit[0])
            extra = details.get(bit.value, "")
            out.append(f"joint moments not trusted on {len(hit)} frames (first: frame index "
                       f"{f}, t = {time[f]:.3f} s): {extra or bit.meaning}")
    return out


def curve_trust(model: Model, trusted: np.ndarray, moment_bits: np.ndarray | None
                ) -> np.ndarray | None:
    """Per frame, the trust of each clinical curve as the gait cycles order them (the clinical
    angles, then their moments): the frame's for an angle, the moment's own for a moment;
    None without moments (every curve as its frame)."""
    if moment_bits is None:
        return None
    clinical = [k for k, a in enumerate(model.angles) if a.clinical_sign is not None]
    if not clinical:
        return None
    angles = np.repeat(trusted[:, None], len(clinical), axis=1)
    return np.concatenate([angles, moment_bits[:, clinical] == 0], axis=1)
