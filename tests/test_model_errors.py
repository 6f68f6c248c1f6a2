"""Every kind of wrong model is one line on stderr, exit status 2, and no traceback.

Each case starts from ``configs/models/pendulum.yaml`` (its text, or its parsed document; the
distance-coordinate and base-motion cases from ``slider.yaml`` or a floating pendulum), breaks
one thing, and runs ``fccgrb check MODEL`` and ``fccgrb synth MODEL -o OUT.c3d``.
The single stderr line must read ``fccgrb: error: FILE: KEY.PATH: …`` with the key path that
was broken and what was expected, and ``synth`` must leave nothing behind in the folder.

Most cases go through ``click.testing.CliRunner``; a few are repeated through a real
``fccgrb`` subprocess so that the stdout/stderr separation and the exit status are genuine.
Each former defect (tracebacks on odd YAML, wording) has its own regression case.
"""

from __future__ import annotations

import copy
import shutil
import subprocess
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import pytest
import yaml
from cli_helpers import one_error_line, runner

from fccgrb_cli.cli.main import main

PENDULUM = Path(__file__).resolve().parents[1] / "configs" / "models" / "pendulum.yaml"
PENDULUM_TEXT = PENDULUM.read_text(encoding="utf-8")
PENDULUM_LINES = PENDULUM_TEXT.splitlines()
SLIDER_TEXT = (PENDULUM.parent / "slider.yaml").read_text(encoding="utf-8")
CRANK_TEXT = (PENDULUM.parent / "crank_rocker.yaml").read_text(encoding="utf-8")
MODEL_NAME = "model.yaml"
SYNTH_OPTIONS = ("--duration", "0.2", "--rate", "50")


def line_of(text: str) -> int:
    """1-based number of the pendulum line that is exactly ``text``."""
    return PENDULUM_LINES.index(text) + 1


def edit_text(edit: Callable[[str], str]) -> Callable[[], str]:
    """A case built by editing the pendulum YAML text."""
    return lambda: edit(PENDULUM_TEXT)


def edit_doc(edit: Callable[[dict], None]) -> Callable[[], str]:
    """A case built by changing one thing in the parsed pendulum document and dumping it."""

    def make() -> str:
        doc = copy.deepcopy(yaml.safe_load(PENDULUM_TEXT))
        edit(doc)
        return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)

    return make


def edit_slider(edit: Callable[[dict], None]) -> Callable[[], str]:
    """A case built by changing one thing in the parsed slider document (a prismatic slide
    driven by the distance coordinate ``lift``, a hinge by the angle ``swing``)."""

    def make() -> str:
        doc = copy.deepcopy(yaml.safe_load(SLIDER_TEXT))
        edit(doc)
        return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)

    return make


def edit_crank(edit: Callable[[dict], None]) -> Callable[[], str]:
    """A case built by changing one thing in the crank-rocker (a signed, full-turn angle)."""

    def make() -> str:
        doc = copy.deepcopy(yaml.safe_load(CRANK_TEXT))
        edit(doc)
        return yaml.safe_dump(doc, sort_keys=False, allow_unicode=True)

    return make


def floating_pendulum(edit: Callable[[dict], None]) -> Callable[[], str]:
    """The pendulum with its shoulder joint and shoulder angles removed: link1 floats."""

    def change(doc: dict) -> None:
        del doc["joints"][0]
        del doc["angles"][:2]
        edit(doc)

    return edit_doc(change)


def setter(*path: str | int, value: object) -> Callable[[dict], None]:
    """An edit that sets ``doc[path[0]][path[1]]… = value``."""

    def edit(doc: dict) -> None:
        node = doc
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value

    return edit


def remover(*path: str | int) -> Callable[[dict], None]:
    """An edit that deletes ``doc[path[0]][path[1]]…``."""

    def edit(doc: dict) -> None:
        node = doc
        for key in path[:-1]:
            node = node[key]
        del node[path[-1]]

    return edit


def drop_motions(doc: dict) -> None:
    for angle in doc["angles"]:
        angle.pop("motion", None)


def add_fifth_angle(doc: dict) -> None:
    doc["angles"].append({"name": "elbow_z", "vectors": ["link1.w", "link2.u"]})


@dataclass(frozen=True)
class Case:
    """A broken model: how to make it, the key path the message must start with, and the
    other fragments it must contain (``None`` text means: no file at all)."""

    make: Callable[[], str] | None
    key: str
    expect: tuple[str, ...] = ()
    commands: tuple[str, ...] = ("check", "synth")


