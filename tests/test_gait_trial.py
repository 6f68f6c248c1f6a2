"""Gait: force-plate contacts, ``fccgrb calibrate`` and a real walking trial end to end.

1. ``dynamics.contact``: runs of loaded frames (at the array's edges too) and the assignment of
   each run to the contact body whose points are on average nearest the centre of pressure, or
   to none beyond ``max_distance``; synthetic arrays whose answers are worked out by hand.
2. ``fccgrb calibrate`` bad input: each case gives one ``fccgrb: error:`` line naming the option,
   file or key, exit status 2, and leaves nothing in the output folder. The cases run on a static
   trial built here from the template's own standing posture (so they need no shared data), and
   a positive control on that trial checks that the same command succeeds, with the segment
   lengths of the posture the trial was built from.
3. The Qualisys walking trial in ``../shared/data/c3d`` (skipped when absent, read in place, never
   copied): calibrate at 67 kg, solve by NRM-WLS with a 6 Hz filter, then check convergence, the
   marker fit, and that each force plate went to the foot whose heel strike (C3D EVENT
   parameters, read here with ezc3d) starts its load; a ``loads.force_plates`` override moves
   plate 1 to the right foot. The results are checked against physics computed here from the
   file and the personal YAML: the angles are those of the solved vectors, the rates those of
   the positions, the pelvis residual wrench the whole body's Newton–Euler with the plates, every
   joint moment the moment balance of the segments distal to it, and left and right agree.
4. The trial is not modified by any of this (SHA-256 before and after).

Also: ``--mass nan`` / ``inf`` are refused as ``--mass``; ``clinical/stance/<body>`` is the plate's
own contact (not the low-passed force's spread).
"""

from __future__ import annotations

import hashlib
import os
import re
from dataclasses import dataclass
from pathlib import Path

import ezc3d
import h5py
import numpy as np
import pytest
import yaml
from cli_helpers import one_error_line, run_cli
from click.testing import Result

from fccgrb_cli.dynamics.contact import Contact, assign, contacts
from fccgrb_cli.trial.record import write_trial

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "configs" / "models" / "lower_limb.yaml"
QUALISYS = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"

SIDES = {"r": "right", "l": "left"}
ANGLES = tuple(f"{name}_{s}" for s in SIDES for name in (
    "hip_flexion", "hip_adduction", "hip_rotation", "knee_flexion", "ankle_dorsiflexion",
    "ankle_inversion"))


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def listing(folder: Path) -> list[str]:
    """Every name in the folder, hidden (temporary) files included."""
    return sorted(os.listdir(folder))


def succeeded(result: Result) -> None:
    assert result.exit_code == 0, (result.exit_code, result.output, result.stderr,
                                   result.exception)
    assert result.exception is None, repr(result.exception)


# ---- 1. contacts and their assignment (synthetic arrays) -----------------------------------


def test_contacts_are_the_runs_of_loaded_frames() -> None:
    loaded = np.array([0, 1, 1, 0, 0, 1, 0, 1, 1, 1], dtype=bool)
    assert contacts(loaded) == [(1, 3), (5, 6), (7, 10)]


def test_contacts_at_both_edges_of_the_trial() -> None:
    # loaded in the first frame and in the last one: [0, 2) and [5, 7)
    loaded = np.array([1, 1, 0, 0, 0, 1, 1], dtype=bool)
    assert contacts(loaded) == [(0, 2), (5, 7)]
    assert contacts(np.ones(4, dtype=bool)) == [(0, 4)]
    assert contacts(np.ones(1, dtype=bool)) == [(0, 1)]
    assert contacts(np.zeros(6, dtype=bool)) == []


def test_assign_at_both_edges() -> None:
    n = 8
    loaded = np.zeros(n, dtype=bool)
    loaded[:3] = loaded[6:] = True
    cop = np.zeros((n, 3))
    foot = np.zeros((n, 1, 3))
    foot[:, 0, 0] = 0.05  # 50 mm from the centre of pressure in every frame
    out = assign(loaded, cop, {"foot": foot})
    assert [(c.start, c.stop, c.body) for c in out] == [(0, 3, "foot"), (6, 8, "foot")]
    assert [c.distance for c in out] == pytest.approx([0.05, 0.05], abs=1e-12)


def test_two_contacts_on_one_plate_go_to_two_bodies() -> None:
    """First contact under the left foot, second under the right; each foot has two points,
    the nearer of which counts; the distance is the mean over the contact's frames."""
    n = 20
    loaded = np.zeros(n, dtype=bool)
    loaded[2:7] = True    # contact A: frames [2, 7)
    loaded[12:18] = True  # contact B: frames [12, 18)
    cop = np.full((n, 3), np.nan)  # undefined while unloaded: must not matter
    cop[2:7] = [0.2, 0.3, 0.0]
    cop[12:18] = [0.8, 0.2, 0.0]
    left = np.zeros((n, 2, 3))
    right = np.zeros((n, 2, 3))
    left[:, 0] = [0.2, 0.3, 0.06]    # heel 60 mm above contact A's centre of pressure
    left[:, 1] = [0.4, 0.3, 0.06]    # toe: farther
    right[:, 0] = [0.8, 0.2, 0.05]   # heel 50 mm above contact B's centre of pressure
    right[:, 1] = [1.0, 0.2, 0.05]
    # during contact B the left foot swings past, 30 mm away in one frame only: the mean decides
    left[15, 0] = [0.8, 0.2, 0.03]
    out = assign(loaded, cop, {"foot_l": left, "foot_r": right})
    assert [(c.start, c.stop, c.body) for c in out] == [(2, 7, "foot_l"), (12, 18, "foot_r")]
    assert out[0].distance == pytest.approx(0.06, abs=1e-12)
    assert out[1].distance == pytest.approx(0.05, abs=1e-12)
    assert all(isinstance(c, Contact) for c in out)


