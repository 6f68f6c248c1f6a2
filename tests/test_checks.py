"""What fccgrb checks for you (README's section of that name): each check, rebuilt from the shared
files or synthesized, with the right answer computed here, never taken from the checks' code.

* no data, no answer: frames without markers are unsolved by every method and engine, and no
  event, stride or spatiotemporal parameter comes from them;
* gaps do not switch the dynamics off: rates and moments on every solved stretch;
* singular positions and branches: a parallelogram four-bar through its change points, its true
  input torque in closed form (tests below), synthesized on one branch;
* plausibility: a wand on the wrong face, an uncalibrated template, markers the model cannot
  fit, angles no person takes;
* moments where the kinematics are fine but a load is not measured or the accelerations are
  noise;
* an optimizer's stop at the precision limit on exact data is a converged frame when the KKT
  conditions hold.

The shared-data tests skip when ``../shared/data`` is absent.
"""

from __future__ import annotations

import json
import re
from functools import cache
from pathlib import Path

import ezc3d
import h5py
import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli

import fccgrb_cli as fc
from fccgrb_cli.solvers import quality
from fccgrb_cli.solvers.quality import (
    ANGLE_RANGE,
    CALIBRATION,
    NO_DATA,
    POOR_FIT,
    SINGULAR,
    UNCONVERGED,
)
from fccgrb_cli.trial.record import Trial

ROOT = Path(__file__).resolve().parents[1]
MODELS = ROOT / "configs" / "models"
SHARED = ROOT.parent / "shared" / "data" / "c3d"
QUALISYS = SHARED / "Qualisys.c3d"
PIG_STATIC = SHARED / "plugin_gait" / "HC030A01.c3d"
PIG_WALK = SHARED / "plugin_gait" / "HC030A05.c3d"
FIVE_BAR = ROOT / "sample_data" / "five_bar.c3d"
needs_shared = pytest.mark.skipif(not QUALISYS.exists(), reason="../shared/data absent")
needs_pig = pytest.mark.skipif(not PIG_WALK.exists(), reason="../shared/data absent")
PIG_MAP = {"sacrum": "SACR", "r asis": "RASI", "l asis": "LASI", "r bar 1": "RTHI",
           "r knee 1": "RKNE", "r bar 2": "RTIB", "r mall": "RANK", "r heel": "RHEE",
           "r met": "RTOE", "l bar 1": "LTHI", "l knee 1": "LKNE", "l bar 2": "LTIB",
           "l mall": "LANK", "l heel": "LHEE", "l met": "LTOE"}


def blanked(source: Path, target: Path, frames: slice, labels: list[str] | None = None) -> Path:
    """A copy of a C3D with the named markers (all when None) missing in ``frames`` (NaN and
    residual −1, as a capture system writes a gap); analogs, plates and events kept."""
    c3d = ezc3d.c3d(str(source))
    names = list(c3d["parameters"]["POINT"]["LABELS"]["value"])
    which = [names.index(label) for label in labels] if labels else list(range(len(names)))
    points = c3d["data"]["points"]
    for k in which:
        points[:3, k, frames] = np.nan
        points[3, k, frames] = -1.0
    c3d["data"]["points"] = points
    del c3d["data"]["meta_points"]
    c3d.write(str(target))
    return target


def said(run: fc.Run) -> str:
    """Everything the run says: the solver's and the checks' messages and the warnings."""
    return " ".join((*run.result.messages, *run.warnings))


@cache
def qualisys_model() -> fc.Model:
    return fc.calibrate(fc.load_model(MODELS / "lower_limb.yaml"), fc.read_trial(QUALISYS),
                        mass=67.0)


# ---- no data, no answer ---------------------------------------------------------------------


def _five_bar_with_a_blank_start(blank: int = 30, frames: int = 60) -> Trial:
    trial = fc.read_trial(FIVE_BAR)
    markers = trial.markers[:frames].copy()
    markers[:blank] = np.nan
    return Trial(trial.path, trial.labels, markers, trial.rate)


