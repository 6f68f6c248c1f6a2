"""``fccgrb report study.h5 --html FOLDER``: the clinical report, checked in a real browser.

Headless Chromium (tests/browser.py; skipped where no chromium binary is found) opens every page
and must report no console message, exception or log entry and fetch nothing but the page; every
plot is laid out with its curves drawn and shows both sides' colours and the normative band in
a screenshot; the pages still lay out for print and print to PDF. The tables are compared with
the results file read here with h5py: every spatiotemporal mean, SD and count (subjects and
groups), every norm against the CSV, every event time, and every flag's frame count recomputed
from ``/runs/<name>/flags`` and the bits its attributes declare — so a flag added to the file
later appears without a change to the report. Without a browser: the SVG's coordinates map back
to the data, the pages hold no script and no external reference, and bad options are one line.
"""

from __future__ import annotations

import base64
import io
import json
import math
import re
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from browser import Browser, chromium_binary
from cli_helpers import one_error_line, run_cli
from flag_bits import declared

from fccgrb_cli.gait.cycles import PARAMETERS
from fccgrb_cli.presentation.clinical_report.svg import (
    BOTTOM,
    HEIGHT,
    LEFT,
    TOP,
    WIDTH,
    Curve,
    cycle_plot,
    nice_ticks,
)

needs_chromium = pytest.mark.skipif(chromium_binary() is None,
                                    reason="no chromium binary (apt-get install chromium)")
STEMS = ("hip_flexion", "hip_adduction", "hip_rotation", "knee_flexion", "ankle_dorsiflexion",
         "ankle_inversion")
LEFT_RGB, RIGHT_RGB, NORM_RGB = (0x1F, 0x5F, 0xBF), (0xC8, 0x30, 0x2C), (0x8C, 0x8C, 0x8C)


def _norms(path: Path) -> Path:
    """A normative CSV: a curve for every angle and moment, a value for every parameter."""
    lines = ["variable,percent,mean,sd"]
    for k, stem in enumerate(STEMS):
        for p in range(0, 101, 5):
            lines.append(f"{stem},{p},{10 * math.sin(math.pi * p / 50 + k):.3f},4")
            lines.append(f"{stem}_moment,{p},{0.3 * math.cos(math.pi * p / 50 + k):.4f},0.1")
    for k, (name, _) in enumerate(PARAMETERS):
        lines.append(f"{name},,{1.5 + k},{0.25 + 0.01 * k}")
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def _flagged_copy(results: Path, target: Path) -> Path:
    """The study file with flags set on some frames of two runs, and a flag no version of
    fccgrb declares (bit 1 << 14, with a description attribute), as a later version could add."""
    shutil.copyfile(results, target)
    with h5py.File(target, "r+") as h5:
        for k, run in enumerate(("A-walk2", "B-walk4")):
            flags = h5["runs"][run]["flags"]
            values = flags[()]
            values[10 + k:40] |= 4
            values[35:37 + 5 * k] |= 2
            values[100:100 + 17 * (k + 1)] |= 1 << 14
            flags[...] = values
            flags.attrs["marker_dropout"] = np.uint16(1 << 14)
            flags.attrs["marker_dropout_means"] = "a marker of the model missing for 50 ms"
        # a per-joint flag dataset describing its bits in JSON, as the moment_flags dataset does
        # (one this version does not write, so its meanings can come from nowhere else)
        run = h5["runs"]["A-walk2"]
        joints = np.zeros(run["theta"].shape, dtype=np.uint16)
        joints[50:60, 3] |= 4
        joints[55:75, 0] |= 1
        joints[200:203, :] |= 4
        moment = run.create_dataset("joint_flags", data=joints)
        moment.attrs.update({"kinematics": np.uint16(1), "contact": np.uint16(4)})
        moment.attrs["bits"] = json.dumps([
            {"name": "kinematics", "value": 1, "meaning": "its frame is flagged",
             "detail": ""},
            {"name": "contact", "value": 4, "meaning": "a foot off the plates",
             "detail": "stance off plate 2"}])
    return target