def test_nearest_on_average_not_in_one_frame() -> None:
    """Body B is nearer in half the frames (0 mm) but 200 mm away in the others (mean 100 mm);
    body A is 80 mm away throughout: A wins."""
    n = 4
    loaded = np.ones(n, dtype=bool)
    cop = np.zeros((n, 3))
    a = np.tile([[[0.08, 0.0, 0.0]]], (n, 1, 1))
    b = np.zeros((n, 1, 3))
    b[2:, 0, 1] = 0.2
    (c,) = assign(loaded, cop, {"B": b, "A": a})
    assert (c.body, c.start, c.stop) == ("A", 0, 4)
    assert c.distance == pytest.approx(0.08, abs=1e-12)


def test_a_contact_farther_than_max_distance_goes_to_no_body() -> None:
    n = 6
    loaded = np.zeros(n, dtype=bool)
    loaded[1:4] = True
    cop = np.zeros((n, 3))
    foot = np.tile([[[0.3, 0.0, 0.0]]], (n, 1, 1))  # 300 mm: beyond the default 250 mm
    (c,) = assign(loaded, cop, {"foot_r": foot, "foot_l": foot + np.array([0.0, 0.1, 0.0])})
    assert c.body is None
    assert (c.start, c.stop) == (1, 4)
    assert c.distance == pytest.approx(0.3, abs=1e-12)  # the nearest body's distance, still
    (c,) = assign(loaded, cop, {"foot_r": foot}, max_distance=0.2)
    assert c.body is None
    (c,) = assign(loaded, cop, {"foot_r": foot}, max_distance=0.35)
    assert c.body == "foot_r"


# ---- 2. calibrate: a static trial from the template, and bad input -------------------------

STATIC_FRAMES = 30
STATIC_RATE = 100.0


def template_doc() -> dict:
    return yaml.safe_load(TEMPLATE.read_text(encoding="utf-8"))


def _global(pose: dict, local: list[float]) -> np.ndarray:
    """r + a u + b v + c w."""
    a, b, c = local
    return (np.asarray(pose["r"], float) + a * np.asarray(pose["u"], float)
            + b * np.asarray(pose["v"], float) + c * np.asarray(pose["w"], float))


@dataclass(frozen=True)
class Static:
    path: Path
    labels: tuple[str, ...]
    markers: dict[str, np.ndarray]  # label → global position, m


@pytest.fixture(scope="module")
def static(tmp_path_factory: pytest.TempPathFactory) -> Static:
    """A quiet-standing trial: every marker the template names, placed where the template's
    initial poses put it, except the PSIS, moved level with the ASIS (v = 0) so that the ISB
    pelvis frame built from them is the template's pelvis frame itself."""
    doc = template_doc()
    markers: dict[str, np.ndarray] = {}
    labels = set(doc["calibration"]["landmarks"].values())
    labels |= {tp["marker"] for tp in doc["tracking"]["points"]}
    for body in doc["bodies"].values():
        for name, local in body["points"].items():
            if name in labels:
                if name in ("R_IPS", "L_IPS"):
                    local = [local[0], 0.0, local[2]]
                markers[name] = _global(body["pose"], local)
    assert set(markers) == labels
    order = tuple(sorted(markers))
    xyz = np.tile(np.array([markers[k] for k in order])[None], (STATIC_FRAMES, 1, 1))
    path = tmp_path_factory.mktemp("static") / "static.c3d"
    write_trial(path, list(order), xyz, STATIC_RATE, "mm")
    return Static(path, order, markers)


def write_template(folder: Path, doc: dict, name: str = "template.yaml") -> Path:
    path = folder / name
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def refused(result: Result, folder: Path, before: list[str], output: Path,
            *fragments: str) -> None:
    one_error_line(result, *fragments)
    assert not output.exists()
    assert listing(folder) == before  # no temporary file left either


def test_calibrate_the_static_trial(static: Static, tmp_path: Path) -> None:
    """Positive control for the bad-input cases below, and a check of the measured lengths.
    Pelvic width PW = 240 mm (ASIS ±120 mm) and depth PD = 160 mm (PSIS 160 mm behind) give
    Harrington et al.'s (2007) hip centre x = −0.24 PD − 9.9 mm, y = −0.30 PW − 10.9 mm,
    z = ±(0.33 PW + 7.3 mm) in the pelvis frame; the knee and ankle centres are midway between
    the epicondyles and the malleoli; the foot runs from the heel to the mid-metatarsal heads."""
    before = digest(static.path)
    out = tmp_path / "personal.yaml"
    result = run_cli("calibrate", TEMPLATE, static.path, "-o", out, "--mass", 70)
    succeeded(result)
    assert out.is_file()
    m = static.markers
    pw, pd = 0.240, 0.160
    pelvis = template_doc()["bodies"]["pelvis"]["pose"]
    expected = {}
    for s in SIDES:
        z = (0.33 * pw + 0.0073) * (1 if s == "r" else -1)
        hip = _global(pelvis, [-0.24 * pd - 0.0099, -0.30 * pw - 0.0109, z])
        S = s.upper()
        knee = 0.5 * (m[f"{S}_FLE"] + m[f"{S}_FME"])
        ankle = 0.5 * (m[f"{S}_FAL"] + m[f"{S}_TAM"])
        toes = 0.5 * (m[f"{S}_FM1"] + m[f"{S}_FM5"])
        expected[f"thigh_{s}"] = np.linalg.norm(knee - hip)
        expected[f"shank_{s}"] = np.linalg.norm(ankle - knee)
        expected[f"foot_{s}"] = np.linalg.norm(toes - m[f"{S}_FCC"])
    # by construction of the template: 420, 410 and 190 mm
    assert expected["shank_r"] == pytest.approx(0.41, abs=1e-9)
    assert expected["foot_l"] == pytest.approx(np.hypot(0.19, 0.0025), abs=1e-9)
    personal = yaml.safe_load(out.read_text(encoding="utf-8"))["bodies"]
    for s in SIDES:
        thigh = np.linalg.norm(personal[f"thigh_{s}"]["points"]["KJC"])
        shank = np.linalg.norm(personal[f"shank_{s}"]["points"]["AJC"])
        assert thigh == pytest.approx(expected[f"thigh_{s}"], abs=5e-4), s
        assert shank == pytest.approx(expected[f"shank_{s}"], abs=5e-4), s
    printed = {k: float(v) for k, v in re.findall(r"(\w+_[rl]) (\d+)", result.stdout)}
    for name, value in expected.items():
        assert printed[name] == pytest.approx(1e3 * value, abs=0.51), name  # printed in mm
    assert "pelvis width 240 mm, depth 160 mm" in result.stdout
    assert digest(static.path) == before


