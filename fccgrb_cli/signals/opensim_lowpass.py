"""OpenSim's low-pass of a coordinates file, as its inverse dynamics tool runs it
(``InverseDynamicsTool``: ``Storage::pad`` by half the rows, then ``Storage::lowpassIIR``).

The rows are extended at each end by half their number, each end's extension the signal
reflected through its end point (2 x₀ − x_k: value and slope kept); then a third-order
Butterworth (the bilinear transform with a prewarped cutoff, every zero at z = −1) runs forward
and backward, each pass starting with its first four outputs equal to its inputs (no initial
state). The result keeps the extension: the tool fits its splines to the padded rows, so the
derivatives at the trial's ends come from the reflected signal, not from end conditions.

This differs from fccgrb's own zero-lag filter (``signals.butterworth``: order of the user's
choice, a short odd extension, a steady-state start): the same cutoff gives the same −6 dB point
but not the same values near the ends, and OpenSim's regression outputs are computed this way."""

from __future__ import annotations

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.signals.butterworth import butter

__all__ = ["lowpass_padded", "padded"]

ORDER = 3


def padded(time: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``time`` (rows, s, uniform) and ``values`` (rows × columns) extended at both ends by
    rows // 2 rows: times continued at the mean step, values reflected through the end rows.

    Returns
    -------
    tuple of numpy.ndarray
        The padded times (rows + 2 · rows // 2) and values (same rows × columns).
    """
    n = len(values)
    pad = n // 2
    if pad == 0:
        return np.asarray(time, dtype=float), np.asarray(values, dtype=float)
    step = float(np.mean(np.diff(time)))
    before = 2 * values[0:1] - values[pad:0:-1]
    after = 2 * values[-1:] - values[-2:-(pad + 2):-1]
    out = np.concatenate([before, values, after], axis=0)
    stamps = np.concatenate([time[0] - step * np.arange(pad, 0, -1), time,
                             time[-1] + step * np.arange(1, pad + 1)])
    return stamps, out


def lowpass_padded(time: np.ndarray, values: np.ndarray, cutoff: float
                   ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`padded`, then the third-order Butterworth at ``cutoff`` Hz forward and backward.

    Parameters
    ----------
    time
        Sample times (rows, s), evenly spaced.
    values
        The signals (rows × columns).
    cutoff
        The cutoff (Hz), below the Nyquist frequency (OpenSim lowers a cutoff at or above it
        to 0.49 × the rate with a warning; fccgrb refuses it).

    Returns
    -------
    tuple of numpy.ndarray
        The padded times and the filtered padded values.
    """
    time = np.asarray(time, dtype=float)
    values = np.asarray(values, dtype=float)
    rate = 1.0 / float(np.mean(np.diff(time)))
    if not 0 < cutoff < rate / 2:
        raise InputError(f"--filter-cutoff: expected a cutoff between 0 and the Nyquist "
                         f"frequency {rate / 2:g} Hz, got {cutoff:g}")
    if len(values) < 2 * (ORDER + 1):
        raise InputError(f"--filter-cutoff: the coordinates have {len(values)} rows; the "
                         f"filter needs at least {2 * (ORDER + 1)}")
    stamps, extended = padded(time, values)
    b, a = butter(ORDER, cutoff / (rate / 2))
    forward = _recursion(b, a, extended)
    return stamps, _recursion(b, a, forward[::-1])[::-1]


def _recursion(b: np.ndarray, a: np.ndarray, x: np.ndarray) -> np.ndarray:
    """y_i = Σ b_k x_{i−k} − Σ_{k≥1} a_k y_{i−k} along axis 0 from row ORDER on, the first
    ORDER rows copied from x (OpenSim's start)."""
    y = np.array(x, dtype=float, copy=True)
    for i in range(ORDER, len(x)):
        y[i] = b @ x[i - ORDER:i + 1][::-1] - a[1:] @ y[i - ORDER:i][::-1]
    return y