METHODS = [("ad", {}), ("nrm-ls", {}), ("nrm-wls", {}), ("nrm-wls", {"engine": "compiled"}),
           ("cno-sqp", {}), ("cno-sqp", {"engine": "compiled"}), ("cno-ip", {}),
           ("mo-tc", {}), ("mo-ed", {}),
           ("cno-sqp", {"parallel": True, "workers": 2, "parallel_init": "nrm"}),
           ("cno-sqp", {"parallel": True, "workers": 2, "parallel_init": "chunks"}),
           ("cno-sqp", {"parallel": True, "workers": 2, "parallel_init": "same"})]


@pytest.mark.parametrize(("method", "extra"), METHODS)
def test_frames_without_markers_are_unsolved_by_every_method(method, extra):
    """The first 30 frames have no marker: no method may report one of them converged (the
    structured optimizers used to return their warm start), each is flagged no_data, and the
    frames with markers are solved as they are without the blank ones."""
    trial = _five_bar_with_a_blank_start()
    model = fc.load_model(MODELS / "five_bar.yaml")
    run = fc.solve(model, trial, method=method, skip_unsolvable=True, dynamics=False, **extra)
    r = run.result
    assert not r.converged[:30].any() and not run.trusted[:30].any()
    assert ((r.flags[:30] & NO_DATA) > 0).all() and ((r.flags[:30] & UNCONVERGED) > 0).all()
    assert np.isnan(r.q[:30]).all()
    assert run.trusted[35:-5].all(), np.flatnonzero(~run.trusted)
    assert not (r.flags[30:] & NO_DATA).any()
    assert "cannot determine the model" in said(run)
    # what the data determine does not depend on the blank frames before them (to 1e-6 rad
    # frame by frame; the whole-trial smoother of the mixed methods bridges the blank second
    # with its prior, which moves the first solved frames by ~3e-5 rad)
    alone = fc.solve(model, Trial(trial.path, trial.labels, trial.markers[30:], trial.rate),
                     method=method, dynamics=False, **extra)
    smoothed = run.uncertainty is not None
    np.testing.assert_allclose(r.theta[30:], alone.result.theta, atol=1e-4 if smoothed else 1e-6)


@pytest.mark.parametrize("method", ["nrm-wls", "cno-sqp", "mo-ed", "ad"])
def test_frames_without_markers_are_an_error_without_skip_unsolvable(method):
    trial = _five_bar_with_a_blank_start()
    with pytest.raises(fc.InputError, match=r"frame index 0 .*cannot determine the model.*"
                                            r"--skip-unsolvable"):
        fc.solve(fc.load_model(MODELS / "five_bar.yaml"), trial, method=method, dynamics=False)


def test_frames_without_markers_on_the_command_line(tmp_path):
    """One error line naming the frame and the option, exit status 2, nothing written; with
    the option, the run and a summary that counts the frames as failed."""
    trial = blanked(FIVE_BAR, tmp_path / "blank.c3d", slice(0, 40))  # of its 300 frames
    out = tmp_path / "r.h5"
    one_error_line(run_cli("solve", MODELS / "five_bar.yaml", trial, "--method", "cno-sqp",
                           "-o", out), "frame index 0", "cannot determine the model",
                   "--skip-unsolvable")
    assert not out.exists()
    result = run_cli("solve", MODELS / "five_bar.yaml", trial, "--method", "cno-sqp",
                     "--skip-unsolvable", "-o", out)
    assert result.exit_code == 0, result.output
    header, values = (re.split(r"\s{2,}", line.strip())
                      for line in result.stdout.splitlines()[:2])
    assert values[header.index("failed")] == "40"


@needs_shared
def test_a_leading_second_without_markers_gives_no_event_and_no_stride_there(tmp_path):
    """Qualisys with its first second (200 frames) blank: no event of any source, no stride and
    no parameter there, and the run says how many frames it left out."""
    trial = blanked(QUALISYS, tmp_path / "late.c3d", slice(0, 200))
    run = fc.solve(qualisys_model(), fc.read_trial(trial), method="nrm-wls",
                   skip_unsolvable=True, filter_cutoff=6.0)
    assert not run.result.converged[:200].any()
    gait = run.gait
    start = 200 / 200.0
    for events in [gait.events, *gait.found.values()]:
        assert (events.time >= start - 1e-9).all(), (events.source, events.time)
    for cycles in gait.cycles.values():
        assert (cycles.start >= start - 1e-9).all()
    assert "200 frames" in said(run)


# ---- gaps do not switch the dynamics off -----------------------------------------------------


