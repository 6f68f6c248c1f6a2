"""The mixed-coordinate (MC) method, NRM with LS and WLS, against independently known answers.

What is independent of the code under test:

* True angles and their rates are evaluated here from the prescribed motions in the model YAML
  (``θ = mean + Σ A sin(2π f t + φ)``, read with ``yaml.safe_load``) and compared with the
  synthesized truth before being used; the true markers are those of the angular-driver (AD)
  synthesis, a different system of equations (AR drivers, no tracking) from the MC one solved here.
* Tolerances: 1e-8 rad / 1e-8 m from exact markers (the solver's tolerance is 1e-10); 1e-6 through
  a C3D file, whose 32-bit floats round ~1.4 m in mm to ~6e-8 m, i.e. ~1e-6 rad over the 5 cm
  lever arms of the off-axis points; rate errors bounded by the Taylor remainders of the
  finite-difference stencils of the documented ``central_derivatives`` (derived below from the
  YAML amplitudes and frequencies).
* Perturbation properties are checked against docs/formulation.md §5 (max |noise| per axis = level,
  seeded, per-marker, band-limited), not against the output of ``perturb`` itself.
* Topological consistency of q̇, q̈ is checked row by row with the Jacobian and γ of the
  constraint library (docs/formulation.md §2), and determinacy in gaps from the model's joint types.

Package defect found (see ``test_skip_unsolvable_reports_frame``): ``solve_nrm`` with
``NrmSettings(skip_unsolvable=True)`` crashed with ``LinAlgError: Singular matrix`` as soon as a
frame was actually skipped, because the NaN coordinates of that frame are zeroed
(``np.nan_to_num``) before ``consistent_rates`` solves with their (all-zero, singular) Jacobian.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest
import yaml
from click.testing import CliRunner

from fccgrb_cli.cli.main import main
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import load_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.signals.artefact import perturb
from fccgrb_cli.solvers.initial import initial_guess, rigid_fit, rigid_fits
from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm
from fccgrb_cli.system import Drive, compile_system

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "configs" / "models"
RATE = 100.0
H = 1.0 / RATE
TOL = 1e-10
EXACT_TOL = 1e-8      # rad and m, exact markers
C3D_TOL = 1e-6        # rad and m, markers through 32-bit floats
WLS_WEIGHT = 1e-3
DEG = np.pi / 180.0


# --- independent truth from the YAML -----------------------------------------------------------

def spec(name: str) -> dict:
    return yaml.safe_load((MODELS / f"{name}.yaml").read_text(encoding="utf-8"))


def closed_form(name: str, t: np.ndarray) -> tuple[list[str], np.ndarray, np.ndarray, np.ndarray]:
    """Names and θ, θ̇, θ̈ (frames × angles, rad) of the YAML's prescribed motions (deg in file)."""
    doc = spec(name)
    assert doc["units"]["angle"] == "deg"
    names, th, thd, thdd = [], [], [], []
    for angle in doc["angles"]:
        m = angle["motion"]
        a0 = np.full_like(t, m["mean"] * DEG)
        a1, a2 = np.zeros_like(t), np.zeros_like(t)
        for term in m.get("terms", []):
            amp, w = term["amplitude"] * DEG, 2 * np.pi * term["frequency"]
            arg = w * t + term.get("phase", 0.0) * DEG
            a0 += amp * np.sin(arg)
            a1 += amp * w * np.cos(arg)
            a2 -= amp * w**2 * np.sin(arg)
        names.append(angle["name"])
        th.append(a0)
        thd.append(a1)
        thdd.append(a2)
    return names, np.column_stack(th), np.column_stack(thd), np.column_stack(thdd)


def derivative_bounds(name: str, order: int) -> np.ndarray:
    """Per angle, an upper bound of max_t |θ^(order)(t)|: Σ A ω^order (rad/s^order)."""
    out = []
    for angle in spec(name)["angles"]:
        out.append(sum(term["amplitude"] * DEG * (2 * np.pi * term["frequency"]) ** order
                       for term in angle["motion"].get("terms", [])))
    return np.array(out)


# --- shared fixtures ---------------------------------------------------------------------------

_SYNTH: dict[tuple[str, str, float], object] = {}


