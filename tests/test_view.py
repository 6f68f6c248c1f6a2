"""``fccgrb view``: the 3D page of a results file's runs or of a model, and its still SVG.

Without a browser: the projection against its closed form for the camera presets; the display
decimation; the scene against the results file (every tracked point rebuilt from q through the
model text equals the solver's model_points; each marker's drawn distance equals the file's
ed_input and the distance between the drawn points); a reduced body's w = u × v; the curves
against the file's own clinical angles and moments; the model view against the five-bar's
closed-form initial pose; the still SVG's dots at the projected file points; bad input is one
line, status 2, nothing written.

In headless Chromium (tests/browser.py, skipped without a chromium binary): the pages of the
five-bar (two runs overlaid, some frames flagged and markers moved in a copy) and of the shared
gait trial (skipped without ../shared) open with no console message and fetch nothing; the scene
is drawn; moving the timeline changes the picture; the flag, untrusted-marker and overlay
colours are on the canvas where, and only where, the file says; the frame count and the clock
match the file; the page's projection equals camera.py's; the page plays.
"""

from __future__ import annotations

import io
import math
import os
import re
import shutil
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from browser import Browser, chromium_binary
from cli_helpers import one_error_line, run_cli

from fccgrb_cli.model import load_model
from fccgrb_cli.view.camera import PRESETS, Camera, framing, lab_axes, project
from fccgrb_cli.view.runs import motion_scene
from fccgrb_cli.view.scene import display_frames, model_scene
from fccgrb_cli.view.skeleton import body_coordinates, pose_coordinates, skeleton
from fccgrb_cli.view.styles import (
    BAND_ALPHA,
    CURVE,
    FLAGGED,
    OVERLAY,
    OVERLAY_ALPHA,
    STYLES,
    UNTRUSTED,
)

ROOT = Path(__file__).resolve().parents[1]
FIVE_BAR = ROOT / "configs" / "models" / "five_bar.yaml"
TRIAL = ROOT / "sample_data" / "five_bar.c3d"
SHARED = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"
FLAGGED_FRAMES = slice(50, 80)  # jump | poor_fit in the copy
MOVED = (120, "P6")  # a marker moved 0.3 m away in the copy
MISSING = (120, "P3")  # a marker removed in the copy
needs_chromium = pytest.mark.skipif(chromium_binary() is None,
                                    reason="no chromium binary (apt-get install chromium)")
SCREENSHOTS = os.environ.get("FCCGRB_VIEW_SCREENSHOTS")  # a folder to save the pages' pictures


