"""Synthesized pendulum markers against an independent forward kinematics.

What is independent: the expected marker positions are computed here from the prescribed angle
motions in ``configs/models/pendulum.yaml`` (read with ``yaml.safe_load``, evaluated by this
file) with elementary rotation matrices composed along the chain,

    R1 = Rx(α) Ry(β),   R2 = R1 Rx(γ) Ry(δ),   α, β, γ, δ = θ1..θ4 − 90°,

and the joint points placed by hand (A of link1 at O, C of link2 at P1 of link1). Only lengths,
local coordinates and motion parameters come from the YAML; none of the package's model
loading, constraint equations, compiled system or solver is used for the expectation. The
package (``synthesize`` and the ``fccgrb synth`` command) only produces the thing under test.

The same file also checks, independently of the FK, that this parametrisation reproduces the
YAML's angle definitions (cos θ = s1·s2) and its universal-joint axes (s1·s2 = 0).
"""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from fccgrb_cli.cli.main import main
from fccgrb_cli.model import load_model
from fccgrb_cli.pipeline.synth import synthesize

ROOT = Path(__file__).parents[1]
MODEL_PATH = ROOT / "configs" / "models" / "pendulum.yaml"
DURATION, RATE = 3.0, 100.0
N_FRAMES = 300
LABELS = ["P1", "P2", "P3"]
UNIT_SCALE = {"mm": 1e-3, "m": 1.0}  # metres per file unit

SPEC = yaml.safe_load(MODEL_PATH.read_text(encoding="utf-8"))
ANGLE_ORDER = ["shoulder_x", "shoulder_y", "elbow_x", "elbow_y"]


# --- independent kinematics --------------------------------------------------------------------

def rot_x(a: np.ndarray) -> np.ndarray:
    """Rotation matrices about x, shape (..., 3, 3), for angles ``a`` in radians."""
    c, s = np.cos(a), np.sin(a)
    one, zero = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([one, zero, zero], -1),
                     np.stack([zero, c, -s], -1),
                     np.stack([zero, s, c], -1)], -2)


def rot_y(a: np.ndarray) -> np.ndarray:
    """Rotation matrices about y, shape (..., 3, 3), for angles ``a`` in radians."""
    c, s = np.cos(a), np.sin(a)
    one, zero = np.ones_like(a), np.zeros_like(a)
    return np.stack([np.stack([c, zero, s], -1),
                     np.stack([zero, one, zero], -1),
                     np.stack([-s, zero, c], -1)], -2)


def local(body: str, point: str, spec: dict = SPEC) -> np.ndarray:
    return np.array(spec["bodies"][body]["points"][point], dtype=float)


def frame_times() -> np.ndarray:
    return np.arange(N_FRAMES) / RATE


def true_angles(time: np.ndarray) -> np.ndarray:
    """θ(t) = mean + Σ amplitude·sin(2π f t + phase) from the YAML, in radians (frames × 4)."""
    assert SPEC["units"]["angle"] == "deg"
    by_name = {a["name"]: a for a in SPEC["angles"]}
    assert [a["name"] for a in SPEC["angles"]] == ANGLE_ORDER
    columns = []
    for name in ANGLE_ORDER:
        motion = by_name[name]["motion"]
        deg = np.full_like(time, float(motion["mean"]))
        for term in motion["terms"]:
            deg = deg + term["amplitude"] * np.sin(
                2 * np.pi * term["frequency"] * time + np.radians(term.get("phase", 0.0)))
        columns.append(np.radians(deg))
    return np.column_stack(columns)