@needs_shared
@pytest.mark.parametrize("smoothed", [False, True], ids=["6Hz", "smoothed"])
def test_a_gap_in_one_foot_leaves_the_dynamics_on_elsewhere(tmp_path, smoothed):
    """Ten frames (100–109, in the left foot's swing) without the left foot's markers: the
    foot cannot be determined there, so those frames are unsolved and reported, and everything
    else — moments on at least 90 % of the frames, both plates' events, the strides — stays.
    Filtered, the dynamics run stretch by stretch and leave the gap out; smoothed
    (--smooth auto), the smoother bridges it, and its frames' moments are there but not
    trusted."""
    trial = blanked(QUALISYS, tmp_path / "gap.c3d", slice(100, 110),
                    ["L_FCC", "L_FM1", "L_FM5"])
    run = fc.solve(qualisys_model(), fc.read_trial(trial), method="nrm-wls",
                   skip_unsolvable=True,
                   **({"smooth": "auto"} if smoothed else {"filter_cutoff": 6.0}))
    assert (run.uncertainty is not None) == smoothed
    assert not run.result.converged[100:110].any()
    assert run.result.converged[:100].all() and run.result.converged[110:].all()
    moments = run.moments.values
    has_moment = np.isfinite(moments).all(axis=1)
    assert has_moment.mean() >= 0.9, has_moment.mean()
    assert not run.moments_trusted[100:110].any()
    if not smoothed:
        assert not has_moment[100:110].any()
    # the floating base's residual only over frames the checks trust
    measured = run.residuals.measured
    assert measured.any() and not measured[~run.trusted].any()
    plates = run.gait.found["plates"]
    assert {side for side in plates.side} == {"left", "right"}
    assert "frame index 100" in said(run) and "10 frames" in said(run)


# ---- singular positions and branches: the parallelogram four-bar ---------------------------

PARALLELOGRAM = MODELS / "parallelogram.yaml"


def parallelogram_torque(model: fc.Model, theta: np.ndarray, theta_dd: np.ndarray) -> np.ndarray:
    """The crank's input torque on the parallelogram branch in closed form (Lagrange with the
    crank angle θ as the one coordinate): the coupler translates with the crank pin A, the rocker
    turns with the crank, so T = ½ J θ̇² with J = I_crank,O + m_coupler |OA|² + I_rocker,D and
    V = g (m_crank c_crank + m_coupler |OA| + m_rocker c_rocker) sin θ (gravity −y), hence
    τ = J θ̈ + g (m_crank c_crank + m_coupler |OA| + m_rocker c_rocker) cos θ."""
    crank, coupler, rocker = (model.body(name) for name in ("crank", "coupler", "rocker"))
    arm = float(np.linalg.norm(crank.points["A"].local))

    def about_pivot(body):
        c = float(np.linalg.norm(body.inertia.com))
        return body.inertia.tensor[2][2] + body.inertia.mass * c * c, body.inertia.mass * c

    (j1, s1), (j3, s3) = about_pivot(crank), about_pivot(rocker)
    inertia = j1 + j3 + coupler.inertia.mass * arm**2
    weight = -model.gravity[1] * (s1 + s3 + coupler.inertia.mass * arm)
    return inertia * theta_dd + weight * np.cos(theta)


@cache
def parallelogram_trial(folder: str) -> Path:
    out = Path(folder) / "parallelogram.c3d"
    result = run_cli("synth", PARALLELOGRAM, "-o", out)
    assert result.exit_code == 0, result.output
    return out


def test_synth_follows_the_parallelogram_branch_through_its_change_points(tmp_path):
    trial = tmp_path / "p.c3d"
    result = run_cli("synth", PARALLELOGRAM, "-o", trial)
    assert result.exit_code == 0, result.output
    assert "change point" in result.stderr or "singular" in result.stderr
    with h5py.File(tmp_path / "p.truth.h5") as h5:
        markers = h5["markers"][()]
        theta = h5["theta"][()][:, 0]
    model = fc.load_model(PARALLELOGRAM)
    labels = model.marker_labels
    crank = markers[:, labels.index("A")]                 # the crank pin, O at the origin
    pin_b = markers[:, labels.index("B")]
    pivot_d = np.array([0.40, 0.0, 0.0])
    assert np.degrees(theta).max() > 365 and np.degrees(theta).min() < 175
    # on the parallelogram branch the rocker DB is parallel to the crank OA, on every frame
    np.testing.assert_allclose(pin_b - pivot_d, crank, atol=1e-9)


