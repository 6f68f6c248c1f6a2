"""Regenerate every figure of README.md and docs/ by running the commands, as a user would.

    python docs/generate.py --part cheap|tables|benchmarks|figures|study|all [--check]
    python docs/generate.py --block example-session [--block gait-trial ...] [--check]

Every command runs through the installed ``fccgrb`` (or ``python benchmarks/...``) in a
temporary folder laid out like the repository (``configs`` linked to the repository's, and
``../shared`` to the shared data folder when it exists), so each console block shows exactly
what the command it names prints (on stdout and stderr, less progress lines and the compiled
kernels' notices, which depend on this machine's cache). The generated blocks of README.md and
of the guides in docs/ sit between ``<!-- generated: NAME -->`` and ``<!-- /generated -->``; only
their content is rewritten, in whichever page holds the block.

Parts and their blocks:

* ``cheap`` (seconds): ``example-session`` (the five-bar session), ``full-turns`` (the
  crank-rocker through three turns, and docs/crank_angle.png), ``gait-trial`` (calibrate,
  solve, plot and export the walking trial of ../shared/data/c3d/Qualisys.c3d, and
  docs/gait_qualisys.png and docs/gait_cycles.png; skipped when the trial is absent),
  ``table-subset`` (check only: the AD and NRM rows of docs/table1.md and docs/table2.md
  against a sweep of just those cells), ``cli-reference`` (docs/cli.md from every command's
  ``--help``), ``opensim-agreement`` (OpenSim's IK and ID regression cases, by
  benchmarks/opensim_agreement.py; skipped without ../shared/data/opensim).
* ``tables`` (minutes): ``sweeps`` (configs/sweeps/table1.yaml and table2.yaml → docs/table1.md,
  docs/table2.md and the README's sweep paragraph), ``gait-methods`` (CNO-SQP against NRM-WLS on
  the walking trial), ``whole-body`` (the whole body on the walking trial with the residual
  reduction: its console, the residual table beside the published ones, and
  docs/residual_force.png).
* ``benchmarks`` (minutes): ``bench-kinematics``, ``bench-optimization``, ``bench-gait``,
  ``bench-dynamics``, ``bench-peers`` (OpenSim's IK beside ours where ``opensim`` is
  installed), ``bench-long`` (a 10-minute trial under /usr/bin/time -v), ``bench-startup``
  (whole commands in fresh processes), ``bench-batch`` (a 50-trial study on this machine),
  ``bench-opensim-tools`` (the whole command beside OpenSim 4.6's IK and ID tools on OpenSim's
  own trial, where a Python with ``opensim`` is given by FCCGRB_OPENSIM_PYTHON),
  ``bench-smoothing`` (the smoother's table; its longer checks and figure are run by hand):
  the performance tables from benchmarks/*.py.
* ``study`` (a minute; the shared data and a chromium binary): ``study`` (``fccgrb batch
  configs/studies/shared.yaml`` and its clinical report, with norms from a stand-in control
  group of perturbed copies of the adult's walk; docs/report_subject.png, the adult's page in
  headless Chromium).
* ``figures``: ``figures`` (the Figure 8 case: docs/point_P6.png, ed_P6.png, angle_J4_uv.png,
  velocity_P6_x.png via ``fccgrb plot``, and the commands that make them) and ``figure8-seeds``
  (the end point's distance to the truth over three seeds).

``--check`` writes nothing: it compares and exits with status 1 naming the blocks that differ.
Timing figures change from run to run, so the comparison replaces them by a placeholder first:
a number followed by ``ms/frame``, ``ms``, ``s``, ``min`` or ``frames/s`` in running text; in a
console table, the values under a ``ms/frame``, ``frames/s``, ``x real time``, seconds
(``wall s``, ``CPU s``, ``per trial s``, ``solve s``, ``kernels s``, a trial's ``.c3d s``),
``trials/min`` or ``peak RSS MiB`` header; in a
markdown table, the cells of a column whose header names ``ms/frame``, ``frames/s``, ``real
time`` or ``total ms`` (not the paper's column), and the level columns of a table whose caption
names ``ms/frame`` (there only our figure; the paper's, in brackets, is kept). Spacing is
ignored. Every other number must match as printed. Images are compared pixel by pixel (with
matplotlib's RMS tolerance when the PNG was written by another matplotlib version).
"""

from __future__ import annotations

import argparse
import csv
import difflib
import importlib.util
import os
import re
import shlex
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
SHARED = ROOT.parent / "shared"
QUALISYS = SHARED / "data" / "c3d" / "Qualisys.c3d"
PAPER_TABLES = ROOT / "fccgrb_cli" / "data" / "paper_tables.csv"
FIVE_BAR = "configs/models/five_bar.yaml"
GAIT_TRIAL = "../shared/data/c3d/Qualisys.c3d"

# ---------------------------------------------------------------------------------------------
# What a block produces


@dataclass(frozen=True)
class ReadmeBlock:
    """The content between ``<!-- generated: NAME -->`` and ``<!-- /generated -->``."""

    name: str
    text: str


@dataclass(frozen=True)
class TextFile:
    """A whole generated file of docs/ (path relative to the repository)."""

    path: str
    text: str


@dataclass(frozen=True)
class Image:
    """A figure (PNG bytes) for ``path`` (relative to the repository)."""

    path: str
    data: bytes

    @classmethod
    def made(cls, path: str, ws: Workspace) -> Image:
        return cls(path, (ws.dir / path).read_bytes())


@dataclass(frozen=True)
class RowCheck:
    """Check only: every row of ``text`` (markdown tables) must be in the file at ``path``."""

    path: str
    text: str


Artifact = ReadmeBlock | TextFile | Image | RowCheck


class Skip(Exception):
    """A block that cannot be made here (say, the shared data folder is absent)."""


# ---------------------------------------------------------------------------------------------
# Running commands


def _executable(name: str) -> str:
    beside = Path(sys.executable).parent / name
    return str(beside) if beside.exists() else (shutil.which(name) or name)


# progress lines (fccgrb_cli.core.progress: "LABEL: [###...] frame|trial N/M (P %, T...) …"; the
# sweep's "sweep: N/M cells (…"): on stderr only when a run is slow, so never in a block
PROGRESS = re.compile(r"^([\w .-]+: (\[[#.]*\] )?(frame|trial) \d+/\d+ \(\d+ %, .*"
                      r"|sweep: \d+/\d+ cells \(.*)$")


