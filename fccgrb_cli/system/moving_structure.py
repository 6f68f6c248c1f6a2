"""The model check for models with moving joints (an imported OpenSim model).

Their coordinates have no rows of their own: the joints' rows hold them. So the check is made on
the mixed system at the initial pose: with θ fixed the topological rows must determine every
body (their Jacobian in the body coordinates of full column rank), the degrees of freedom left
are the coordinates less the couplings, and the prescribed coordinates (drivers) must determine
the bodies. A moving joint's nine rotation rows hold three degrees of freedom by design; only
the other dependent rows are reported as redundant.
"""

from __future__ import annotations

from fccgrb_cli.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.system.compiled import compile_system
from fccgrb_cli.system.rank import dependent_rows, rank_of


def analyse_moving(model: Model, report_type):
    """The :class:`StructureReport` (``report_type``) of a model with moving joints; raises
    InputError when the joints do not determine the bodies from the coordinates."""
    mc = compile_system(model, angles="coordinate", track=True)
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
    labels = tuple(mc.labels[k] for k in range(len(mc.labels)) if top[k])
    redundant = tuple(name for name in dependent_rows(Jm[top], labels)
                      if "(moving): R" not in name)
    return report_type(
        n_bodies=len(model.bodies), nq=ad.nq, n_topology_rows=int(top.sum()),
        topology_rank=top_rank, dof=mc.nq - top_rank, n_angles=len(model.angles),
        ad_rank=rank_of(J), redundant=redundant,
        n_tracking_rows=int(mc.masks()["tracking"].sum()), mc_rank=rank_of(Jm),
        nq_mixed=mc.nq, floating=(),
        n_distances=sum(bool(getattr(a, "translational", False)) for a in model.angles))