@pytest.mark.parametrize(("method", "smooth"), [("nrm-wls", "auto"), ("cno-sqp", "auto"),
                                               ("nrm-wls", "none")])
def test_parallelogram_moments_are_right_or_flagged(method, smooth, tmp_path_factory):
    """Through both change points: every frame within 2° of one is flagged; no moment it trusts
    is more than 10× the true peak (in fact each trusted one is within 2 % of the peak of the
    closed form), and the classical model stays on the mixed solution's branch on every frame:
    assembled by the smoother from the mixed solution (the default), or, without it, solved
    from each frame's mixed configuration (dynamics/convert.py)."""
    trial = parallelogram_trial(str(tmp_path_factory.mktemp("parallelogram")))
    model = fc.load_model(PARALLELOGRAM)
    run = fc.solve(model, fc.read_trial(trial), method=method, smooth=smooth)
    theta = run.result.theta[:, 0]
    truth = parallelogram_torque(model, theta, run.result.theta_dd[:, 0])
    peak = np.abs(truth).max()
    degrees = np.degrees(theta)
    near = np.abs((degrees + 90.0) % 180.0 - 90.0) <= 2.0
    assert near.sum() >= 4
    assert ((run.result.flags[near] & SINGULAR) > 0).all(), degrees[near & ~(
        (run.result.flags & SINGULAR) > 0)]
    tau = run.moments.values[:, 0]
    trusted = run.moments_trusted[:, 0]
    assert trusted.sum() >= 0.8 * len(tau)
    assert np.all(np.abs(tau[trusted]) <= 10 * peak)
    np.testing.assert_allclose(tau[trusted], truth[trusted], atol=0.02 * peak)
    # the classical model on the mixed solution's branch: the same bodies on every frame
    classical = run.dynamics.kinematics.q
    mixed = run.result.q[:, :classical.shape[1]]
    np.testing.assert_allclose(classical, mixed, atol=1e-6)
    assert "singular" in said(run)


def test_the_summary_maximum_is_over_trusted_moments(tmp_path_factory):
    trial = parallelogram_trial(str(tmp_path_factory.mktemp("parallelogram")))
    model = fc.load_model(PARALLELOGRAM)
    run = fc.solve(model, fc.read_trial(trial), method="nrm-wls")
    tau = run.moments.values[:, 0]
    assert run.summary()["max |τ| N·m"] == pytest.approx(
        np.abs(tau[run.moments_trusted[:, 0]]).max())


# ---- plausibility ------------------------------------------------------------------------------


def _wrong_face(trial: fc.Trial, wand: str, knee: str, ankle: str) -> Trial:
    """The wand turned half a turn about the line from the knee marker to the ankle marker:
    on the other face of the shank, at the same height and distance from the bone."""
    markers = trial.markers.copy()
    labels = list(trial.labels)
    a, b = markers[:, labels.index(knee)], markers[:, labels.index(ankle)]
    axis = (b - a) / np.linalg.norm(b - a, axis=1, keepdims=True)
    k = labels.index(wand)
    rel = markers[:, k] - a
    markers[:, k] = a + 2 * np.sum(rel * axis, axis=1, keepdims=True) * axis - rel
    return Trial(trial.path, trial.labels, markers, trial.rate)