@pytest.fixture(scope="module")
def report(walking_reference: Path) -> tuple[Path, Path, Path]:
    """(folder, results, norms): the report of the synthetic study (some frames flagged, one
    flag unknown to this version) with norms."""
    folder = walking_reference.parent / "report"
    norms = _norms(walking_reference.parent / "norms.csv")
    flagged = _flagged_copy(walking_reference, walking_reference.parent / "flagged.h5")
    result = run_cli("report", flagged, "--html", folder, "--normative", norms)
    assert result.exit_code == 0, (result.output, result.stderr)
    assert sorted(p.name for p in folder.iterdir()) == ["index.html", "subject-A.html",
                                                        "subject-B.html"]
    return folder, flagged, norms


# --- without a browser ---------------------------------------------------------------------

def test_svg_coordinates_map_back_to_the_data() -> None:
    """The mean curve's path, read back through the axes' tick labels, gives the data."""
    percent = np.linspace(0, 100, 101)
    mean = 20 * np.sin(2 * np.pi * percent / 100) + 5
    svg = cycle_plot("Knee flexion", "deg", [Curve("right", mean, np.full(101, 3.0), 4, 61.0)])
    path = re.search(r'd="([^"]+)" class="mean"', svg)[1]
    xy = np.array([[float(v) for v in p[1:].split(",")] for p in path.split()])
    ticks = [(float(y), float(t)) for y, t in re.findall(
        r'<text x="\d+" y="([\d.]+)" class="tick" text-anchor="end">([-\d.]+)</text>', svg)]
    ys, vs = np.array(ticks).T
    assert (np.diff(vs) > 0).all() and (np.diff(ys) < 0).all()  # values grow upwards
    (y0, v0), (y1, v1) = ticks[0], ticks[-1]  # label baselines sit 3 units below their line
    values = v0 + (xy[:, 1] - (y0 - 3)) * (v1 - v0) / (y1 - y0)
    np.testing.assert_allclose(values, mean, atol=0.01)
    width = WIDTH - LEFT - 8
    np.testing.assert_allclose((xy[:, 0] - LEFT) / width * 100, percent, atol=0.01)
    assert xy[:, 1].min() >= TOP and xy[:, 1].max() <= HEIGHT - BOTTOM
    assert 'class="toe-off"' in svg and "right (n=4)" in svg


@pytest.mark.parametrize(("low", "high"), [(-23.4, 65.3), (0.0, 1e-12), (-1.24, 0.35),
                                           (3.0, 3.0), (-0.61, 1.24), (100.0, 2000.0)])
def test_ticks_cover_the_range_with_round_steps(low: float, high: float) -> None:
    ticks = nice_ticks(low, high)
    assert ticks[0] <= low and ticks[-1] >= high and 2 <= len(ticks) <= 9
    steps = np.diff(ticks)
    np.testing.assert_allclose(steps, steps[0])
    mantissa = steps[0] / 10 ** math.floor(math.log10(steps[0]))
    assert any(abs(mantissa - m) < 1e-9 for m in (1, 2, 5))


def test_pages_are_self_contained(report: tuple[Path, Path, Path]) -> None:
    folder, _, _ = report
    for page in folder.iterdir():
        text = page.read_text(encoding="utf-8")
        assert "<script" not in text.lower()
        assert not re.search(r"(src|href)=\"(https?:)?//", text), page.name
        assert "@media print" in text and text.count("<svg") >= (12 if "subject-" in page.name
                                                                else 24)
        if "subject-" in page.name:  # what the calibration did, from the model it wrote
            assert "personalized by `fccgrb calibrate`" in text
        if "subject-A" in page.name:  # the flags' descriptions, as the file states them
            assert "a marker of the model missing for 50 ms" in text
            assert "a foot off the plates" in text and "stance off plate 2" in text


