"""Prescribed angular motion: a constant plus a sum of sinusoids (used to synthesize trials)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Motion:
    """θ(t) = mean + Σ A_i sin(2π f_i t + φ_i), angles in radians, frequencies in Hz."""

    mean: float
    terms: tuple[tuple[float, float, float], ...] = ()

    def bounds(self) -> tuple[float, float]:
        """Guaranteed lower and upper bound of θ(t) over all t."""
        spread = sum(abs(a) for a, _, _ in self.terms)
        return self.mean - spread, self.mean + spread

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """θ, θ̇ and θ̈ at the times t (s), each shaped like t."""
        t = np.asarray(t, dtype=float)
        theta = np.full_like(t, self.mean)
        theta_d = np.zeros_like(t)
        theta_dd = np.zeros_like(t)
        for amplitude, frequency, phase in self.terms:
            omega = 2.0 * np.pi * frequency
            arg = omega * t + phase
            theta += amplitude * np.sin(arg)
            theta_d += amplitude * omega * np.cos(arg)
            theta_dd -= amplitude * omega**2 * np.sin(arg)
        return theta, theta_d, theta_dd