# the compiled kernels' notices ("compiling the compiled kernels…", "compiled kernels loaded in …
# s"): what this machine's cache holds, not what the command answers; on stderr, never in a block
KERNEL_NOTICE = re.compile(r"^fccgrb: (compiling|compiled kernels) ")


class Workspace:
    """A temporary folder laid out like the repository; runs each command once (cached)."""

    def __init__(self, keep: bool = False):
        self.top = Path(tempfile.mkdtemp(prefix="fccgrb-docs-"))
        self.dir = self.top / "work"
        self.dir.mkdir()
        (self.dir / "configs").symlink_to(ROOT / "configs")
        (self.dir / "docs").mkdir()
        if SHARED.is_dir():
            (self.top / "shared").symlink_to(SHARED)
        self.keep = keep
        self.outputs: dict[str, str] = {}
        self.seconds: dict[str, float] = {}

    def __enter__(self) -> Workspace:
        return self

    def __exit__(self, *exc) -> None:
        if not self.keep:
            shutil.rmtree(self.top, ignore_errors=True)

    def run(self, command: str, cwd: Path | None = None, stderr: bool = True) -> str:
        """stdout and stderr of ``command`` in order (stdout alone with ``stderr=False``),
        without progress lines; exit status 0 required. ``fccgrb`` and ``python`` are this
        interpreter's."""
        if command in self.outputs:
            return self.outputs[command]
        argv = shlex.split(command)
        argv[0] = {"fccgrb": _executable("fccgrb"), "python": sys.executable}.get(argv[0],
                                                                                  argv[0])
        env = dict(os.environ, PYTHONUNBUFFERED="1", PYTHONHASHSEED="0", COLUMNS="80")
        started = time.perf_counter()
        errors = subprocess.STDOUT if stderr else subprocess.DEVNULL
        done = subprocess.run(argv, cwd=cwd or self.dir, env=env, stdout=subprocess.PIPE,
                              stderr=errors, check=False)
        self.seconds[command] = time.perf_counter() - started
        # bytes, not text mode: universal newlines would turn progress's '\r' into new lines
        lines = [line.split("\r")[-1]
                 for line in done.stdout.decode("utf-8", "replace").split("\n")]
        while lines and not lines[-1]:
            lines.pop()
        text = "\n".join(line for line in lines
                         if not PROGRESS.match(line) and not KERNEL_NOTICE.match(line))
        if done.returncode != 0:
            raise RuntimeError(f"`{command}` exited with status {done.returncode}:\n{text}")
        self.outputs[command] = text
        return text

    def console(self, commands: list[str]) -> str:
        """A console block: each command after a ``$`` prompt, then what it printed."""
        parts = []
        for command in commands:
            parts.append(f"$ {command}")
            out = self.run(command)
            if out:
                parts.append(out)
        return "```console\n" + "\n".join(parts) + "\n```"


# ---------------------------------------------------------------------------------------------
# The blocks

SESSION = [
    f"fccgrb synth {FIVE_BAR} -o trial.c3d",
    f"fccgrb solve {FIVE_BAR} trial.c3d --method nrm-ls --perturb 30",
    f"fccgrb solve {FIVE_BAR} trial.c3d --method nrm-wls --perturb 30",
    f"fccgrb solve {FIVE_BAR} trial.c3d --method nrm-wls --perturb 30 --hessian gauss-newton "
    "--name nrm-wls-gauss-newton-P30",
    f"fccgrb solve {FIVE_BAR} trial.c3d --method cno-sqp --perturb 30",
    f"fccgrb solve {FIVE_BAR} trial.c3d --method ad --filter-cutoff 6 --perturb 30 "
    "--perturb-markers P4,P9",
    f"fccgrb solve {FIVE_BAR} trial.c3d --method nrm-wls --perturb 30 --perturb-markers P4,P9",
]


def example_session(ws: Workspace) -> list[Artifact]:
    return [ReadmeBlock("example-session", ws.console(SESSION))]


CRANK = "configs/models/crank_rocker.yaml"
FULL_TURNS = [
    f"fccgrb synth {CRANK} -o crank.c3d",
    f"fccgrb solve {CRANK} crank.c3d --method cno-sqp --perturb 10 -o crank.h5",
    "fccgrb plot crank.h5 --kind angle --angle crank -o docs/crank_angle.png",
]


def full_turns(ws: Workspace) -> list[Artifact]:
    return [ReadmeBlock("full-turns", ws.console(FULL_TURNS)),
            Image.made("docs/crank_angle.png", ws)]


GAIT = [
    f"fccgrb calibrate configs/models/lower_limb.yaml {GAIT_TRIAL} --mass 67 -o personal.yaml",
    f"fccgrb solve personal.yaml {GAIT_TRIAL} --method nrm-wls --filter-cutoff 6 -o gait.h5",
    "fccgrb plot gait.h5 --kind clinical -o docs/gait_qualisys.png",
    "fccgrb plot gait.h5 --kind cycles -o docs/gait_cycles.png",
    "fccgrb export gait.h5 --format mot -o gait.mot",
    "fccgrb export gait.h5 --format c3d -o gait.c3d",
]


def _need_gait_trial() -> None:
    if not QUALISYS.exists():
        raise Skip(f"{QUALISYS} is absent")


def gait_trial(ws: Workspace) -> list[Artifact]:
    _need_gait_trial()
    return [ReadmeBlock("gait-trial", ws.console(GAIT)),
            Image.made("docs/gait_qualisys.png", ws), Image.made("docs/gait_cycles.png", ws)]