@needs_pig
def test_a_tibia_wand_on_the_wrong_face_is_named_and_its_trial_flagged(tmp_path):
    """The Plug-in Gait child's static with the right tibia wand (RTIB) on the shank's other
    face: calibrate warns naming it, and every frame of the walking trial solved with that
    model is flagged (its right knee flexion correlates negatively with Vicon's)."""
    static = fc.read_trial(PIG_STATIC)
    template = fc.load_model(MODELS / "helen_hayes.yaml")
    widths = {"knee_width": 103.0, "ankle_width": 60.0, "marker_diameter": 14.0}
    good = fc.calibrate(template, static, mass=45.8, mapping=PIG_MAP, **widths)
    assert good.calibrated.warnings == ()
    bad = fc.calibrate(template, _wrong_face(static, "RTIB", "RKNE", "RANK"), mass=45.8,
                       mapping=PIG_MAP, **widths)
    assert len(bad.calibrated.warnings) == 1 and "RTIB" in bad.calibrated.warnings[0]
    walk = fc.read_trial(PIG_WALK)
    vicon = ezc3d.c3d(str(PIG_WALK))
    names = list(vicon["parameters"]["POINT"]["LABELS"]["value"])
    vicon_knee = vicon["data"]["points"][0, names.index("RKneeAngles")]
    for model, flagged in ((good, False), (bad, True)):
        run = fc.solve(model, walk, method="nrm-wls", mapping=tuple(PIG_MAP.items()),
                       filter_cutoff=6.0)
        knee = run.clinical_angles["knee_flexion_r"]
        r = np.corrcoef(knee, vicon_knee)[0, 1]
        assert (r < 0) == flagged
        assert ((run.result.flags & CALIBRATION) > 0).all() == flagged
        assert not run.trusted.any() if flagged else run.trusted.all()
    assert "RTIB" in said(run)


@needs_pig
def test_calibrate_warns_on_the_command_line(tmp_path):
    trial = tmp_path / "static.c3d"
    c3d = ezc3d.c3d(str(PIG_STATIC))
    labels = list(c3d["parameters"]["POINT"]["LABELS"]["value"])
    points = c3d["data"]["points"]
    i, j = labels.index("RTIB"), labels.index("LTIB")   # left and right tibia wands swapped
    points[:, [i, j]] = points[:, [j, i]]
    c3d["data"]["points"] = points
    del c3d["data"]["meta_points"]
    c3d.write(str(trial))
    maps = tmp_path / "pig.yaml"
    maps.write_text("".join(f"{k}: {v}\n" for k, v in PIG_MAP.items()))
    result = run_cli("calibrate", MODELS / "helen_hayes.yaml", trial, "--map", maps,
                     "--mass", 45.8, "-o", tmp_path / "p.yaml")
    assert result.exit_code == 0, result.output
    warned = [line for line in result.stderr.splitlines() if "implausible calibration" in line]
    assert any("RTIB" in line for line in warned) and any("LTIB" in line for line in warned)


@needs_shared
def test_the_uncalibrated_template_on_a_real_trial_is_flagged_and_said():
    run = fc.solve(fc.load_model(MODELS / "lower_limb.yaml"), fc.read_trial(QUALISYS),
                   method="nrm-wls", dynamics=False)
    distance = 1e3 * np.nanmean(run.ed_input)
    assert distance > 25  # the generic adult's markers are far from this subject's
    assert ((run.result.flags & CALIBRATION) > 0).all()
    assert ((run.result.flags & POOR_FIT) > 0).all()
    assert "template" in said(run)


@needs_shared
def test_a_model_that_fits_badly_is_flagged_naming_its_worst_markers():
    """The personal model with the left thigh wand's place moved 60 mm (a marker re-stuck
    after the static): the frames it spoils are flagged, and the warning names it first."""
    import yaml

    model = qualisys_model()
    doc = yaml.safe_load(model.text)
    points = doc["bodies"]["thigh_l"]["points"]
    name = next(n for n in points if "WAND" in n.upper() or "TTC" in n.upper() or
                n.upper().endswith("FTC"))
    points[name] = [points[name][0] + 0.06, points[name][1], points[name][2]]
    moved = fc.load_model(doc)
    run = fc.solve(moved, fc.read_trial(QUALISYS), method="nrm-wls", dynamics=False)
    largest = 1e3 * np.nanmax(run.ed_input, axis=1)
    assert ((run.result.flags & POOR_FIT) > 0).tolist() == \
        ((largest > quality.FIT_MARKER_MM) | (1e3 * np.nanmean(run.ed_input, axis=1)
                                               > quality.FIT_MEAN_MM)).tolist()
    assert ((run.result.flags & POOR_FIT) > 0).any()
    said = next(w for w in run.result.messages if "fits its markers" in w)
    assert said.index(name) < len(said)


