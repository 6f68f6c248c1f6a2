"""Clinical joint angles and moments: every angle declared with a `clinical` sign, as
sign·(θ − 90°) in degrees, and the joint moment conjugate to it, in N·m and N·m/kg.

The moment conjugate to the clinical angle φ = s(θ − 90°) is s·τ (τ conjugate to θ, paper
§5): positive is the net internal moment acting towards positive φ (a flexor moment for
flexion, a dorsiflexor moment for dorsiflexion), as OpenSim reports generalized forces.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.model import Model
from fccgrb_cli.model.elements import Coordinate
from fccgrb_cli.system.constraints import joint_neighbours, reachable


@dataclass(frozen=True)
class ClinicalResults:
    """Clinical angles (frames × n, deg), their moments (frames × n, N·m, None without the
    dynamics), the subject's mass (kg, None when the model has none), the frames of each
    contact body's loaded stance (name → boolean per frame), the contact body beyond each
    joint, and which moments are trusted (frames × n; None: all)."""

    names: tuple[str, ...]
    angles: np.ndarray
    moments: np.ndarray | None
    mass: float | None
    stance: dict[str, np.ndarray]
    contact: tuple[str | None, ...] = ()
    moments_trusted: np.ndarray | None = None

    def stance_of(self, k: int) -> np.ndarray | None:
        """Frames in which a force plate loads the contact body distal to angle k, or None."""
        body = self.contact[k] if self.contact else None
        return self.stance.get(body) if body is not None else None

    @property
    def moments_per_kg(self) -> np.ndarray | None:
        if self.moments is None or self.mass is None:
            return None
        return self.moments / self.mass


def clinical_series(coordinate: Coordinate, theta: np.ndarray) -> np.ndarray:
    """The clinical angle (deg) of a coordinate that declares its clinical sign."""
    angle = coordinate.clinical(theta)
    assert angle is not None  # declared: only a coordinate without a sign gives None
    return angle


def clinical_results(model: Model, theta: np.ndarray, joint_moments: np.ndarray | None,
                     stance: dict[str, np.ndarray] | None = None) -> ClinicalResults | None:
    """The clinical view of a run (θ: frames × angles in the model's order, rad; moments τ:
    frames × angles, N·m), or None when no angle declares a clinical sign."""
    index = [k for k, a in enumerate(model.angles) if a.clinical_sign is not None]
    if not index:
        return None
    signs = np.array([model.angles[k].clinical_sign for k in index], dtype=float)
    angles = np.column_stack([clinical_series(model.angles[k], theta[:, k]) for k in index])
    moments = None if joint_moments is None else joint_moments[:, index] * signs
    contact = tuple(distal_contact(model, model.angles[k]) for k in index)
    return ClinicalResults(tuple(model.angles[k].name for k in index), angles, moments,
                           model.subject_mass, dict(stance or {}), contact)


def distal_contact(model: Model, angle) -> str | None:
    """The contact body on the far side of an angle's joint (reached from its second body
    without crossing its first), or None: a listed contact body (``loads.contact``) or a body
    a force plate is assigned to. An imported coordinate's joint is the moving joint whose
    transform it drives (the first, for a coordinate several drive); one no joint uses (a
    coupler's independent coordinate alone) has none."""
    if hasattr(angle, "body2"):
        near, far = angle.body1, angle.body2
    else:
        joint = next((j for j in model.moving_joints
                      if angle.name in j.transform.coordinates), None)
        if joint is None:
            return None
        near, far = joint.parent, joint.child
    beyond = reachable(joint_neighbours(model), far, {near})
    bodies = (*model.contact_bodies, *(p.body for p in model.force_plates))
    return next((body for body in bodies if body in beyond), None)


def clinical_table(c: ClinicalResults, trusted: np.ndarray | None = None) -> str:
    """One line per clinical angle: its range (deg) over the ``trusted`` frames (every frame
    when None) and its trusted moment's extremes (N·m/kg when the subject's mass is known, else
    N·m) while a force plate loads the foot beyond it (over every frame when none does: moments
    in stance off the plates lack the ground reaction, and are not trusted); '–' where no frame
    or moment there is trusted."""
    per_kg = c.moments_per_kg
    moments, unit = (per_kg, "N·m/kg") if per_kg is not None else (c.moments, "N·m")
    width = max(len(n) for n in c.names)
    head = f"{'clinical angle':>{width}}  {'min deg':>8}  {'max deg':>8}"
    if moments is not None:
        head += f"  {'min ' + unit:>12}  {'max ' + unit:>12}  {'over':>10}"
    lines = [head]
    for k, name in enumerate(c.names):
        angle = c.angles[:, k] if trusted is None else c.angles[trusted, k]
        line = (f"{name:>{width}}  {np.nanmin(angle):8.1f}  {np.nanmax(angle):8.1f}"
                if np.isfinite(angle).any() else f"{name:>{width}}  {'–':>8}  {'–':>8}")
        if moments is not None:
            stance = c.stance_of(k)
            over = stance if stance is not None and stance.any() else \
                np.ones(len(moments), dtype=bool)
            if c.moments_trusted is not None:
                over = over & c.moments_trusted[:, k]
            m = moments[over, k]
            where = f"{int(over.sum())} " + ("stance" if stance is not None and stance.any()
                                             else "all")
            low, high = (f"{v:12.2f}" for v in (np.nanmin(m), np.nanmax(m))) if \
                np.isfinite(m).any() else (f"{'–':>12}",) * 2
            line += f"  {low}  {high}  {where:>10}"
        lines.append(line)
    return "\n".join(lines)