def gait_methods(ws: Workspace) -> list[Artifact]:
    """CNO-SQP against NRM-WLS on the walking trial: clinical angles and moments."""
    import h5py
    import numpy as np

    _need_gait_trial()
    for command in GAIT[:2]:
        ws.run(command)
    sqp = f"fccgrb solve personal.yaml {GAIT_TRIAL} --method cno-sqp --filter-cutoff 6 -o gait.h5"
    ws.run(sqp)
    with h5py.File(ws.dir / "gait.h5", "r") as h5:
        a, b = (h5[f"runs/{name}/clinical"] for name in ("nrm-wls-f6Hz", "cno-sqp-f6Hz"))
        names = [str(n) for n in a["angles"].attrs["names"]]
        sagittal = np.array(["flexion" in n for n in names])
        angles = np.abs(a["angles"][()] - b["angles"][()])
        moments = np.abs(a["moments_per_kg"][()] - b["moments_per_kg"][()])
    text = (f"* **Methods agree**: CNO-SQP (`--method cno-sqp`) on the same trial gives the "
            f"clinical angles within {angles.max():.2g}° (sagittal "
            f"{angles[:, sagittal].max():.2g}°) of NRM-WLS and the moments within "
            f"{moments.max():.2g} N·m/kg.")
    return [ReadmeBlock("gait-methods", text)]


STUDY = [
    "fccgrb batch configs/studies/shared.yaml -o study.h5",
    "fccgrb report study.h5 --html report --normative controls.csv",
]
CONTROLS = 5  # perturbed copies of the adult's walk standing in for a lab's control group


def _controls_norms(ws: Workspace) -> None:
    """controls.csv for the report's picture: the mean ± between-subject SD of a "control
    group" of five copies of the adult's walk, each with its own soft-tissue artefact (4–12 mm,
    benchmarks/batch.py's copies: plates and events kept), both sides averaged. It shows the
    report's layout; a lab gives its own norms."""
    import h5py
    import numpy as np
    import yaml

    spec = importlib.util.spec_from_file_location("bench_batch", ROOT / "benchmarks" / "batch.py")
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    subjects = []
    for k in range(CONTROLS):
        name = f"control{k + 1}"
        bench.perturbed_copy(QUALISYS, ws.dir / f"{name}.c3d", 4.0 + 2.0 * k, 10 + k)
        subjects.append({"name": name, "static": f"{name}.c3d", "trials": [f"{name}.c3d"],
                         "mass": 67})
    (ws.dir / "controls.yaml").write_text(yaml.safe_dump(
        {"name": "controls", "template": "configs/models/lower_limb.yaml",
         "options": {"filter_cutoff": 6}, "subjects": subjects}), encoding="utf-8")
    ws.run("fccgrb batch controls.yaml -o controls.h5")
    lines = ["variable,percent,mean,sd"]
    with h5py.File(ws.dir / "controls.h5", "r") as h5:
        group = h5["groups/all"]
        sides = [group["cycles"][side] for side in ("left", "right")]
        names = [str(n)[:-2] for n in sides[0].attrs["names"]]
        mean = np.mean([s["mean"][()] for s in sides], axis=0)
        sd = np.mean([s["sd"][()] for s in sides], axis=0)
        for j, name in enumerate(names):  # a curve no control has a trusted stride of (its
            # moments on a foot no plate measures) has no norm
            lines += [f"{name},{p},{mean[p, j]:.4g},{sd[p, j]:.3g}" for p in range(0, 101, 2)
                      if np.isfinite(mean[p, j]) and np.isfinite(sd[p, j])]
        table = group["spatiotemporal"]
        means = np.mean([table[s]["mean"][()] for s in ("left", "right")], axis=0)
        sds = np.mean([table[s]["sd"][()] for s in ("left", "right")], axis=0)
        parameters = [str(n) for n in h5["subjects/control1/spatiotemporal/left"].attrs["names"]]
        lines += [f"{p},,{m:.4g},{d if d > 1e-9 * abs(m) else 0.0:.3g}"  # rounding: 0
                  for p, m, d in zip(parameters, means, sds, strict=True)]
    (ws.dir / "controls.csv").write_text("\n".join(lines) + "\n", encoding="utf-8")


def _screenshot(page: Path, target: Path, size: tuple[int, int]) -> None:
    """A page as headless Chromium draws it (the window's size, CSS pixels)."""
    binary = next((shutil.which(n) for n in ("chromium", "chromium-browser", "google-chrome")
                   if shutil.which(n)), None)
    if binary is None:
        raise Skip("no chromium binary for the report's screenshot")
    with tempfile.TemporaryDirectory() as profile:
        subprocess.run([binary, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                        "--no-first-run", "--disable-background-networking",
                        "--disable-component-update", "--disable-sync", "--hide-scrollbars",
                        f"--user-data-dir={profile}", f"--window-size={size[0]},{size[1]}",
                        f"--screenshot={target}", page.as_uri()], check=True,
                       stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)


def study(ws: Workspace) -> list[Artifact]:
    """The shared walking trials as one study, its report, and a screenshot of the adult's
    page (docs/report_subject.png)."""
    _need_gait_trial()
    _controls_norms(ws)
    text = ws.console(STUDY)
    _screenshot(ws.dir / "report" / "subject-Q01.html", ws.dir / "docs" / "report_subject.png",
                (1100, 1720))
    return [ReadmeBlock("study", text), Image.made("docs/report_subject.png", ws)]


def bench_batch(ws: Workspace) -> list[Artifact]:
    """The 50-trial study; with FCCGRB_OPENSIM_PYTHON (a Python that has ``opensim``), OpenSim's
    IK + ID tools per frame in the same run beside it."""
    _need_gait_trial()
    python = os.environ.get("FCCGRB_OPENSIM_PYTHON")
    if python and subprocess.run([python, "-c", "import opensim"],
                                 capture_output=True).returncode == 0:
        out = ws.run(f"python benchmarks/batch.py --opensim-python {python}", cwd=ROOT)
        return [ReadmeBlock("bench-batch", "```console\n$ python benchmarks/batch.py "
                                           f"--opensim-python PYTHON\n{out}\n```")]
    return _bench_console(ws, "bench-batch", "batch.py")


WHOLE_BODY = [
    f"fccgrb calibrate configs/models/full_body.yaml {GAIT_TRIAL} --mass 67 -o whole.yaml",
    f"fccgrb solve whole.yaml {GAIT_TRIAL} --method nrm-wls --filter-cutoff 6 "
    "--reduce-residuals --write-model whole_adjusted.yaml -o whole.h5",
    "fccgrb plot whole.h5 --kind residuals -o docs/residual_force.png",
]
# Published residuals beside ours (typed from the papers; mean |F| and |M| where they give
# means, the guidelines' peaks where they give peaks)
RESIDUAL_ANCHORS = [
    "| AddBiomechanics (Werling et al. 2023), Hamner running | mean | 5.7 | – | 34.8 |",
    "| AddBiomechanics (Werling et al. 2023), Uhlrich walking | mean | 12.8 | – | 11.4 |",
    "| OpenSim RRA guidelines (OpenSim documentation) | peak | 10–20 | – | < 75 |",
]