@needs_shared
def test_angles_no_person_takes_are_never_trusted():
    """A stretch of 60 frames whose shank and foot markers of the left leg are swapped with the
    right's (a labelling error): every frame whose clinical angle (computed here from the
    model's vectors, not the package's clinical view) leaves the table's range is flagged."""
    trial = fc.read_trial(QUALISYS)
    markers = trial.markers.copy()
    labels = list(trial.labels)
    for stem in ("FAL", "TAM", "FCC", "FM1", "FM5"):
        i, j = labels.index(f"L_{stem}"), labels.index(f"R_{stem}")
        markers[150:210, [i, j]] = markers[150:210, [j, i]]
    swapped = Trial(trial.path, trial.labels, markers, trial.rate)
    model = qualisys_model()
    run = fc.solve(model, swapped, method="nrm-wls", dynamics=False)
    theta = run.result.theta
    outside = np.zeros(len(theta), dtype=bool)
    table = {"hip_flexion": (-50, 150), "hip_adduction": (-60, 45), "hip_rotation": (-70, 70),
             "knee_flexion": (-25, 160), "ankle_dorsiflexion": (-70, 50),
             "ankle_inversion": (-75, 75)}
    for k, angle in enumerate(model.angles):
        low, high = table[angle.name[:-2]]
        clinical = angle.clinical_sign * (np.degrees(theta[:, k]) - 90.0)
        outside |= (clinical < low) | (clinical > high)
    assert outside.any()
    assert ((run.result.flags[outside] & ANGLE_RANGE) > 0).all()
    assert not run.trusted[outside].any()
    assert not run.trusted[150:210].any()


def test_a_declared_range_replaces_the_table():
    model = fc.load_model(MODELS / "lower_limb.yaml")
    assert model.angles[3].clinical_range == (-25.0, 160.0)
    import yaml

    doc = yaml.safe_load(model.text)
    doc["angles"][3]["clinical"]["range_deg"] = [0, 10]
    assert fc.load_model(doc).angles[3].clinical_range == (0.0, 10.0)
    doc["angles"][3]["clinical"]["range_deg"] = [10, 0]
    with pytest.raises(fc.InputError, match=r"angles\[3\]\.clinical\.range_deg: expected min"):
        fc.load_model(doc)


def test_a_mirrored_angle_is_flagged_as_another_branch():
    """s1·s2 = cos θ holds for θ and −θ: a solution at −θ has sin θ < 0 and moments of the
    wrong sign. Checked on the five-bar's exact angles, one frame put at −θ."""
    run = fc.solve(fc.load_model(MODELS / "five_bar.yaml"), fc.read_trial(FIVE_BAR),
                   method="nrm-wls", dynamics=False)
    theta = run.result.theta.copy()
    theta[100, 2] = -theta[100, 2]
    flat, mirrored = quality.flat_or_mirrored(theta, run.result.angle_names,
                                              np.ones(theta.shape[1], dtype=bool))
    assert np.flatnonzero(mirrored.frames).tolist() == [100]
    assert not flat.frames.any()
    theta[200, 4] = np.radians(3.0)
    flat, _ = quality.flat_or_mirrored(theta, run.result.angle_names,
                                       np.ones(theta.shape[1], dtype=bool))
    assert np.flatnonzero(flat.frames).tolist() == [200]


# ---- moments: trusted only where a moment can be right --------------------------------------


@needs_shared
def test_unfiltered_real_markers_give_no_trusted_moment():
    """Qualisys without a filter: the double-differentiated marker noise is most of the
    accelerations (the hip moment swings −2.0…3.2 N·m/kg where the 6 Hz run gives −0.6…1.2), so
    no moment is trusted and the run says to filter; with the filter they are, and with the
    whole-trial smoother (--smooth auto) too."""
    trial = fc.read_trial(QUALISYS)
    raw = fc.solve(qualisys_model(), trial, method="nrm-wls", smooth="none")
    assert raw.trusted.all()                   # the kinematics are fine
    assert not raw.moments_trusted.any()
    assert "--filter-cutoff" in said(raw)
    filtered = fc.solve(qualisys_model(), trial, method="nrm-wls", filter_cutoff=6.0)
    assert filtered.moments_trusted.any()
    smoothed = fc.solve(qualisys_model(), trial, method="nrm-wls", smooth="auto")
    assert smoothed.uncertainty is not None and smoothed.moments_trusted.any()