def synth(name: str, form: str = "full", duration: float = 3.0):
    """(model, synthesis) cached per module; the truth angles are checked against the YAML."""
    key = (name, form, duration)
    if key not in _SYNTH:
        model = load_model(MODELS / f"{name}.yaml").with_form(form)
        s = synthesize(model, duration=duration)
        names, th, thd, thdd = closed_form(name, s.result.time)
        assert tuple(names) == s.result.angle_names
        np.testing.assert_allclose(s.result.theta, th, rtol=0, atol=1e-12)
        np.testing.assert_allclose(s.result.theta_d, thd, rtol=0, atol=1e-10)
        np.testing.assert_allclose(s.result.theta_dd, thdd, rtol=0, atol=1e-8)
        assert s.markers.dtype == np.float64 and s.markers.shape[1:] == (len(s.labels), 3)
        _SYNTH[key] = (model, s)
    return _SYNTH[key]


def mc_system(model):
    return compile_system(model, angles="coordinate", track=True)


def model_points(system, model, q: np.ndarray) -> np.ndarray:
    which = [(tp.body, tp.point) for tp in model.tracked_points]
    return np.array([system.point_positions(qf, which) for qf in np.atleast_2d(q)])


def errors(system, model, result, theta_true, markers_true) -> tuple[float, float]:
    """Max |θ − θ_true| (rad) and max distance of model points to the true markers (m)."""
    angle = float(np.abs(result.theta - theta_true).max())
    points = model_points(system, model, result.q)
    dist = float(np.linalg.norm(points - markers_true, axis=2).max())
    return angle, dist


def assert_recovered(system, model, result, theta_true, markers_true, tol=EXACT_TOL):
    angle, dist = errors(system, model, result, theta_true, markers_true)
    assert angle < tol, f"max |θ − θ_true| = {angle:.3e} rad"
    assert dist < tol, f"max model point ↔ true marker = {dist:.3e} m"
    return angle, dist


# --- 1. recovery from exact markers ------------------------------------------------------------

@pytest.mark.parametrize("name", ["pendulum", "five_bar"])
@pytest.mark.parametrize("form", ["full", "reduced"])
@pytest.mark.parametrize("weight", [None, WLS_WEIGHT], ids=["LS", "WLS"])
def test_recovery_from_exact_markers(name, form, weight):
    # full 3 s trials for every case: each solve takes ~0.1 s
    model, s = synth(name, form)
    assert s.markers.shape[0] == 300
    system = mc_system(model)
    result = solve_nrm(system, s.result.time, s.markers,
                       NrmSettings(tracking_weight=weight, tol=TOL))
    assert result.converged.all(), result.messages
    assert result.method == ("nrm-ls" if weight is None else "nrm-wls")
    angle, dist = assert_recovered(system, model, result, s.result.theta, s.markers)
    # the solved angles are also the angles the solved body vectors make (MCR satisfied)
    np.testing.assert_allclose(np.array([system.angles_at(q) for q in result.q]),
                               result.theta, rtol=0, atol=EXACT_TOL)
    print(f"\n[in-memory] {name} {form} {'LS' if weight is None else 'WLS'}: "
          f"max dθ {angle:.2e} rad, max point {dist:.2e} m")


# --- 2. through a synthesized C3D file and the CLI ---------------------------------------------

RUN_ATTRS = ("method", "tol", "perturb_level_m", "perturb_markers", "perturb_seed",
             "tracking_weight", "warm_start", "hessian", "form")


def invoke(args: list[str]) -> str:
    out = CliRunner().invoke(main, args, catch_exceptions=False)
    assert out.exit_code == 0, out.output
    return out.output