def regression(case: Case, case_id: str, reason: str) -> object:
    """A case that once crashed; ``reason`` records how."""
    assert reason
    return pytest.param(case, id=case_id)


CASES = {
    # ---- the file and its YAML ----------------------------------------------------------
    "missing-file": Case(None, "model file not found"),
    "yaml-syntax": Case(
        edit_text(lambda t: t.replace("\nname: pendulum\n", "\nname: pendulum: oops\n")),
        f"line {line_of('name: pendulum')}, column",
        ("invalid YAML", "mapping values are not allowed")),
    "yaml-duplicate-key": Case(
        edit_text(lambda t: t.replace("    mass: 1.5 ", "    mass: 1.5\n    mass: 2.0 ")),
        f"line {line_of('    mass: 1.5                  # kg') + 1}, column",
        ("duplicate key 'mass'",)),
    "top-level-list": Case(lambda: "- name: pendulum\n- bodies: {}\n", "",
                           ("expected a mapping", "got [")),
    "top-level-empty-file": Case(lambda: "", "", ("expected a mapping", "got None")),
    "unknown-top-level-key": Case(edit_doc(setter("bodys", value={})), "bodys",
                                  ("expected one of the keys", "'bodies'")),
    # ---- names ----------------------------------------------------------------------------
    "joint-unknown-body": Case(edit_doc(setter("joints", 0, "bodies", 1, value="link9")),
                               "joints[0].bodies[1]", ("expected a body name", "'link9'")),
    "joint-unknown-point": Case(edit_doc(setter("joints", 1, "points", 1, value="Z")),
                                "joints[1].points[1]", ("expected a point of link2", "'Z'")),
    "joint-unknown-vector": Case(edit_doc(setter("joints", 0, "axes", 0, value="q")),
                                 "joints[0].axes[0]", ("expected a vector of ground", "'q'")),
    "joint-unknown-type": Case(edit_doc(setter("joints", 1, "type", value="hinge")),
                               "joints[1].type", ("expected a joint type", "'hinge'")),
    "angle-unknown-vector": Case(
        edit_doc(setter("angles", 1, "vectors", 1, value="link1.nope")),
        "angles[1].vectors[1]", ("expected a vector of link1", "'nope'")),
    "tracked-point-unknown-body": Case(
        edit_doc(setter("tracking", "points", 2, "point", value="link7.P3")),
        "tracking.points[2].point", ("expected a body name", "'link7'")),
    "dotted-name-without-dot": Case(
        edit_doc(setter("angles", 0, "vectors", 0, value="grounddown")),
        "angles[0].vectors[0]", ("expected 'body.vector'", "'grounddown'")),
    # ---- shapes ---------------------------------------------------------------------------
    "point-two-coordinates": Case(edit_doc(setter("bodies", "link2", "points", "P3", value=[0, 0])),
                                  "bodies.link2.points.P3", ("expected a list of 3 numbers",)),
    "point-non-number": Case(
        edit_doc(setter("bodies", "link1", "points", "A", value=[0, "x", 0.2])),
        "bodies.link1.points.A[1]", ("expected a finite number", "'x'")),
    "inertia-two-values": Case(
        edit_doc(setter("bodies", "link1", "inertia", value=[0.02, 0.02])),
        "bodies.link1.inertia", ("expected 3 principal moments",)),
    # ---- frames and vectors ---------------------------------------------------------------
    "pose-u-not-unit": Case(
        edit_doc(setter("bodies", "link1", "pose", "u", value=[1.1, 0, 0])),
        "bodies.link1.pose.u", ("expected a unit vector", "norm 1.1")),
    "pose-not-orthogonal": Case(
        edit_doc(setter("bodies", "link2", "pose", "v", value=[0.6, 0.8, 0])),
        "bodies.link2.pose", ("expected u, v, w unit and mutually orthogonal",)),
    "pose-left-handed": Case(
        edit_doc(setter("bodies", "link1", "pose", "w", value=[0, 0, -1])),
        "bodies.link1.pose", ("expected a right-handed frame",)),
    "ground-vector-not-unit": Case(
        edit_doc(setter("ground", "vectors", "down", value=[0, 0, -2])),
        "ground.vectors.down", ("expected a unit vector", "norm 2")),
    "body-vector-not-unit": Case(
        edit_doc(setter("bodies", "link1", "vectors", "minus_u", value=[-0.5, 0, 0])),
        "bodies.link1.vectors.minus_u", ("expected a unit vector", "norm 0.5")),
    # ---- mass properties ------------------------------------------------------------------
    "negative-mass": Case(edit_doc(setter("bodies", "link1", "mass", value=-1.5)),
                          "bodies.link1.mass", ("expected a positive mass", "-1.5")),
    "inertia-triangle-inequality": Case(
        edit_doc(setter("bodies", "link2", "inertia", value=[1, 1, 3])),
        "bodies.link2.inertia", ("expected principal moments satisfying the triangle",)),
    "inertia-negative-moment": Case(
        edit_doc(setter("bodies", "link1", "inertia", value=[-0.01, 0.02, 0.02])),
        "bodies.link1.inertia", ("expected non-negative principal moments",)),
    # ---- do the constraints determine the coordinates? -----------------------------------
    "too-few-angles": Case(edit_doc(remover("angles", 3)), "angles",
                           ("expected 4 angular coordinates", "got 3")),
    "too-many-angles": Case(edit_doc(add_fifth_angle), "angles",
                            ("expected 4 angular coordinates", "got 5")),
    # elbow_y rewritten to measure the elbow_x motion (link1.w = -link1.minus_w)
    "two-angles-same-motion": Case(
        edit_doc(setter("angles", 3, "vectors", value=["link1.w", "link2.v"])),
        "angles", ("expected angular coordinates that determine", "rank 23 of 24")),
    # link1.minus_w and link2.w are antiparallel at the neutral pose
    "angle-vectors-parallel": Case(
        edit_doc(setter("angles", 2, "vectors", value=["link1.minus_w", "link2.w"])),
        "angles", ("expected angular coordinates that determine", "parallel")),
    # ---- motions --------------------------------------------------------------------------
    "motion-leaves-0-180": Case(
        edit_doc(setter("angles", 2, "motion", value={
            "mean": 100, "terms": [{"amplitude": 85, "frequency": 1.0}]})),
        "angles[2].motion", ("expected a motion that stays inside (0, 180) deg", "185")),
    "synth-angles-without-motion": Case(edit_doc(drop_motions), "angles",
                                        ("expected a motion for every angle", "elbow_y"),
                                        commands=("synth",)),
    "synth-nothing-tracked": Case(edit_doc(remover("tracking")), "tracking.points",
                                  ("expected at least one tracked point",), commands=("synth",)),
    # ---- gait keys: clinical signs, subject, contact bodies, calibration landmarks ----------
    "clinical-sign-not-unit": Case(edit_doc(setter("angles", 0, "clinical", value={"sign": 2})),
                                   "angles[0].clinical.sign", ("expected 1 or -1", "2")),
    "clinical-without-sign": Case(edit_doc(setter("angles", 0, "clinical", value={})),
                                  "angles[0].clinical.sign", ("expected this key",)),
    "subject-mass-negative": Case(edit_doc(setter("subject", value={"mass": -70})),
                                  "subject.mass", ("expected a positive body mass", "-70")),
    "contact-unknown-body": Case(edit_doc(setter("loads", value={"contact": ["foot"]})),
                                 "loads.contact[0]", ("expected a body name", "'foot'")),
    "contact-twice": Case(edit_doc(setter("loads", value={"contact": ["link2", "link2"]})),
                          "loads.contact[1]", ("expected a moving body not listed before",)),
    # ---- distance coordinates (slider.yaml) ------------------------------------------------
    "distance-unknown-body": Case(
        edit_slider(setter("distances", 0, "points", 0, value="rail.O")),
        "distances[0].points[0]", ("expected a body name", "'rail'")),
    "distance-unknown-point": Case(
        edit_slider(setter("distances", 0, "points", 1, value="carriage.Z")),
        "distances[0].points[1]", ("expected a point of carriage", "'Z'")),
    "distance-unknown-vector": Case(
        edit_slider(setter("distances", 0, "axis", value="ground.up")),
        "distances[0].axis", ("expected a vector of ground", "'up'")),
    "distance-axis-of-second-body": Case(
        edit_slider(setter("distances", 0, "axis", value="carriage.w")),
        "distances[0].axis", ("expected a vector of ground, the body of the first point",
                              "'carriage.w'")),
    "distance-points-one-body": Case(
        edit_slider(setter("distances", 0, "points", value=["carriage.C", "carriage.A"])),
        "distances[0].points", ("expected points of two different bodies",)),
    "distance-name-of-an-angle": Case(
        edit_slider(setter("distances", 0, "name", value="swing")),
        "distances[0].name", ("expected a coordinate name not used before", "'swing'")),
    "distance-unknown-key": Case(
        edit_slider(setter("distances", 0, "vectors", value=["ground.z", "carriage.w"])),
        "distances[0].vectors", ("expected one of the keys", "'axis'")),
    "angle-range-unknown": Case(
        edit_crank(setter("angles", 0, "range", value="quarter")),
        "angles[0].range", ("expected 'full' (a signed angle", "'quarter'")),
    "angle-full-without-axis": Case(
        edit_crank(remover("angles", 0, "axis")),
        "angles[0].axis", ("expected the joint axis that signs a 'range: full' angle",)),
    "angle-axis-without-full": Case(
        edit_crank(remover("angles", 0, "range")),
        "angles[0].axis", ("expected an axis only with 'range: full'", "'ground.z'")),
    "angle-axis-of-a-third-body": Case(
        edit_crank(setter("angles", 0, "axis", value="coupler.w")),
        "angles[0].axis", ("expected a vector of ground or crank", "'coupler.w'")),
    "angle-axis-not-perpendicular": Case(
        edit_crank(setter("angles", 0, "axis", value="ground.x")),
        "angles[0].axis", ("expected a vector perpendicular to ground's vector",)),
    "angle-rate-on-a-half-range-angle": Case(
        edit_doc(setter("angles", 0, "motion", "rate", value=90)),
        "angles[0].motion", ("stays inside (0, 180) deg", "'range: full'")),
    "distance-without-axis": Case(edit_slider(remover("distances", 0, "axis")),
                                  "distances[0].axis", ("expected this key to be present",)),
    "distance-axis-not-unit": Case(
        edit_slider(setter("ground", value={"vectors": {"up": [0, 0, 2]}})),
        "ground.vectors.up", ("expected a unit vector", "norm 2")),
    "distance-motion-not-a-number": Case(
        edit_slider(setter("distances", 0, "motion", "mean", value="high")),
        "distances[0].motion.mean", ("expected a finite number", "'high'")),
    "distance-missing": Case(edit_slider(remover("distances")), "angles",
                             ("expected 2 coordinates (angles and distances)", "got 1")),
    # the axis ground.x is perpendicular to the slide along z: lift cannot drive it
    "distance-axis-across-the-slide": Case(
        edit_slider(setter("distances", 0, "axis", value="ground.x")),
        "angles", ("expected angular coordinates that determine", "distance lift",
                   "perpendicular")),
    "synth-distance-without-motion": Case(
        edit_slider(remover("distances", 0, "motion")), "distances",
        ("expected a motion for every angle and distance", "lift"), commands=("synth",)),
    # ---- a floating base's prescribed motion ------------------------------------------------
    "motion-on-a-jointed-body": Case(
        edit_doc(setter("bodies", "link1", "motion", value={"translation": [
            {"mean": 0}, {"mean": 0}, {"mean": 0.1}]})),
        "bodies.link1.motion", ("expected a motion on a floating base only", "none")),
    "motion-on-a-floating-group's-second-body": Case(
        floating_pendulum(setter("bodies", "link2", "motion", value={"rotation": [
            {"mean": 0}, {"mean": 0}, {"mean": 10}]})),
        "bodies.link2.motion", ("expected a motion on a floating base only", "link1")),
    "base-translation-two-items": Case(
        floating_pendulum(setter("bodies", "link1", "motion", value={"translation": [
            {"mean": 0}, {"mean": 0}]})),
        "bodies.link1.motion.translation", ("expected a list of 3 motions",)),
    "base-motion-unknown-key": Case(
        floating_pendulum(setter("bodies", "link1", "motion", value={"spin": []})),
        "bodies.link1.motion.spin", ("expected one of the keys", "'rotation'")),
    "base-rotation-bad-term": Case(
        floating_pendulum(setter("bodies", "link1", "motion", value={"rotation": [
            {"mean": 0}, {"mean": 0, "terms": [{"amplitude": 5}]}, {"mean": 0}]})),
        "bodies.link1.motion.rotation[1].terms[0].frequency", ("expected this key",)),
    "landmark-label-not-text": Case(
        edit_doc(setter("calibration", value={"landmarks": {"right_asis": [1, 2]}})),
        "calibration.landmarks.right_asis", ("expected",)),
}