def test_bad_report_options_are_one_line(report: tuple[Path, Path, Path], tmp_path: Path
                                         ) -> None:
    folder, results, norms = report
    foreign = tmp_path / "mine"
    foreign.mkdir()
    (foreign / "notes.txt").write_text("keep me", encoding="utf-8")
    one_error_line(run_cli("report", results, "--html", foreign), "not an fccgrb report")
    assert (foreign / "notes.txt").read_text(encoding="utf-8") == "keep me"
    one_error_line(run_cli("report", results, "--normative", norms), "--normative")
    bad = tmp_path / "bad.csv"
    bad.write_text("variable,percent,mean,sd\nknee_flexion,140,1,2\n", encoding="utf-8")
    one_error_line(run_cli("report", results, "--html", tmp_path / "r", "--normative", bad),
                   "line 2")
    other = tmp_path / "plain.h5"
    with h5py.File(other, "w") as h5:
        h5.attrs["format_version"] = 2
    one_error_line(run_cli("report", other, "--html", tmp_path / "r2"), "expected a study file")
    # a second report replaces the first as a whole
    assert run_cli("report", results, "--html", folder, "--normative", norms).exit_code == 0


# --- in the browser ------------------------------------------------------------------------

LAYOUT = """(() => {
  const box = e => { const r = e.getBoundingClientRect();
    return [r.left + window.scrollX, r.top + window.scrollY, r.width, r.height]; };
  const plots = [...document.querySelectorAll('figure.cycle')].map(f => ({
    variable: f.dataset.variable, box: box(f.querySelector('svg')),
    means: [...f.querySelectorAll('path.mean')].map(p => [p.dataset.side, p.getTotalLength()]),
    norm: f.querySelectorAll('path.norm').length}));
  const cells = sel => [...document.querySelectorAll(sel)].map(tr =>
    [...tr.querySelectorAll('td')].map(td => ({text: td.textContent.trim(), ...td.dataset})));
  return {plots, width: document.documentElement.scrollWidth,
          spatiotemporal: [...document.querySelectorAll('table.spatiotemporal')].map(t =>
            [...t.querySelectorAll('tbody tr')].map(tr => ({parameter: tr.dataset.parameter,
              cells: [...tr.querySelectorAll('td')].slice(1).map(td => ({...td.dataset,
                text: td.textContent.trim()}))}))),
          sides: [...document.querySelectorAll('table.spatiotemporal')].map(t =>
            [...t.querySelectorAll('thead th')].slice(1, -1).map(th =>
              th.textContent.trim().split(' ')[0])),
          groups: [...document.querySelectorAll('section.group')].map(s => s.dataset.group),
          quality: cells('table.quality tbody tr'),
          qualityTrials: [...document.querySelectorAll('table.quality tbody tr')].map(
            tr => tr.dataset.trial),
          flags: [...document.querySelectorAll('table.quality thead th[data-flag]')].map(
            th => th.dataset.flag),
          events: cells('table.events tbody tr'),
          nav: getComputedStyle(document.querySelector('nav')).display};
})()"""


def _formatted(mean: float, sd: float, n: int) -> str:
    """The cell text the report must show for these numbers (3 and 2 significant digits)."""
    if n == 0 or not math.isfinite(mean):
        return f"– ({n})"
    return f"{mean:.3g}" + (f" ± {sd:.2g}" if math.isfinite(sd) else "") + f" ({n})"


def _check_table(rows: list[dict], table: h5py.Group, sides: list[str],
                 norms: dict[str, tuple[float, float]]) -> None:
    assert [r["parameter"] for r in rows] == [p for p, _ in PARAMETERS]
    assert sides == list(table)
    for k, row in enumerate(rows):
        for cell, side in zip(row["cells"], sides, strict=False):
            mean, sd = (float(table[side][key][k]) for key in ("mean", "sd"))
            n = int(table[side]["n"][k])
            assert same(float(cell["mean"]), mean) and same(float(cell["sd"]), sd)
            assert int(cell["n"]) == n
            assert cell["text"] == _formatted(mean, sd, n)
        norm = row["cells"][-1]
        expected = norms[row["parameter"]]
        assert (float(norm["mean"]), float(norm["sd"])) == expected


def same(a: float, b: float) -> bool:
    """Equal to the last bit (NaN equal to NaN)."""
    return a == b or (math.isnan(a) and math.isnan(b))


def _read_norms(path: Path) -> dict[str, tuple[float, float]]:
    out = {}
    for line in path.read_text(encoding="utf-8").splitlines()[1:]:
        name, percent, mean, sd = line.split(",")
        if not percent:
            out[name] = (float(mean), float(sd))
    return out


