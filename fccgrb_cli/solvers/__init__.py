"""Kinematic solution methods: one module per method, one result type."""

from fccgrb_cli.solvers.ad.solve import assemble, solve_ad
from fccgrb_cli.solvers.result import KinematicResult

__all__ = ["KinematicResult", "assemble", "solve_ad"]