@needs_shared
def test_stance_off_the_plates_and_a_trial_without_plates(tmp_path):
    """The left foot's second stance (from its strike at 1.015 s to the end) is on no plate:
    the left leg's moments are not trusted there, the right leg's swing ones are. A TRC copy
    of the trial has no plates at all: no moment of a leg in stance is trusted."""
    trial = fc.read_trial(QUALISYS)
    run = fc.solve(qualisys_model(), trial, method="nrm-wls", filter_cutoff=6.0)
    names = run.moments.names
    left = [k for k, n in enumerate(names) if n.endswith("_l")]
    right = [k for k, n in enumerate(names) if n.endswith("_r")]
    late = run.result.time > 1.015 + 0.05
    assert not run.moments_trusted[np.ix_(late, left)].any()
    stance_r = run.clinical.stance["foot_r"]
    assert run.moments_trusted[np.ix_(stance_r, right)].all()
    assert "force plate measures" in said(run) and "foot_l" in said(run)
    trc = tmp_path / "walk.trc"
    fc_io = __import__("fccgrb_cli.trial.record", fromlist=["write_trial"])
    fc_io.write_trial(trc, list(trial.labels), trial.markers, trial.rate, "mm")
    without = fc.solve(qualisys_model(), fc.read_trial(trc), method="nrm-wls",
                       filter_cutoff=6.0)
    for foot, joints in (("foot_r", right), ("foot_l", left)):
        on_ground = run.clinical.stance[foot]   # the plates of the C3D saw it there
        assert not without.moments_trusted[np.ix_(on_ground, joints)].any()
    assert without.moments_trusted.any()        # the swings' moments need no ground reaction


# ---- the optimizers' stop at the precision limit -----------------------------------------------


def test_a_stop_at_the_precision_limit_with_the_kkt_conditions_met_is_converged():
    """Exact markers and --tol 1e-14: SLSQP stops at goal attainment's degenerate optimum
    (every goal active at zero residual) with 'positive directional derivative'; its multipliers
    are not unique, and non-negative ones exist, so the frame is converged (frames 40–69 of the
    five-bar hold two such stops) and the dynamics run."""
    trial = fc.read_trial(FIVE_BAR)
    part = Trial(trial.path, trial.labels, trial.markers[40:70], trial.rate)
    run = fc.solve(fc.load_model(MODELS / "five_bar.yaml"), part, method="mo-ed", tol=1e-14)
    assert run.result.converged.all(), [m for m in run.result.messages]
    assert any("first-order optimality verified" in s for s in run.result.status)
    assert run.dynamics is not None and np.isfinite(run.moments.values).all()


# ---- where the flags show ----------------------------------------------------------------------


def test_flags_are_self_describing_in_the_results_file(tmp_path):
    run = fc.solve(fc.load_model(MODELS / "five_bar.yaml"), _five_bar_with_a_blank_start(),
                   method="nrm-wls", skip_unsolvable=True)
    out = tmp_path / "r.h5"
    fc.write_results(run, out)
    with h5py.File(out) as h5:
        g = h5[f"runs/{run.name}"]
        assert g["flags"].dtype == np.uint16
        bits = json.loads(g["flags"].attrs["bits"])
        by_name = {b["name"]: b for b in bits}
        assert by_name["no_data"]["frames"] == 30 and by_name["no_data"]["first"] == 0
        assert by_name["no_data"]["value"] == NO_DATA and by_name["no_data"]["meaning"]
        assert {b["name"] for b in bits} >= {"unconverged", "topology", "jump", "no_data",
                                             "singular", "branch", "angle_range", "poor_fit",
                                             "calibration"}
        moments = g["moment_flags"]
        assert moments.shape == g["joint_moments"].shape
        assert json.loads(moments.attrs["bits"])
    again = fc.read_results(out)[run.name]
    np.testing.assert_array_equal(again.result.flags, run.result.flags)
    np.testing.assert_array_equal(again.moments_trusted, run.moments_trusted)


