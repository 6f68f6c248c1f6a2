"""The smoother's own low-pass, for signals beside the kinematics (force plates).

A signal of frames × channels goes through the same prior and passes as the driver coordinates,
each channel a coordinate of unit noise whose equivalent cutoff is given: in the trial's middle
the zero-lag filter |H(f)| = 1 / (1 + (f/f_c)^(2p)), at its ends the prior's polynomial rather
than a padded filter's ringing. A ground reaction filtered this way meets accelerations filtered
the same way, so an impact's transient is neither left in one of them nor removed from the
other (Bisseling & Hof 2006; Kristianslund et al. 2012: the same bandwidth for both).
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.solvers.smooth.filter import Chains
from fccgrb_cli.solvers.smooth.prior import DERIVATIVES, ORDER, density
from fccgrb_cli.solvers.smooth.start import initial_state


def smoothed_signal(signal: np.ndarray, rate: float, cutoff_hz: float) -> np.ndarray:
    """``signal`` (frames × channels) through the smoother's filter at ``cutoff_hz``."""
    from fccgrb_cli.solvers.smooth.kernels import smooth_passes

    signal = np.asarray(signal, dtype=float)
    frames, channels = signal.shape
    if frames < 2 or not channels:
        return signal.copy()
    dt = 1.0 / rate
    time = np.arange(frames) * dt
    omega = 2.0 * np.pi * cutoff_hz
    ones = np.ones(frames)
    starts = [initial_state(time, signal[:, k], ones, ORDER, omega) for k in range(channels)]
    chains = Chains.build(ORDER, dt, np.full(channels, omega),
                          np.full(channels, density(cutoff_hz, 1.0, dt)),
                          np.array([s[0] for s in starts]), np.array([s[1] for s in starts]))
    A = np.broadcast_to(np.eye(channels), (frames, channels, channels)).copy()
    values = np.empty((frames, DERIVATIVES * channels))
    smooth_passes(chains.arrays(), A, np.ascontiguousarray(signal), False, values,
                  np.empty((0, DERIVATIVES * channels, DERIVATIVES * channels)))
    return values[:, :channels]