def whole_body(ws: Workspace) -> list[Artifact]:
    """The whole body on the walking trial with the residual reduction, its residual figure,
    and the residual table beside the published ones."""
    import h5py
    import numpy as np

    _need_gait_trial()
    console = ws.console(WHOLE_BODY)
    rows = ["| Qualisys walk, frames where every contact is measured | statistic | force N | "
            "force % BW | moment N·m |", "|---|---|---|---|---|"]
    with h5py.File(ws.dir / "whole.h5", "r") as h5:
        g = h5["runs/nrm-wls-f6Hz"]
        res = g["residuals"]
        weight = float(res.attrs["weight"])
        for label, force, moment, mask in (
                ("full_body.yaml, first model", g["residual_force_first_model"][()],
                 g["residual_moment_first_model"][()], "single"),
                ("full_body.yaml, reduced", res["force"][()], res["moment"][()], "single")):
            frames = res[mask][()]
            f = np.linalg.norm(force[frames], axis=1)
            m = np.linalg.norm(moment[frames], axis=1)
            for stat, fn in (("mean", np.mean), ("RMS", lambda x: np.sqrt(np.mean(x ** 2))),
                             ("peak", np.max)):
                rows.append(f"| {label}, single support ({int(frames.sum())} frames) | {stat} | "
                            f"{fn(f):.1f} | {100 * fn(f) / weight:.2f} | {fn(m):.1f} |")
    table = "\n".join([*rows, *RESIDUAL_ANCHORS])
    return [ReadmeBlock("whole-body", console), ReadmeBlock("residual-table", table),
            Image.made("docs/residual_force.png", ws)]


def _sweep_subset(config: Path, target: Path) -> None:
    """A copy of a sweep config keeping only its cells of the fast methods (AD, NRM)."""
    import yaml

    doc = yaml.safe_load(config.read_text(encoding="utf-8"))
    doc["model"] = str((config.parent / doc["model"]).resolve())
    fast = {"ad", "nrm-ls", "nrm-wls"}

    def methods(cell: dict) -> set:
        m = cell["method"]
        return set(m if isinstance(m, list) else [m])

    doc["cells"] = [c for c in doc["cells"] if methods(c) <= fast and not c.get("parallel")]
    target.write_text(yaml.safe_dump(doc, sort_keys=False), encoding="utf-8")


def table_subset(ws: Workspace) -> list[Artifact]:
    out: list[Artifact] = []
    for name in ("table1", "table2"):
        subset = ws.dir / f"{name}_subset.yaml"
        _sweep_subset(ROOT / "configs" / "sweeps" / f"{name}.yaml", subset)
        ws.run(f"fccgrb sweep {subset.name} --workers 2 -o {name}_subset.h5")
        out.append(RowCheck(f"docs/{name}.md",
                            ws.run(f"fccgrb report {name}_subset.h5 --format markdown")))
    return out


TABLE_TITLES = {"table1": "Table 1 — pendulum", "table2": "Table 2 — five-bar"}
CELLS_RUN = re.compile(r"wrote \S+: (\d+) cells run, \d+ already done \((\d+) s\)")


def sweeps(ws: Workspace) -> list[Artifact]:
    out: list[Artifact] = []
    facts = {}
    for name in ("table1", "table2"):
        command = f"fccgrb sweep configs/sweeps/{name}.yaml --workers 2"
        match = CELLS_RUN.search(ws.run(command))
        if match is None:
            raise RuntimeError(f"`{command}`: no 'cells run' line in its output")
        cells, seconds = match.groups()
        facts[name] = (cells, seconds)
        tables = ws.run(f"fccgrb report {name}.h5 --format markdown").rstrip("\n")
        out.append(TextFile(f"docs/{name}.md", (
            f"<!-- generated by `python docs/generate.py --part tables`: do not edit -->\n"
            f"# {TABLE_TITLES[name]}\n\n"
            f"`{command}`: {cells} cells, {seconds} s on this project's 2-core machine. Ours, "
            f"the paper's figure in brackets; the tables are `fccgrb report {name}.h5 "
            f"--format markdown`.\n\n{tables}\n")))
    (c1, s1), (c2, s2) = facts["table1"], facts["table2"]
    out.append(ReadmeBlock("sweep-times", (
        f"The full grids: `fccgrb sweep configs/sweeps/table1.yaml --workers 2` ({c1} cells, "
        f"{s1} s) and `configs/sweeps/table2.yaml` ({c2} cells, {s2} s); their tables, ours "
        f"beside the paper's, are in [docs/table1.md](table1.md) and "
        f"[docs/table2.md](table2.md).")))
    return out


FIGURE_RUNS = [  # the paper's Figure 8 case: only P4 and P9 perturbed at 30 mm
    ("AD", "--method ad"),
    ("AD-6Hz", "--method ad --filter-cutoff 6"),
    ("NRM-WLS", "--method nrm-wls"),
    ("CNO-SQP", "--method cno-sqp"),
]
FIGURE_PLOTS = [
    ("point_P6.png", "--kind point --marker P6"),
    ("ed_P6.png", "--kind ed --marker P6"),
    ("angle_J4_uv.png", "--kind angle --angle J4_uv"),
    ("velocity_P6_x.png", "--kind velocity --marker P6 --axis x"),
]


def _figure_commands(seed: int, output: str, names: list[str]) -> list[str]:
    return [f"fccgrb solve {FIVE_BAR} trial.c3d {options} --perturb 30 --perturb-markers P4,P9"
            + (f" --seed {seed}" if seed else "") + f" --name {name} -o {output}"
            for name, options in FIGURE_RUNS if name in names]


