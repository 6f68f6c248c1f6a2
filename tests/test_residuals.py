"""Residuals and their reduction (docs/formulation.md §14), against computations written here.

* The rigid-motion residual of a whole floating group (``dynamics.residuals``, from K matrices)
  against Newton–Euler for each body (tests/synthetic_body.py: Σ m (a_G − g), Σ r_G × m (a_G −
  g) + I α + ω × I ω) on a synthesized whole body, and against the engine's multipliers.
* The inertia fit on a synthetic whole body (open chains) and on a barbell held in both hands
  (configs/models/barbell_curl.yaml, a closed chain), every segment's mass off by 20 %, the
  ground reaction from Newton–Euler plus white noise: every mass back within 5 %, the residual
  down to the noise's own level (the true model's residual with the same noise).
* The kinematic correction on the whole body moved off its trajectory by a known rigid
  translation: the correction is that translation, back, and the residual falls to nothing.
* On the Qualisys walking trial (skipped without ../shared/data): the frames where a foot
  touches the ground off the plates are not measured, and after the reduction the
  residual, masses and marker misfit meet the targets of the last test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli
from synthetic_body import full_body_text, newton_euler, wrench_load

from fccgrb_cli.dynamics import residuals as R
from fccgrb_cli.dynamics.inertia_fit import fit_inertia
from fccgrb_cli.dynamics.kinematic_correction import CorrectionData, correction_step
from fccgrb_cli.dynamics.mass import mass_blocks
from fccgrb_cli.model import load_model, parse_model
from fccgrb_cli.pipeline.synth import synthesize
from fccgrb_cli.system import compile_system

ROOT = Path(__file__).resolve().parents[1]
BARBELL = ROOT / "configs" / "models" / "barbell_curl.yaml"
QUALISYS = ROOT / ".." / "shared" / "data" / "c3d" / "Qualisys.c3d"
NOISE_FORCE, NOISE_MOMENT = 0.5, 0.25  # N, N·m: white noise on the synthetic ground reaction
RATE = 50.0  # Hz: the motion is exact (synthesized), so a low rate samples more of it per frame


class Case:
    """A synthesized model, its motion, the Newton–Euler wrench as a load on a foot, and the
    same load with seeded white noise."""

    def __init__(self, model, duration: float) -> None:
        self.model = model
        s = synthesize(model, duration=duration, rate=RATE)
        self.result = s.result
        self.markers = s.markers
        system = compile_system(model, angles="driver")
        r = s.result
        self.motion = R.BodyMotion.of(system, r.q, r.qd, r.qdd)
        self.force, self.moment = newton_euler(model, r.q, r.qd, r.qdd)
        foot = self.motion.X[:, self.motion.index("foot_r"), :, 0]
        self.load = wrench_load("foot_r", foot, self.force, self.moment)
        rng = np.random.default_rng(5)
        self.noisy = wrench_load("foot_r", foot,
                                 self.force + rng.normal(0, NOISE_FORCE, self.force.shape),
                                 self.moment + rng.normal(0, NOISE_MOMENT, self.moment.shape))


@pytest.fixture(scope="module")
def body() -> Case:
    return Case(parse_model(full_body_text(), "synthetic.yaml"), duration=4.0)


@pytest.fixture(scope="module")
def barbell() -> Case:
    return Case(load_model(BARBELL), duration=4.0)


def test_rigid_balance_is_newton_euler(body: Case) -> None:
    """With the Newton–Euler wrench applied, the residual of the true inertia vanishes; with no
    load it is minus that wrench, moved to the pelvis's origin."""
    K = mass_blocks(body.model)
    force, moment = R.whole_body_residual(body.model, body.motion, K, [body.load])
    scale = np.abs(body.force).max()
    assert scale > 500.0  # the motion is vigorous: over 700 N of net external force
    assert np.abs(force).max() < 1e-10 * scale and np.abs(moment).max() < 1e-10 * scale
    force, moment = R.whole_body_residual(body.model, body.motion, K, [])
    origin = body.motion.X[:, body.motion.index("pelvis"), :, 0]
    np.testing.assert_allclose(force[:, 0], body.force, atol=1e-9 * scale)
    np.testing.assert_allclose(moment[:, 0], body.moment - np.cross(origin, body.force),
                               atol=1e-9 * scale)


