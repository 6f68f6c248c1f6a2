"""A synthetic walking subject for the study tests, made without the shared data: the lower-limb
template with a walking-like motion of every angle (1 Hz strides, the legs half a cycle apart)
and a pelvis travelling forward, synthesized by ``fccgrb synth`` into a C3D of the template's 28
markers; perturbed copies (``fccgrb perturb``) are further trials. Events come from the markers
(Zeni et al. 2008), so each trial has strides on both sides. The walker touches nothing (its
pelvis is driven, no ground reaction acts on it), so the study calibrates a copy of the
template without contact bodies: with them, every moment of a leg in stance would lack its
ground reaction and not be trusted (README, "What fccgrb checks for you")."""

from __future__ import annotations

from pathlib import Path

import yaml
from cli_helpers import run_cli

ROOT = Path(__file__).resolve().parents[1]
TEMPLATE = ROOT / "configs" / "models" / "lower_limb.yaml"

# clinical angle → (mean, amplitude, phase in deg) of a 1 Hz sinusoid (deg)
CLINICAL = {"hip_flexion": (12.0, 22.0, 0.0), "hip_adduction": (2.0, 4.0, 60.0),
            "hip_rotation": (0.0, 4.0, 120.0), "knee_flexion": (30.0, 26.0, -90.0),
            "ankle_dorsiflexion": (2.0, 10.0, 30.0), "ankle_inversion": (3.0, 4.0, 75.0)}


def walking_model(folder: Path, speed: float = 1.1) -> Path:
    """The template with prescribed motions: each clinical angle c(t) as in CLINICAL (the left
    leg half a cycle later), so θ = 90° + sign·c(t); the pelvis travelling at ``speed`` m/s."""
    doc = yaml.safe_load(TEMPLATE.read_text(encoding="utf-8"))
    for angle in doc["angles"]:
        stem, side = angle["name"].rsplit("_", 1)
        mean, amplitude, phase = CLINICAL[stem]
        sign = angle["clinical"]["sign"]
        angle["motion"] = {"mean": 90.0 + sign * mean, "terms": [
            {"amplitude": sign * amplitude, "frequency": 1.0,
             "phase": phase + (180.0 if side == "l" else 0.0)}]}
    doc["bodies"]["pelvis"]["motion"] = {"translation": [{"mean": 0.0, "rate": speed},
                                                         {"mean": 0.0}, {"mean": 0.0}]}
    path = folder / "walker.yaml"
    path.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")
    return path


def walking_trials(folder: Path, count: int, duration: float = 2.6) -> list[Path]:
    """``count`` trials of the walker: the synthesized one and perturbed copies (5 mm, seeds
    1, 2, …), C3D at 100 Hz; beside them ``template.yaml``, the template without contacts."""
    model = walking_model(folder)
    doc = yaml.safe_load(TEMPLATE.read_text(encoding="utf-8"))
    doc.pop("loads", None)
    (folder / "template.yaml").write_text(yaml.safe_dump(doc, sort_keys=False),
                                          encoding="utf-8")
    first = folder / "walk1.c3d"
    result = run_cli("synth", model, "-o", first, "--duration", duration)
    assert result.exit_code == 0, result.output
    out = [first]
    for k in range(2, count + 1):
        path = folder / f"walk{k}.c3d"
        result = run_cli("perturb", first, path, "--level", 5, "--seed", k)
        assert result.exit_code == 0, result.output
        out.append(path)
    return out


def study_doc(trials: list[Path]) -> dict:
    """Two subjects in two groups: A with three trials (one a glob), B with two."""
    return {
        "name": "walkers",
        "template": str(trials[0].parent / "template.yaml"),  # without contact bodies
        "options": {"filter_cutoff": 6},
        "subjects": [
            {"name": "A", "group": "control", "static": trials[0].name,
             "trials": ["walk[12].c3d", trials[2].name], "mass": 70},
            {"name": "B", "group": "patients", "static": trials[3].name,
             "trials": [trials[3].name, trials[1].name], "mass": 55.5},
        ]}