def figures(ws: Workspace) -> list[Artifact]:
    commands = [SESSION[0], *_figure_commands(0, "figure8.h5", [n for n, _ in FIGURE_RUNS])]
    commands += [f"fccgrb plot figure8.h5 {options} -o docs/{png}" for png, options in FIGURE_PLOTS]
    for command in commands:
        ws.run(command)
    text = "```bash\n" + "\n".join(commands) + "\n```"
    return [ReadmeBlock("figure-commands", text),
            *(Image.made(f"docs/{png}", ws) for png, _ in FIGURE_PLOTS)]


def figure8_seeds(ws: Workspace) -> list[Artifact]:
    """Mean distance of the chain's end point P6 to the truth, per seed and method."""
    import h5py
    import numpy as np

    names = ["AD", "AD-6Hz", "NRM-WLS"]
    ws.run(SESSION[0])
    rows = []
    for seed in (0, 1, 2):
        output = f"seed{seed}.h5"
        for command in _figure_commands(seed, output, names):
            ws.run(command)
        with h5py.File(ws.dir / output, "r") as h5:
            labels = [str(x) for x in h5["reference/markers"].attrs["labels"]]
            k = labels.index("P6")
            means = [1e3 * float(np.mean(h5[f"runs/{n}/ed"][:, k])) for n in names]
        rows.append(f"| {seed} | " + " | ".join(f"{m:.1f}" for m in means) + " |")
    head = ("| seed | AD | AD, 6 Hz filter | NRM-WLS |\n"
            "|---|---|---|---|")
    caption = ("Mean distance (mm) of the end point P6 to the truth, P4 and P9 perturbed at "
               "30 mm (the figure's commands with `--seed`):")
    return [ReadmeBlock("figure8-seeds", caption + "\n\n" + head + "\n" + "\n".join(rows))]


def _paper(table: str, method: str, variant: str, points: tuple[str, ...]) -> str:
    rows = list(csv.DictReader(line for line in PAPER_TABLES.read_text(encoding="utf-8")
                               .splitlines() if line and not line.startswith("#")))
    for p in points:
        for r in rows:
            if (r["table"], r["method"], r["variant"], r["ref_points"], float(r["tol"]),
                    r["level"]) == (table, method, variant, p, 1e-10, "P0"):
                value = f"{float(r['time_ms_per_frame']):.4g}"
                return value if p in (points[0], "") else f"{value} ({p} points)"
    return "–"


def _fields(output: str, width: int) -> list[list[str]]:
    return [line.split() for line in output.splitlines()[1:] if len(line.split()) == width]


def bench_kinematics(ws: Workspace) -> list[Artifact]:
    command = "python benchmarks/kinematics.py --forms full"
    rows = _fields(ws.run(command, cwd=ROOT), 11)
    by = {(r[0], r[2], r[3], float(r[4]), float(r[5])): r for r in rows}
    lines = [f"`{command}`, its tol 1e-10 rows:", "",
             "| model (full form), tol 1e-10 | engine | P0 ms/frame | P0 total ms/frame "
             "| iterations | P7.5 ms/frame | P30 ms/frame | iterations | failed (P0–P30) "
             "| paper P0 ms/frame |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    models = {"pendulum": ("pendulum", "table1", ("",)),
              "five_bar": ("five-bar", "table2", ("9", "8", ""))}
    for model, (label, table, points) in models.items():
        for method, (family, variant) in (("ad", ("KA", "AD")), ("nrm-ls", ("NRM", "LS")),
                                          ("nrm-wls", ("NRM", "WLS"))):
            for engine in ("numpy", "compiled"):
                p0 = by.get((model, method, engine, 1e-10, 0.0))
                if p0 is None:
                    continue
                p7 = by.get((model, method, engine, 1e-10, 7.5))
                p30 = by.get((model, method, engine, 1e-10, 30.0))
                failed = sum(int(r[10]) for r in (p0, p7, p30) if r)
                lines.append(
                    f"| {label}, {method.upper()} | {engine} | {p0[6]} | {p0[7]} | {p0[8]} | "
                    f"{p7[6] if p7 else '–'} | {p30[6] if p30 else '–'} | "
                    f"{p30[8] if p30 else '–'} | {failed} | "
                    f"{_paper(table, family, variant, points)} |")
    return [ReadmeBlock("bench-kinematics", "\n".join(lines))]


def bench_optimization(ws: Workspace) -> list[Artifact]:
    command = "python benchmarks/optimization.py"
    rows = _fields(ws.run(command, cwd=ROOT), 10)
    lines = [f"`{command}` (9 points; max \\|Φ_top\\| and failed frames over P0, P7.5 and "
             "P30):", "",
             "| five-bar, tol 1e-10 | solver | P0 ms/frame | iterations | P7.5 ms/frame "
             "| P30 ms/frame | iterations | max \\|Φ_top\\| | failed (solver's verdict) "
             "| paper P0 ms/frame |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    paper = {("cno-sqp", "tc"): ("CNO", "SQP"), ("mo-tc", "tc"): ("MO", "TC"),
             ("mo-ed", "ed"): ("MO", "ED")}
    seen: list[tuple[str, str, str]] = []
    for r in rows:
        if (r[0], r[1], r[2]) not in seen:
            seen.append((r[0], r[1], r[2]))
    for method, objective, solver in seen:
        by = {float(r[3]): r for r in rows if (r[0], r[1], r[2]) == (method, objective, solver)}
        p0, p7, p30 = by[0.0], by[7.5], by[30.0]
        top = max(float(r[7]) for r in by.values())
        failed = sum(int(r[9]) for r in by.values())
        family_variant = paper.get((method, objective))
        ref = _paper("table2", *family_variant, ("9", "8")) if family_variant else "–"
        name = method.upper() + (f" ({objective})" if method.startswith("cno") else "")
        lines.append(f"| {name} | {solver} | {p0[5]} | {p0[6]} | {p7[5]} | {p30[5]} | "
                     f"{p30[6]} | {top:.2g} | {failed} | {ref} |")
    return [ReadmeBlock("bench-optimization", "\n".join(lines))]


def _bench_console(ws: Workspace, name: str, script: str) -> list[Artifact]:
    """A README block holding what ``python benchmarks/SCRIPT`` prints, as a console session."""
    command = f"python benchmarks/{script}"
    out = ws.run(command, cwd=ROOT)
    return [ReadmeBlock(name, f"```console\n$ {command}\n{out}\n```")]