def test_rigid_balance_is_the_engines_residual(body: Case) -> None:
    """The classical model's base-driver multipliers (dynamics.convert) give the same residual
    as the rigid-motion balance, joints and all."""
    from fccgrb_cli.dynamics.convert import classical_dynamics
    from fccgrb_cli.solvers.result import KinematicResult

    r = body.result
    theta = np.array([body.model.angles[k].motion.evaluate(r.time)[0]
                      for k in range(len(body.model.angles))]).T
    result = KinematicResult(**{**r.__dict__, "theta": theta})
    d = classical_dynamics(body.model, result, loads=[body.noisy], tol=1e-12)
    force, moment = R.whole_body_residual(body.model, R.BodyMotion.of(
        compile_system(body.model, angles="driver"), d.kinematics.q, d.kinematics.qd,
        d.kinematics.qdd), mass_blocks(body.model), [body.noisy])
    np.testing.assert_allclose(force, d.inverse.residual_force, atol=1e-8)
    np.testing.assert_allclose(moment, d.inverse.residual_moment, atol=1e-8)


def _off_by_20(model, seed: int):
    """The model with every segment's mass (and inertia tensor) off by ±20 %, seeded."""
    from dataclasses import replace

    from fccgrb_cli.model import Inertia

    rng = np.random.default_rng(seed)
    bodies = []
    for b in model.bodies:
        f = 1.0 + 0.2 * rng.choice([-1.0, 1.0])
        i = b.inertia
        bodies.append(replace(b, inertia=Inertia(
            i.mass * f, i.com, tuple(tuple(f * x for x in row) for row in i.tensor))))
    return replace(model, bodies=tuple(bodies))


def _fit_off_by_20(case: Case) -> tuple:
    """The model with its masses off by 20 %, fitted to the noisy reaction over every frame;
    the true masses, the fit, and the RMS residual force and moment of the true model (the
    noise alone), of the wrong one and of the fitted one."""
    wrong = _off_by_20(case.model, seed=2)
    true = np.array([b.inertia.mass for b in case.model.bodies])
    assert np.abs(np.array([b.inertia.mass for b in wrong.bodies]) / true - 1.0).min() > 0.19
    fit = fit_inertia(wrong, case.motion, [case.noisy], np.ones(len(case.force), dtype=bool),
                      true.sum() * 9.81)
    assert fit.names == tuple(b.name for b in case.model.bodies)

    def rms(K: np.ndarray) -> tuple[float, float]:
        f, m = R.whole_body_residual(wrong, case.motion, K, [case.noisy])
        return (float(np.sqrt(np.mean(np.sum(f ** 2, axis=2)))),
                float(np.sqrt(np.mean(np.sum(m ** 2, axis=2)))))

    return true, fit, rms(mass_blocks(case.model)), rms(mass_blocks(wrong)), rms(fit.K)


def test_masses_off_by_20_percent_come_back(body: Case) -> None:
    """Every segment of the whole body (open chains): mass within 5 %, residual at the noise's
    level (the fit's 60 parameters take a little of the noise: no more than 5 % above it)."""
    true, fit, noise, before, after = _fit_off_by_20(body)
    error = fit.mass / true - 1.0
    assert np.abs(error).max() < 0.05, dict(zip(fit.names, np.round(100 * error, 1),
                                                strict=True))
    assert before[0] > 10 * noise[0]
    assert after[0] < 1.05 * noise[0] and after[1] < 1.05 * noise[1], (noise, after)


