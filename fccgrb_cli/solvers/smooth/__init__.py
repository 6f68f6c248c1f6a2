"""The whole-trial smoother (docs/formulation.md §12): every frame's driver coordinates — the
angles, the distances, a floating base's origin and orientation — and their first two derivatives
from all frames' markers at once, with the topological equations kept at every frame.

prior.py (the integrated-Wiener-process prior), start.py (its first frame), filter.py (the
linear smoother and its covariance, numpy; the reference), kernels.py (the same, compiled),
noise.py (marker noise and each coordinate's cutoff from the data), rotation.py (a floating
base's rotation-vector chart), coordinates.py (the markers as functions of the coordinates
through the topology; model_kernels.py compiled), trial.py (Gauss–Newton over the trial).
"""

from fccgrb_cli.solvers.smooth.trial import SmoothedMotion, SmoothSettings, smooth_motion

__all__ = ["SmoothSettings", "SmoothedMotion", "smooth_motion"]