def bench_gait(ws: Workspace) -> list[Artifact]:
    _need_gait_trial()
    return _bench_console(ws, "bench-gait", "gait.py")


def bench_dynamics(ws: Workspace) -> list[Artifact]:
    return _bench_console(ws, "bench-dynamics", "dynamics.py")


def bench_peers(ws: Workspace) -> list[Artifact]:
    return _bench_console(ws, "bench-peers", "peers.py")


def bench_long(ws: Workspace) -> list[Artifact]:
    _need_gait_trial()
    return _bench_console(ws, "bench-long", "long_trial.py")


def bench_startup(ws: Workspace) -> list[Artifact]:
    """Whole commands' wall time; with FCCGRB_OPENSIM_PYTHON (a Python that has ``opensim``),
    OpenSim's IK + ID tools per frame in the same run beside the gait solve's."""
    python = os.environ.get("FCCGRB_OPENSIM_PYTHON")
    if not python:
        return _bench_console(ws, "bench-startup", "startup.py")
    out = ws.run(f"python benchmarks/startup.py --opensim-python {shlex.quote(python)}",
                 cwd=ROOT)
    return [ReadmeBlock("bench-startup", "```console\n$ python benchmarks/startup.py "
                        f"--opensim-python PYTHON\n{out}\n```")]


def clean_margins(ws: Workspace) -> list[Artifact]:
    _need_gait_trial()
    return _bench_console(ws, "clean-margins", "clean_margins.py")


def bench_smoothing(ws: Workspace) -> list[Artifact]:
    """The smoother's table (about a minute). Its other checks (``--orders --floor 10
    --monte-carlo 100 --gait 3 --cost 10000``, 35–60 min here) and the Qualisys figure
    (``--figure docs/smoothing_qualisys.png``) are run by hand; the README says so."""
    return _bench_console(ws, "bench-smoothing", "smoothing.py")


def plugin_gait(ws: Workspace) -> list[Artifact]:
    """The Plug-in Gait comparison's tables, as ``benchmarks/plugin_gait.py`` prints them
    (markdown), its captions as paragraphs."""
    if not (SHARED / "data" / "c3d" / "plugin_gait" / "HC030A05.c3d").exists():
        raise SystemExit(f"plugin-gait: needs {SHARED}/data/c3d/plugin_gait")
    out = ws.run("python benchmarks/plugin_gait.py --rigid-knees", cwd=ROOT)
    lines = []
    for line in out.splitlines():
        if line and not line.startswith("|") and lines and lines[-1].startswith("|"):
            lines.append("")
        lines.append(line)
    return [ReadmeBlock("plugin-gait", "\n".join(lines).strip())]


def opensim_agreement(ws: Workspace) -> list[Artifact]:
    """OpenSim's IK and ID regression cases beside OpenSim's own outputs (the tables alone, as
    ``benchmarks/opensim_agreement.py`` prints them on stdout; timing columns ignored)."""
    if not (SHARED / "data" / "opensim").is_dir():
        raise Skip("../shared/data/opensim is absent")
    out = ws.run(f"python {ROOT / 'benchmarks' / 'opensim_agreement.py'}", stderr=False)
    return [ReadmeBlock("opensim-agreement", out)]


def bench_opensim_tools(ws: Workspace) -> list[Artifact]:
    """fccgrb's whole command beside OpenSim 4.6's IK and ID tools on OpenSim's own trial
    (``benchmarks/opensim_tools.py``; OpenSim from the Python that FCCGRB_OPENSIM_PYTHON names,
    by default this one). Skipped without the shared OpenSim data or without opensim there."""
    if not (SHARED / "data" / "opensim").is_dir():
        raise Skip("../shared/data/opensim is absent")
    python = os.environ.get("FCCGRB_OPENSIM_PYTHON", sys.executable)
    if subprocess.run([python, "-c", "import opensim"], capture_output=True).returncode:
        raise Skip(f"{python}: no opensim (set FCCGRB_OPENSIM_PYTHON to a Python that has it)")
    out = ws.run(f"python {ROOT / 'benchmarks' / 'opensim_tools.py'} --opensim-python {python}",
                 stderr=False)
    return [ReadmeBlock("bench-opensim-tools", out)]


def cli_reference(ws: Workspace) -> list[Artifact]:
    """docs/cli.md: every command's own ``--help``, as the installed ``fccgrb`` prints it."""
    top = ws.run("fccgrb --help")
    names = re.findall(r"^  (\w[\w-]*)\s", top.split("Commands:", 1)[1], re.M)
    parts = ["# Command-line reference", "",
             "Generated from the commands' own `--help` by `python docs/generate.py --block "
             "cli-reference`", "(compared with a fresh run by the tests).", "",
             "```console", "$ fccgrb --help", top, "```"]
    for name in names:
        parts += ["", f"## fccgrb {name}", "", "```console", f"$ fccgrb {name} --help",
                  ws.run(f"fccgrb {name} --help"), "```"]
    return [TextFile("docs/cli.md", "\n".join(parts) + "\n")]


@dataclass(frozen=True)
class Block:
    name: str
    part: str
    make: Callable[[Workspace], list[Artifact]]
    what: str = field(default="")


