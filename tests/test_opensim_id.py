"""Inverse dynamics of imported models, coordinates in: the power balance Σ τ θ̇ = d(T + V)/dt on
a generated model (an independent closed check of every term), and OpenSim's own ID regression
on arm26 (coordinates low-passed at 6 Hz as its setup says) within OpenSim's 2.0 N·m."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.dynamics.mass import gravity_forces, mass_matrix
from fccgrb_cli.dynamics.moving import coordinate_forces, forces_from_coordinates
from fccgrb_cli.model import load_model
from fccgrb_cli.model.osim.convert import parse_osim_model
from fccgrb_cli.system.compiled import compile_system
from fccgrb_cli.system.moving_pose import pose_from_coordinates
from tests.osim_text import knee_model

ID_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim" / "id_gait2392"
TOLERANCE = 2.0  # N·m: OpenSim's own, RMS per column


def test_coordinate_forces_balance_the_power_of_the_motion():
    system = compile_system(parse_osim_model(knee_model(), "knee.osim"), angles="coordinate")
    nb = system.layout.n_body_q
    M, g = mass_matrix(system.model), gravity_forces(system.model)
    rng = np.random.default_rng(7)
    n = len(system.model.angles)
    amplitude, frequency, phase = rng.uniform(0.1, 0.5, n), rng.uniform(0.5, 2.0, n), \
        rng.uniform(0, 2 * np.pi, n)

    def theta(t: float, order: int = 0) -> np.ndarray:
        w = 2 * np.pi * frequency
        return amplitude * w**order * np.sin(w * t + phase + order * np.pi / 2) + \
            (system.functions.defaults if order == 0 else 0.0)

    def x(t: float) -> np.ndarray:
        return pose_from_coordinates(system, theta(t))[:nb]

    def energy(t: float, h: float = 1e-5) -> float:
        xd = (x(t + h) - x(t - h)) / (2 * h)
        return 0.5 * xd @ M @ xd - g @ x(t)

    for t in (0.1, 0.37, 0.8):
        tau = coordinate_forces(system, theta(t)[None], theta(t, 1)[None], theta(t, 2)[None])[0]
        h = 1e-4  # central differences: truncation h²·E‴/6 ~ 1e-5 W here
        power = (energy(t + h) - energy(t - h)) / (2 * h)
        assert tau @ theta(t, 1) == pytest.approx(power, rel=1e-5, abs=1e-6)
        assert np.abs(tau).max() > 1.0  # the check is not of zeros


def read_storage(path: Path) -> tuple[list[str], np.ndarray]:
    lines = path.read_text().splitlines()
    end = next(k for k, line in enumerate(lines) if line.strip() == "endheader")
    rows = np.array([[float(v) for v in line.split()] for line in lines[end + 2:] if line.strip()])
    return lines[end + 1].split(), rows


@pytest.mark.skipif(not ID_DIR.is_dir(), reason="../shared/data/opensim not here")
def test_opensims_arm26_inverse_dynamics_within_its_tolerance():
    model = load_model(ID_DIR / "arm26.osim")
    system = compile_system(model, angles="coordinate")
    names, rows = read_storage(ID_DIR / "arm26_InverseKinematics.mot")  # degrees (its setup)
    time = rows[:, 0]
    order = [c.name for c in model.angles]
    theta = np.column_stack([np.radians(rows[:, names.index(n)]) for n in order])
    tau, smooth, rate, _ = forces_from_coordinates(system, time, theta, cutoff=6.0)
    # the rates are those of the filtered coordinates (a check of the spline, not of OpenSim)
    assert np.allclose(rate[1:-1], np.gradient(smooth, time, axis=0)[1:-1], atol=0.05)
    columns, reference = read_storage(ID_DIR / "std_arm26_InverseDynamics.sto")
    assert np.allclose(reference[:, 0], time, atol=1e-6)
    for k, name in enumerate(order):
        expected = reference[:, columns.index(f"{name}_moment")]
        rms = float(np.sqrt(np.mean((tau[:, k] - expected) ** 2)))
        assert rms < TOLERANCE, (name, rms)
        assert rms < 0.1 * np.abs(expected).max()  # far inside: 0.04 N·m of 2.8 N·m