@pytest.fixture(scope="module")
def five_bar(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The five-bar solved twice (nrm-wls and cno-sqp, 30 mm artefact) into one file."""
    path = tmp_path_factory.mktemp("view") / "five.h5"
    for method in ("nrm-wls", "cno-sqp"):
        result = run_cli("solve", FIVE_BAR, TRIAL, "--perturb", 30, "--method", method,
                         "-o", path)
        assert result.exit_code == 0, result.output
    return path


@pytest.fixture(scope="module")
def flagged(five_bar: Path) -> Path:
    """A copy whose nrm-wls run has frames flagged (jump and poor_fit), one marker 0.3 m off
    its place and one missing at frame 120 (its distances rewritten as the solver would)."""
    path = five_bar.with_name("flagged.h5")
    shutil.copyfile(five_bar, path)
    with h5py.File(path, "r+") as h5:
        run = h5["runs/nrm-wls-P30"]
        flags = run["flags"][()]
        flags[FLAGGED_FRAMES] |= 4 | 128
        run["flags"][...] = flags
        labels = [str(x) for x in run.attrs["labels"]]
        markers, ed = run["markers_input"][()], run["ed_input"][()]
        frame, moved = MOVED
        markers[frame, labels.index(moved), 2] += 0.3
        missing = labels.index(MISSING[1])
        markers[frame, missing] = np.nan
        ed[frame] = np.linalg.norm(markers[frame] - run["model_points"][frame], axis=1)
        run["markers_input"][...] = markers
        run["ed_input"][...] = ed
    return path


@pytest.fixture(scope="module")
def smoothed(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The five-bar solved with the whole-trial smoother: every angle and moment with its
    standard deviation."""
    path = tmp_path_factory.mktemp("smooth") / "smooth.h5"
    result = run_cli("solve", FIVE_BAR, TRIAL, "--perturb", 30, "--smooth", "auto", "--name",
                     "nrm-wls-P30", "-o", path)
    assert result.exit_code == 0, result.output
    return path


@pytest.fixture(scope="module")
def gait(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The shared gait trial calibrated and solved as the README shows."""
    if not SHARED.exists():
        pytest.skip("no ../shared/data/c3d/Qualisys.c3d")
    folder = tmp_path_factory.mktemp("gait")
    model, results = folder / "personal.yaml", folder / "gait.h5"
    lower = ROOT / "configs" / "models" / "lower_limb.yaml"
    assert run_cli("calibrate", lower, SHARED, "--mass", 67, "-o", model).exit_code == 0
    result = run_cli("solve", model, SHARED, "--method", "nrm-wls", "--filter-cutoff", 6,
                     "-o", results)
    assert result.exit_code == 0, result.output
    return results


# --- the projection and the decimation --------------------------------------------------------

def test_presets_project_as_their_closed_form() -> None:
    """z up, walking along x: frontal sees lateral (y) to the screen's right and up up;
    sagittal sees forward to the right; transverse (from above) forward right and y up; a
    point in the target's plane at offset (a, b) lands at centre + k (a, −b) / distance."""
    axes = lab_axes(np.array([0.0, 0.0, 1.0]), np.array([1.0, 0.0, 0.0]))
    target, distance, width, height = np.array([1.0, 2.0, 0.5]), 4.0, 800, 600
    k = 0.5 * height / math.tan(math.radians(20.0))
    offsets = np.array([[0.3, -0.2], [-0.5, 0.4]])
    cases = {"frontal": ([0, 1, 0], [0, 0, 1]), "sagittal": ([1, 0, 0], [0, 0, 1]),
             "transverse": ([1, 0, 0], [0, 1, 0])}
    for name, (right, up) in cases.items():
        cam = Camera.preset(name, target, distance)
        points = target + offsets[:, :1] * np.array(right) + offsets[:, 1:] * np.array(up)
        got = project(points, cam, axes, width, height)
        expected = np.column_stack([width / 2 + k * offsets[:, 0] / distance,
                                    height / 2 - k * offsets[:, 1] / distance,
                                    np.full(2, distance)])
        np.testing.assert_allclose(got, expected, atol=1e-9, err_msg=name)
    cam = Camera.preset("orbit", target, distance)
    back = np.cos(cam.pitch) * (np.cos(cam.yaw) * axes.forward + np.sin(cam.yaw) * axes.lateral) \
        + np.sin(cam.pitch) * axes.up
    ahead = project(np.stack([target, target - back, target + 2 * distance * back]), cam, axes,
                    width, height)
    np.testing.assert_allclose(ahead[:2, :2], [[width / 2, height / 2]] * 2, atol=1e-9)
    np.testing.assert_allclose(ahead[:, 2], [distance, distance + 1, -distance], atol=1e-12)


def test_lab_axes_are_right_handed_with_forward_horizontal() -> None:
    axes = lab_axes(np.array([0.0, 0.1, 1.0]), np.array([1.0, 0.0, 0.3]))
    basis = np.stack([axes.forward, axes.lateral, axes.up])
    np.testing.assert_allclose(basis @ basis.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(basis) == pytest.approx(1.0)
    assert axes.forward[0] > 0.99 and abs(axes.forward @ axes.up) < 1e-12


@pytest.mark.parametrize("n, per_frame, budget", [(1, 10, 5), (340, 1000, 10**9),
                                                   (10_000, 4000, 8_000_000), (7, 100, 300)])
def test_display_keeps_first_and_last_within_budget(n: int, per_frame: int, budget: int
                                                    ) -> None:
    frames = display_frames(n, per_frame, budget)
    assert frames[0] == 0 and frames[-1] == n - 1
    assert (np.diff(frames) > 0).all()
    steps = np.diff(frames[:-1])
    assert len(set(steps.tolist())) <= 1  # one stride (the last step may be shorter)
    stride = int(steps[0]) if len(steps) else 1
    assert (len(frames) - 1) * per_frame <= budget or stride == 1
    if stride > 1:  # the smallest stride that fits
        assert math.ceil(n / (stride - 1)) * per_frame > budget


# --- the scene against the file -------------------------------------------------------------

def test_scene_rebuilds_the_solver_points(five_bar: Path) -> None:
    scene = motion_scene(five_bar)
    with h5py.File(five_bar, "r") as h5:
        for layer in scene.layers:
            run = h5["runs"][layer.name]
            model_points = run["model_points"][()][scene.frames]
            labels = [str(x) for x in run.attrs["labels"]]
            # the skeleton's body points, placed from q through the model text
            for tracked in load_model(FIVE_BAR).tracked_points:
                drawn = layer.positions[:, layer.labels.index(f"{tracked.body}.{tracked.point}")]
                gap = np.linalg.norm(drawn - model_points[:, labels.index(tracked.marker)], axis=1)
                assert gap.max() < 1e-9, tracked
            markers = run["markers_input"][()][scene.frames]
            np.testing.assert_array_equal(layer.positions[:, layer.markers], markers)
            np.testing.assert_array_equal(layer.positions[:, layer.model_points], model_points)
            np.testing.assert_allclose(layer.distance, run["ed_input"][()][scene.frames])
            np.testing.assert_allclose(layer.distance,
                                       np.linalg.norm(markers - model_points, axis=2),
                                       atol=1e-12)
            np.testing.assert_array_equal(layer.flags, run["flags"][()])
            assert len(scene.time) == len(run["time"])
            np.testing.assert_allclose(scene.time,
                                       run.attrs["start_time_s"] + run["time"][()])


def test_frames_drawn_are_orthonormal_and_reduced_bodies_have_w(five_bar: Path) -> None:
    model = load_model(FIVE_BAR)
    with h5py.File(five_bar, "r") as h5:
        q = h5["runs/nrm-wls-P30/q"][()]
        topology = h5["runs/nrm-wls-P30/phi_top_max"][()]  # the rigid-body rows among them
    x = body_coordinates(model, q).reshape(len(q), -1, 4, 3)
    frames = x[:, :, 1:]
    gram = np.einsum("fbid,fbjd->fbij", frames, frames)
    assert (np.abs(gram - np.eye(3)).max(axis=(1, 2, 3)) <= topology + 1e-12).all()
    reduced = model.with_form("reduced")
    q_reduced = np.concatenate([x[:, :, :3].reshape(len(q), -1), q[:, x.shape[1] * 12:]],
                               axis=1)
    again = body_coordinates(reduced, q_reduced).reshape(x.shape)
    np.testing.assert_allclose(again[:, :, :3], x[:, :, :3], atol=0)
    np.testing.assert_allclose(again[:, :, 3], np.cross(x[:, :, 1], x[:, :, 2]), atol=1e-15)
    np.testing.assert_allclose(again[:, :, 3], x[:, :, 3], atol=10 * np.sqrt(topology.max()))


def test_curves_are_the_files(five_bar: Path) -> None:
    scene = motion_scene(five_bar, ("nrm-wls-P30",), curve="J3_w")
    angle, moment = scene.layers[0].curves
    with h5py.File(five_bar, "r") as h5:
        run = h5["runs/nrm-wls-P30"]
        k = [str(n) for n in run["theta"].attrs["names"]].index("J3_w")
        np.testing.assert_allclose(angle.values, np.degrees(run["theta"][:, k]))
        np.testing.assert_allclose(moment.values, run["joint_moments"][:, k])
        np.testing.assert_array_equal(moment.trusted, run["moment_flags"][:, k] == 0)
    assert (angle.unit, moment.unit) == ("deg", "N·m")


def test_bands_are_the_files_standard_deviations(smoothed: Path) -> None:
    angle, moment = motion_scene(smoothed, curve="J2_v").layers[0].curves
    with h5py.File(smoothed, "r") as h5:
        run = h5["runs/nrm-wls-P30"]
        k = [str(n) for n in run["theta"].attrs["names"]].index("J2_v")
        np.testing.assert_allclose(angle.sd, np.degrees(run["uncertainty/theta_sd"][:, k]))
        np.testing.assert_allclose(moment.sd, run["uncertainty/moments_sd"][:, k])
    assert (angle.sd > 0).all() and (moment.sd > 0).all()


@pytest.mark.parametrize("name", ["knee_flexion_r", "ankle_dorsiflexion_r"])  # signs + and −
def test_gait_curves_are_the_clinical_ones(gait: Path, name: str) -> None:
    scene = motion_scene(gait, curve=name)
    angle, moment = scene.layers[0].curves
    with h5py.File(gait, "r") as h5:
        clinical = h5["runs/nrm-wls-f6Hz/clinical"]
        k = [str(n) for n in clinical["angles"].attrs["names"]].index(name)
        np.testing.assert_allclose(angle.values, clinical["angles"][:, k], atol=1e-9)
        np.testing.assert_allclose(moment.values, clinical["moments"][:, k], atol=1e-9)
    assert angle.name == f"{name} (clinical)"


def test_plate_forces_start_at_the_centre_of_pressure(gait: Path) -> None:
    scene = motion_scene(gait)
    layer = scene.layers[0]
    with h5py.File(gait, "r") as h5:
        loads = h5["runs/nrm-wls-f6Hz/loads"]
        for name in loads:
            force, point = loads[name]["force"][()], loads[name]["point"][()]
            cop = next(i for i, t in enumerate(layer.labels) if t.startswith(f"{name} on "))
            line = next(j for j, (kind, t) in enumerate(zip(layer.line_kinds, layer.line_labels,
                                                            strict=True))
                        if kind == "force" and t == name)
            start, end = layer.lines[line]
            assert start == cop
            loaded = np.linalg.norm(force, axis=1) >= 20.0
            assert loaded.any() and (~loaded).any()
            np.testing.assert_allclose(layer.positions[loaded, start], point[loaded])
            np.testing.assert_allclose(layer.positions[loaded, end] - point[loaded],
                                       force[loaded] / 1000.0)  # 1 m per 1000 N
            assert np.isnan(layer.positions[~loaded, start]).all()


def test_model_view_is_the_initial_pose() -> None:
    """The five-bar lies along x at its initial pose: P6 (B5's end) at x = 1.4 m, J3 at B2's
    P3 (0.65 m), J1's axis the ground's z through O, B3's u along x."""
    scene = model_scene(load_model(FIVE_BAR))
    layer = scene.layers[0]
    where = {label: layer.positions[0, i] for i, label in enumerate(layer.labels) if label}
    np.testing.assert_allclose(where["B5.P6 ← P6"], [1.4, 0, 0], atol=1e-12)
    np.testing.assert_allclose(where["J3 (revolute)"], [0.65, 0, 0], atol=1e-12)
    np.testing.assert_allclose(where["B2.P9 ← P9"], [0.475, 0, 0.08], atol=1e-12)
    axis = next(k for k, t in enumerate(layer.line_labels) if t.startswith("J1 axis"))
    ends = layer.positions[0, layer.lines[axis]]
    np.testing.assert_allclose(ends[:, :2], 0, atol=1e-12)
    assert ends[0, 2] == -ends[1, 2] and ends[1, 2] > 0
    u = next(k for k, t in enumerate(layer.line_labels) if t == "B3.u")
    start, end = layer.positions[0, layer.lines[u]]
    np.testing.assert_allclose(start, [0.8, 0, 0], atol=1e-12)
    assert end[0] > start[0] and np.allclose(end[1:], 0)
    kinds = set(layer.kinds) | set(layer.line_kinds)
    assert {"origin", "joint", "model_point", "u", "v", "w", "axis", "segment"} <= kinds
    tracked = [t for t, kind in zip(layer.labels, layer.kinds, strict=True)
               if kind == "model_point"]
    assert len(tracked) == 9


def test_still_svg_draws_the_projected_file_points(five_bar: Path, tmp_path: Path) -> None:
    out = tmp_path / "still.svg"
    result = run_cli("view", five_bar, "--run", "nrm-wls-P30", "--frame", 123, "--camera",
                     "sagittal", "-o", out)
    assert result.exit_code == 0, result.output
    text = out.read_text(encoding="utf-8")
    dots = np.array([[float(x), float(y)] for x, y in re.findall(
        r'class="model_point" cx="([-\d.]+)" cy="([-\d.]+)"', text)])
    scene = motion_scene(five_bar, ("nrm-wls-P30",), frames=np.array([123]))
    with h5py.File(five_bar, "r") as h5:
        points = h5["runs/nrm-wls-P30/model_points"][123]
    target, distance = framing(scene.layers[0].positions)
    expected = project(points, Camera.preset("sagittal", target, distance), scene.axes,
                       900, 560)[:, :2]
    np.testing.assert_allclose(dots, expected, atol=0.06)  # the SVG's 0.1 px
    assert "frame 123" in text and 'class="vertical"' in text


def test_still_svg_colours_what_the_file_distrusts(flagged: Path, tmp_path: Path) -> None:
    """Frame 60 (flagged): the first run's segments red; frame 120: the moved marker amber, the
    missing one not drawn; frame 10: neither; the second run drawn translucent under it."""
    pictures = {}
    for frame in (10, 60, 120):
        out = tmp_path / f"{frame}.svg"
        result = run_cli("view", flagged, "--run", "nrm-wls-P30", "--run", "cno-sqp-P30",
                         "--frame", frame, "-o", out)
        assert result.exit_code == 0, result.output
        pictures[frame] = out.read_text(encoding="utf-8")
    red = f'class="segment" x1="[^"]*" y1="[^"]*" x2="[^"]*" y2="[^"]*" stroke="{FLAGGED}"'
    amber = f'fill="{UNTRUSTED}"><title>([^<]*)</title>'
    assert len(re.findall(red, pictures[60])) > 5 and not re.findall(red, pictures[10])
    assert re.findall(amber, pictures[120]) == [MOVED[1]]
    assert not re.findall(amber, pictures[10]) and not re.findall(amber, pictures[60])
    assert pictures[10].index(f'<g opacity="{OVERLAY_ALPHA:g}">') < pictures[10].index(
        '<g opacity="1">')  # the second run first, under the first
    assert f'stroke="{OVERLAY}"' in pictures[10]


@pytest.mark.parametrize("args, fragments", [
    (["-o", "{tmp}/x.png"], ["-o", ".html", "screenshot"]),
    (["--frame", 300, "-o", "{tmp}/x.svg"], ["--frame", "0 to 299"]),
    (["-o", "{tmp}/x.svg"], ["--frame"]),
    (["--frame", 3, "-o", "{tmp}/x.html"], ["--frame", ".svg"]),
    (["--run", "nope", "-o", "{tmp}/x.html"], ["--run", "nrm-wls-P30", "nope"]),
    (["--run", "a", "--run", "b", "--run", "c", "-o", "{tmp}/x.html"], ["--run", "two"]),
    (["--curve", "J9", "-o", "{tmp}/x.html"], ["--curve", "J9", "J1_z"]),
])
def test_bad_input_is_one_line(five_bar: Path, tmp_path: Path, args: list,
                               fragments: list[str]) -> None:
    args = [str(a).format(tmp=tmp_path) for a in args]
    one_error_line(run_cli("view", five_bar, *args), *fragments)
    assert list(tmp_path.iterdir()) == []


def test_bad_sources_are_one_line(tmp_path: Path) -> None:
    out = tmp_path / "x.html"
    one_error_line(run_cli("view", TRIAL, "-o", out), str(TRIAL), ".h5", ".yaml")
    one_error_line(run_cli("view", FIVE_BAR, "--frame", 1, "-o", out), "--frame")
    broken = tmp_path / "broken.h5"
    broken.write_bytes(b"not hdf5")
    one_error_line(run_cli("view", broken, "-o", out), str(broken))
    one_error_line(run_cli("view", tmp_path / "none.h5", "-o", out), "none.h5")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["broken.h5"]


def test_three_runs_need_a_choice(five_bar: Path, tmp_path: Path) -> None:
    three = tmp_path / "three.h5"
    shutil.copyfile(five_bar, three)
    with h5py.File(three, "r+") as h5:
        h5.copy(h5["runs/nrm-wls-P30"], h5["runs"], "again")
    out = tmp_path / "x.html"
    one_error_line(run_cli("view", three, "-o", out), "3 runs", "again", "--run")
    assert not out.exists()
    result = run_cli("view", three, "--run", "again", "--run", "cno-sqp-P30", "-o", out)
    assert result.exit_code == 0, result.output
    assert "again vs cno-sqp-P30" in result.output


def test_an_existing_output_survives_an_error(five_bar: Path, tmp_path: Path) -> None:
    out = tmp_path / "motion.html"
    out.write_text("old", encoding="utf-8")
    one_error_line(run_cli("view", five_bar, "--curve", "J9", "-o", out), "--curve")
    assert out.read_text(encoding="utf-8") == "old"


# --- in the browser -----------------------------------------------------------------------

def _pixels(png: bytes) -> np.ndarray:
    image = pytest.importorskip("matplotlib.image")
    return (image.imread(io.BytesIO(png))[:, :, :3] * 255).round().astype(int)


def _count(region: np.ndarray, rgb, tolerance: int = 12) -> int:
    return int((np.abs(region - np.array(rgb)).max(axis=2) <= tolerance).sum())


def _rgb(color: str) -> tuple[int, int, int]:
    return tuple(int(color[k:k + 2], 16) for k in (1, 3, 5))


def _canvas(browser: Browser) -> np.ndarray:
    x, y, w, h = (round(v) for v in browser.evaluate(
        "(() => { const r = document.getElementById('view').getBoundingClientRect();"
        " return [r.left + scrollX, r.top + scrollY, r.width, r.height]; })()"))
    return _pixels(browser.screenshot())[y:y + h, x:x + w]


def _at(browser: Browser, frame: int) -> int:
    """Show file frame ``frame`` (it must be displayed); its display index."""
    k = browser.evaluate(f"Array.from(fccgrbView.frames).indexOf({frame})")
    assert k >= 0
    browser.evaluate(f"fccgrbView.setFrame({k})")
    return k


def _opens_clean(browser: Browser, page: Path):
    loaded = browser.open(page)
    assert loaded.messages == [], loaded.messages
    assert all(url.startswith("file:") for url in loaded.requests), loaded.requests
    return loaded


def _check_projection(browser: Browser, scene_axes, points: np.ndarray) -> None:
    """The page's projection equals camera.py's for the page's own camera and canvas."""
    cam = browser.evaluate("(() => { const c = fccgrbView.camera, v = "
                           "document.getElementById('view'); return {...c, w: v.width, "
                           "h: v.height}; })()")
    got = np.array(browser.evaluate(f"{points.tolist()}.map(p => fccgrbView.project(p))"))
    camera = Camera(np.array(cam["target"]), cam["yaw"], cam["pitch"], cam["distance"],
                    cam["fov"])
    np.testing.assert_allclose(got, project(points, camera, scene_axes, cam["w"], cam["h"]),
                               rtol=1e-9, atol=1e-9)


@needs_chromium
def test_five_bar_page_in_a_browser(flagged: Path, tmp_path: Path) -> None:
    page = tmp_path / "five.html"
    result = run_cli("view", flagged, "--run", "nrm-wls-P30", "--run", "cno-sqp-P30",
                     "--camera", "sagittal", "-o", page)
    assert result.exit_code == 0, result.output
    scene = motion_scene(flagged, ("nrm-wls-P30", "cno-sqp-P30"))
    with Browser() as browser, h5py.File(flagged, "r") as h5:
        _opens_clean(browser, page)
        run = h5["runs/nrm-wls-P30"]
        n = len(run["time"])
        assert browser.evaluate("fccgrbView.time.length") == n
        assert browser.evaluate("fccgrbView.frames.length") == len(scene.frames)
        assert browser.evaluate("fccgrbView.layers.map(L => L.name)") == \
            ["nrm-wls-P30", "cno-sqp-P30"]
        for frame in (0, 10, 60, 120, n - 1):
            _at(browser, frame)
            clock = browser.evaluate("document.getElementById('clock').textContent")
            t = run.attrs["start_time_s"] + run["time"][frame]
            assert clock == f"t = {t:.3f} s · frame {frame} of {n} (0–{n - 1})"
        _at(browser, 10)
        trusted = _canvas(browser)
        assert trusted[..., 0].size - _count(trusted, (255, 255, 255), 0) > 5000  # drawn
        assert _count(trusted, _rgb(str(STYLES["segment"]["color"]))) > 50
        assert browser.evaluate("document.getElementById('status').textContent") == ""
        assert _count(trusted, _rgb(FLAGGED)) == 0
        assert _count(trusted, _rgb(UNTRUSTED)) == 0
        overlay = np.array(_rgb(OVERLAY)) * OVERLAY_ALPHA + 255 * (1 - OVERLAY_ALPHA)
        assert _count(trusted, overlay.round().astype(int)) > 20  # the second run's halo
        _at(browser, 60)
        flagged_frame = _canvas(browser)
        assert _count(flagged_frame, _rgb(FLAGGED)) > 50
        status = browser.evaluate("document.getElementById('status').textContent")
        assert status.startswith("nrm-wls-P30: frame 60 not trusted — jump: ")
        assert "poor_fit: " in status and "cno-sqp-P30" not in status
        assert np.abs(flagged_frame - trusted).max(axis=2).astype(bool).sum() > 200  # moved
        _at(browser, 120)
        moved = _canvas(browser)
        assert _count(moved, _rgb(UNTRUSTED)) > 10
        hover = browser.evaluate("fccgrbView.state.drawn.map(d => fccgrbView.hoverText(d))")
        assert any(t.startswith(f"nrm-wls-P30: {MOVED[1]} — ") and "beyond" in t
                   for t in hover), hover
        assert not any(t.startswith(f"nrm-wls-P30: {MISSING[1]} — ") for t in hover)
        strip = browser.evaluate("(() => { const c = document.getElementById('flags'); "
                                 "const d = c.getContext('2d').getImageData(0, 0, c.width, 1)"
                                 ".data; const out = []; for (let x = 0; x < c.width; x++) "
                                 "out.push(d[4 * x] === 208 && d[4 * x + 1] === 2); "
                                 "return out; })()")
        red = np.flatnonzero(strip) / len(strip) * n
        assert red.min() >= FLAGGED_FRAMES.start - 1 and red.max() <= FLAGGED_FRAMES.stop + 1
        _check_projection(browser, scene.axes, scene.layers[0].positions[0, :5])
        if SCREENSHOTS:
            _at(browser, 60)
            Path(SCREENSHOTS, "view_five_bar.png").write_bytes(browser.screenshot())
        browser.evaluate("fccgrbView.setFrame(0); fccgrbView.play(true)")
        time.sleep(1.0)
        state = browser.evaluate("fccgrbView.play(false), fccgrbView.state")
        assert state["k"] > 10 and state["draws"] > 10


@needs_chromium
def test_gait_page_in_a_browser(gait: Path, tmp_path: Path) -> None:
    page = tmp_path / "gait.html"
    assert run_cli("view", gait, "-o", page).exit_code == 0
    scene = motion_scene(gait)
    with Browser() as browser, h5py.File(gait, "r") as h5:
        _opens_clean(browser, page)
        run = h5["runs/nrm-wls-f6Hz"]
        n = len(run["time"])
        assert browser.evaluate("fccgrbView.time.length") == n
        assert browser.evaluate("fccgrbView.frames.length") == n  # 340 frames: all shown
        first = _canvas(browser)
        assert first[..., 0].size - _count(first, (255, 255, 255), 0) > 5000
        assert _count(first, _rgb(str(STYLES["segment"]["color"]))) > 50
        _at(browser, 200)
        later = _canvas(browser)
        assert np.abs(later - first).max(axis=2).astype(bool).sum() > 200
        assert _count(later, _rgb(str(STYLES["force"]["color"]))) > 5  # plate 2 loads foot_r
        clock = browser.evaluate("document.getElementById('clock').textContent")
        assert clock.startswith(f"t = {run.attrs['start_time_s'] + run['time'][200]:.3f} s")
        _check_projection(browser, scene.axes, scene.layers[0].positions[200, :5])
        if SCREENSHOTS:
            Path(SCREENSHOTS, "view_gait.png").write_bytes(browser.screenshot())


@needs_chromium
def test_band_drawn_under_the_curve(smoothed: Path, five_bar: Path, tmp_path: Path) -> None:
    """The curves' standard-deviation band is on the page's curve canvas (the curve's colour
    at the band's transparency over white), and not on the page of a run without one. The
    five-bar's own bands are under a pixel: the copy's moment has a standard deviation of 3 N·m
    (a seventh of its range), as a noisier trial's would."""
    wide = tmp_path / "wide.h5"
    shutil.copyfile(smoothed, wide)
    with h5py.File(wide, "r+") as h5:
        run = h5["runs/nrm-wls-P30"]
        k = [str(n) for n in run["theta"].attrs["names"]].index("J2_v")
        sd = run["uncertainty/moments_sd"][()]
        sd[:, k] = 3.0
        run["uncertainty/moments_sd"][...] = sd
    band = (np.array(_rgb(CURVE)) * BAND_ALPHA + 255 * (1 - BAND_ALPHA)).round().astype(int)
    counts = []
    with Browser() as browser:
        for results in (wide, five_bar):
            page = tmp_path / f"{results.stem}.html"
            result = run_cli("view", results, "--run", "nrm-wls-P30", "--curve", "J2_v", "-o",
                             page)
            assert result.exit_code == 0, result.output
            _opens_clean(browser, page)
            x, y, w, h = (round(v) for v in browser.evaluate(
                "(() => { const r = document.getElementById('curves').getBoundingClientRect();"
                " return [r.left + scrollX, r.top + scrollY, r.width, r.height]; })()"))
            counts.append(_count(_pixels(browser.screenshot())[y:y + h, x:x + w], band, 3))
    assert counts[0] > 5000 and counts[1] < 500, counts


@needs_chromium
def test_model_page_in_a_browser(tmp_path: Path) -> None:
    page = tmp_path / "model.html"
    assert run_cli("view", FIVE_BAR, "-o", page).exit_code == 0
    with Browser() as browser:
        _opens_clean(browser, page)
        drawn = browser.evaluate("fccgrbView.state.drawn.map(d => fccgrbView.hoverText(d))")
        for label in ("J1 (revolute)", "J4 (spherical)", "B5.P6 ← P6", "B1"):
            assert f"five_bar: {label}" in drawn, (label, drawn)
        canvas = _canvas(browser)
        for kind in ("u", "v", "w", "joint", "axis", "model_point"):
            assert _count(canvas, _rgb(str(STYLES[kind]["color"]))) > 3, kind
        if SCREENSHOTS:
            Path(SCREENSHOTS, "view_model.png").write_bytes(browser.screenshot())


def test_presets_are_the_cli_choices() -> None:
    from fccgrb_cli.cli.main import view

    choices = next(p for p in view.params if p.name == "camera").type.choices
    assert list(choices) == list(PRESETS)


def test_skeleton_of_every_model_file_places() -> None:
    """Every shipped model draws: its skeleton placed at its initial pose is finite."""
    for path in sorted((ROOT / "configs" / "models").glob("*.yaml")):
        model = load_model(path)
        s = skeleton(model)
        assert np.isfinite(s.place(pose_coordinates(model))).all(), path.name