BLOCKS = {b.name: b for b in (
    Block("example-session", "cheap", example_session, "docs: the five-bar session"),
    Block("full-turns", "cheap", full_turns, "docs/crank_angle.png"),
    Block("gait-trial", "cheap", gait_trial, "docs/gait_qualisys.png"),
    Block("table-subset", "cheap", table_subset, "check only: docs tables' AD and NRM rows"),
    Block("cli-reference", "cheap", cli_reference, "docs/cli.md from every command's --help"),
    Block("opensim-agreement", "cheap", opensim_agreement,
          "docs/opensim.md: OpenSim's IK and ID regression cases beside OpenSim's outputs"),
    Block("sweeps", "tables", sweeps, "docs/table1.md, docs/table2.md, README sweep line"),
    Block("gait-methods", "tables", gait_methods, "docs: CNO-SQP against NRM-WLS on gait"),
    Block("clean-margins", "tables", clean_margins, "docs: each check on clean and broken "
          "trials"),
    Block("whole-body", "tables", whole_body,
          "docs: whole body, residual reduction, docs/residual_force.png"),
    Block("bench-kinematics", "benchmarks", bench_kinematics, "README performance table"),
    Block("bench-optimization", "benchmarks", bench_optimization, "README performance table"),
    Block("bench-gait", "benchmarks", bench_gait, "README gait speed"),
    Block("bench-dynamics", "benchmarks", bench_dynamics, "README dynamics stage speed"),
    Block("bench-peers", "benchmarks", bench_peers, "docs: against OpenSim's IK"),
    Block("bench-long", "benchmarks", bench_long, "docs: a 10-minute trial"),
    Block("bench-startup", "benchmarks", bench_startup, "docs: whole commands' wall time"),
    Block("bench-batch", "benchmarks", bench_batch, "docs: a 50-trial study"),
    Block("bench-opensim-tools", "benchmarks", bench_opensim_tools,
          "docs: the whole command beside OpenSim's IK and ID tools"),
    Block("study", "study", study, "docs/report_subject.png: a study, its report"),
    Block("bench-smoothing", "benchmarks", bench_smoothing,
          "docs: the smoother's table"),
    Block("plugin-gait", "tables", plugin_gait, "docs: Plug-in Gait against Vicon's angles"),
    Block("figures", "figures", figures, "docs/*.png of the Figure 8 case and their commands"),
    Block("figure8-seeds", "figures", figure8_seeds, "docs: P6's distance over seeds"),
)}
PARTS = ("cheap", "tables", "benchmarks", "figures", "study")

# ---------------------------------------------------------------------------------------------
# Comparing without the timing figures

T = "‹t›"
NUMBER = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"
FREE_TIMING = re.compile(rf"(?<![\w.]){NUMBER}(?=\s*(?:ms/frame|ms|s|min|frames/s)\b)")
CONSOLE_TIMING = ("ms/frame", "frames/s", "x real time", "wall s", "CPU s", "per trial s",
                  "solve s", "kernels s", "trials/min", ".c3d s", "peak RSS MiB")
MARKDOWN_TIMING = ("ms/frame", "frames/s", "real time", "total ms", "wall (s)", "timing ratio")
EPS = "‹ε›"
ROUNDING = re.compile(r"(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)[eE]-(?:1[3-9]|[2-9]\d|\d{3})\b")
"""Numbers below 1e-12: rounding residues (‖Φ‖ of an exact solve, max |Φ_top| of a method that
holds the topology), whose digits depend on the BLAS, the compiler and the numpy release; they
are compared as 'rounding level', not digit by digit."""


def _cells(row: str) -> list[str]:
    return [c.strip() for c in row.strip().strip("|").split("|")]


def _markdown_table(rows: list[str], caption: str) -> list[str]:
    header = _cells(rows[0])
    timing = {k for k, h in enumerate(header)
              if any(w in h for w in MARKDOWN_TIMING) and "paper" not in h}
    if "ms/frame" in caption:
        timing |= {k for k, h in enumerate(header) if re.fullmatch(r"P[\d.]+", h)}
    out = []
    for row in rows:
        cells = _cells(row.replace("\\|", "¦"))
        for k in timing:
            if k < len(cells) and not set(cells[k]) <= set("-:"):
                ours, bracket, rest = cells[k].partition("[")
                cells[k] = re.sub(NUMBER, T, ours).strip() + (f" [{rest}" if bracket else "")
        out.append("| " + " | ".join(FREE_TIMING.sub(T, c) for c in cells) + " |")
    return out


def _timing_spans(header: str) -> list[tuple[int, int]]:
    return [(m.start(), m.end()) for w in CONSOLE_TIMING for m in re.finditer(re.escape(w), header)]


def _timing_tokens(row: str, spans: list[tuple[int, int]]) -> list[tuple[bool, str]]:
    """The row's tokens, each with whether it lies under a timing header."""
    return [(any(m.start() < b and a < m.end() for a, b in spans), m.group())
            for m in re.finditer(r"\S+", row)]


def _is_row(row: str, width: int, spans: list[tuple[int, int]]) -> bool:
    """A data row of the table: as many fields as the first, numbers under the timing headers."""
    tokens = _timing_tokens(row, spans)
    return (len(tokens) == width and not row.startswith("$")
            and all(re.fullmatch(NUMBER + "|nan", t) for timing, t in tokens if timing))


def _console_table(header: str, rows: list[str]) -> list[str]:
    spans = _timing_spans(header)
    out = [" ".join(header.split())]
    for row in rows:
        out.append(" ".join(T if timing else t for timing, t in _timing_tokens(row, spans)))
    return out


def normalize(text: str) -> list[str]:
    """The lines of a block with its timing figures replaced by a placeholder, spacing
    collapsed (see the module's docstring)."""
    lines = text.splitlines()
    out: list[str] = []
    caption = ""
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.lstrip().startswith("|"):
            j = i
            while j < len(lines) and lines[j].lstrip().startswith("|"):
                j += 1
            out.extend(_markdown_table(lines[i:j], caption))
            i = j
            continue
        following = lines[i + 1] if i + 1 < len(lines) else ""
        if (any(w in line for w in CONSOLE_TIMING) and not line.startswith("$")
                and following.strip() and not following.startswith("$")
                and not FREE_TIMING.search(line)):
            width, spans = len(following.split()), _timing_spans(line)
            j = i + 1
            while j < len(lines) and _is_row(lines[j], width, spans):
                j += 1
            out.extend(_console_table(line, lines[i + 1:j]))
            i = j
            continue
        if line.strip():
            caption = line
        out.append(" ".join(FREE_TIMING.sub(T, line).split()))
        i += 1
    return [ROUNDING.sub(EPS, line) for line in out]


def readme_blocks(text: str) -> dict[str, str]:
    """NAME → content of every generated block of a README text."""
    return {m.group(1): m.group(2) for m in BLOCK_RE.finditer(text)}


def pages(root: Path = ROOT) -> list[Path]:
    """The pages generated blocks may sit in: the README, then docs/*.md."""
    return [root / "README.md", *sorted((root / "docs").glob("*.md"))]