@pytest.mark.parametrize("name", ["pendulum", "five_bar"])
def test_c3d_roundtrip_through_cli(name, tmp_path):
    model_file = str(MODELS / f"{name}.yaml")
    doc = spec(name)
    labels = [p["marker"] for p in doc["tracking"]["points"]]
    n_frames, n_markers, n_angles = 300, len(labels), len(doc["angles"])
    nq = 12 * len(doc["bodies"]) + n_angles   # full form in both YAML files
    assert doc["form"] == "full"
    c3d, h5 = tmp_path / "x.c3d", tmp_path / "r.h5"
    invoke(["synth", model_file, "-o", str(c3d)])

    import ezc3d  # the file really holds 32-bit floats in mm
    raw = ezc3d.c3d(str(c3d))
    assert raw["parameters"]["POINT"]["SCALE"]["value"][0] < 0
    assert raw["parameters"]["POINT"]["UNITS"]["value"] == ["mm"]
    read = np.transpose(raw["data"]["points"][:3], (2, 1, 0)) * 1e-3

    for method in ("nrm-wls", "nrm-ls"):
        invoke(["solve", model_file, str(c3d), "--method", method, "-o", str(h5)])

    _, theta_true, _, _ = closed_form(name, np.arange(n_frames) / RATE)
    with h5py.File(h5, "r") as f:
        for key in ("model", "command", "versions", "trial"):
            assert key in f.attrs, key
        assert f.attrs["model"] == (MODELS / f"{name}.yaml").read_text(encoding="utf-8")
        assert "numpy" in json.loads(f.attrs["versions"])
        ref = f["reference/markers"]
        assert ref.shape == (n_frames, n_markers, 3)
        assert [str(x) for x in ref.attrs["labels"]] == labels
        assert float(ref.attrs["rate"]) == RATE
        reference = ref[()]
        # the reference is the exact (double) truth; the C3D holds its float32 rounding
        float32_step = np.abs(reference).max() * 1e3 * 2.0**-24 * 1e-3
        assert 0 < np.abs(read - reference).max() <= float32_step
        truth = f["truth/theta"]
        assert truth.shape == (n_frames, n_angles)
        assert [str(x) for x in truth.attrs["names"]] == [a["name"] for a in doc["angles"]]
        np.testing.assert_allclose(truth[()], theta_true, rtol=0, atol=1e-12)
        assert set(f["runs"]) == {"nrm-wls", "nrm-ls"}
        for run in ("nrm-wls", "nrm-ls"):
            g = f[f"runs/{run}"]
            for key in RUN_ATTRS:
                assert key in g.attrs, (run, key)
            assert g.attrs["method"] == run
            assert float(g.attrs["tol"]) == TOL
            assert float(g.attrs["perturb_level_m"]) == 0.0
            assert len(g.attrs["perturb_markers"]) == 0
            assert int(g.attrs["perturb_seed"]) == 0
            weight = float(g.attrs["tracking_weight"])
            assert np.isnan(weight) if run == "nrm-ls" else weight == WLS_WEIGHT
            assert g.attrs["form"] == "full"
            shapes = {"q": (n_frames, nq), "qd": (n_frames, nq), "qdd": (n_frames, nq),
                      "theta": (n_frames, n_angles), "theta_d": (n_frames, n_angles),
                      "theta_dd": (n_frames, n_angles),
                      "model_points": (n_frames, n_markers, 3),
                      "markers_input": (n_frames, n_markers, 3),
                      "iterations": (n_frames,), "time_s": (n_frames,),
                      "phi_norm": (n_frames,), "phi_top_max": (n_frames,),
                      "converged": (n_frames,), "ed": (n_frames, n_markers),
                      "ed_input": (n_frames, n_markers)}
            for key, shape in shapes.items():
                assert g[key].shape == shape, (run, key, g[key].shape)
            for key in ("theta", "theta_d", "theta_dd"):
                assert [str(x) for x in g[key].attrs["names"]] == list(truth.attrs["names"])
            assert g["converged"][()].all()
            points, inputs = g["model_points"][()], g["markers_input"][()]
            np.testing.assert_allclose(inputs, read, rtol=0, atol=1e-12)
            np.testing.assert_allclose(g["ed"][()], np.linalg.norm(points - reference, axis=2),
                                       rtol=0, atol=1e-15)
            np.testing.assert_allclose(g["ed_input"][()], np.linalg.norm(points - inputs, axis=2),
                                       rtol=0, atol=1e-15)
            np.testing.assert_array_equal(g["q"][:, nq - n_angles:], g["theta"][()])
            angle = float(np.abs(g["theta"][()] - theta_true).max())
            dist = float(np.linalg.norm(points - reference, axis=2).max())
            print(f"\n[C3D] {name} {run}: max dθ {angle:.2e} rad, max point {dist:.2e} m")
            assert angle < C3D_TOL, (run, angle)
            assert dist < C3D_TOL, (run, dist)


