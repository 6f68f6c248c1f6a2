"""From a solved walking trial to a gait report: events (C3D, plates, markers), cycles normalized
to 0–100 %, spatiotemporal parameters — checked against the lab's own events, hand calculations
from the raw markers, published ranges for adult walking and synthetic cases with known answers."""

from __future__ import annotations

from pathlib import Path

import ezc3d
import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli

import fccgrb_cli as fc
from fccgrb_cli.gait.cycles import PARAMETERS, Walk, side_cycles
from fccgrb_cli.gait.events import Events, c3d_events, kinematic_events

ROOT = Path(__file__).resolve().parents[1]
GAIT = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"
needs_gait = pytest.mark.skipif(not GAIT.exists(), reason=f"{GAIT} is absent (a user's clone)")


# --- events from a C3D, both conventions --------------------------------------------------

def _c3d_with_events(path: Path, events: list[tuple[float, str, str]], rate: float = 100.0,
                     frames: int = 200) -> Path:
    c3d = ezc3d.c3d()
    c3d["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c3d["parameters"]["POINT"]["LABELS"]["value"] = ["M"]
    c3d["data"]["points"] = np.ones((4, 1, frames))
    for t, context, label in events:
        c3d.add_event([0, t], context=context, label=label)
    c3d.write(str(path))
    return path


@pytest.mark.parametrize("style", ["abbreviations", "nexus"])
def test_c3d_events_are_read_in_both_conventions(tmp_path: Path, style: str):
    """Times (frame 1 at t = 0), sides and kinds as written; events that are not foot contacts
    (a 'General' event) and events outside the trial are left out."""
    truth = [(0.31, "left", "strike"), (0.52, "right", "off"), (0.83, "right", "strike"),
             (1.07, "left", "off")]
    if style == "abbreviations":
        written = [(t, "", ("L" if s == "left" else "R") + ("HS" if k == "strike" else "TO"))
                   for t, s, k in truth]
    else:
        written = [(t, s.capitalize(), "Foot Strike" if k == "strike" else "Foot Off")
                   for t, s, k in truth]
    written += [(0.5, "General", "Event"), (3.5, "Left", "Foot Strike")]
    events = c3d_events(_c3d_with_events(tmp_path / "e.c3d", written), 200, 100.0)
    np.testing.assert_allclose(events.time, [t for t, _, _ in truth], atol=1e-6)
    assert events.side == tuple(s for _, s, _ in truth)
    assert events.kind == tuple(k for _, _, k in truth)


# --- cycles and parameters on synthetic events: answers known by hand --------------------

def _walk(time: np.ndarray, speed: float) -> dict[str, np.ndarray]:
    """Heels that advance in steps along x at ``speed`` on average, 0.2 m apart across."""
    left = np.column_stack([speed * time, np.full_like(time, 0.1), np.zeros_like(time)])
    right = np.column_stack([speed * time, np.full_like(time, -0.1), np.zeros_like(time)])
    return {"left": left, "right": right + np.array([0.3, 0.0, 0.0])}


def test_cycles_are_normalized_and_parameters_follow_from_the_events():
    rate = 100.0
    time = np.arange(300) / rate
    a, b = 0.40, 1.40  # right strikes
    events = Events("test", np.array([a, 0.52, 0.90, 1.02, b]),
                    ("right", "left", "left", "right", "right"),
                    ("strike", "off", "strike", "off", "strike"))
    phase = 2 * np.pi * (time - a) / (b - a)
    values = np.column_stack([np.sin(phase), np.cos(phase)])
    curves = (("knee_flexion_r", "knee_flexion_l"), ("deg", "deg"), values)
    heels = _walk(time, 1.2)
    walk = Walk(time, heels, np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
    cycles = side_cycles("right", events, np.ones(300, bool), curves, walk)
    assert cycles.n == 1 and cycles.names == ("knee_flexion_r",)
    percent = np.linspace(0, 1, 101)
    np.testing.assert_allclose(cycles.curves[0, :, 0], np.sin(2 * np.pi * percent), atol=2e-3)
    p = dict(zip([name for name, _ in PARAMETERS], cycles.parameters[0], strict=True))
    assert p["stride_time"] == pytest.approx(1.0)
    assert p["cadence"] == pytest.approx(120.0)
    assert p["stride_length"] == pytest.approx(1.2)
    assert p["walking_speed"] == pytest.approx(1.2)
    assert p["step_length"] == pytest.approx(0.3)
    assert p["step_width"] == pytest.approx(0.2)
    assert p["stance"] == pytest.approx(62.0)   # off at 1.02 s: 0.62 of the stride
    assert p["swing"] == pytest.approx(38.0)
    # both feet down from 0.40 to the left off at 0.52, and from the left strike at 0.90 to
    # the right off at 1.02: 0.24 s of 1 s
    assert p["double_support"] == pytest.approx(24.0)


def test_a_stride_with_an_untrusted_frame_is_marked_and_left_out_of_the_mean():
    rate = 100.0
    time = np.arange(400) / rate
    events = Events("test", np.array([0.2, 1.2, 2.2, 3.2]), ("left",) * 4, ("strike",) * 4)
    values = np.column_stack([np.where(time < 1.2, 10.0, 20.0)])
    trusted = np.ones(400, bool)
    trusted[170] = False  # inside the second stride (1.2–2.2 s)
    walk = Walk(time, {}, np.array([1.0, 0, 0]), np.array([0, 0, 1.0]))
    cycles = side_cycles("left", events, trusted, (("hip_flexion_l",), ("deg",), values), walk)
    assert list(cycles.trusted) == [True, False, True]
    np.testing.assert_allclose(cycles.mean()[5:95, 0], 15.0)  # strides 1 (10) and 3 (20) only
    assert np.isnan(cycles.parameter("stride_length")).all()  # no heels given


def test_zeni_events_on_a_synthetic_walk():
    """Heels and toes oscillating about a pelvis moving forward: strikes at the heel's most
    anterior position, offs at the toe's most posterior (Zeni et al. 2008)."""
    rate = 100.0
    time = np.arange(400) / rate
    pelvis = np.column_stack([1.3 * time, np.zeros_like(time), np.ones_like(time)])
    markers = {"pelvis": pelvis}
    for side, shift in (("left", 0.0), ("right", 0.5)):
        swing = np.column_stack([0.4 * np.cos(2 * np.pi * (time - shift)), np.zeros_like(time),
                                 np.zeros_like(time)])
        markers[f"{side}_heel"] = pelvis + swing
        markers[f"{side}_toe"] = pelvis + swing + np.array([0.15, 0.0, 0.0])
    events = kinematic_events(markers, rate, np.array([0, 0, 1.0]), "synthetic")
    np.testing.assert_allclose(events.of("left", "strike"), [1.0, 2.0, 3.0], atol=0.01)
    np.testing.assert_allclose(events.of("right", "strike"), [0.5, 1.5, 2.5, 3.5], atol=0.01)
    np.testing.assert_allclose(events.of("left", "off"), [0.5, 1.5, 2.5, 3.5], atol=0.01)


# --- the Qualisys walking trial ----------------------------------------------------------

@pytest.fixture(scope="module")
def walk(tmp_path_factory) -> tuple[Path, fc.Run]:
    trial = fc.read_trial(GAIT)
    model = fc.calibrate(fc.load_model(ROOT / "configs" / "models" / "lower_limb.yaml"),
                         trial, mass=67)
    results = tmp_path_factory.mktemp("gait") / "gait.h5"
    run = fc.solve(model, trial, filter_cutoff=6)
    fc.write_results(run, results)
    return results, run


@needs_gait
def test_plate_events_agree_with_the_labs_within_20_ms(walk):
    _, run = walk
    found, used = run.gait.found, run.gait.events
    assert used.source == "c3d" and len(used) == 7
    plates = found["plates"]
    assert len(plates) == 4  # two plates: a strike and an off each
    for t, side, kind in zip(plates.time, plates.side, plates.kind, strict=True):
        nearest = np.min(np.abs(used.of(side, kind) - t))
        assert nearest <= 0.020, (side, kind, t, nearest)
    kinematic = found["kinematic"]  # Zeni's method: strikes a few frames early is typical
    for t, side, kind in zip(used.time, used.side, used.kind, strict=True):
        assert np.min(np.abs(kinematic.of(side, kind) - t)) <= 0.05, (side, kind, t)


@needs_gait
def test_knee_flexion_through_the_cycle_is_that_of_adult_walking(walk):
    """Perry & Burnfield, Gait Analysis (2nd ed., 2010), and Kadaba et al., J Orthop Res 7
    (1989) 849: the knee is near extension at initial contact (about 0–10°, up to 15–20° in
    some healthy adults), flexes to 60–70° in swing, peaking at about 70–75 % of the cycle."""
    _, run = walk
    for side, suffix in (("left", "_l"), ("right", "_r")):
        c = run.gait.cycles[side]
        assert c.n == 1 and c.trusted.all()
        knee = c.curves[0, :, c.names.index("knee_flexion" + suffix)]
        assert -2.0 <= knee[0] <= 20.0, (side, knee[0])
        assert 55.0 <= knee.max() <= 75.0, (side, knee.max())
        assert 62 <= int(knee.argmax()) <= 80, (side, int(knee.argmax()))
        assert 55.0 <= c.parameter("stance")[0] <= 65.0


@needs_gait
def test_cadence_and_speed_agree_with_a_hand_calculation_from_the_markers(walk):
    """By hand: the stride time between the file's two right strikes, and the pelvis (mean of
    the four iliac spine markers) displacement over that stride, read straight from the C3D."""
    _, run = walk
    c3d = ezc3d.c3d(str(GAIT))
    labels = list(c3d["parameters"]["POINT"]["LABELS"]["value"])
    times = c3d["parameters"]["EVENT"]["TIMES"]["value"][1]
    right = [t for t, label in zip(times, c3d["parameters"]["EVENT"]["LABELS"]["value"],
                                   strict=True) if label == "RHS"]
    first = (c3d["header"]["points"]["first_frame"] + 1 - 1) / 200.0
    a, b = right[0] - first, right[1] - first
    points = c3d["data"]["points"][:3] / 1000.0
    pelvis = np.mean([points[:, labels.index(n)] for n in ("R_IAS", "L_IAS", "R_IPS", "L_IPS")],
                     axis=0)
    at = [np.array([np.interp(t * 200, np.arange(points.shape[2]), pelvis[k])
                    for k in range(3)]) for t in (a, b)]
    speed = np.linalg.norm((at[1] - at[0])[:2]) / (b - a)
    c = run.gait.cycles["right"]
    assert c.parameter("stride_time")[0] == pytest.approx(b - a, abs=1e-6)
    assert c.parameter("cadence")[0] == pytest.approx(120.0 / (b - a), rel=1e-6)
    assert c.parameter("walking_speed")[0] == pytest.approx(speed, rel=0.03)
    assert 1.0 <= speed <= 1.8


@needs_gait
def test_the_report_the_figure_and_the_results_file_carry_the_gait(walk, tmp_path: Path):
    results, run = walk
    back = fc.read_results(results)[run.name].gait
    np.testing.assert_array_equal(back.cycles["left"].curves, run.gait.cycles["left"].curves)
    assert set(back.found) == {"c3d", "plates", "kinematic"} and back.events.source == "c3d"
    report = run_cli("report", results)
    assert report.exit_code == 0
    assert "cadence (steps/min)" in report.output and "plates Δms" in report.output
    normative = tmp_path / "norm.csv"
    normative.write_text("variable,percent,mean,sd\n" + "".join(
        f"knee_flexion,{p},{30 + 25 * np.sin(np.pi * p / 100):.2f},5\n" for p in range(101)),
        encoding="utf-8")
    figure = tmp_path / "cycles.png"
    assert run_cli("plot", results, "--kind", "cycles", "--normative", normative, "-o",
                   figure).exit_code == 0
    assert figure.stat().st_size > 10_000
    normative.write_text("variable,percent,mean,sd\nknee_flexion,0,ten,5\n", encoding="utf-8")
    one_error_line(run_cli("plot", results, "--kind", "cycles", "--normative", normative, "-o",
                           figure), "line 2", "variable, percent, mean, sd")


def test_events_on_a_model_without_legs_is_one_line(tmp_path: Path):
    model = ROOT / "configs" / "models" / "five_bar.yaml"
    trial = ROOT / "sample_data" / "five_bar.c3d"
    one_error_line(run_cli("solve", model, trial, "--events", "plates", "-o", tmp_path / "x.h5"),
                   "--events plates", "clinical angles of both legs")


@needs_gait
def test_several_trials_of_one_subject_are_pooled(walk, tmp_path: Path):
    """Two trials (here the same walk under two names, so the pooled answer is known: each
    stride twice, the same mean, zero spread) give one run each and the subject's cycles."""
    import h5py

    _, run = walk
    for name in ("walk1.c3d", "walk2.c3d"):
        (tmp_path / name).symlink_to(GAIT)
    model = tmp_path / "subject.yaml"
    model.write_text(run.model_text, encoding="utf-8")
    out = tmp_path / "subject.h5"
    result = run_cli("solve", model, str(tmp_path / "walk*.c3d"), "--filter-cutoff", "6",
                     "-o", out)
    assert result.exit_code == 0, result.stderr
    assert "subject: 2 trials pooled" in result.output
    runs = fc.read_results(out)
    assert sorted(runs) == ["walk1-nrm-wls-f6Hz", "walk2-nrm-wls-f6Hz"]
    with h5py.File(out) as h5:
        right = h5["subject/cycles/right"]
        assert right["curves"].shape[0] == 2 and right["trusted"][()].all()
        np.testing.assert_allclose(right["mean"][()], run.gait.cycles["right"].mean(),
                                   atol=1e-12)
        np.testing.assert_allclose(right["sd"][()], 0.0, atol=1e-9)
    one_error_line(run_cli("solve", model, str(tmp_path / "nothing*.c3d"), "-o", out),
                   "nothing*.c3d", "matching the pattern")
    (tmp_path / "other").mkdir()
    (tmp_path / "other" / "walk1.c3d").symlink_to(GAIT)
    one_error_line(run_cli("solve", model, tmp_path / "walk1.c3d",
                           tmp_path / "other" / "walk1.c3d", "-o", out),
                   "walk1", "different file names")
