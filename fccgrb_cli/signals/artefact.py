"""Soft-tissue-artefact perturbation (docs/formulation.md §5).

For each perturbed marker and axis: a sum of a few sinusoids with frequencies inside the band of
the movement, seeded random phases and relative amplitudes, scaled so that its largest absolute
value over the trial equals the level. The noise of a marker depends only on the seed, its label
and the trial's length and rate, not on which other markers are perturbed.
"""

from __future__ import annotations

import zlib

import numpy as np

N_COMPONENTS = 4
DEFAULT_BAND_HZ = (0.3, 3.0)


def artefact(label: str, n_frames: int, rate: float, level_m: float, seed: int,
             band_hz: tuple[float, float] = DEFAULT_BAND_HZ) -> np.ndarray:
    """The artefact of one marker (frames × 3, metres), max |·| per axis equal to ``level_m``."""
    rng = np.random.default_rng([seed, zlib.crc32(label.encode())])
    t = np.arange(n_frames) / rate
    out = np.zeros((n_frames, 3))
    for axis in range(3):
        freqs = rng.uniform(*band_hz, N_COMPONENTS)
        phases = rng.uniform(0.0, 2.0 * np.pi, N_COMPONENTS)
        amps = rng.uniform(0.2, 1.0, N_COMPONENTS)
        signal = (amps * np.sin(2.0 * np.pi * freqs * t[:, None] + phases)).sum(axis=1)
        peak = np.abs(signal).max()
        out[:, axis] = signal * (level_m / peak) if peak > 0 else 0.0
    return out


def perturb(markers: np.ndarray, labels: tuple[str, ...] | list[str], rate: float,
            level_m: float, seed: int = 0, only: tuple[str, ...] | list[str] | None = None,
            band_hz: tuple[float, float] = DEFAULT_BAND_HZ) -> np.ndarray:
    """A perturbed copy of ``markers`` (frames × markers × 3, m); ``only`` names a subset."""
    out = markers.copy()
    if level_m <= 0:
        return out
    chosen = set(labels if only is None else only)
    for k, label in enumerate(labels):
        if label in chosen:
            out[:, k] += artefact(label, markers.shape[0], rate, level_m, seed, band_hz)
    return out