def test_cli_perturbation_attributes(tmp_path):
    """--perturb/--perturb-markers/--seed reach the solver and the run attributes."""
    model_file = str(MODELS / "pendulum.yaml")
    c3d, h5 = tmp_path / "x.c3d", tmp_path / "r.h5"
    invoke(["synth", model_file, "-o", str(c3d), "--duration", "1"])
    invoke(["solve", model_file, str(c3d), "--method", "nrm-ls", "-o", str(h5)])
    invoke(["solve", model_file, str(c3d), "--perturb", "7.5", "--perturb-markers", "P3",
            "--seed", "4", "-o", str(h5)])
    with h5py.File(h5, "r") as f:
        assert set(f["runs"]) == {"nrm-ls", "nrm-wls-P7.5-P3"}
        g = f["runs/nrm-wls-P7.5-P3"]
        assert float(g.attrs["perturb_level_m"]) == 0.0075
        assert [str(x) for x in g.attrs["perturb_markers"]] == ["P3"]
        assert int(g.attrs["perturb_seed"]) == 4
        clean, noisy = f["runs/nrm-ls/markers_input"][()], g["markers_input"][()]
        np.testing.assert_array_equal(noisy[:, :2], clean[:, :2])
        noise = noisy[:, 2] - clean[:, 2]
        np.testing.assert_allclose(np.abs(noise).max(axis=0), 0.0075, rtol=0, atol=1e-12)


# --- 3. the paper's WLS finding at 30 mm -------------------------------------------------------

def test_wls_keeps_topology_far_better_than_ls_at_30mm():
    model, s = synth("five_bar")
    noisy = perturb(s.markers, s.labels, s.rate, 0.03, seed=0)
    system = mc_system(model)
    worst = {}
    top, tracking = system.masks()["topology"], system.masks()["tracking"]
    for label, weight in (("LS", None), ("WLS", WLS_WEIGHT)):
        result = solve_nrm(system, s.result.time, noisy,
                           NrmSettings(tracking_weight=weight, tol=TOL))
        assert result.converged.all(), (label, result.messages)
        # each frame is the minimum of ½ΦᵀWΦ with W built here (1 on topological rows, the
        # tracking weight on tracking rows): Φ_qᵀWΦ = 0 to 1e-10 relative (measured ~1e-12),
        # and the reported violation is the solution's own, recomputed from q (to the rounding
        # of the unit-size terms it is a difference of: the compiled kernels sum in another
        # order than numpy)
        W = np.where(tracking, 1.0 if weight is None else weight, 1.0)
        stationarity, violation = 0.0, np.empty(len(result.q))
        for f, (q, y) in enumerate(zip(result.q, noisy, strict=True)):
            phi, J = system.residual(q, Drive(ref=y)), system.jacobian(q)
            stationarity = max(stationarity, float(np.linalg.norm(J.T @ (W * phi))
                                                   / (np.linalg.norm(J) * np.linalg.norm(W * phi))))
            violation[f] = np.abs(phi[top]).max()
        assert stationarity <= 1e-10, (label, stationarity)
        np.testing.assert_allclose(result.phi_top_max, violation, rtol=1e-12, atol=1e-15)
        worst[label] = float(result.phi_top_max.max())
    ratio = worst["LS"] / worst["WLS"]
    print(f"\n[P30] max |Φ_top| LS {worst['LS']:.3e}, WLS {worst['WLS']:.3e}, ratio {ratio:.1f}")
    assert ratio >= 10.0, worst


# --- 4. perturbation properties (docs/formulation.md §5) ------------------------------------

def hann_power(x: np.ndarray, rate: float) -> tuple[np.ndarray, np.ndarray]:
    P = np.abs(np.fft.rfft(x * np.hanning(len(x)))) ** 2
    return np.fft.rfftfreq(len(x), 1.0 / rate), P


