"""One calibration path: ``fccgrb calibrate``, the Python API's ``calibrate`` and a study's
calibration job give the same personal model, byte for byte, for the lower limb (Qualisys),
the whole body (Qualisys) and Plug-in Gait (a Vicon Nexus static with its PROCESSING group);
and the study reads the static's PROCESSING group as the command line does."""

from __future__ import annotations

from pathlib import Path

import pytest
from cli_helpers import run_cli

import fccgrb_cli as fc
from fccgrb_cli.batch.study.jobs import CalibrationJob, calibrate_job
from fccgrb_cli.batch.study.spec import SubjectSpec

ROOT = Path(__file__).resolve().parents[1]
C3D = ROOT.parent / "shared" / "data" / "c3d"
MODELS = ROOT / "configs" / "models"

CASES = [  # template, static, mass (kg) or None (read from PROCESSING)
    ("lower_limb.yaml", C3D / "Qualisys.c3d", 67.0),
    ("full_body.yaml", C3D / "Qualisys.c3d", 67.0),
    ("plugin_gait.yaml", C3D / "plugin_gait" / "HC030A01.c3d", None),
]


LABELS = ROOT / "configs" / "studies" / "plugin_gait_labels.yaml"


def _by_study(template: Path, static: Path, mass: float | None, target: Path,
              mapping: tuple[tuple[str, str], ...] = ()) -> str:
    subject = SubjectSpec(name="s1", group="g", template=template, static=static, frames=None,
                          trials=(), mass=mass, measurements=None, mapping=mapping)
    calibrate_job(CalibrationJob(subject, target, False))
    return target.read_text(encoding="utf-8")


@pytest.mark.parametrize("name, static, mass", CASES, ids=[c[0] for c in CASES])
def test_the_command_line_the_api_and_a_study_calibrate_alike(tmp_path, name, static, mass):
    if not static.exists():
        pytest.skip(f"{static} is absent")
    template = MODELS / name
    out = tmp_path / "cli.yaml"
    args = ["calibrate", template, static, "-o", out]
    result = run_cli(*args, *(["--mass", mass] if mass is not None else []))
    assert result.exit_code == 0, (result.output, result.stderr)
    by_cli = out.read_text(encoding="utf-8")
    by_api = fc.calibrate(fc.load_model(template), fc.read_trial(static), mass=mass).text
    by_study = _by_study(template, static, mass, tmp_path / "study.yaml")
    assert by_cli == by_api == by_study
    personal = fc.load_model(out)
    assert personal.bodies and all(b.inertia is not None for b in personal.bodies)


def test_a_study_reads_the_statics_processing_group_as_the_command_line_does(tmp_path):
    """The Helen Hayes template on the child's Nexus static: knee and ankle widths and the
    marker diameter come from its PROCESSING group (102/104, 61/59 and 10 mm; the sides
    averaged) in the study as on the command line, not the template's defaults."""
    static = C3D / "plugin_gait" / "HC030A01.c3d"
    if not static.exists():
        pytest.skip(f"{static} is absent")
    template = MODELS / "helen_hayes.yaml"
    out = tmp_path / "cli.yaml"
    result = run_cli("calibrate", template, static, "-o", out, "--map", LABELS)
    assert result.exit_code == 0, (result.output, result.stderr)
    import yaml

    mapping = tuple(yaml.safe_load(LABELS.read_text(encoding="utf-8")).items())
    by_study = _by_study(template, static, None, tmp_path / "study.yaml", mapping)
    assert out.read_text(encoding="utf-8") == by_study
    defaults = run_cli("calibrate", template, static, "-o", tmp_path / "typed.yaml", "--map",
                       LABELS, "--knee-width", "100", "--ankle-width", "70",
                       "--marker-diameter", "14")
    assert defaults.exit_code == 0, defaults.stderr
    assert (tmp_path / "typed.yaml").read_text(encoding="utf-8") != by_study