def test_a_closed_chain_is_fitted_alike(barbell: Case) -> None:
    """The barbell curl (arms, hands and bar close a loop): residual to the noise's level, the
    bar's and the whole body's mass within 5 % and 1 %. (Its slow, mirror-symmetric squat and
    curl cannot tell a left segment from its right twin, nor a thigh from the pelvis: the
    segment masses are not all identifiable from this motion, and are not asserted.)"""
    true, fit, noise, before, after = _fit_off_by_20(barbell)
    assert before[0] > 10 * noise[0]
    assert after[0] < 1.05 * noise[0] and after[1] < 1.05 * noise[1], (noise, after)
    names = list(fit.names)
    assert fit.mass[names.index("bar")] == pytest.approx(true[names.index("bar")], rel=0.05)
    assert fit.mass.sum() == pytest.approx(true.sum(), rel=0.01)


def test_a_known_translation_is_corrected_back(body: Case) -> None:
    """The motion moved by δr(t) (every body, exact derivatives): its residual force is m δr̈
    (Newton), and one correction step gives −δr back (to the difference stencils' error); moved
    by it (accelerations by numpy's differences), the residual is a few per cent of what it
    was."""
    t = body.result.time
    w = 2 * np.pi
    shift = np.stack([0.005 * np.sin(w * t), 0.003 * np.cos(1.5 * w * t), 0 * t], axis=1)
    accel = np.stack([-0.005 * w**2 * np.sin(w * t), -0.003 * (1.5 * w)**2 * np.cos(1.5 * w * t),
                      0 * t], axis=1)
    m = body.motion
    X, Xdd = m.X.copy(), m.Xdd.copy()
    X[:, :, :, 0] += shift[:, None]
    Xdd[:, :, :, 0] += accel[:, None]
    moved = R.BodyMotion(m.names, X, m.Xd, Xdd)
    K = mass_blocks(body.model)
    mass = K[:, 0, 0].sum()
    before = R.whole_body_residual(body.model, moved, K, [body.load])[0][:, 0]
    np.testing.assert_allclose(before, mass * accel, atol=1e-9 * mass)
    data = CorrectionData(moved, K, [body.load], np.ones(len(t), dtype=bool),
                          body.markers + shift[:, None], body.markers, mass * 9.81, RATE)
    step = correction_step(body.model, data)
    inner = slice(2, -2)  # the one-sided end stencils are less accurate
    np.testing.assert_allclose(step.translation[inner], -shift[inner], atol=2e-5)
    assert np.abs(step.rotation[inner]).max() < 5e-4  # rad: 0.03°
    # the corrected motion: moved again by the step, its acceleration by second differences
    d2 = np.gradient(np.gradient(step.translation, 1 / RATE, axis=0), 1 / RATE, axis=0)
    X[:, :, :, 0] += step.translation[:, None]
    Xdd[:, :, :, 0] += d2[:, None]
    after = R.whole_body_residual(body.model, R.BodyMotion(m.names, X, m.Xd, Xdd), K,
                                  [body.load])[0][:, 0]
    assert np.abs(after[inner]).max() < 0.05 * np.abs(before).max()


@pytest.fixture(scope="module")
def qualisys():
    """The Qualisys walking trial, the whole body calibrated from it (67 kg), solved with a 6 Hz
    low-pass and the residual reduction."""
    if not QUALISYS.exists():
        pytest.skip("../shared/data not present")
    import fccgrb_cli as fc
    from fccgrb_cli.anatomy.full_body import personalize

    trial = fc.read_trial(str(QUALISYS))
    template = load_model(ROOT / "configs" / "models" / "full_body.yaml")
    personal = parse_model(personalize(template, trial, mass=67.0).text, "personal.yaml")
    run = fc.solve(personal, trial, method="nrm-wls", filter_cutoff=6, engine="compiled",
                   reduce_residuals=True)
    return trial, personal, run


def test_feet_off_the_plates_are_not_measured(qualisys) -> None:
    """The right foot is on the ground off the plates until its toe-off (0.165 s in the file's
    events) and from its last strike (1.510 s), the left from its strike at 1.015 s: no frame
    there is measured; left stance on plate 1 and right stance on plate 2 are."""
    trial, _, run = qualisys
    measured = run.residuals.measured
    frame = {name: round(t * trial.rate) for name, t in (
        ("right off", 0.165), ("left strike", 1.015), ("right strike", 1.510))}
    assert not measured[: frame["right off"]].any()
    assert not measured[frame["left strike"]:].any()
    assert run.residuals.single.sum() > 100
    states = run.residuals.states
    assert (states["foot_r"][: frame["right off"] - 2] == R.UNMEASURED).all()