def test_perturbation_level_seed_and_subset():
    _, s = synth("five_bar")
    markers, labels = s.markers, s.labels
    before = markers.copy()
    level = 0.03
    out = perturb(markers, labels, RATE, level, seed=0)
    np.testing.assert_array_equal(markers, before)          # input untouched
    assert out is not markers
    noise = out - markers
    # every marker and axis: max |noise| equals the level
    np.testing.assert_allclose(np.abs(noise).max(axis=0), level, rtol=0, atol=1e-12)
    # exactly, on a zero array (no rounding from the addition)
    zero = np.zeros_like(markers)
    pure = perturb(zero, labels, RATE, 0.0075, seed=2)
    np.testing.assert_allclose(np.abs(pure).max(axis=0), 0.0075, rtol=0, atol=1e-15)
    # seeded: same seed identical, other seed different (for every marker)
    np.testing.assert_array_equal(perturb(markers, labels, RATE, level, seed=0), out)
    other = perturb(markers, labels, RATE, level, seed=1)
    assert (np.abs(other - out).max(axis=(0, 2)) > 1e-3).all()
    # different markers get different noise
    assert np.abs(noise[:, 0] - noise[:, 1]).max() > 1e-3
    # level 0 is the identity
    np.testing.assert_array_equal(perturb(markers, labels, RATE, 0.0, seed=0), markers)
    # a subset: other markers bit-identical, subset noise as when all are perturbed
    subset = ("P4", "P9")
    part = perturb(markers, labels, RATE, level, seed=0, only=subset)
    np.testing.assert_array_equal(markers, before)
    for k, label in enumerate(labels):
        if label in subset:
            np.testing.assert_array_equal(part[:, k], out[:, k])
        else:
            np.testing.assert_array_equal(part[:, k], markers[:, k])
    # the noise depends on the label, not on the marker's position in the array
    order = [labels.index(x) for x in reversed(labels)]
    swapped = perturb(markers[:, order], tuple(reversed(labels)), RATE, level, seed=0)
    np.testing.assert_array_equal(swapped, out[:, order])


def test_perturbation_spectrum_in_movement_band():
    """The artefact is a sum of sinusoids in the movement band (0.3–3 Hz, perturb's docstring).

    Bound for a 3 s, 100 Hz trial: DFT bins are 1/3 Hz apart, so the first bin above 3.5 Hz is
    11/3 = 3.67 Hz, at least 2 bins from any component (≤ 3.0 Hz). Without a window a component
    ~1.5 bins off a bin leaks ~10 % of its power beyond 3.5 Hz (sidelobes ∝ 1/δ²), so a plain FFT
    cannot support a 1 % bound. With a Hann window 2 bins is the edge of the main lobe and the
    sidelobes fall as 1/δ⁶: a single sinusoid anywhere in 0.3–3 Hz puts < 0.06 % of its power
    above 3.5 Hz (computed below). 1 % leaves a factor ~20 for interference between the four
    components. On a 60 s trial (bins 1/60 Hz) the band edges are resolved: < 1e-4 of the power
    lies outside 0.2–3.2 Hz.
    """
    t = np.arange(300) / RATE
    single = 0.0
    for f0 in np.linspace(0.3, 3.0, 28):
        for phase in (0.0, 1.0, 2.0):
            f, P = hann_power(np.sin(2 * np.pi * f0 * t + phase), RATE)
            single = max(single, P[f > 3.5].sum() / P.sum())
    assert single < 1e-3       # the bound's premise
    labels = tuple(f"P{k}" for k in range(1, 10))
    for n_frames, low, high, bound in ((300, 0.0, 3.5, 1e-2), (6000, 0.2, 3.2, 1e-4)):
        worst = 0.0
        for seed in range(3):
            noise = perturb(np.zeros((n_frames, len(labels), 3)), labels, RATE, 0.03, seed=seed)
            for k in range(len(labels)):
                for axis in range(3):
                    f, P = hann_power(noise[:, k, axis], RATE)
                    worst = max(worst, P[(f < low) | (f > high)].sum() / P.sum())
        print(f"\n[spectrum] {n_frames} frames: worst power outside {low}-{high} Hz {worst:.1e}")
        assert worst < bound, (n_frames, worst)


# --- 5. velocities and accelerations -----------------------------------------------------------

