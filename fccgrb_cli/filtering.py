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
    if len(signal) < frames_needed(order):
        raise InputError(f"--filter-cutoff: the trial has {len(signal)} frames; the filter needs "
                         f"at least {frames_needed(order)}")
    return filtfilt(b, a, signal, axis=0)



NOISE_BAND_HZ = 15.0
NOISE_FLOOR = 1e-6  # rad (m) per frame²: second differences this small are rounding, not noise


def noise_share(signal: np.ndarray, rate: float, above: float = NOISE_BAND_HZ) -> np.ndarray:
    """Per column of ``signal`` (frames × columns, NaN rows where unknown), the share of its
    second differences' RMS (∝ the acceleration) above ``above`` Hz (at most 0.3 × the sampling
    rate), over every stretch of known rows long enough for the filter: movement has next to
    nothing there (gait: under 10 Hz), differentiated marker noise most of its power. Zero where
    the high part's RMS is under ``NOISE_FLOOR`` (a crank at constant speed: its second
    differences are rounding); NaN when no stretch is long enough."""
    from fccgrb_cli.stretches import runs

    high = np.zeros(signal.shape[1])
    total = np.zeros(signal.shape[1])
    for a, b in runs(np.isfinite(signal).all(axis=1), 16):
        second = np.diff(signal[a:b], n=2, axis=0)
        rest = second - lowpass(second, rate, min(above, 0.3 * rate), 2)
        high += np.sum(rest**2, axis=0)
        total += np.sum(second**2, axis=0)
    count = max(sum(b - a - 2 for a, b in runs(np.isfinite(signal).all(axis=1), 16)), 1)
    with np.errstate(invalid="ignore", divide="ignore"):
        share = np.where(total > 0, np.sqrt(high / total), np.nan)
    return np.where(np.sqrt(high / count) < NOISE_FLOOR, 0.0, share)


def frames_needed(order: int) -> int:
    """The fewest samples the forward-backward filter of ``order`` takes: more than its padding,
    three times the filter's length (order + 1 coefficients), as scipy's filtfilt pads."""
    return 3 * (order + 1) + 1


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