@pytest.mark.parametrize("frames", ["5", "a:b", "10:5", "5:5", "-1:3", "1:2:3", "", "3:"])
def test_calibrate_malformed_frames(static: Static, tmp_path: Path, frames: str) -> None:
    out = tmp_path / "personal.yaml"
    before = listing(tmp_path)
    result = run_cli("calibrate", TEMPLATE, static.path, "-o", out, f"--frames={frames}")
    refused(result, tmp_path, before, out, "--frames", "A:B")


@pytest.mark.parametrize("frames", [f"0:{STATIC_FRAMES + 1}",
                                    f"{STATIC_FRAMES}:{STATIC_FRAMES + 5}", "25:400"])
def test_calibrate_frames_beyond_the_trial(static: Static, tmp_path: Path, frames: str) -> None:
    out = tmp_path / "personal.yaml"
    before = listing(tmp_path)
    result = run_cli("calibrate", TEMPLATE, static.path, "-o", out, "--frames", frames)
    refused(result, tmp_path, before, out, "--frames", frames, str(STATIC_FRAMES))


def test_calibrate_frames_inside_the_trial_are_accepted(static: Static, tmp_path: Path) -> None:
    """The boundary just inside: B equal to the frame count (B is excluded)."""
    out = tmp_path / "personal.yaml"
    result = run_cli("calibrate", TEMPLATE, static.path, "-o", out, "--frames",
                     f"{STATIC_FRAMES - 1}:{STATIC_FRAMES}")
    succeeded(result)
    assert out.is_file()
    assert f"frame indices {STATIC_FRAMES - 1}:{STATIC_FRAMES}" in result.stdout


def test_calibrate_landmark_label_absent_from_the_trial(static: Static, tmp_path: Path) -> None:
    doc = template_doc()
    doc["calibration"]["landmarks"]["right_asis"] = "R_ASIS_NOWHERE"
    template = write_template(tmp_path, doc)
    out = tmp_path / "personal.yaml"
    before = listing(tmp_path)
    result = run_cli("calibrate", template, static.path, "-o", out)
    refused(result, tmp_path, before, out, str(static.path), "R_ASIS_NOWHERE",
            "calibration.landmarks.right_asis")


def test_calibrate_template_missing_a_landmark(static: Static, tmp_path: Path) -> None:
    doc = template_doc()
    del doc["calibration"]["landmarks"]["left_medial_malleolus"]
    template = write_template(tmp_path, doc)
    out = tmp_path / "personal.yaml"
    before = listing(tmp_path)
    result = run_cli("calibrate", template, static.path, "-o", out)
    refused(result, tmp_path, before, out, str(template), "calibration.landmarks",
            "left_medial_malleolus")


def test_calibrate_template_missing_a_body(static: Static, tmp_path: Path) -> None:
    """foot_l removed with its joint, its two angles, its tracked markers and its contact: a
    valid model (checked first with ``fccgrb check``), but not the lower limbs calibrate needs."""
    doc = template_doc()
    del doc["bodies"]["foot_l"]
    doc["joints"] = [j for j in doc["joints"] if "foot_l" not in j["bodies"]]
    doc["angles"] = [a for a in doc["angles"]
                     if not any(v.startswith("foot_l.") for v in a["vectors"])]
    doc["tracking"]["points"] = [t for t in doc["tracking"]["points"]
                                 if not t["point"].startswith("foot_l.")]
    doc["loads"]["contact"] = ["foot_r"]
    assert len(doc["angles"]) == 10
    template = write_template(tmp_path, doc)
    succeeded(run_cli("check", template))
    out = tmp_path / "personal.yaml"
    before = listing(tmp_path)
    result = run_cli("calibrate", template, static.path, "-o", out)
    refused(result, tmp_path, before, out, str(template), "bodies", "foot_l")


def test_calibrate_missing_trial(tmp_path: Path) -> None:
    trial = tmp_path / "absent.c3d"
    out = tmp_path / "personal.yaml"
    before = listing(tmp_path)
    result = run_cli("calibrate", TEMPLATE, trial, "-o", out)
    refused(result, tmp_path, before, out, str(trial), "not found")


@pytest.mark.parametrize("mass", ["0", "-67"])
def test_calibrate_refuses_a_mass_that_is_not_positive(static: Static, tmp_path: Path,
                                                       mass: str) -> None:
    """click refuses it (its own usage message), exit status 2 and no file."""
    out = tmp_path / "personal.yaml"
    before = listing(tmp_path)
    result = run_cli("calibrate", TEMPLATE, static.path, "-o", out, f"--mass={mass}")
    assert result.exit_code == 2, (result.output, result.exception)
    assert "Traceback" not in result.output + result.stderr
    assert "--mass" in result.stderr
    assert not out.exists()
    assert listing(tmp_path) == before


@pytest.mark.parametrize("mass", ["nan", "inf"])
def test_calibrate_refuses_a_mass_that_is_not_finite(static: Static, tmp_path: Path,
                                                     mass: str) -> None:
    out = tmp_path / "personal.yaml"
    before = listing(tmp_path)
    result = run_cli("calibrate", TEMPLATE, static.path, "-o", out, f"--mass={mass}")
    assert not out.exists()
    assert listing(tmp_path) == before
    one_error_line(result, "--mass")


# ---- 3. the Qualisys walking trial ---------------------------------------------------------

BODY_MASS = 67.0  # kg
G = 9.81
THRESHOLD = 20.0  # N: the template's loads.threshold (checked on the calibrated model)


@pytest.fixture(scope="module")
def qualisys() -> Path:
    if not QUALISYS.is_file():
        pytest.skip(f"{QUALISYS} is not present")
    return QUALISYS


@dataclass(frozen=True)
class Gait:
    trial: Path
    digest_before: str
    beside_before: list[str]
    folder: Path
    model: Path
    calibrate: Result
    solve: Result | None  # None when calibrate wrote no model
    results: Path