def test_rates_against_closed_form_and_topology():
    """θ̇, θ̈ of the MC solution vs the closed form, and Φ_q,top q̇ = 0, Φ_q,top q̈ = γ_top.

    With θ exact, the documented stencils err by (Taylor, Lagrange remainder, h = 0.01 s):
    inside, (θ₊ − θ₋)/2h − θ' = h²/6 θ'''(ξ) and (θ₊ − 2θ + θ₋)/h² − θ'' = h²/12 θ''''(ξ);
    at the ends, (−3θ₀ + 4θ₁ − θ₂)/2h errs by h²/3 (θ'''(ξ₁) − 2θ'''(ξ₂)) ≤ h² M3 and
    (2θ₀ − 5θ₁ + 4θ₂ − θ₃)/h² by ≤ (5 + 4·16 + 81)/24 h² M4 = 6.25 h² M4, with
    M_k = Σ A ω^k ≥ max|θ^(k)|. The worst five-bar angle (J5_w: 25° at 0.9 Hz + 5° at 2.5 Hz)
    gives M3 ≈ 417 rad/s³, M4 ≈ 5.8e3 rad/s⁴: bounds 7.0e-3 rad/s and 4.8e-2 rad/s² inside.
    A position error ε adds at most ε/h and 4ε/h² inside, 4ε/h and 12ε/h² at the ends (sums of
    the stencils' |coefficients|); ε is measured and added. The measured interior errors reach
    99.9 % of these bounds: the error is the stencils' truncation, nothing else.
    """
    model, s = synth("five_bar")
    system = mc_system(model)
    result = solve_nrm(system, s.result.time, s.markers,
                       NrmSettings(tracking_weight=WLS_WEIGHT, tol=TOL))
    assert result.converged.all()
    m3, m4 = derivative_bounds("five_bar", 3), derivative_bounds("five_bar", 4)
    assert m3.max() < 420 and m4.max() < 5.8e3
    ev = np.abs(result.theta_d - s.result.theta_d)
    ea = np.abs(result.theta_dd - s.result.theta_dd)
    eps = float(np.abs(result.theta - s.result.theta).max()) + 1e-15
    assert eps < 1e-12
    inner = slice(1, -1)
    assert (ev[inner] <= H**2 / 6 * m3 + eps / H).all(), ev[inner].max(axis=0)
    assert (ea[inner] <= H**2 / 12 * m4 + 4 * eps / H**2).all(), ea[inner].max(axis=0)
    ends = [0, -1]
    assert (ev[ends] <= H**2 * m3 + 4 * eps / H).all(), ev[ends]
    assert (ea[ends] <= 6.25 * H**2 * m4 + 12 * eps / H**2).all(), ea[ends]
    print(f"\n[rates] max |dθ̇| inside {ev[inner].max():.2e} rad/s "
          f"(bound {(H**2 / 6 * m3).max():.2e}), ends {ev[ends].max():.2e}; "
          f"max |dθ̈| inside {ea[inner].max():.2e} rad/s² "
          f"(bound {(H**2 / 12 * m4).max():.2e}), ends {ea[ends].max():.2e}")

    nb = system.layout.n_body_q
    np.testing.assert_array_equal(result.qd[:, nb:], result.theta_d)
    np.testing.assert_array_equal(result.qdd[:, nb:], result.theta_dd)
    top = system.masks()["topology"]
    assert top.sum() > 0
    worst_v = worst_a = 0.0
    for q, qd, qdd in zip(result.q, result.qd, result.qdd, strict=True):
        J = system.jacobian(q)[top]
        worst_v = max(worst_v, float(np.abs(J @ qd).max()))
        gamma = system.gamma(q, qd, Drive())[top]
        worst_a = max(worst_a, float(np.abs(J @ qdd - gamma).max()))
    print(f"[rates] max |Φ_q,top q̇| {worst_v:.1e}, max |Φ_q,top q̈ − γ_top| {worst_a:.1e}")
    assert worst_v < 1e-9 and worst_a < 1e-9


# --- 6. first-frame initializer and rigid fit --------------------------------------------------

@pytest.mark.parametrize("first", [0, 75, 150, 225])
def test_initial_guess_leads_to_truth(first):
    model, s = synth("five_bar")
    system = mc_system(model)
    guess = initial_guess(system, s.markers[first])
    assert guess.shape == (system.nq,) and np.isfinite(guess).all()
    window = slice(first, first + 1)
    result = solve_nrm(system, s.result.time[window], s.markers[window],
                       NrmSettings(tracking_weight=WLS_WEIGHT, tol=TOL))
    assert result.converged.all(), result.messages
    assert_recovered(system, model, result, s.result.theta[window], s.markers[window])
    nb = system.layout.n_body_q
    print(f"\n[initial] frame {first}: guess max dθ "
          f"{np.degrees(np.abs(guess[nb:] - s.result.theta[first]).max()):.2f} deg, "
          f"{result.iterations[0]} iterations")


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


