"""Zero-lag Butterworth low-pass filter (docs/formulation.md §6): run forward and backward.

The design and the forward-backward run are scipy.signal's ``butter`` and ``filtfilt`` (odd
extension of 3 × (order + 1) samples at each end, the initial state of the step response),
written out here with the same operations in the same order, so the values are scipy's to the
bit (tests/test_filtering.py compares them): importing scipy.signal takes 0.4–1 s, longer than
the rest of a short solve, and every solve runs a filter (the moments' noise test).

The recursion itself is a Python loop over the samples (every column at once), ~7 µs a sample
whatever the number of columns: callers filter their signals together (a trial's loads, its
angles and bases, the markers of its events), each column alone, the same values as one by one.
The warm server imports scipy.signal once (:func:`preload`); from then on every recursion runs
in lfilter's C loop, the same values to the bit."""

from __future__ import annotations

import sys

import numpy as np

from fccgrb_cli.core.errors import InputError

LONG = 5000  # samples: beyond, the recursion runs in scipy.signal.lfilter


def lowpass(signal: np.ndarray, rate: float, cutoff: float, order: int = 2) -> np.ndarray:
    """Filter along axis 0 with a Butterworth of ``order`` at ``cutoff`` Hz, forward and backward
    (zero lag; the magnitude response is squared, so −6 dB at the cutoff)."""
    if not 0 < cutoff < rate / 2:
        raise InputError(f"--filter-cutoff: expected a cutoff between 0 and the Nyquist "
                         f"frequency {rate / 2:g} Hz, got {cutoff:g}")
    b, a = butter(order, cutoff / (rate / 2))
    if len(signal) < frames_needed(order):
        raise InputError(f"--filter-cutoff: the trial has {len(signal)} frames; the filter needs "
                         f"at least {frames_needed(order)}")
    return filtfilt(b, a, signal)


def butter(order: int, wn: float) -> tuple[np.ndarray, np.ndarray]:
    """The digital Butterworth low-pass of ``order`` at ``wn`` × Nyquist as (b, a): the analog
    prototype's poles on the unit circle, scaled to the prewarped cutoff 4 tan(π wn / 2), mapped
    by the bilinear transform (fs = 2), every zero at z = −1 (scipy.signal.butter)."""
    m = np.arange(-order + 1, order, 2, dtype=np.float64)
    poles = -np.exp(1j * np.pi * m / (2 * order))
    warped = float(2 * 2.0 * np.tan(np.pi * np.asarray(wn, dtype=np.float64) / 2.0))
    poles = warped * poles
    gain = 1.0 * warped**order
    fs2 = 2.0 * 2.0
    digital = (fs2 + poles) / (fs2 - poles)
    gain = gain * np.real(np.prod(fs2 - np.zeros(0)) / np.prod(fs2 - poles))
    b = np.multiply(np.atleast_1d(np.asarray(gain, dtype=np.float64)),
                    _poly(-np.ones(order)))
    a = np.real(_poly(digital)).copy()
    return b, a


def _poly(roots: np.ndarray) -> np.ndarray:
    """The monic polynomial with these roots, highest power first (numpy.poly's product of
    (x − r) factors, one convolution each)."""
    out = np.ones((1,), dtype=roots.dtype)
    one = np.ones_like(roots[0])
    for root in roots:
        out = np.convolve(out, np.stack((one, -root)), mode="full")
    return out