REGRESSION_CASES = [
    regression(Case(edit_text(lambda t: t + "? [a, b]\n: 1\n"), f"line {len(PENDULUM_LINES) + 1}"),
           "yaml-unhashable-key",
           "a sequence used as a mapping key crashes _construct_mapping with "
           "'TypeError: unhashable type: list' (traceback, exit status 1)"),
    regression(Case(edit_doc(setter("joints", 1, "type", value=["universal"])), "joints[1].type",
                ("expected a joint type",)),
           "joint-type-is-a-list",
           "a list as a joint type crashes '_joints' (jtype not in JOINT_EQUATIONS) with "
           "'TypeError: unhashable type: list' (traceback, exit status 1)"),
    regression(Case(edit_doc(setter("bodies", "link1", "mass", value=10**400)), "bodies.link1.mass",
                ("expected a finite number",)),
           "number-too-large-integer",
           "_Reader.number calls math.isfinite on a huge YAML integer: 'OverflowError: int "
           "too large to convert to float' (traceback, exit status 1)"),
]


def case_params() -> list:
    params = [pytest.param(case, command, id=f"{name}-{command}")
              for name, case in CASES.items() for command in case.commands]
    for param in REGRESSION_CASES:
        (case,), marks, case_id = param.values, param.marks, param.id
        params += [pytest.param(case, command, id=f"{case_id}-{command}", marks=marks)
                   for command in case.commands]
    return params