def rotations(theta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Body rotation matrices R1, R2 (frames × 3 × 3); columns are u, v, w."""
    alpha, beta, gamma, delta = (theta - np.pi / 2).T
    r1 = rot_x(alpha) @ rot_y(beta)
    r2 = r1 @ rot_x(gamma) @ rot_y(delta)
    return r1, r2


def forward_kinematics(theta: np.ndarray, spec: dict = SPEC) -> np.ndarray:
    """Marker positions P1, P2, P3 (frames × 3 × 3, metres) for angles ``theta`` (radians)."""
    r1_rot, r2_rot = rotations(theta)
    origin = np.array(spec["ground"]["points"]["O"], dtype=float)
    r1 = origin - r1_rot @ local("link1", "A", spec)
    elbow = r1 + r1_rot @ local("link1", "P1", spec)
    r2 = elbow - r2_rot @ local("link2", "C", spec)
    positions = {
        ("link1", "P1"): elbow,
        ("link2", "P2"): r2 + r2_rot @ local("link2", "P2", spec),
        ("link2", "P3"): r2 + r2_rot @ local("link2", "P3", spec),
    }
    tracked = spec["tracking"]["points"]
    assert [t["marker"] for t in tracked] == LABELS
    return np.stack([positions[tuple(t["point"].split("."))] for t in tracked], axis=1)


# --- fixtures ----------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def expected() -> np.ndarray:
    return forward_kinematics(true_angles(frame_times()))


@pytest.fixture(scope="module", params=["full", "reduced"])
def synthesis(request):
    model = load_model(str(MODEL_PATH)).with_form(request.param)
    return synthesize(model, duration=DURATION, rate=RATE)


# --- the FK matches the model's definitions ----------------------------------------------------

def test_yaml_geometry_is_as_assumed():
    joints = {j["name"]: j for j in SPEC["joints"]}
    assert joints["shoulder"]["bodies"] == ["ground", "link1"]
    assert joints["shoulder"]["points"] == ["O", "A"]
    assert joints["shoulder"]["type"] == "universal"
    assert joints["elbow"]["bodies"] == ["link1", "link2"]
    assert joints["elbow"]["points"] == ["P1", "C"]
    assert joints["elbow"]["type"] == "universal"
    assert [t["point"] for t in SPEC["tracking"]["points"]] == [
        "link1.P1", "link2.P2", "link2.P3"]
    # the YAML's neutral pose: identity frames with the joint points coinciding
    for body in ("link1", "link2"):
        pose = SPEC["bodies"][body]["pose"]
        np.testing.assert_array_equal(np.column_stack([pose["u"], pose["v"], pose["w"]]),
                                      np.eye(3))
    r1 = np.array(SPEC["bodies"]["link1"]["pose"]["r"], dtype=float)
    r2 = np.array(SPEC["bodies"]["link2"]["pose"]["r"], dtype=float)
    np.testing.assert_allclose(r1 + local("link1", "A"), SPEC["ground"]["points"]["O"])
    np.testing.assert_allclose(r2 + local("link2", "C"), r1 + local("link1", "P1"))
    # ... which is what the FK gives at θ = 90° for all four angles
    neutral = forward_kinematics(np.full((1, 4), np.pi / 2))[0]
    np.testing.assert_allclose(neutral, [r1 + local("link1", "P1"),
                                         r2 + local("link2", "P2"),
                                         r2 + local("link2", "P3")], atol=1e-15)


def _vector(spec_ref: str, r1: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """Global components (frames × 3) of a YAML vector reference such as ``link1.minus_w``."""
    body, name = spec_ref.split(".")
    builtin = {"x": [1, 0, 0], "y": [0, 1, 0], "z": [0, 0, 1],
               "u": [1, 0, 0], "v": [0, 1, 0], "w": [0, 0, 1]}
    if body == "ground":
        vec = np.array(SPEC["ground"]["vectors"].get(name, builtin.get(name)), dtype=float)
        return np.broadcast_to(vec, (r1.shape[0], 3))
    vec = np.array(SPEC["bodies"][body].get("vectors", {}).get(name, builtin.get(name)),
                   dtype=float)
    return {"link1": r1, "link2": r2}[body] @ vec


def test_fk_reproduces_yaml_angle_and_joint_definitions():
    theta = true_angles(frame_times())
    r1, r2 = rotations(theta)
    # rotation matrices are proper orthonormal
    for rot in (r1, r2):
        np.testing.assert_allclose(rot @ np.swapaxes(rot, -1, -2), np.broadcast_to(
            np.eye(3), rot.shape), atol=1e-14)
        np.testing.assert_allclose(np.linalg.det(rot), 1.0, atol=1e-14)
    # angles: cos θ = s1·s2 with the YAML's vector pairs
    for k, angle in enumerate(SPEC["angles"]):
        s1, s2 = (_vector(ref, r1, r2) for ref in angle["vectors"])
        np.testing.assert_allclose(np.einsum("ij,ij->i", s1, s2), np.cos(theta[:, k]),
                                   atol=1e-14, err_msg=angle["name"])
    # universal joints: the two axes stay perpendicular
    for joint in SPEC["joints"]:
        refs = [f"{b}.{a}" for b, a in zip(joint["bodies"], joint["axes"], strict=True)]
        s1, s2 = (_vector(ref, r1, r2) for ref in refs)
        np.testing.assert_allclose(np.einsum("ij,ij->i", s1, s2), 0.0, atol=1e-14,
                                   err_msg=joint["name"])


# --- the package against the FK ----------------------------------------------------------------

def test_result_theta_matches_yaml_motion(synthesis):
    r = synthesis.result
    np.testing.assert_allclose(r.time, frame_times(), rtol=0, atol=1e-15)
    assert r.theta.shape == (N_FRAMES, 4)
    np.testing.assert_allclose(r.theta, true_angles(frame_times()), rtol=0, atol=1e-12)


def test_in_memory_markers_match_independent_fk(synthesis, expected):
    assert tuple(synthesis.labels) == tuple(LABELS)
    assert synthesis.markers.shape == (N_FRAMES, 3, 3)
    assert synthesis.markers.dtype == np.float64
    error = np.abs(synthesis.markers - expected).max()
    print(f"in-memory max |markers - FK| = {error:.3e} m")
    assert error < 1e-9


@pytest.mark.parametrize(("form", "units"),
                         [("full", "mm"), ("reduced", "mm"), ("full", "m"), ("reduced", "m")])
def test_c3d_from_cli_matches_independent_fk(tmp_path, expected, form, units):
    out = tmp_path / f"pendulum_{form}_{units}.c3d"
    result = CliRunner().invoke(main, ["synth", str(MODEL_PATH), "-o", str(out),
                                       "--form", form, "--units", units])
    assert result.exit_code == 0, result.output
    assert out.is_file()
    assert (tmp_path / f"pendulum_{form}_{units}.truth.h5").is_file()

    c = ezc3d.c3d(str(out))
    point = c["parameters"]["POINT"]
    assert point["UNITS"]["value"][0].strip() == units
    assert point["RATE"]["value"][0] == pytest.approx(RATE)
    assert [label.strip() for label in point["LABELS"]["value"]] == LABELS
    data = c["data"]["points"]
    assert data.shape == (4, 3, N_FRAMES)
    # (xyz, markers, frames) → (frames, markers, xyz); 3 markers × 3 axes: the order matters
    markers = np.transpose(data[:3], (2, 1, 0)) * UNIT_SCALE[units]
    error = np.abs(markers - expected).max()
    print(f"C3D ({form}, {units}) max |markers - FK| = {error:.3e} m")
    assert error < 1e-6


# --- the comparison can fail -------------------------------------------------------------------

@pytest.mark.parametrize("k", range(4))
def test_fk_is_sensitive_to_a_microradian(expected, k):
    theta = true_angles(frame_times())
    theta[:, k] += 1e-6
    assert np.abs(forward_kinematics(theta) - expected).max() > 1e-8


def test_fk_is_sensitive_to_a_micrometre_geometry_change(expected):
    spec = yaml.safe_load(MODEL_PATH.read_text(encoding="utf-8"))
    spec["bodies"]["link2"]["points"]["C"][2] += 1e-6
    shifted = forward_kinematics(true_angles(frame_times()), spec)
    assert np.abs(shifted - expected).max() > 1e-8