def filtfilt(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """The filter (b, a) (a[0] = 1) run forward then backward along axis 0 of ``x``, each pass
    starting in the steady state of a step to its first sample, on the signal extended at both
    ends by its point reflection over 3 × len(a) samples (removed after)."""
    edge = 3 * max(len(a), len(b))
    if len(x) <= edge:
        raise ValueError(f"the filter needs more than {edge} samples, got {len(x)}")
    ext = np.concatenate((2 * x[0:1] - x[edge:0:-1], x,
                          2 * x[-1:] - x[-2:-(edge + 2):-1]), axis=0)
    zi = _step_state(b, a).reshape(-1, *[1] * (x.ndim - 1))
    y = _recursion(b, a, ext, zi * ext[0:1])
    y = _recursion(b, a, y[::-1], zi * y[-1:])
    return y[::-1][edge:-edge]


def _step_state(b: np.ndarray, a: np.ndarray) -> np.ndarray:
    """The filter's state after a long run of ones (scipy.signal.lfilter_zi): z = A z + B."""
    n = len(a)
    companion = np.zeros((n - 1, n - 1))
    companion[0, :] = -a[1:] / (1.0 * a[0:1])
    companion[np.arange(1, n - 1), np.arange(0, n - 2)] = 1
    return np.linalg.solve(np.eye(n - 1) - companion.T, b[1:] - a[1:] * b[0])


def preload() -> None:
    """Import scipy.signal (0.4–1 s), so that every later filter of this process runs in
    lfilter's C loop (:func:`in_lfilter`): for a process that filters many trials."""
    import scipy.signal  # noqa: F401


def in_lfilter(samples: int) -> bool:
    """Whether a recursion over ``samples`` runs in scipy.signal.lfilter: when its C loop pays
    back scipy.signal's import (longer than ``LONG``), or the import is already paid
    (:func:`preload`, or whatever else imported it)."""
    return samples > LONG or "scipy.signal" in sys.modules


def _recursion(b: np.ndarray, a: np.ndarray, x: np.ndarray, state: np.ndarray) -> np.ndarray:
    """y along axis 0 of the direct form II transposed from ``state``: in lfilter where
    :func:`in_lfilter` says, else in :func:`_loop` (the same values)."""
    if in_lfilter(len(x)):
        from scipy.signal import lfilter

        return lfilter(b, a, x, axis=0, zi=state)[0]
    return _loop(b, a, x, state)


def _loop(b: np.ndarray, a: np.ndarray, x: np.ndarray, state: np.ndarray) -> np.ndarray:
    """scipy.signal.lfilter's arithmetic, every column at once: y = z₀ + b₀x, then
    z_j = z_{j+1} + x b_{j+1} − y a_{j+1}, the last z_j without z_{j+1}."""
    z = [np.array(part) for part in state]
    y = np.empty(x.shape)
    last = len(b) - 1
    for k in range(len(x)):
        xk = x[k]
        yk = z[0] + b[0] * xk
        y[k] = yk
        for j in range(last - 1):
            z[j] = z[j + 1] + xk * b[j + 1] - yk * a[j + 1]
        z[last - 1] = xk * b[last] - yk * a[last]
    return y


NOISE_BAND_HZ = 15.0
NOISE_FLOOR = 1e-6  # rad (m) per frame²: second differences this small are rounding, not noise


def noise_share(signal: np.ndarray, rate: float, above: float = NOISE_BAND_HZ) -> np.ndarray:
    """Per column of ``signal`` (frames × columns, NaN rows where unknown), the share of its
    second differences' RMS (∝ the acceleration) above ``above`` Hz (at most 0.3 × the sampling
    rate), over every stretch of known rows long enough for the filter: movement has next to
    nothing there (gait: under 10 Hz), differentiated marker noise most of its power. Zero where
    the high part's RMS is under ``NOISE_FLOOR`` (a crank at constant speed: its second
    differences are rounding); NaN when no stretch is long enough."""
    from fccgrb_cli.core.stretches import runs

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
    b, a = butter(order, cutoff / (rate / 2))
    half = max(64, int(20 * rate / cutoff))
    step = np.r_[np.zeros(half), np.ones(half)]
    spread = np.flatnonzero(np.abs(filtfilt(b, a, step) - step) > tolerance)
    return int(max(half - spread.min(), spread.max() - half + 1)) if spread.size else 0