def test_qualisys_residuals_fall_to_their_targets(qualisys) -> None:
    """The targets: markers within 10 mm; the first model's residual reported; after the
    reduction, over the single-support frames on a plate, force RMS ≤ 2 % and peak ≤ 5 % of body
    weight, moment RMS ≤ 10 N·m; every mass within ±25 % of de Leva's (the calibrated ones), the
    total within 2 % of the plates' body weight; the markers' RMS up by ≤ 2 mm."""
    _, personal, run = qualisys
    assert run.summary()["mean ED mm"] <= 10.0
    before, after = run.reduction.before.over_single, run.residuals.over_single
    assert before.force_rms_bw > 2.0  # the first model's residual is there to reduce
    assert after.force_rms_bw <= 2.0 and after.force_peak_bw <= 5.0
    assert after.moment_rms <= 10.0
    fit = run.reduction.fit
    de_leva = np.array([personal.body(n).inertia.mass for n in fit.names])
    np.testing.assert_allclose(fit.mass0, de_leva)
    assert np.abs(fit.mass / de_leva - 1.0).max() <= 0.25 + 1e-9
    plates = after.weight / 9.81
    assert abs(fit.mass.sum() / plates - 1.0) <= 0.02
    growth = np.array(run.reduction.markers_after) - np.array(run.reduction.markers_before)
    assert growth.max() <= 0.002
    # the residual the run reports is the adjusted model's, from the engine's multipliers
    np.testing.assert_allclose(run.dynamics.inverse.residual_force[:, 0], run.residuals.force,
                               atol=1e-6)


def test_qualisys_leg_moments_keep_to_walking_norms(qualisys) -> None:
    """After the reduction the legs' curves stay in published walking ranges (Winter 2009;
    Kadaba et al. 1989): peak knee flexion 55–70°, peak plantarflexor moment 1.0–1.8 N·m/kg,
    hip extensor and abductor moments in stance 0.5–1.5 N·m/kg."""
    _, _, run = qualisys
    c = run.clinical
    names = list(c.names)
    per_kg = c.moments_per_kg
    for side in "rl":
        stance = c.stance[f"foot_{side}"]
        knee = c.angles[:, names.index(f"knee_flexion_{side}")]
        assert 55.0 <= knee.max() <= 70.0
        ankle = per_kg[stance, names.index(f"ankle_dorsiflexion_{side}")]
        assert 1.0 <= -ankle.min() <= 1.8
        hip = per_kg[stance, names.index(f"hip_flexion_{side}")]
        assert 0.5 <= -hip.min() <= 1.5
        abductor = per_kg[stance, names.index(f"hip_adduction_{side}")]
        assert 0.5 <= -abductor.min() <= 1.5


def test_the_reduction_is_stored_and_reported(qualisys, tmp_path: Path) -> None:
    """The results file holds the adjusted residual, the first model's beside it and the
    reduction; `fccgrb report` prints both from it."""
    import fccgrb_cli as fc

    _, _, run = qualisys
    path = tmp_path / "walk.h5"
    fc.write_results(run, path)
    back = fc.read_results(path)[run.name]
    assert back.residuals.over_single == run.residuals.over_single
    assert back.reduction.before.over_single == run.reduction.before.over_single
    np.testing.assert_array_equal(back.reduction.fit.mass, run.reduction.fit.mass)
    np.testing.assert_array_equal(back.residuals.measured, run.residuals.measured)
    assert back.reduction.text == run.reduction.text
    adjusted = parse_model(back.reduction.text, "adjusted.yaml")
    masses = [adjusted.body(n).inertia.mass for n in back.reduction.fit.names]
    np.testing.assert_allclose(masses, back.reduction.fit.mass, rtol=1e-5)
    result = run_cli("report", str(path))
    assert result.exit_code == 0
    assert "first model, single support" in result.output
    assert "reduced, single support" in result.output


