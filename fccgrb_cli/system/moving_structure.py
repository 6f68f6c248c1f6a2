"""The model check for models with moving joints (an imported OpenSim model).

Their coordinates have no rows of their own: the joints' rows hold them. So the check is made on
the mixed system at the initial pose: with θ fixed the topological rows must determine every
body (their Jacobian in the body coordinates of full column rank), the degrees of freedom left
are the coordinates less the couplings, and the prescribed coordinates (drivers) must determine
the bodies. A moving joint's nine rotation rows hold three degrees of freedom by design: the
dependent rows are reported only when there are more than those six per moving joint.
"""

from __future__ import annotations

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.model.observed import holding_unobserved
from fccgrb_cli.system.compiled import compile_system
from fccgrb_cli.system.rank import dependent_rows, rank_of


def analyse_moving(model: Model, report_type):
    """The :class:`StructureReport` (``report_type``) of a model with moving joints; raises
    InputError when the joints do not determine the bodies from the coordinates. The tracking
    rank is that of a solve: coordinates no tracked marker moves held at their defaults."""
    held_model, held = holding_unobserved(model)
    mc = compile_system(held_model, angles="coordinate", track=True)
    Jm = mc.jacobian(mc.pose())
    top = mc.masks()["topology"]
    nb = mc.layout.n_body_q
    body_rank = rank_of(Jm[top][:, :nb])
    if body_rank < nb:
        raise InputError(f"{model.source}: joints: expected joints that place every body from "
                         f"the coordinates, got rank {body_rank} of {nb} at the default pose")
    top_rank = rank_of(Jm[top])
    ad = compile_system(model, angles="driver")
    J = ad.jacobian(ad.pose())
    # nine rotation rows hold three degrees of freedom: six dependent rows per moving joint by
    # design (which six the pivoting names is arbitrary: a child's own u·v may be one of them)
    extra = int(top.sum()) - top_rank - 6 * len(model.moving_joints)
    labels = tuple(mc.labels[k] for k in range(len(mc.labels)) if top[k])
    redundant = dependent_rows(Jm[top], labels) if extra > 0 else ()
    return report_type(
        n_bodies=len(model.bodies), nq=ad.nq, n_topology_rows=int(top.sum()),
        topology_rank=top_rank, dof=mc.nq - top_rank + len(held), held=len(held),
        n_angles=len(model.angles),
        ad_rank=rank_of(J), redundant=redundant,
        n_tracking_rows=int(mc.masks()["tracking"].sum()), mc_rank=rank_of(Jm),
        nq_mixed=mc.nq, floating=(),
        n_distances=sum(bool(getattr(a, "translational", False)) for a in model.angles))
