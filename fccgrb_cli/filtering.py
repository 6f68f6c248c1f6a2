"""Zero-lag Butterworth low-pass filter (FORMULATION §6): run forward and backward."""

from __future__ import annotations

import numpy as np

from fccgrb_cli.errors import InputError


def lowpass(signal: np.ndarray, rate: float, cutoff: float, order: int = 2) -> np.ndarray:
    """Filter along axis 0 with a Butterworth of ``order`` at ``cutoff`` Hz, forward and backward
    (zero lag; the magnitude response is squared, so −6 dB at the cutoff)."""
    if not 0 < cutoff < rate / 2:
        raise InputError(f"--filter-cutoff: expected a cutoff between 0 and the Nyquist "
                         f"frequency {rate / 2:g} Hz, got {cutoff:g}")
    from scipy.signal import butter, filtfilt  # 0.5 s to import: only where a filter is used

    b, a = butter(order, cutoff / (rate / 2))
    pad = 3 * max(len(a), len(b))
    if len(signal) <= pad:
        raise InputError(f"--filter-cutoff: the trial has {len(signal)} frames; the filter needs "
                         f"more than {pad}")
    return filtfilt(b, a, signal, axis=0)


def settling_frames(rate: float, cutoff: float, order: int = 2, tolerance: float = 0.05) -> int:
    """How many frames either side of a step :func:`lowpass` spreads it by more than
    ``tolerance`` of the step (its reach: a frame that near a jump in the input carries part of
    it). Measured on the filter's own step response."""
    from scipy.signal import butter, filtfilt

    b, a = butter(order, cutoff / (rate / 2))
    half = max(64, int(20 * rate / cutoff))
    step = np.r_[np.zeros(half), np.ones(half)]
    spread = np.flatnonzero(np.abs(filtfilt(b, a, step) - step) > tolerance)
    return int(max(half - spread.min(), spread.max() - half + 1)) if spread.size else 0