def page_of(name: str, root: Path = ROOT) -> Path | None:
    """The page holding the block ``name``, or None."""
    start = f"<!-- generated: {name} -->"
    return next((page for page in pages(root) if start in page.read_text(encoding="utf-8")),
                None)


BLOCK_RE = re.compile(r"<!-- generated: ([\w-]+) -->\n(.*?)\n?<!-- /generated -->", re.S)


def _diff(old: str, new: str, label: str) -> list[str]:
    a, b = normalize(old), normalize(new)
    if a == b:
        return []
    return list(difflib.unified_diff(a, b, f"{label} (now)", f"{label} (fresh run)",
                                     lineterm="", n=1))


def _table_rows(text: str) -> dict[tuple, str]:
    """(caption, key cells) → the normalized row, for every row of the markdown tables."""
    rows: dict[tuple, str] = {}
    caption = ""
    for line in normalize(text):
        if line.startswith("|"):
            cells = _cells(line)
            if not set("".join(cells)) <= set("-:"):
                rows[(caption, *cells[:4])] = line
        elif line.strip():
            caption = line
    return rows


def _same_image(old: Path, new: bytes) -> str | None:
    """None when the figures agree, else why not."""
    import io

    import numpy as np
    from matplotlib import __version__ as mpl
    from matplotlib.image import imread
    from PIL import Image as PILImage

    if not old.exists():
        return "missing"
    a, b = imread(old), imread(io.BytesIO(new), format="png")
    if a.shape == b.shape and np.array_equal(a, b):
        return None
    software = PILImage.open(old).info.get("Software", "")
    if mpl not in software:  # another matplotlib drew it: compare loosely
        from matplotlib.testing.compare import compare_images

        with tempfile.TemporaryDirectory() as tmp:
            fresh = Path(tmp) / old.name
            fresh.write_bytes(new)
            result = compare_images(str(old), str(fresh), tol=2.0, in_decorator=True)
        return None if result is None else f"RMS {result['rms']:.2f} (written by {software})"
    if a.shape != b.shape:
        return f"size {a.shape[1]}×{a.shape[0]} now, {b.shape[1]}×{b.shape[0]} fresh"
    return f"{int(np.any(a != b, axis=-1).sum())} pixels differ"


def differences(artifact: Artifact, readme: str, root: Path = ROOT) -> list[str]:
    """Why ``artifact`` disagrees with the repository (an empty list when it agrees)."""
    if isinstance(artifact, ReadmeBlock):
        label, blocks = "README.md", readme_blocks(readme)
        if artifact.name not in blocks:  # a guide's block: the docs/ page that holds it
            page = page_of(artifact.name, root)
            if page is None:
                return [f"no page of README.md and docs/ has a block "
                        f"<!-- generated: {artifact.name} -->"]
            label = str(page.relative_to(root))
            blocks = readme_blocks(page.read_text(encoding="utf-8"))
        return _diff(blocks[artifact.name], artifact.text, f"{label}:{artifact.name}")
    path = root / artifact.path
    if isinstance(artifact, Image):
        why = _same_image(path, artifact.data)
        return [] if why is None else [f"{artifact.path}: {why}"]
    if not path.exists():
        return [f"{artifact.path}: missing"]
    current = path.read_text(encoding="utf-8")
    if isinstance(artifact, TextFile):
        return _diff(current, artifact.text, artifact.path)
    have, fresh = _table_rows(current), _table_rows(artifact.text)
    out = []
    for key, row in fresh.items():
        if have.get(key) != row:
            out += [f"{artifact.path}: row {' / '.join(key[1:])} under {key[0]}",
                    f"  now:   {have.get(key, '(missing)')}", f"  fresh: {row}"]
    return out


def write(artifact: Artifact, root: Path = ROOT) -> None:
    """Write one artifact; a block is replaced in the page (README or docs/) that holds it."""
    if isinstance(artifact, RowCheck):
        return
    if isinstance(artifact, ReadmeBlock):
        start = f"<!-- generated: {artifact.name} -->"
        path = page_of(artifact.name, root)
        if path is None:
            raise RuntimeError(f"README.md and docs/: no {start} to fill")
        text = path.read_text(encoding="utf-8")
        pattern = re.compile(re.escape(start) + r"\n.*?\n?<!-- /generated -->", re.S)
        new = pattern.sub(lambda _: f"{start}\n{artifact.text}\n<!-- /generated -->", text,
                          count=1)
        _replace(path, new.encode("utf-8"))
    elif isinstance(artifact, TextFile):
        _replace(root / artifact.path, artifact.text.encode("utf-8"))
    else:
        _replace(root / artifact.path, artifact.data)


def _replace(path: Path, data: bytes) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    tmp.write_bytes(data)
    os.replace(tmp, path)


# ---------------------------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--part", choices=[*PARTS, "all"], default=None)
    parser.add_argument("--block", action="append", choices=sorted(BLOCKS), default=[],
                        help="Only this block (repeatable); instead of --part.")
    parser.add_argument("--check", action="store_true",
                        help="Compare with README.md and docs/ instead of writing; exit 1 "
                             "naming the blocks that differ.")
    parser.add_argument("--keep", action="store_true", help="Keep the temporary folder.")
    args = parser.parse_args(argv)
    if args.part is None and not args.block:
        parser.error("expected --part or --block")
    names = list(args.block) + [b.name for b in BLOCKS.values()
                                if args.part in (b.part, "all")]
    differing: list[str] = []
    with Workspace(keep=args.keep) as ws:
        if args.keep:
            print(f"workspace: {ws.dir}", file=sys.stderr)
        for name in dict.fromkeys(names):
            started = time.perf_counter()
            try:
                artifacts = BLOCKS[name].make(ws)
            except Skip as why:
                print(f"{name}: skipped ({why})", file=sys.stderr)
                continue
            seconds = time.perf_counter() - started
            if args.check:
                readme = README.read_text(encoding="utf-8")
                found = [line for a in artifacts for line in differences(a, readme)]
                if found:
                    differing.append(name)
                    print("\n".join(found))
                status = "differs" if found else "agrees"
            else:
                for artifact in artifacts:
                    write(artifact)
                status = "written"
            print(f"{name}: {status} ({seconds:.0f} s)", file=sys.stderr)
    if differing:
        print(f"differ from a fresh run: {', '.join(differing)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