@pytest.mark.parametrize("n_points", [3, 4, 7])
def test_rigid_fit_recovers_known_motion(n_points):
    rng = np.random.default_rng(n_points)
    R_true, r_true = random_rotation(rng), rng.normal(scale=2.0, size=3)
    local = rng.normal(scale=0.3, size=(n_points, 3))
    if n_points == 4:
        local[:, 2] = 0.0   # coplanar: the SVD's third direction is free, det must fix it
    assert np.linalg.matrix_rank(local - local.mean(axis=0)) >= 2
    world = local @ R_true.T + r_true
    R, r = rigid_fit(local, world)
    np.testing.assert_allclose(R, R_true, rtol=0, atol=1e-12)
    np.testing.assert_allclose(r, r_true, rtol=0, atol=1e-12)
    assert abs(np.linalg.det(R) - 1.0) < 1e-12


def test_rigid_fits_equal_rigid_fit_frame_by_frame():
    """Many frames at once (the lab axes' marker cue), each the single fit's rotation: noisy
    points, coplanar ones (det fixes the SVD's free direction) and a mirrored cloud (the best
    proper rotation, not the reflection)."""
    rng = np.random.default_rng(7)
    for local in (rng.normal(scale=0.3, size=(5, 3)),
                  np.column_stack([rng.normal(scale=0.3, size=(4, 2)), np.zeros(4)])):
        frames = [local @ random_rotation(rng).T + rng.normal(size=3)
                  + rng.normal(scale=0.01, size=local.shape) for _ in range(6)]
        frames.append(local * np.array([1.0, 1.0, -1.0]))  # a mirror image
        many = rigid_fits(local, np.array(frames))
        for world, R in zip(frames, many, strict=True):
            np.testing.assert_allclose(R, rigid_fit(local, world)[0], rtol=0, atol=1e-12)
            assert abs(np.linalg.det(R) - 1.0) < 1e-12


# --- 7. gaps -----------------------------------------------------------------------------------

def test_gap_that_leaves_model_determined():
    """P1 sits on the fixed joint point O (redundant); B3 (P3, P4, P7) turns about one revolute,
    fixed by P4 alone: dropping P1 or P7 for a few frames leaves the model determined."""
    model, s = synth("five_bar", duration=1.0)
    labels = model.marker_labels
    y = s.markers.copy()
    gaps = {"P1": range(20, 25), "P7": range(50, 54)}
    for label, frames in gaps.items():
        y[list(frames), labels.index(label)] = np.nan
    system = mc_system(model)
    for weight in (None, WLS_WEIGHT):
        result = solve_nrm(system, s.result.time, y, NrmSettings(tracking_weight=weight, tol=TOL),
                           labels=labels)
        assert result.converged.all(), result.messages
        assert not result.messages
        assert_recovered(system, model, result, s.result.theta, s.markers)
        # the gap frames themselves, explicitly
        for frames in gaps.values():
            f = list(frames)
            assert np.abs(result.theta[f] - s.result.theta[f]).max() < EXACT_TOL
            # ‖Φ‖ over the equations left: ~0 on exact markers; the missing marker's rows
            # (target zeroed, ~1 m away) are not among them
            assert (result.phi_norm[f] < EXACT_TOL).all(), result.phi_norm[f]


GAP_FRAME = 60


def undetermined_trial():
    """B5 (universal joint to B4: 2 dof) carries P6 only; without it B5's direction is free.
    P9 (on B2, whose roll its universal joint fixes anyway) goes missing too."""
    model, s = synth("five_bar", duration=1.0)
    labels = model.marker_labels
    y = s.markers.copy()
    y[GAP_FRAME, [labels.index("P6"), labels.index("P9")]] = np.nan
    return model, s, y


