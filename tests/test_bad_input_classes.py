"""The bad-input classes of the next lab's files and a user's second run, each closed as a class
and checked here in-process (the generated cases in tests/fuzz run the same classes as
processes): every rate a file states, a TRC whose clock skips, a model without tracked points
for every method, every sweep grid key given a mapping or a list of lists, a level or tolerance
out of range, --parallel with a method that solves in sequence, an export onto another trial's
C3D, a sweep output that is not this sweep's, a YAML bomb inside a key, an oversized label map.
Each: exit status 2, one line naming the file and the key or option, nothing written.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from cli_helpers import one_error_line, run_cli

from fccgrb_cli.pipeline.options import METHODS

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
TRIAL = ROOT / "sample_data" / "five_bar.c3d"


@pytest.fixture(scope="module")
def lab(tmp_path_factory) -> Path:
    folder = tmp_path_factory.mktemp("lab")
    for args in (("synth", MODEL, "-o", folder / "t.c3d", "--duration", "0.5"),
                 ("perturb", folder / "t.c3d", folder / "t.trc", "--level", "0"),
                 ("perturb", folder / "t.c3d", folder / "u.c3d", "--level", "5"),
                 ("solve", MODEL, folder / "t.c3d", "-o", folder / "r.h5", "--method",
                  "nrm-ls")):
        out = run_cli(*args)
        assert out.exit_code == 0, out.output + out.stderr
    return folder


def files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in folder.iterdir() if p.is_file()}


def refused(folder: Path, args: tuple, *fragments: str) -> str:
    before = files(folder)
    line = one_error_line(run_cli(*args), *fragments)
    assert files(folder) == before
    assert not any(p.is_dir() for p in folder.iterdir())
    return line


def _trc_with_rate(lab: Path, target: Path, rate: str) -> Path:
    lines = (lab / "t.trc").read_text(encoding="utf-8").split("\n")
    fields = lines[2].split("\t")
    fields[0] = fields[1] = rate
    lines[2] = "\t".join(fields)
    target.write_text("\n".join(lines), encoding="utf-8")
    return target


@pytest.mark.parametrize("rate", ["1e30", "0", "-5", "nan", "inf", "100000.5"])
def test_every_trc_rate(lab, tmp_path, rate):
    trc = _trc_with_rate(lab, tmp_path / "r.trc", rate)
    refused(tmp_path, ("solve", MODEL, trc, "-o", tmp_path / "n.h5"), "r.trc: line 3: DataRate",
            "at most 100000 Hz")


def test_the_largest_rate_is_read_and_a_coarse_clock_is_not_refused(lab, tmp_path):
    """100 kHz, its Times written as write_trc writes them; 2 kHz with Times rounded to 3
    decimals (half a millisecond: twice the quarter frame) is still one uniform clock."""
    from fccgrb_cli.trial.record import read_trial, write_trc

    trial = read_trial(lab / "t.c3d")
    write_trc(tmp_path / "fast.trc", list(trial.labels), trial.markers, 1e5)
    assert read_trial(tmp_path / "fast.trc").rate == 1e5
    write_trc(tmp_path / "k.trc", list(trial.labels), trial.markers, 2000.0)
    lines = (tmp_path / "k.trc").read_text(encoding="utf-8").split("\n")
    for k in range(6, len(lines) - 1):
        fields = lines[k].split("\t")
        fields[1] = f"{float(fields[1]):.3f}"
        lines[k] = "\t".join(fields)
    (tmp_path / "k.trc").write_text("\n".join(lines), encoding="utf-8")
    assert read_trial(tmp_path / "k.trc").n_frames == trial.n_frames


@pytest.mark.parametrize("rate", [1e30, -1.0, float("nan"), 2e5])
def test_every_c3d_point_rate(lab, tmp_path, rate):
    import struct

    from fuzz import c3dpatch

    data = c3dpatch.set_parameter((lab / "t.c3d").read_bytes(), "POINT:RATE", rate)
    path = tmp_path / "r.c3d"
    path.write_bytes(c3dpatch.set_header(data, "rate", rate))
    assert struct.unpack("<f", path.read_bytes()[20:24])[0] == pytest.approx(rate, nan_ok=True)
    refused(tmp_path, ("solve", MODEL, path, "-o", tmp_path / "n.h5"), "r.c3d: POINT:RATE")


def test_a_trc_clock_that_skips_rows(lab, tmp_path):
    """Rows 10–12 taken out, NumFrames made to agree: the first line off the clock named."""
    lines = (lab / "t.trc").read_text(encoding="utf-8").split("\n")
    fields = lines[2].split("\t")
    fields[2] = str(int(fields[2]) - 3)
    lines[2] = "\t".join(fields)
    path = tmp_path / "g.trc"
    path.write_text("\n".join(lines[:14] + lines[17:]), encoding="utf-8")
    refused(tmp_path, ("solve", MODEL, path, "-o", tmp_path / "n.h5"), "g.trc: line 15: Time",
            "uniform clock")


@pytest.mark.parametrize("method", METHODS)
@pytest.mark.parametrize("section", ["tracking:\n  points: []\n", "tracking: {}\n", ""])
def test_no_tracked_point_for_every_method(lab, tmp_path, method, section):
    text = MODEL.read_text(encoding="utf-8")
    model = tmp_path / "e.yaml"
    model.write_text(text[:text.index("\ntracking:")] + "\n" + section, encoding="utf-8")
    refused(tmp_path, ("solve", model, lab / "t.c3d", "--method", method, "-o",
                       tmp_path / "n.h5"), "e.yaml: tracking.points: expected at least one")


def sweep_file(folder: Path, cells: str, name: str = "sw") -> Path:
    path = folder / "s.yaml"
    path.write_text(f"name: {name}\nmodel: {MODEL}\ntrial: {{file: {folder / 't.c3d'}}}\n"
                    f"cells:\n{cells}\n", encoding="utf-8")
    return path


@pytest.mark.parametrize("key", ["seed", "level", "tol", "filter_cutoff", "tracking_weight",
                                 "points", "method", "perturb_markers"])
@pytest.mark.parametrize("value", ["{a: 1}", "[[1, 2]]", "[1, {a: 1}]"])
def test_every_sweep_grid_key_given_a_mapping_or_nested_lists(lab, tmp_path, key, value):
    (tmp_path / "t.c3d").write_bytes((lab / "t.c3d").read_bytes())
    cells = f"  - {{method: nrm-ls, {key}: {value}}}" if key != "method" else \
        f"  - {{method: {value}}}"
    if key == "perturb_markers" and value == "[[1, 2]]":
        cells = "  - {method: nrm-ls, perturb_markers: [[P1, {a: 1}]]}"
    config = sweep_file(tmp_path, cells)
    refused(tmp_path, ("sweep", config, "-o", tmp_path / "n.h5"), f"s.yaml: cells[0].{key}")


@pytest.mark.parametrize("key,value", [("level", "-5"), ("level", ".inf"), ("level", ".nan"),
                                       ("level", "1001"), ("tol", "0"), ("tol", ".inf")])
def test_sweep_levels_and_tolerances_out_of_range(lab, tmp_path, key, value):
    (tmp_path / "t.c3d").write_bytes((lab / "t.c3d").read_bytes())
    config = sweep_file(tmp_path, f"  - {{method: nrm-ls, {key}: {value}}}")
    refused(tmp_path, ("sweep", config, "-o", tmp_path / "n.h5"), f"s.yaml: cells[0].{key}")


@pytest.mark.parametrize("method", ["ad", "nrm-ls", "nrm-wls"])
def test_parallel_with_a_method_that_would_ignore_it(lab, tmp_path, method):
    refused(tmp_path, ("solve", MODEL, lab / "t.c3d", "--method", method, "--parallel", "-o",
                       tmp_path / "n.h5"), "--parallel: expected only with", method)


def test_export_onto_another_trials_c3d(lab, tmp_path):
    """u.c3d: the same labels and frames, its markers 5 mm away: refused; the run's own trial
    (moved) is taken."""
    refused(tmp_path, ("export", lab / "r.h5", "--format", "c3d", "--trial", lab / "u.c3d",
                       "-o", tmp_path / "x.c3d"), "u.c3d: its markers are up to",
            "expected the trial it was solved from")
    moved = tmp_path / "moved.c3d"
    moved.write_bytes((lab / "t.c3d").read_bytes())
    out = run_cli("export", lab / "r.h5", "--format", "c3d", "--trial", moved, "-o",
                  tmp_path / "x.c3d")
    assert out.exit_code == 0, out.stderr
    out = run_cli("solve", MODEL, moved, "--perturb", "30", "-o", tmp_path / "p.h5")
    assert out.exit_code == 0, out.stderr  # its markers up to √3 × 30 mm from the file's:
    out = run_cli("export", tmp_path / "p.h5", "--format", "c3d", "-o", tmp_path / "y.c3d")
    assert out.exit_code == 0, out.stderr  # still its own trial


def test_sweep_output_that_is_not_this_sweeps(lab, tmp_path):
    (tmp_path / "t.c3d").write_bytes((lab / "t.c3d").read_bytes())
    config = sweep_file(tmp_path, "  - {method: nrm-ls}")
    (tmp_path / "notes.txt").write_text("my notes\n", encoding="utf-8")
    refused(tmp_path, ("sweep", config, "-o", tmp_path / "notes.txt"), "notes.txt: exists")
    (tmp_path / "r.h5").write_bytes((lab / "r.h5").read_bytes())
    refused(tmp_path, ("sweep", config, "-o", tmp_path / "r.h5"), "r.h5: exists and holds no")
    (tmp_path / "notes.txt").unlink()
    (tmp_path / "r.h5").unlink()
    out = run_cli("sweep", config, "-o", tmp_path / "o.h5")
    assert out.exit_code == 0, out.stderr
    again = run_cli("sweep", config, "-o", tmp_path / "o.h5")  # its own: merged again
    assert again.exit_code == 0, again.stderr
    other = sweep_file(tmp_path, "  - {method: nrm-ls}", name="other")
    before = (tmp_path / "o.h5").read_bytes()
    one_error_line(run_cli("sweep", other, "-o", tmp_path / "o.h5"),
                   "o.h5: holds the results of the sweep 'sw', not 'other'")
    assert (tmp_path / "o.h5").read_bytes() == before


@pytest.mark.parametrize("key", ["name", "gravity"])
def test_a_yaml_bomb_inside_a_key_names_it(tmp_path, key):
    row = "[" + ", ".join(["x"] * 30) + "]"
    value = f"[&b0 {row}" + "".join(
        f", &b{n} [" + ", ".join([f"*b{n - 1}"] * 30) + "]" for n in range(1, 6)) + "]"
    lines = [line for line in MODEL.read_text(encoding="utf-8").splitlines()
             if not line.startswith(key + ":")]
    path = tmp_path / "b.yaml"
    path.write_text("\n".join([*lines, f"{key}: {value}"]) + "\n", encoding="utf-8")
    one_error_line(run_cli("check", path), "b.yaml: line", f": {key}[",
                   "at most 1,000,000 values")


def test_a_label_map_past_one_mebibyte(lab, tmp_path):
    big = tmp_path / "big.yaml"
    big.write_text("P1: P1\n" * (160 * 1024), encoding="utf-8")
    refused(tmp_path, ("solve", MODEL, lab / "t.c3d", "--map", big, "-o", tmp_path / "n.h5"),
            "big.yaml: expected a label map of at most 1 MiB")