def write_model(tmp_path: Path, case: Case) -> Path:
    model = tmp_path / MODEL_NAME
    if case.make is not None:
        model.write_text(case.make(), encoding="utf-8")
    return model


def arguments(command: str, model: Path, tmp_path: Path) -> list[str]:
    if command == "synth":
        return ["synth", str(model), "-o", str(tmp_path / "out.c3d"), *SYNTH_OPTIONS]
    return ["check", str(model)]


def the_error_line(stderr: str, model: Path, case: Case) -> str:
    """The one stderr line, checked against the file, the key path and the expected text."""
    assert "Traceback" not in stderr
    lines = stderr.splitlines()
    assert len(lines) == 1, f"expected exactly one stderr line, got {lines!r}"
    line = lines[0]
    assert line.strip()
    prefix = f"fccgrb: error: {model}: {case.key}"
    assert line.startswith(prefix), f"{line!r} does not start with {prefix!r}"
    for fragment in case.expect:
        assert fragment in line, f"{fragment!r} missing from {line!r}"
    return line


def assert_nothing_written(tmp_path: Path, model: Path) -> None:
    left = sorted(p.name for p in tmp_path.iterdir())
    assert left == ([model.name] if model.exists() else []), f"left behind: {left}"


@pytest.mark.parametrize(("case", "command"), case_params())
def test_wrong_model_is_one_line_and_status_2(tmp_path: Path, case: Case, command: str) -> None:
    model = write_model(tmp_path, case)
    result = runner().invoke(main, arguments(command, model, tmp_path))
    assert result.exception is None or isinstance(result.exception, SystemExit), (
        f"uncaught {result.exception!r}")
    assert result.exit_code == 2, result.output
    the_error_line(result.stderr, model, case)
    assert "Traceback" not in result.stdout
    assert_nothing_written(tmp_path, model)