def _pixels(png: bytes):
    image = pytest.importorskip("matplotlib.image")
    return (image.imread(io.BytesIO(png))[:, :, :3] * 255).round().astype(int)


def _has(region: np.ndarray, rgb: tuple[int, int, int], tolerance: int = 40) -> bool:
    return bool((np.abs(region - np.array(rgb)).max(axis=2) <= tolerance).any())


@needs_chromium
def test_report_in_a_browser(report: tuple[Path, Path, Path]) -> None:
    folder, results, norms_path = report
    norms = _read_norms(norms_path)
    with Browser() as browser, h5py.File(results, "r") as h5:
        for page in sorted(folder.iterdir()):
            loaded = browser.open(page)
            assert loaded.messages == [], (page.name, loaded.messages)
            assert loaded.requests == [page.resolve().as_uri()], loaded.requests
            layout = browser.evaluate(LAYOUT)
            subject = page.stem.removeprefix("subject-") if page.name != "index.html" else None
            # every plot laid out and drawn, both sides and the norm in the screenshot
            pixels = _pixels(browser.screenshot())
            expected = 12 if subject else 12 * len(h5["groups"])
            assert len(layout["plots"]) == expected
            for plot in layout["plots"]:
                x, y, w, h = (round(v) for v in plot["box"])
                assert w > 200 and h > 120, plot
                assert sorted(s for s, _ in plot["means"]) == ["left", "right"], plot
                assert all(length > 100 for _, length in plot["means"]), plot
                assert plot["norm"] == 1, plot
                region = pixels[y:y + h, x:x + w]
                assert region.shape[:2] == (h, w)
                for rgb in (LEFT_RGB, RIGHT_RGB, NORM_RGB):
                    assert _has(region, rgb), (page.name, plot["variable"], rgb)
            # the tables hold the results file's numbers
            if subject is None:
                assert layout["groups"] == list(h5["groups"])
                for rows, sides, group in zip(layout["spatiotemporal"], layout["sides"],
                                              layout["groups"], strict=True):
                    _check_table(rows, h5["groups"][group]["spatiotemporal"], sides, norms)
                continue
            g = h5["subjects"][subject]
            (rows,), (sides,) = layout["spatiotemporal"], layout["sides"]
            _check_table(rows, g["spatiotemporal"], sides, norms)
            runs = [r.decode() if isinstance(r, bytes) else r for r in g.attrs["runs"]]
            assert layout["qualityTrials"] == runs
            per_run = {run: declared(h5["runs"][run]) for run in runs}
            union = {label for found in per_run.values() for label in found}
            assert set(layout["flags"]) == union  # every flag any of its trials declares
            assert {"unconverged", "topology", "jump", "marker_dropout"} <= union
            assert "moment_flags:contact" in union  # this version's own
            assert subject == "B" or "joint_flags:contact" in union
            for row, run in zip(layout["quality"], runs, strict=True):
                counted = {c["flag"]: int(c["value"]) for c in row if "flag" in c}
                assert counted == {label: per_run[run][label][2] if label in per_run[run] else 0
                                   for label in union}
                assert int(row[2]["value"]) == len(h5["runs"][run]["flags"])
                assert int(row[3]["value"]) == int(h5["runs"][run]["converged"][()].sum())
            events = [(row[0]["text"], float(row[4]["value"])) for row in layout["events"]]
            expected_events = []
            for run in runs:
                e = h5["runs"][run]["gait/events"]
                used = e.attrs["used"]
                expected_events += [(run, float(t)) for t in e[used]["time"][()]]
            assert events == expected_events
        # print: the same plots, navigation hidden, a PDF of a few A4 pages
        browser.open(folder / "subject-A.html")
        browser.call("Emulation.setEmulatedMedia", media="print")
        printed = browser.evaluate(LAYOUT)
        assert printed["nav"] == "none"
        assert all(p["box"][2] > 150 and p["box"][3] > 90 for p in printed["plots"])
        pdf = base64.b64decode(browser.call("Page.printToPDF", preferCSSPageSize=True)["data"])
        assert pdf.startswith(b"%PDF")
        assert 2 <= len(re.findall(rb"/Type\s*/Page\b(?!s)", pdf)) <= 12