def test_a_results_file_with_8_bit_flags_still_reads(tmp_path):
    """Files written before the flags grew to 16 bits (uint8, three bits) read as before."""
    run = fc.solve(fc.load_model(MODELS / "five_bar.yaml"), fc.read_trial(FIVE_BAR),
                   method="nrm-wls")
    out = tmp_path / "old.h5"
    fc.write_results(run, out)
    with h5py.File(out, "a") as h5:
        g = h5[f"runs/{run.name}"]
        flags = g["flags"][()].astype(np.uint8)
        flags[7] = 4
        del g["flags"]
        g.create_dataset("flags", data=flags)
        g["flags"].attrs.update({"unconverged": 1, "topology": 2, "jump": 4})
        del g["moment_flags"]
    again = fc.read_results(out)[run.name]
    assert again.result.flags.dtype == np.uint16 and again.result.flags[7] == 4
    assert not again.trusted[7]
    assert again.moments_trusted is None or not again.moments_trusted[7].any()


def test_the_kkt_check_wants_non_negative_multipliers_where_some_exist():
    """min f over x ≥ 0, y free, at the corner x = 0 with two copies of the active constraint
    (a degenerate point, as goal attainment's at zero residual): ∇f = (1, 0) is met by λ = (1,
    0) — or by λ = (−1, 1), which a minimum-norm fit need not avoid — so the point is optimal;
    for ∇f = (−1, 0) every fit needs a negative λ: not optimal (moving into x > 0 descends)."""
    from fccgrb_cli.solvers.goal.reference import kkt_satisfied

    no_equality = np.zeros((0, 2)), np.zeros(0)
    active = np.array([[1.0, 0.0], [2.0, 0.0]]), np.zeros(2)
    assert kkt_satisfied(np.array([1.0, 0.0]), *no_equality, *active)
    assert not kkt_satisfied(np.array([-1.0, 0.0]), *no_equality, *active)
    assert not kkt_satisfied(np.array([1.0, 0.5]), *no_equality, *active)  # ∇f off their span


def test_the_clinical_table_ranges_over_trusted_frames_only():
    """The summary's clinical table: an angle's range over the trusted frames (a poorly fitting
    stretch put −5,288,815° into a vendor trial's ankle inversion, flagged but printed), '–'
    where no frame is trusted; the ranges computed here from the frames the mask keeps."""
    from fccgrb_cli.anatomy.clinical import ClinicalResults, clinical_table

    rng = np.random.default_rng(3)
    angles = rng.uniform(-30, 30, size=(50, 2))
    angles[10:15, 0] = -5.3e6
    angles[:, 1] = np.nan
    trusted = np.ones(50, dtype=bool)
    trusted[10:15] = False
    c = ClinicalResults(("ankle_inversion_r", "knee_flexion_r"), angles, None, None, {})
    rows = {line.split()[0]: line.split()[1:] for line in clinical_table(c, trusted)
            .splitlines()[1:]}
    kept = np.delete(angles[:, 0], range(10, 15))
    assert rows["ankle_inversion_r"] == [f"{kept.min():.1f}", f"{kept.max():.1f}"]
    assert rows["knee_flexion_r"] == ["–", "–"]
    assert "-5300000.0" in clinical_table(c)  # without a mask: every frame, as before


@needs_shared
def test_a_late_start_is_smoothed_and_its_residual_is_over_frames_with_dynamics(tmp_path):
    """Qualisys with its first 100 frames blank, solved with the whole-trial smoother
    (--smooth auto): the smoother runs from the first frame with data (its prior extrapolated over
    the blank frames failed to assemble there, which switched smoothing off for the trial), the
    blank frames stay unsolved, and the floating base's residual is taken over frames where the
    dynamics ran and the kinematics are trusted (it printed NaN, then 1e9 N, on a vendor file)."""
    trial = blanked(QUALISYS, tmp_path / "late.c3d", slice(0, 100))
    run = fc.solve(qualisys_model(), fc.read_trial(trial), method="nrm-wls",
                   skip_unsolvable=True, smooth="auto")
    assert run.uncertainty is not None, said(run)
    assert "could not be assembled" not in said(run)
    assert np.isnan(run.result.q[:100]).all() and not run.trusted[:100].any()
    report = run.residuals
    measured = report.measured
    assert measured.any() and not measured[:100].any()
    assert run.trusted[measured].all()
    assert np.isfinite(report.force[measured]).all()
    force = np.linalg.norm(report.force[measured], axis=1)
    assert report.over_measured.force_rms == pytest.approx(np.sqrt(np.mean(force**2)))
    assert report.over_measured.frames == int(measured.sum())
    assert 40 < report.over_measured.weight / 9.81 < 100  # the plates weigh the 67 kg subject