def test_check_accepts_a_model_whose_angles_have_no_motion(tmp_path: Path) -> None:
    """The motion is needed by ``synth`` only; ``check`` must accept such a model."""
    model = write_model(tmp_path, CASES["synth-angles-without-motion"])
    result = runner().invoke(main, ["check", str(model)])
    assert result.exit_code == 0, result.output
    assert result.stderr == ""
    assert "is valid" in result.stdout


def test_unbroken_pendulum_passes_both_commands(tmp_path: Path) -> None:
    """Control: the cases fail because of their one change, and ``synth`` does write here."""
    model = tmp_path / MODEL_NAME
    model.write_text(PENDULUM_TEXT, encoding="utf-8")
    checked = runner().invoke(main, ["check", str(model)])
    assert checked.exit_code == 0, checked.output
    assert checked.stderr == ""
    synth = runner().invoke(main, arguments("synth", model, tmp_path))
    assert synth.exit_code == 0, synth.output
    assert sorted(p.name for p in tmp_path.iterdir()) == [MODEL_NAME, "out.c3d", "out.truth.h5"]


# ---- the same through a real process -----------------------------------------------------

FCCGRB = shutil.which("fccgrb")
SUBPROCESS_CASES = [
    ("yaml-syntax", "check"),
    ("joint-unknown-body", "synth"),
    ("inertia-triangle-inequality", "check"),
    ("angle-vectors-parallel", "synth"),
    ("missing-file", "check"),
    ("synth-angles-without-motion", "synth"),
]