@pytest.fixture(scope="module")
def gait(qualisys: Path, tmp_path_factory: pytest.TempPathFactory) -> Gait:
    before = digest(qualisys)
    beside = listing(qualisys.parent)
    folder = tmp_path_factory.mktemp("gait")
    model = folder / "personal.yaml"
    calibrated = run_cli("calibrate", TEMPLATE, qualisys, "--mass", BODY_MASS, "-o", model)
    results = folder / "r.h5"
    solved = run_cli("solve", model, qualisys, "--method", "nrm-wls", "--filter-cutoff", 6,
                     "-o", results) if model.is_file() else None
    return Gait(qualisys, before, beside, folder, model, calibrated, solved, results)


def the_run(path: Path) -> h5py.Group:
    h5 = h5py.File(path, "r")
    (name,) = list(h5["runs"])
    return h5["runs"][name]


@dataclass(frozen=True)
class Load:
    body: str
    force: np.ndarray
    point: np.ndarray


def loads_of(path: Path) -> dict[str, Load]:
    run = the_run(path)
    try:
        return {name: Load(str(g.attrs["body"]), g["force"][()], g["point"][()])
                for name, g in run["loads"].items()}
    finally:
        run.file.close()


def runs_of(on: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of the True frames (written here, not the package's)."""
    out, start = [], None
    for k, flag in enumerate([*on.tolist(), False]):
        if flag and start is None:
            start = k
        elif not flag and start is not None:
            out.append((start, k))
            start = None
    return out


@dataclass(frozen=True)
class RawPlate:
    """One plate as ezc3d reads it, averaged to the marker rate: vertical force (N, on the
    subject) per frame and the runs of frames at or above the model's threshold."""

    fz: np.ndarray
    contacts: list[tuple[int, int]]


def raw_plates(path: Path, n_frames: int = 340) -> list[RawPlate]:
    c3d = ezc3d.c3d(str(path), extract_forceplat_data=True)
    out = []
    for raw in c3d["data"]["platform"]:
        force = np.asarray(raw["force"], float)  # 3 × analog samples
        fz = force[2].reshape(n_frames, -1).mean(axis=1)
        out.append(RawPlate(fz, runs_of(fz >= THRESHOLD)))
    return out


def gait_events(path: Path) -> dict[str, list[float]]:
    """EVENT:LABELS → frame indices (from 0, fractional) of the trial's first frame."""
    c3d = ezc3d.c3d(str(path))
    event = c3d["parameters"]["EVENT"]
    times = np.asarray(event["TIMES"]["value"], float)
    seconds = 60.0 * times[0] + times[1]  # row 0 minutes, row 1 seconds
    rate = float(c3d["header"]["points"]["frame_rate"])
    first = int(c3d["header"]["points"]["first_frame"])
    out: dict[str, list[float]] = {}
    for label, t in zip(event["LABELS"]["value"], seconds, strict=True):
        out.setdefault(label.strip(), []).append(t * rate - first)
    return {k: sorted(v) for k, v in out.items()}


def test_gait_events_as_described(qualisys: Path) -> None:
    """The data's own parameters: 200 Hz, first frame 704 (3.52 s); LHS 3.59 s → index 14."""
    events = gait_events(qualisys)
    assert events["LHS"][0] == pytest.approx(14, abs=0.1)
    assert events["RHS"][0] == pytest.approx(106, abs=0.1)


def test_calibrate_walking_trial(gait: Gait) -> None:
    succeeded(gait.calibrate)
    assert gait.model.is_file()
    assert gait.calibrate.stdout.startswith(f"wrote {gait.model}")
    loads = yaml.safe_load(gait.model.read_text(encoding="utf-8"))["loads"]
    assert loads == {"threshold": THRESHOLD, "contact": ["foot_r", "foot_l"]}


def test_calibrated_segment_lengths_are_anatomical(gait: Gait) -> None:
    """Thigh (hip to knee centre) and shank (knee to ankle centre) lengths are each about
    0.245 and 0.246 of stature (Winter, Biomechanics and Motor Control of Human Movement, 4th
    ed., Fig. 4.1; de Leva 1996 gives similar fractions). Adult statures of 1.40–1.95 m give
    0.34–0.48 m; the ranges below (thigh 0.33–0.50 m, shank 0.33–0.48 m) add a margin for the
    marker-based joint centres. Left and right of one subject agree to about a centimetre;
    25 mm is allowed for the landmark placement."""
    bodies = yaml.safe_load(gait.model.read_text(encoding="utf-8"))["bodies"]
    length = {}
    for s in SIDES:
        length[f"thigh_{s}"] = float(np.linalg.norm(bodies[f"thigh_{s}"]["points"]["KJC"]))
        length[f"shank_{s}"] = float(np.linalg.norm(bodies[f"shank_{s}"]["points"]["AJC"]))
        assert 0.33 <= length[f"thigh_{s}"] <= 0.50, length
        assert 0.33 <= length[f"shank_{s}"] <= 0.48, length
    assert abs(length["thigh_r"] - length["thigh_l"]) < 0.025, length
    assert abs(length["shank_r"] - length["shank_l"]) < 0.025, length
    # the command's summary reports the same lengths (mm)
    printed = {k: float(v) for k, v in re.findall(r"(\w+_[rl]) (\d+)", gait.calibrate.stdout)}
    for name, value in length.items():
        assert printed[name] == pytest.approx(1e3 * value, abs=0.51), name


def test_calibrated_segment_masses_are_anatomical(gait: Gait) -> None:
    """Segment mass fractions of body mass in the usual tables: thigh 0.100 (Winter) to 0.148
    (de Leva, women), shank 0.043 (de Leva, men) to 0.0481 (de Leva, women; Winter 0.0465),
    foot 0.0129 to 0.0145."""
    bodies = yaml.safe_load(gait.model.read_text(encoding="utf-8"))["bodies"]
    for s in SIDES:
        assert 0.095 <= bodies[f"thigh_{s}"]["mass"] / BODY_MASS <= 0.15
        assert 0.042 <= bodies[f"shank_{s}"]["mass"] / BODY_MASS <= 0.049
        assert 0.0125 <= bodies[f"foot_{s}"]["mass"] / BODY_MASS <= 0.015


def test_solve_walking_trial_converges_and_fits(gait: Gait) -> None:
    assert gait.solve is not None, "calibrate wrote no model"
    succeeded(gait.solve)
    run = the_run(gait.results)
    try:
        converged = run["converged"][()]
        ed = run["ed"][()]
    finally:
        run.file.close()
    assert converged.shape == (340,)
    assert converged.all(), np.flatnonzero(~converged)
    assert ed.shape == (340, 28)  # the template tracks 28 markers
    assert np.isfinite(ed).all()
    assert 1e3 * ed.mean() < 15.0


# What the solve wrote is checked against physics computed here from the same file: the
# personal model's numbers (masses, centres of mass, principal inertias, points and vectors, read
# with yaml.safe_load) and the run's own positions, accelerations and plate loads. None of the
# package's mass matrices, constraint equations or multipliers is used for the expectations.

BUILTIN = {"u": (1.0, 0.0, 0.0), "v": (0.0, 1.0, 0.0), "w": (0.0, 0.0, 1.0)}
RATE = 200.0  # Hz, the Qualisys trial's


def _vee(S: np.ndarray) -> np.ndarray:
    """The vector of the skew-symmetric part of 3 × 3 matrices (frames × 3 × 3 → frames × 3)."""
    return 0.5 * np.stack([S[:, 2, 1] - S[:, 1, 2], S[:, 0, 2] - S[:, 2, 0],
                           S[:, 1, 0] - S[:, 0, 1]], axis=1)


@dataclass(frozen=True)
class Segment:
    """One body along the classical motion: rotation R (columns u, v, w), its rates, origin,
    centre of mass G with its acceleration, angular velocity and dH_G/dt (global)."""

    R: np.ndarray
    origin: np.ndarray
    mass: float
    G: np.ndarray
    a_G: np.ndarray
    omega: np.ndarray
    H_rate: np.ndarray


@dataclass(frozen=True)
class Solution:
    """A solved gait run read back: the personal model (YAML), the classical model's motion
    and what the inverse dynamics reported."""

    spec: dict
    segments: dict[str, Segment]
    q: dict[str, np.ndarray]          # mixed run and classical model: frames × coordinates
    qd: dict[str, np.ndarray]
    qdd: dict[str, np.ndarray]
    theta: np.ndarray                 # the run's angles (rad)
    classical_theta: np.ndarray       # the classical model's drivers (filtered)
    moments: np.ndarray               # N·m, conjugate to θ
    loads: dict[str, tuple[str, np.ndarray, np.ndarray, np.ndarray]]  # body, f, point, n
    residual_force: np.ndarray
    residual_moment: np.ndarray

    @property
    def gravity(self) -> np.ndarray:
        return np.asarray(self.spec["gravity"], dtype=float)

    def vector(self, body: str, name: str) -> np.ndarray:
        """A body vector along the classical motion (frames × 3)."""
        local = BUILTIN.get(name) or self.spec["bodies"][body]["vectors"][name]
        return self.segments[body].R @ np.asarray(local, dtype=float)

    def point(self, body: str, name: str) -> np.ndarray:
        seg = self.segments[body]
        return seg.origin + seg.R @ np.asarray(self.spec["bodies"][body]["points"][name], float)


def segment_of(spec: dict, body: str, q: np.ndarray, qd: np.ndarray, qdd: np.ndarray
               ) -> Segment:
    """Newton–Euler quantities of one body from its 12 coordinates [r, u, v, w] per frame:
    ω from Ṙ Rᵀ, α from (R̈ − Ω Ṙ) Rᵀ, dH/dt = I_G α + ω × I_G ω with I_G = R I Rᵀ."""
    b = spec["bodies"][body]
    x, xd, xdd = (a.reshape(-1, 4, 3) for a in (q, qd, qdd))
    R, Rd, Rdd = (np.transpose(a[:, 1:], (0, 2, 1)) for a in (x, xd, xdd))
    com = np.asarray(b.get("com", [0.0, 0.0, 0.0]), dtype=float)
    inertia = np.asarray(b["inertia"], dtype=float)
    inertia = np.diag(inertia) if inertia.ndim == 1 else inertia
    Rt = np.transpose(R, (0, 2, 1))
    Omega = Rd @ Rt
    omega = _vee(Omega)
    alpha = _vee((Rdd - Omega @ Rd) @ Rt)
    I_G = R @ inertia @ Rt
    H_rate = np.einsum("fij,fj->fi", I_G, alpha) + np.cross(omega,
                                                            np.einsum("fij,fj->fi", I_G, omega))
    return Segment(R, x[:, 0], float(b["mass"]), x[:, 0] + R @ com, xdd[:, 0] + Rdd @ com,
                   omega, H_rate)


def read_solution(gait: Gait) -> Solution:
    assert gait.solve is not None and gait.solve.exit_code == 0
    spec = yaml.safe_load(gait.model.read_text(encoding="utf-8"))
    bodies = list(spec["bodies"])
    assert spec["form"] == "full" and all("form" not in b for b in spec["bodies"].values())
    run = the_run(gait.results)
    try:
        assert tuple(run["theta"].attrs["names"]) == ANGLES
        assert tuple(run["joint_moments"].attrs["names"]) == ANGLES
        assert tuple(run["residual_force"].attrs["bases"]) == ("pelvis",)
        q, qd, qdd = {}, {}, {}
        for kind, prefix in (("mixed", ""), ("classical", "classical/")):
            q[kind], qd[kind], qdd[kind] = (run[prefix + k][()] for k in ("q", "qd", "qdd"))
        loads = {name: (str(g.attrs["body"]), g["force"][()], g["point"][()], g["moment"][()])
                 for name, g in run["loads"].items()}
        solution = dict(theta=run["theta"][()], classical_theta=run["classical/theta"][()],
                        moments=run["joint_moments"][()],
                        residual_force=run["residual_force"][:, 0],
                        residual_moment=run["residual_moment"][:, 0])
    finally:
        run.file.close()
    # coordinates: [r, u, v, w] per body in the file's order, then (mixed run) the angles
    assert q["classical"].shape == (340, 12 * len(bodies))
    assert q["mixed"].shape == (340, 12 * len(bodies) + len(ANGLES))
    segments = {body: segment_of(spec, body, *(a["classical"][:, 12 * k:12 * k + 12]
                                                for a in (q, qd, qdd)))
                for k, body in enumerate(bodies)}
    return Solution(spec, segments, q, qd, qdd, loads=loads, **solution)


@pytest.fixture(scope="module")
def solution(gait: Gait) -> Solution:
    return read_solution(gait)


def distal(spec: dict, body: str) -> list[str]:
    """The body and every body beyond it along the joints (proximal body first in each)."""
    out = [body]
    for joint in spec["joints"]:
        if joint["bodies"][0] == body:
            out += distal(spec, joint["bodies"][1])
    return out


def test_angles_are_those_of_the_solved_segments(solution: Solution) -> None:
    """θ_k in the file is the angle the solved body vectors make, acos(s1·s2), recomputed from
    the mixed run's q (NRM-WLS keeps the MCR rows to its topology level, ~3e-5: 1e-4 rad
    allowed); each angle stays clear of the 0°/180° singularity by more than the 5° at which
    solve warns (90° in the neutral posture, knee flexion up to ~70° in gait)."""
    spec = solution.spec
    bodies = list(spec["bodies"])
    q = solution.q["mixed"]
    assert solution.theta.shape == solution.moments.shape == (340, 12)
    np.testing.assert_array_equal(q[:, 12 * len(bodies):], solution.theta)
    for k, angle in enumerate(spec["angles"]):
        s = []
        for ref in angle["vectors"]:
            body, name = ref.split(".")
            start = 12 * bodies.index(body)
            R = np.transpose(q[:, start + 3:start + 12].reshape(-1, 3, 3), (0, 2, 1))
            s.append(R @ np.asarray(BUILTIN.get(name) or spec["bodies"][body]["vectors"][name],
                                    dtype=float))
        recomputed = np.arccos(np.clip(np.einsum("fi,fi->f", *s), -1.0, 1.0))
        assert np.abs(recomputed - solution.theta[:, k]).max() < 1e-4, angle["name"]
    assert (np.degrees(solution.theta) > 5).all() and (np.degrees(solution.theta) < 175).all()


def test_rates_are_the_motion_s_own(solution: Solution) -> None:
    """Velocities and accelerations in the file against central differences of the file's own
    positions (interior frames), body block by body block: a dropped base acceleration, or a
    rate from another motion, leaves them far apart. The classical model follows the 6 Hz
    low-passed angles: truncation ≈ (2π·6 Hz·h)²/12 ≈ 3e-3 of a block's largest acceleration
    at 200 Hz; 1e-2 allowed (measured ≤ 2.0e-3 in every block). The mixed run's rates come
    from its unfiltered solution, noisier: 3e-2 allowed (measured ≤ 1.3e-2)."""
    h = 1.0 / RATE
    n_bodies = len(solution.spec["bodies"])
    for kind, bound in (("classical", 1e-2), ("mixed", 3e-2)):
        q = solution.q[kind][:, :12 * n_bodies]
        qd = solution.qd[kind][:, :12 * n_bodies]
        qdd = solution.qdd[kind][:, :12 * n_bodies]
        velocity = (q[2:] - q[:-2]) / (2 * h)
        acceleration = (q[2:] - 2 * q[1:-1] + q[:-2]) / h**2
        inner = slice(2, -2)  # frames 3 … n−4: away from the one-sided stencils at the ends
        for k, body in enumerate(solution.spec["bodies"]):
            block = slice(12 * k, 12 * k + 12)
            v_err = np.abs(velocity[inner, block] - qd[1:-1][inner, block]).max()
            a_err = np.abs(acceleration[inner, block] - qdd[1:-1][inner, block]).max()
            assert v_err <= bound * np.abs(qd[:, block]).max(), (kind, body, v_err)
            assert a_err <= bound * np.abs(qdd[:, block]).max(), (kind, body, a_err)


def test_pelvis_residual_wrench_is_newtons_law_for_the_whole_body(solution: Solution) -> None:
    """The floating pelvis's residual wrench is what the whole body's motion needs beyond
    gravity and the plates: F_res = Σ m_i (a_Gi − g) − Σ F_plate, and about the pelvis origin o
    M_res = Σ [(G_i − o) × m_i (a_Gi − g) + dH_i/dt] − Σ [(p − o) × F_plate + n_free]
    (Newton–Euler of 7 segments, in this file). Force: measured 7e-13 N. Moment: 2e-3 N·m of up
    to 216 N·m; this Newton–Euler takes the pelvis as rigid, and the classical model's pelvis is
    not quite: its base drivers follow the 6 Hz low-passed u, v, w, whose filtering shrinks them
    (|w|² − 1 up to 3.9e-4; without the filter 5e-7), a package defect reported with this test.
    0.01 N·m allowed; a dropped plate (800 N), gravity's sign (1300 N) or a mass error are
    orders of magnitude above."""
    origin = solution.segments["pelvis"].origin
    force = np.zeros_like(origin)
    moment = np.zeros_like(origin)
    for seg in solution.segments.values():
        inertial = seg.mass * (seg.a_G - solution.gravity)
        force += inertial
        moment += np.cross(seg.G - origin, inertial) + seg.H_rate
    assert set(solution.loads) == {"plate1", "plate2"}
    for _, f, p, n in solution.loads.values():
        force -= f
        moment -= np.cross(p - origin, f) + n
    print(f"\nresidual force: Newton {np.abs(force).max():.1f} N, "
          f"|Δ| {np.abs(force - solution.residual_force).max():.1e} N; residual moment "
          f"{np.abs(moment).max():.1f} N·m, |Δ| "
          f"{np.abs(moment - solution.residual_moment).max():.1e} N·m")
    np.testing.assert_allclose(solution.residual_force, force, rtol=0, atol=1e-6)
    np.testing.assert_allclose(solution.residual_moment, moment, rtol=0, atol=1e-2)
    assert np.abs(force).max() > 100.0  # not a still or weightless body: the check has teeth


def test_joint_moments_balance_the_segments_distal_to_them(solution: Solution) -> None:
    """Each joint: the moment M that the proximal body exerts on everything distal to the joint,
    about the joint centre c, from the distal segments' Newton–Euler with their plate loads:
    M = Σ_distal [(G_i − c) × m_i (a_Gi − g) + dH_i/dt] − Σ_loads on them [(p − c) × F + n].
    The joint's angles θ_k (cos θ_k = s_p·s_d, s_p on the proximal body, s_d on the distal one)
    change as θ̇_k = ω_rel·(s_p × s_d)/sin θ_k, so the moments τ_k conjugate to them apply
    Σ τ_k (s_p × s_d)/sin θ_k; the joint's reaction takes the rest, in directions it does not
    let turn. So along every direction e the joint lets turn (hip, spherical: all three axes;
    knee, revolute: its axis; ankle, universal: its two arms), M·e = Σ τ_k (s_p × s_d)·e / sin θ_k.
    Every joint, left and right, every frame: measured 5e-13 N·m of up to ~130 N·m; 1e-8
    allowed. The hips' balance includes the pelvis's acceleration through the distal segments'."""
    spec = solution.spec
    names = list(ANGLES)
    worst = 0.0
    for joint in spec["joints"]:
        proximal, body = joint["bodies"]
        centre = solution.point(body, joint["points"][1])
        beyond = distal(spec, body)
        M = np.zeros_like(centre)
        for name in beyond:
            seg = solution.segments[name]
            M += np.cross(seg.G - centre, seg.mass * (seg.a_G - solution.gravity)) + seg.H_rate
        for load_body, f, p, n in solution.loads.values():
            if load_body in beyond:
                M -= np.cross(p - centre, f) + n
        driven = np.zeros_like(centre)
        count = 0
        for angle in spec["angles"]:
            (b1, n1), (b2, n2) = (ref.split(".") for ref in angle["vectors"])
            if {b1, b2} != {proximal, body}:
                continue
            count += 1
            s1, s2 = solution.vector(b1, n1), solution.vector(b2, n2)
            s_p, s_d = (s1, s2) if b1 == proximal else (s2, s1)
            k = names.index(angle["name"])
            driven += (solution.moments[:, [k]] * np.cross(s_p, s_d)
                       / np.sin(solution.classical_theta[:, [k]]))
        if joint["type"] == "spherical":
            directions = [np.broadcast_to(e, centre.shape) for e in np.eye(3)]
        elif joint["type"] == "revolute":
            directions = [solution.vector(proximal, joint["axes"][0])]
        else:
            assert joint["type"] == "universal", joint
            directions = [solution.vector(proximal, joint["axes"][0]),
                          solution.vector(body, joint["axes"][1])]
        assert count == {"spherical": 3, "revolute": 1, "universal": 2}[joint["type"]], joint
        for e in directions:
            balance = np.einsum("fi,fi->f", M, e)
            assert np.abs(balance).max() > 10.0, joint["name"]  # a loaded joint, N·m
            error = np.abs(balance - np.einsum("fi,fi->f", driven, e)).max()
            assert error <= 1e-8, (joint["name"], error)
            worst = max(worst, error)
    print(f"\njoint moments against the distal Newton–Euler: max |Δ| {worst:.1e} N·m")


def test_left_and_right_agree(gait: Gait) -> None:
    """A steady walk is nearly symmetric: peak knee flexion within 5° left to right (swing,
    55–75° in healthy gait: Winter's norms ~60–65°), and each foot's stance peaks of the ankle
    plantarflexor moment (0.8–1.8 N·m/kg; Winter ~1.2–1.6) and of the hip abductor moment agree
    within 25 % (measured: knee 65.3° and 65.1°; ankle 1.12 and 1.24 N·m/kg; hip 1.14 and 0.93
    N·m/kg, 20 % apart). Clinical signs make both sides read alike: a side whose sign or
    moment is wrong shows here."""
    assert gait.solve is not None and gait.solve.exit_code == 0
    run = the_run(gait.results)
    try:
        names = list(run["clinical/angles"].attrs["names"])
        angles, per_kg = run["clinical/angles"][()], run["clinical/moments_per_kg"][()]
        stance = {s: run[f"clinical/stance/foot_{s}"][()] for s in SIDES}
    finally:
        run.file.close()

    def peak(values: np.ndarray, name: str, s: str, frames: np.ndarray | None = None,
             sign: float = 1.0) -> float:
        column = values[:, names.index(f"{name}_{s}")]
        return float((sign * (column if frames is None else column[frames])).max())

    knee = {s: peak(angles, "knee_flexion", s) for s in SIDES}
    ankle = {s: peak(per_kg, "ankle_dorsiflexion", s, stance[s], -1.0) for s in SIDES}
    hip = {s: peak(per_kg, "hip_adduction", s, stance[s], -1.0) for s in SIDES}
    print(f"\nknee flexion {knee}, plantarflexor {ankle}, abductor {hip}")
    assert all(55.0 <= v <= 75.0 for v in knee.values()) and abs(knee["r"] - knee["l"]) < 5.0
    assert all(0.8 <= v <= 1.8 for v in ankle.values())
    assert 0.8 <= ankle["r"] / ankle["l"] <= 1.25
    assert all(v > 0.5 for v in hip.values()) and 0.75 <= hip["r"] / hip["l"] <= 1.33


def test_raw_plate_contacts_begin_at_heel_strikes(qualisys: Path) -> None:
    """The premise of the assignment, from the data alone (ezc3d's platform data): each plate
    has one contact; plate 1's starts at the left heel strike (LHS, index 14), plate 2's at the
    right one (RHS, 106). The 20 N threshold crosses within a few frames of the events: 4
    frames (20 ms) allowed, far less than the 92 frames between the strikes. Each ends near the
    same foot's toe-off, where the force falls off more gradually: 8 frames (40 ms) allowed."""
    events = gait_events(qualisys)
    plates = raw_plates(qualisys)
    assert len(plates) == 2
    for plate, side in zip(plates, "LR", strict=True):
        (start, stop), = plate.contacts
        assert abs(start - events[f"{side}HS"][0]) <= 4, (side, start, events)
        toe_off = min(t for t in events[f"{side}TO"] if t > start)
        assert abs(stop - toe_off) <= 8, (side, stop, events)


def test_force_plates_go_to_the_foot_that_strikes_them(gait: Gait) -> None:
    """Each plate's load goes to the foot whose heel strike begins its (raw) contact: plate 1
    to foot_l, plate 2 to foot_r, one load per plate."""
    assert gait.solve is not None and gait.solve.exit_code == 0
    loads = loads_of(gait.results)
    events = gait_events(gait.trial)
    plates = raw_plates(gait.trial)
    assert {name: load.body for name, load in loads.items()} == \
        {"plate1": "foot_l", "plate2": "foot_r"}
    for number, plate in enumerate(plates, start=1):
        (start, _), = plate.contacts
        side = min(("L", "R"), key=lambda s: min(abs(t - start) for t in events[f"{s}HS"]))
        assert loads[f"plate{number}"].body == f"foot_{side.lower()}"


def test_plate_loads_are_physical(gait: Gait) -> None:
    """The loads used: the plate's impulse ∫Fz dt over its contact (a zero-lag low-pass has
    unit gain at 0 Hz, so filtering keeps it; 1 % allowed for the filter's edges), centres of
    pressure on their plates (FORCE_PLATFORM:CORNERS, mm) wherever the force reaches the
    threshold, upward ground reactions through the raw contact, and a vertical peak of
    1.0–1.5 body weights, as in walking."""
    assert gait.solve is not None and gait.solve.exit_code == 0
    loads = loads_of(gait.results)
    plates = raw_plates(gait.trial)
    corners = np.asarray(ezc3d.c3d(str(gait.trial))["parameters"]["FORCE_PLATFORM"]["CORNERS"]
                         ["value"], float) * 1e-3  # 3 × 4 × plates, m
    dt = 1 / 200.0
    for number, plate in enumerate(plates, start=1):
        load = loads[f"plate{number}"]
        (start, stop), = plate.contacts
        impulse = plate.fz[start:stop].sum() * dt
        # a ~0.55 s stance averaging ~0.8 body weight (657 N; the other foot shares the double
        # supports): ~290 N·s
        assert 200 < impulse < 400
        assert load.force[:, 2].sum() * dt == pytest.approx(impulse, rel=0.01)
        on = np.linalg.norm(load.force, axis=1) >= THRESHOLD
        c = corners[:, :, number - 1]
        cop = load.point[on]
        assert (cop[:, 0] >= c[0].min() - 1e-3).all() and (cop[:, 0] <= c[0].max() + 1e-3).all()
        assert (cop[:, 1] >= c[1].min() - 1e-3).all() and (cop[:, 1] <= c[1].max() + 1e-3).all()
        assert np.allclose(cop[:, 2], c[2].mean(), atol=1e-3)
        assert (load.force[start:stop, 2] > 0).all()
        peak = load.force[:, 2].max() / (BODY_MASS * G)
        assert 1.0 <= peak <= 1.5, peak


def test_clinical_stance_is_the_plate_contact(gait: Gait) -> None:
    """README: clinical/stance/<body> is 'True while a force plate loads that body'. The plate
    loads the foot over its raw contact; 2 frames allowed at either end."""
    assert gait.solve is not None and gait.solve.exit_code == 0
    run = the_run(gait.results)
    try:
        stance = {body: g[()] for body, g in run["clinical"]["stance"].items()}
    finally:
        run.file.close()
    for plate, body in zip(raw_plates(gait.trial), ("foot_l", "foot_r"), strict=True):
        (start, stop), = plate.contacts
        (s_start, s_stop), = runs_of(stance[body])
        assert abs(s_start - start) <= 2, (body, s_start, start)
        assert abs(s_stop - stop) <= 2, (body, s_stop, stop)


def the_override(gait: Gait) -> Path:
    doc = yaml.safe_load(gait.model.read_text(encoding="utf-8"))
    doc["loads"]["force_plates"] = [{"plate": 1, "body": "foot_r"}]
    path = gait.folder / "override.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


@pytest.fixture(scope="module")
def override(gait: Gait) -> tuple[Result, Path]:
    if not gait.model.is_file():
        pytest.fail("calibrate wrote no model")
    results = gait.folder / "override.h5"
    result = run_cli("solve", the_override(gait), gait.trial, "--method", "nrm-wls",
                     "--filter-cutoff", 6, "-o", results)
    return result, results


def _stance_moment(path: Path, angle: str, start: int, stop: int) -> float:
    run = the_run(path)
    try:
        k = list(run["joint_moments"].attrs["names"]).index(angle)
        return float(np.abs(run["joint_moments"][start:stop, k]).max())
    finally:
        run.file.close()


def test_force_plate_override_moves_plate_1_to_the_right_foot(
        gait: Gait, override: tuple[Result, Path]) -> None:
    """With plate 1 given to foot_r, the left foot carries no ground reaction during its own
    stance: its ankle moment drops to what the foot's weight and inertia need (0.9 kg of foot,
    ~0.1 m lever: about 1 N·m; 5 N·m allowed), from a stance plantarflexor moment of the order of
    1–1.5 N·m/kg (Winter's norms) in the automatic assignment."""
    result, path = override
    succeeded(result)
    loads = loads_of(path)
    assert {name: load.body for name, load in loads.items()} == \
        {"plate1": "foot_r", "plate2": "foot_r"}
    auto = loads_of(gait.results)
    np.testing.assert_allclose(loads["plate1"].force, auto["plate1"].force, rtol=0, atol=1e-9)
    (start, stop), = raw_plates(gait.trial)[0].contacts
    left_auto = _stance_moment(gait.results, "ankle_dorsiflexion_l", start, stop)
    left_override = _stance_moment(path, "ankle_dorsiflexion_l", start, stop)
    assert 0.7 * BODY_MASS <= left_auto <= 2.0 * BODY_MASS, left_auto
    assert left_override < 5.0, left_override


# ---- 4. inputs unmodified ------------------------------------------------------------------


def test_the_trial_is_not_modified(gait: Gait, override: tuple[Result, Path]) -> None:
    assert digest(gait.trial) == gait.digest_before
    assert listing(gait.trial.parent) == gait.beside_before  # no temporary file beside it