def test_undetermined_frame_raises_input_error():
    model, s, y = undetermined_trial()
    system = mc_system(model)
    with pytest.raises(InputError) as info:
        solve_nrm(system, s.result.time, y, NrmSettings(tol=TOL), labels=model.marker_labels)
    text = str(info.value)
    assert f"frame index {GAP_FRAME}" in text
    assert "P6" in text and "P9" in text
    assert "P5" not in text and "P7" not in text
    # P6 alone fixes B5's 2 dof, so restoring it is enough; restoring P9 is not
    z = y.copy()
    k = model.marker_labels.index("P6")
    z[GAP_FRAME, k] = s.markers[GAP_FRAME, k]
    result = solve_nrm(system, s.result.time, z, NrmSettings(tol=TOL), labels=model.marker_labels)
    assert result.converged.all()
    assert_recovered(system, model, result, s.result.theta, s.markers)
    z = y.copy()
    k = model.marker_labels.index("P9")
    z[GAP_FRAME, k] = s.markers[GAP_FRAME, k]
    with pytest.raises(InputError, match="missing: P6\\)"):
        solve_nrm(system, s.result.time, z, NrmSettings(tol=TOL), labels=model.marker_labels)


def check_skipped(model, s, result):
    system = mc_system(model)
    assert any(f"frame index {GAP_FRAME}" in m and "P6" in m and "P9" in m
               for m in result.messages)
    assert np.isnan(result.q[GAP_FRAME]).all()
    assert not result.converged[GAP_FRAME]
    others = np.delete(np.arange(len(s.result.time)), GAP_FRAME)
    assert result.converged[others].all()
    theta = result.theta[others]
    assert np.abs(theta - s.result.theta[others]).max() < EXACT_TOL
    points = model_points(system, model, result.q[others])
    assert np.linalg.norm(points - s.markers[others], axis=2).max() < EXACT_TOL


def test_skip_unsolvable_reports_frame():
    """The skipped frame is reported and NaN (rates too, where its neighbours' differences need
    it); every other frame is solved. Once a LinAlgError in the rates step (regression)."""
    model, s, y = undetermined_trial()
    result = solve_nrm(mc_system(model), s.result.time, y,
                       NrmSettings(tol=TOL, skip_unsolvable=True), labels=model.marker_labels)
    check_skipped(model, s, result)
    assert np.isnan(result.qd[GAP_FRAME]).all()
    # away from the gap the rates are the closed form's, to the stencils' truncation (the
    # bounds of test_rates_against_closed_form_and_topology; frames beside the gap difference
    # across it centrally, the trial's two ends one-sidedly)
    n = len(s.result.time)
    far = [f for f in range(n) if abs(f - GAP_FRAME) > 1]
    m3, m4 = derivative_bounds("five_bar", 3), derivative_bounds("five_bar", 4)
    eps = float(np.abs(result.theta[far] - s.result.theta[far]).max()) + 1e-15
    ev = np.abs(result.theta_d - s.result.theta_d)
    ea = np.abs(result.theta_dd - s.result.theta_dd)
    inner = [f for f in far if 0 < f < n - 1]
    assert (ev[inner] <= H**2 / 6 * m3 + eps / H).all(), ev[inner].max(axis=0)
    assert (ea[inner] <= H**2 / 12 * m4 + 4 * eps / H**2).all(), ea[inner].max(axis=0)
    assert (ev[[0, -1]] <= H**2 * m3 + 4 * eps / H).all()
    assert (ea[[0, -1]] <= 6.25 * H**2 * m4 + 12 * eps / H**2).all()
    nb = mc_system(model).layout.n_body_q
    np.testing.assert_array_equal(result.qd[far, nb:], result.theta_d[far])
    np.testing.assert_array_equal(result.qdd[far, nb:], result.theta_dd[far])


# --- 8. guard against a vacuous check ----------------------------------------------------------

def test_wrong_target_fails_the_point_check():
    model, s = synth("five_bar", duration=1.0)
    system = mc_system(model)
    wrong = s.markers.copy()
    wrong[:, model.marker_labels.index("P6"), 0] += 1e-3
    for weight in (None, WLS_WEIGHT):
        result = solve_nrm(system, s.result.time, wrong,
                           NrmSettings(tracking_weight=weight, tol=TOL))
        assert result.converged.all()
        angle, dist = errors(system, model, result, s.result.theta, s.markers)
        assert dist > 1e-5 and angle > 1e-5, (angle, dist)
        with pytest.raises(AssertionError):
            assert_recovered(system, model, result, s.result.theta, s.markers)
    # and the same check passes on the right targets
    result = solve_nrm(system, s.result.time, s.markers, NrmSettings(tol=TOL))
    assert_recovered(system, model, result, s.result.theta, s.markers)
