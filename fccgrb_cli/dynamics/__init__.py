"""Inverse dynamics: mass matrices, generalized forces, multipliers and joint moments
(docs/formulation.md §4)."""

from fccgrb_cli.dynamics.inverse import InverseDynamics, inverse_dynamics
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.dynamics.mass import gravity_forces, inertia_coefficients, mass_matrix

__all__ = [
    "ExternalLoad",
    "InverseDynamics",
    "gravity_forces",
    "inertia_coefficients",
    "inverse_dynamics",
    "mass_matrix",
]