@pytest.mark.skipif(FCCGRB is None, reason="the fccgrb command is not on PATH")
@pytest.mark.parametrize(("name", "command"), SUBPROCESS_CASES,
                         ids=[f"{n}-{c}" for n, c in SUBPROCESS_CASES])
def test_real_process_separates_streams(tmp_path: Path, name: str, command: str) -> None:
    case = CASES[name]
    model = write_model(tmp_path, case)
    proc = subprocess.run([FCCGRB, *arguments(command, model, tmp_path)], capture_output=True,
                          text=True, timeout=120, check=False)
    assert proc.returncode == 2, proc.stderr
    the_error_line(proc.stderr, model, case)
    assert "Traceback" not in proc.stdout
    assert "fccgrb: error:" not in proc.stdout
    assert_nothing_written(tmp_path, model)


@pytest.mark.skipif(FCCGRB is None, reason="the fccgrb command is not on PATH")
def test_real_process_unhashable_key_is_one_line(tmp_path: Path) -> None:
    """A sequence as a mapping key, through a real process: one line, status 2."""
    model = tmp_path / MODEL_NAME
    model.write_text(PENDULUM_TEXT + "? [a, b]\n: 1\n", encoding="utf-8")
    proc = subprocess.run([FCCGRB, "check", str(model)], capture_output=True, text=True,
                          timeout=120, check=False)
    assert "Traceback" not in proc.stderr
    assert proc.returncode == 2
    assert len(proc.stderr.splitlines()) == 1


# ---- wording ------------------------------------------------------

RANK_CASES = ["too-few-angles", "too-many-angles", "two-angles-same-motion",
              "angle-vectors-parallel"]


@pytest.mark.parametrize("name", RANK_CASES)
def test_check_does_not_call_a_rejected_model_valid(tmp_path: Path, name: str) -> None:
    model = write_model(tmp_path, CASES[name])
    result = runner().invoke(main, ["check", str(model)])
    assert result.exit_code == 2
    assert "valid" not in result.stdout


@pytest.mark.parametrize("name", ["top-level-list", "top-level-empty-file"])
def test_top_level_error_has_no_empty_key_path(tmp_path: Path, name: str) -> None:
    model = write_model(tmp_path, CASES[name])
    result = runner().invoke(main, ["check", str(model)])
    assert result.exit_code == 2
    assert f"{model}: : " not in result.stderr


def test_rank_error_names_the_offending_angle_only(tmp_path: Path) -> None:
    model = write_model(tmp_path, CASES["angle-vectors-parallel"])
    result = runner().invoke(main, ["check", str(model)])
    assert result.exit_code == 2
    assert "elbow_x" in result.stderr
    assert "shoulder_x" not in result.stderr



def test_distance_motions_are_not_held_to_angle_ranges(tmp_path: Path) -> None:
    """(0, 180) deg binds angles only: a slide may pass through zero and negative values, and
    a base may turn by any angle; ``check`` and ``synth`` accept both."""
    doc = yaml.safe_load(SLIDER_TEXT)
    doc["distances"][0]["motion"] = {"mean": 0.0, "terms": [{"amplitude": 4.0,
                                                             "frequency": 0.2}]}
    model = tmp_path / MODEL_NAME
    model.write_text(yaml.safe_dump(doc, sort_keys=False, allow_unicode=True), encoding="utf-8")
    for command in ("check", "synth"):
        result = runner().invoke(main, arguments(command, model, tmp_path))
        assert result.exit_code == 0, result.output
    spin = {"mean": 0, "terms": [{"amplitude": 400, "frequency": 1}]}
    make = floating_pendulum(setter("bodies", "link1", "motion", value={"rotation": [
        {"mean": 200}, {"mean": -300}, spin]}))
    model.write_text(make(), encoding="utf-8")
    result = runner().invoke(main, arguments("synth", model, tmp_path))
    assert result.exit_code == 0, result.output
    # its markers lie on the links' axes: they cannot fix the floating chain's roll, which
    # ``check`` reports as one error line while ``synth``, driving the base, needs no markers
    one_error_line(runner().invoke(main, ["check", str(model)]), "tracking", "rank")
