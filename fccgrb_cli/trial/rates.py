"""The sampling rates a trial file may state: one bound for every reader (C3D ``POINT:RATE``
and ``ANALOG:RATE``, TRC ``DataRate``) and the synthesizer, so that a rate no motion capture
records (1e30 Hz: every frame at the same instant, the differenced velocities infinite and
the filters' matrices singular) is refused where it is read, naming the file and the key."""

from __future__ import annotations

import math

POINT_RATE_MAX = 1e5   # Hz: marker frames (the fastest optical systems: a few kHz)
ANALOG_RATE_MAX = 1e6  # Hz: analog samples (force plates, EMG: up to tens of kHz)


def rate_problem(rate: float, high: float, zero_ok: bool = False) -> str | None:
    """What is wrong with ``rate`` (Hz) as a sampling rate at most ``high``, or None.

    Parameters
    ----------
    rate : float
        The rate as read (Hz).
    high : float
        The largest rate accepted (Hz).
    zero_ok : bool
        Whether 0 stands for 'no samples' here (a C3D without points or analog channels).

    Returns
    -------
    str or None
        The expectation to state in the error, or None for a rate that is fine.
    """
    if math.isfinite(rate) and (0.0 < rate <= high or (zero_ok and rate == 0.0)):
        return None
    return f"a positive, finite rate of at most {high:g} Hz"