@pytest.mark.parametrize("args, message", [
    (["--write-model", "{tmp}/m.yaml"], "--write-model: expected --reduce-residuals"),
    (["--reduce-residuals"], "expected a model with one floating base"),
])
def test_residual_options_refuse_what_they_cannot_do(args, message, tmp_path: Path) -> None:
    result = run_cli("solve", str(ROOT / "configs" / "models" / "five_bar.yaml"),
                     str(ROOT / "sample_data" / "five_bar.c3d"), "-o", str(tmp_path / "r.h5"),
                     *[a.format(tmp=tmp_path) for a in args])
    assert result.exit_code == 2
    one_error_line(result, message)
    assert not (tmp_path / "r.h5").exists() and not (tmp_path / "m.yaml").exists()


def _weighed(model_mass: float, plates_kg: float) -> R.ResidualReport:
    """A residual report whose plates weighed ``plates_kg`` and whose model's segments hold
    ``model_mass`` (nothing else of it is read by the weight check)."""
    summary = R.ResidualSummary(frames=100, single=40, force_peak=0.0, force_rms=0.0,
                                moment_peak=0.0, moment_rms=0.0,
                                weight=plates_kg * R.STANDARD_GRAVITY, model_mass=model_mass)
    empty = np.zeros(0)
    return R.ResidualReport("pelvis", {}, empty, empty, empty, empty, summary, summary,
                            weighed=True)


@pytest.mark.parametrize("plates", [50.0, 64.0, 67.0, 70.0, 90.0])
def test_the_weight_check_weighs_the_subject_not_a_partial_models_segments(plates) -> None:
    """A calibrated lower-limb model's segments hold half the subject (34 of 67 kg): the plates
    are compared with the subject's mass it records, within 5 %; without one, with the
    segments' sum, which then names what the model leaves out."""
    report = _weighed(34.1, plates)
    with_subject = report.weight_mismatch(subject_mass=67.0)
    assert (with_subject is None) == (abs(67.0 / plates - 1.0) <= R.WEIGHT_TOLERANCE)
    if with_subject is not None:
        assert "subject's mass (67.0 kg)" in with_subject
        assert f"{plates:.1f} kg" in with_subject
        assert "leaves out" not in with_subject
    alone = report.weight_mismatch()
    assert alone is not None and "model's mass (34.1 kg)" in alone and "leaves out" in alone
    whole = _weighed(67.0, plates).weight_mismatch()  # a whole body's segments: the subject
    assert (whole is None) == (abs(67.0 / plates - 1.0) <= R.WEIGHT_TOLERANCE)


def test_an_implausible_plate_weight_is_not_used_and_the_table_says_why(body: Case) -> None:
    """The synthesized motion's own ground reaction weighs the model (its plates' estimate is
    the model's weight); the same reaction turned upside down gives a negative 'weight', which
    is refused: the model's weight is used, unweighed, and the residual table says so."""
    from fccgrb_cli.dynamics.loads import ExternalLoad
    from fccgrb_cli.presentation.residual_table import residual_table

    K = mass_blocks(body.model)
    states = {"foot_r": np.full(len(body.motion.X), R.PLATE)}
    g = float(np.linalg.norm(body.model.gravity))
    mass = float(K[:, 0, 0].sum())
    right = R.residual_report(body.model, body.motion, K, [body.load], states)
    assert right.weighed and right.over_measured.weight == pytest.approx(mass * g, rel=1e-6)
    flipped = ExternalLoad(body.load.name, body.load.body, -body.load.force, body.load.point,
                           -body.load.moment)
    wrong = R.residual_report(body.model, body.motion, K, [flipped], states)
    assert not wrong.weighed and wrong.plates_estimate < 0
    assert wrong.over_measured.weight == pytest.approx(mass * g)
    assert "is not a body weight" in residual_table(wrong)
    assert "is not a body weight" not in residual_table(right)
