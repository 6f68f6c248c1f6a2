"""Does the model determine its coordinates? Rank of Φ_q and redundant equations.

Checked at the model's stated initial pose (with the angles it has there): the joints must leave
exactly as many degrees of freedom as there are driven coordinates (angles and distances), and the
AD Jacobian (topology + AR drivers) must then have full column rank.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import GROUND, Model
from fccgrb_cli.system.compiled import compile_system
from fccgrb_cli.system.constraints import floating_bases, joint_neighbours, reachable
from fccgrb_cli.system.rank import dependent_rows, rank_of


@dataclass(frozen=True)
class StructureReport:
    """What the model check found (printed by ``fccgrb check``)."""

    n_bodies: int
    nq: int
    n_topology_rows: int
    topology_rank: int
    dof: int
    n_angles: int
    ad_rank: int
    redundant: tuple[str, ...]
    n_tracking_rows: int
    mc_rank: int
    nq_mixed: int
    floating: tuple[str, ...] = ()
    n_distances: int = 0
    held: int = 0  # coordinates no tracked marker moves, held at their defaults in a solve

    def lines(self) -> list[str]:
        out = [
            f"bodies {self.n_bodies}, coordinates {self.nq} (+{self.n_angles} mixed)",
            f"topological equations {self.n_topology_rows}, rank {self.topology_rank}: "
            f"{self.dof} degrees of freedom"
            + (f" (6 each for the floating bases {', '.join(self.floating)})"
               if self.floating else "")
            + (f", {self.held} of them held at their default values in a solve (no tracked "
               f"marker moves them)" if self.held else ""),
            (f"angular coordinates {self.n_angles - self.n_distances}, distance coordinates "
             f"{self.n_distances}" if self.n_distances else
             f"angular coordinates {self.n_angles}")
            + f"; AD Jacobian rank {self.ad_rank} of {self.nq}",
            f"tracking equations {self.n_tracking_rows}; MC Jacobian rank {self.mc_rank} "
            f"of {self.nq_mixed}",
        ]
        if self.redundant:
            out.append(f"redundant equations ({len(self.redundant)}): "
                       + "; ".join(self.redundant))
        else:
            out.append("redundant equations: none")
        return out


def check_tracking(model: Model, report: StructureReport) -> None:
    """For ``fccgrb check``: a model that tracks markers must track enough of them to determine
    its mixed coordinates at the initial pose (MC Jacobian of full column rank), or no trial can
    be solved with it. The InputError names a floating base (a body, or a group of bodies, that
    no joint ties to the ground: only its own markers fix its 6 degrees of freedom) that lacks
    the 3 markers it needs, else the rank. A model that tracks nothing can still be synthesized
    (``fccgrb synth`` drives it by its angles); ``solve`` then asks for markers."""
    if report.mc_rank == report.nq_mixed or not (model.tracked_points or
                                                 model.tracked_vectors):
        return
    rank, nq = report.mc_rank, report.nq_mixed
    neighbours = joint_neighbours(model)
    tracked: dict[str, int] = {}
    for tp in model.tracked_points:
        tracked[tp.body] = tracked.get(tp.body, 0) + 1
    seen: set[str] = {GROUND}
    for base in floating_bases(model):
        group = reachable(neighbours, base, seen)
        count = sum(tracked.get(b, 0) for b in group)
        if count < 3:
            members = f" (with {', '.join(sorted(group - {base}))})" if len(group) > 1 else ""
            raise InputError(
                f"{model.source}: bodies.{base}: a floating base{members}: no joint ties it to "
                f"the ground, so its tracked points alone fix its 6 degrees of freedom; "
                f"expected at least 3 not on one line, got {count}")
    raise InputError(f"{model.source}: tracking: expected tracked points and vectors that "
                     f"determine every coordinate at the initial pose, got MC Jacobian rank "
                     f"{rank} of {nq}")


def _refuse_a_singular_pose(model: Model, system, top_rank: int, expected_dof: int) -> None:
    """An InputError when the model's pose is a singular position of its joints (a change
    point): the joints leave more degrees of freedom at the pose than near it, and near it as
    many as the model's coordinates and floating bases take."""
    from fccgrb_cli.system.mobility import generic_topology_rank

    generic = generic_topology_rank(system, system.pose())
    if generic > top_rank and system.nq - generic == expected_dof:
        raise InputError(
            f"{model.source}: bodies' poses: expected a pose off the joints' singular positions; "
            f"the pose given is one (a change point, as a four-bar with its links in line): the "
            f"joints leave {system.nq - top_rank} degrees of freedom there and "
            f"{system.nq - generic} near it, so its coordinates cannot be counted or solved "
            "from it; move the bodies a little along the mechanism's motion")


def analyse(model: Model) -> StructureReport:
    """Rank analysis; raises InputError when the constraints cannot determine the coordinates."""
    if model.moving_joints:
        from fccgrb_cli.system.moving_structure import analyse_moving

        return analyse_moving(model, StructureReport)
    ad = compile_system(model, angles="driver")
    J = ad.jacobian(ad.pose())
    top = ad.masks()["topology"]
    top_rank = rank_of(J[top])
    dof = ad.nq - top_rank
    n_angles = len(model.angles)
    n_distances = sum(a.kind == "distance" for a in model.angles)
    bases = floating_bases(model)
    joint_dof = dof - 6 * len(bases)
    if n_angles != joint_dof:
        _refuse_a_singular_pose(model, ad, top_rank, n_angles + 6 * len(bases))
        slides = n_distances or any(j.type in ("cylindrical", "prismatic", "parallel", "line")
                                    for j in model.joints)
        what = "coordinates (angles and distances)" if slides else "angular coordinates"
        detail = (f"add {what} for the free motions" if n_angles < joint_dof
                  else f"remove {what} that repeat a joint's motion")
        floating = (f" besides the 6 of each floating base ({', '.join(bases)})" if bases
                    else "")
        raise InputError(
            f"{model.source}: angles: expected {joint_dof} {what} for the "
            f"{joint_dof} degrees of freedom the joints leave{floating}, got {n_angles} "
            f"({detail})")
    ad_rank = rank_of(J)
    if ad_rank < ad.nq:
        order = np.concatenate([np.flatnonzero(top), np.flatnonzero(~top)])
        culprits = [name for name in dependent_rows(J[order], tuple(ad.labels[k] for k in order))
                    if name.startswith(("angle ", "distance "))]
        raise InputError(
            f"{model.source}: angles: expected angular coordinates that determine the "
            f"coordinates at the initial pose, got Jacobian rank {ad_rank} of {ad.nq}: "
            f"{', '.join(culprits) or 'the angles'} repeat another coordinate's motion or have "
            "parallel vectors there (a distance: an axis perpendicular to its slide)")
    mc = compile_system(model, angles="coordinate", track=True)
    Jm = mc.jacobian(mc.pose())
    return StructureReport(
        n_bodies=len(model.bodies), nq=ad.nq, n_topology_rows=int(top.sum()),
        topology_rank=top_rank, dof=dof, n_angles=n_angles, ad_rank=ad_rank,
        redundant=dependent_rows(J, ad.labels),
        n_tracking_rows=int(mc.masks()["tracking"].sum()), mc_rank=rank_of(Jm), nq_mixed=mc.nq,
        floating=bases, n_distances=n_distances)
