"""Summary tables laid out like the paper's Tables 1 and 2, from any results or sweep file.

Rows are method / variant / tracked points / tolerance; for each metric (ms/frame, iterations,
mean ‖Φ‖, max topological Φ, mean and max ED) the columns are the perturbation levels P0, P7.5
and P30, with the paper's figure in brackets where a row and level match
(``fccgrb_cli/data/paper_tables.csv``, shipped with the package).
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from fccgrb_cli.core.errors import InputError

PAPER_TABLES = Path(__file__).resolve().parents[1] / "data" / "paper_tables.csv"
LEVELS = ("P0", "P7.5", "P30")
METRICS = (
    ("ms/frame", "time_ms_per_frame", "{:.3g}"),
    ("iterations/frame", "iterations", "{:.3g}"),
    ("mean ‖Φ‖", "phi_norm_mean", "{:.2g}"),
    ("max |Φ_top|", "phi_top_max", "{:.2g}"),
    ("mean ED (mm)", None, "{:.3g}"),
    ("max ED (mm)", None, "{:.3g}"),
    ("jump (mm)", None, "{:.3g}"),
    ("failed frames", None, "{:.0f}"),
    ("flagged frames", None, "{:.0f}"),
)
FAMILY = {"ad": "KA", "nrm": "NRM", "cno": "CNO", "mo": "MO"}
VARIANT = {"ad": "AD", "ls": "LS", "wls": "WLS", "sqp": "SQP", "ip": "IP", "tc": "TC", "ed": "ED"}


@dataclass(frozen=True)
class Row:
    """One run's figures, keyed like a row of the paper's tables."""

    family: str
    variant: str
    points: str
    tol: float
    level: str
    values: dict[str, float]


def describe(method: str) -> tuple[str, str]:
    """('CNO', 'SQP-parallel') from 'cno-sqp-parallel'; CNO with the ED objective → 'SQP (ED)'."""
    parts = method.split("-")
    family = FAMILY.get(parts[0], parts[0].upper())
    rest = parts[1:] if parts[0] != "ad" else ["ad", *parts[1:]]
    variant = VARIANT.get(rest[0], rest[0].upper()) if rest else ""
    tail = rest[1:]
    if family == "CNO" and tail[:1] == ["ed"]:
        variant += " (ED)"
        tail = tail[1:]
    if tail:
        variant += "-" + "-".join(tail)
    return family, variant


def level_name(level_m: float) -> str:
    return f"P{level_m * 1e3:g}"


# Cell parameters that change a run without changing its table row, with their defaults: when a
# cell sets one otherwise, it is named in the variant so that rows do not overwrite each other.
DISTINGUISHING = {"seed": 0, "hessian": "auto", "tracking_weight": 1e-3,
                  "warm_start": "extrapolate", "filter_cutoff": None, "perturb_markers": None,
                  "form": None, "dynamics": None, "workers": None}
# A solve's options that change its answer without changing its table row: named in the
# variant where a run's differ from the defaults (the AD run and the AD run at 6 Hz; the
# smoothed run and the other).
RUN_DISTINGUISHING = ("filter_cutoff", "smooth", "smooth_cutoff", "smooth_noise", "ad_drivers",
                      "perturb_markers", "seed", "hessian", "tracking_weight", "warm_start",
                      "optimizer", "form", "track")


def _run_extra(options: dict) -> str:
    """The variant's suffix for a run's stored options (:data:`RUN_DISTINGUISHING`)."""
    from fccgrb_cli.pipeline.options import SolveOptions

    defaults = SolveOptions()
    chosen = {key: options[key] for key in RUN_DISTINGUISHING if key in options}
    parts = []
    for key, value in chosen.items():
        default = getattr(defaults, key)
        if value == default or (isinstance(default, tuple) and tuple(value) == default):
            continue
        if isinstance(value, (list, tuple)):
            parts.append(f"{key}={'+'.join(map(str, value))}")
        else:
            parts.append(f"{key}={value:g} Hz" if key.endswith("cutoff") else f"{key}={value}")
    return f" [{', '.join(parts)}]" if parts else ""


def _extra(params: dict) -> str:
    parts = []
    for key, default in DISTINGUISHING.items():
        value = params.get(key, default)
        if key == "workers" or value in (default, (), []):
            continue
        shown = "+".join(value) if isinstance(value, (list, tuple)) else value
        parts.append(f"{key}={shown}")
    return f" [{', '.join(parts)}]" if parts else ""


def _row(run, points: str, extra: str = "") -> Row:
    trusted = run["converged"][()]
    converged = run["solver_converged"][()] if "solver_converged" in run else trusted
    ed = run["ed"][()]
    ok = converged & np.isfinite(ed).all(axis=1) & (ed.shape[1] > 0)  # markers were solved
    time_s = run["time_s"][()]
    n = len(time_s)
    attrs = run.attrs
    wall = float(attrs.get("wall_s", np.nan))
    from fccgrb_cli.pipeline.run import mean_jump

    values = {
        "ms/frame": 1e3 * (wall / n if np.isfinite(wall) else float(np.nanmean(time_s))),
        "iterations/frame": float(np.mean(run["iterations"][()])),
        "mean ‖Φ‖": float(np.nanmean(run["phi_norm"][()])),
        "max |Φ_top|": float(np.nanmax(run["phi_top_max"][()])),
        "mean ED (mm)": 1e3 * float(np.mean(ed[ok])) if ok.any() else np.nan,
        "max ED (mm)": 1e3 * float(np.max(ed[ok])) if ok.any() else np.nan,
        "jump (mm)": 1e3 * mean_jump(run["model_points"][()]),
        "failed frames": float((~converged).sum()),
        "flagged frames": float((converged & ~trusted).sum()),
    }
    family, variant = describe(str(attrs["method"]))
    return Row(family, variant + extra, points, float(attrs["tol"]),
               level_name(float(attrs["perturb_level_m"])), values)


def collect(path: str | Path) -> tuple[str, list[Row]]:
    """The table name (a sweep's 'table', else '') and one Row per run in a results or sweep
    file."""
    from fccgrb_cli.core.datasets import open_results
    from fccgrb_cli.results.format import cells_group, check_run, reading, runs_group

    h5 = open_results(path)
    rows: list[Row] = []
    with h5:
        table = str(h5.attrs.get("table", ""))
        if "cells" in h5:
            for key, cell in cells_group(h5, path).items():
                with reading(path, f"/cells/{key}"):
                    params = json.loads(cell.attrs.get("cell", "{}"))
                    points = "" if params.get("points") is None else str(params["points"])
                    for name, run in cell["runs"].items():
                        check_run(run, path, f"/cells/{key}/runs/{name}")
                        rows.append(_row(run, points, _extra(params)))
        elif "runs" in h5:
            named = []
            for name, run in runs_group(h5, path).items():
                with reading(path, f"/runs/{name}"):
                    check_run(run, path, f"/runs/{name}")
                    options = json.loads(run.attrs.get("options", "{}"))
                    named.append((name, _row(run, "", _run_extra(options))))
            rows = _apart(named)
        else:
            raise InputError(f"{path}: expected /runs or /cells in a results file")
    return table, rows


def _apart(named: list[tuple[str, Row]]) -> list[Row]:
    """Each run its own row: runs whose options leave them on one row and level (two runs of
    one method under --name, on other models or trials) are told apart by their names."""
    keys = [(r.family, r.variant, r.points, r.tol, r.level) for _, r in named]
    return [r if keys.count(key) == 1 else replace(r, variant=f"{r.variant} [{name}]")
            for (name, r), key in zip(named, keys, strict=True)]


def paper_figures(table: str, csv_path: Path = PAPER_TABLES) -> dict[tuple, dict[str, float]]:
    """(family, variant, points, tol, level) → the paper's figures for that table."""
    out: dict[tuple, dict[str, float]] = {}
    if not table or not csv_path.exists():
        return out
    lines = [line for line in csv_path.read_text(encoding="utf-8").splitlines()
             if line and not line.startswith("#")]
    for rec in csv.DictReader(lines):
        if rec["table"] != table:
            continue
        key = (rec["method"], rec["variant"], rec["ref_points"], float(rec["tol"]), rec["level"])
        out[key] = {label: float(rec[col]) for label, col, _ in METRICS if col}
    return out


def _paper_value(paper: dict, row: Row, level: str, metric: str) -> float | None:
    for points in (row.points, ""):
        figures = paper.get((row.family, row.variant, points, row.tol, level))
        if figures is not None and metric in figures:
            return figures[metric]
    return None


FAMILY_ORDER = {"KA": 0, "NRM": 1, "CNO": 2, "MO": 3}
VARIANT_ORDER = {"AD": 0, "LS": 1, "WLS": 2, "IP": 3, "SQP": 4, "TC": 5, "ED": 6}


def _order(key: tuple[str, str, str, float]) -> tuple:
    """The paper's row order: KA, NRM, CNO, MO; LS before WLS, IP before SQP, TC before ED;
    sequential before parallel; points; the looser tolerance first."""
    family, variant, points, tol = key
    base = variant.split("-")[0].split(" ")[0]
    return (FAMILY_ORDER.get(family, 9), VARIANT_ORDER.get(base, 9), variant != base, variant,
            points, -tol)


def render(table: str, rows: list[Row], fmt: str = "text",
           paper: dict[tuple, dict[str, float]] | None = None) -> str:
    """The tables as text (aligned), markdown or csv (long format, one line per value)."""
    paper = paper_figures(table) if paper is None else paper
    keys = sorted(dict.fromkeys((r.family, r.variant, r.points, r.tol) for r in rows), key=_order)
    by_key = {(r.family, r.variant, r.points, r.tol, r.level): r for r in rows}
    if fmt == "csv":
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(["table", "method", "variant", "points", "tol", "level", "metric", "ours",
                         "paper"])
        for key in keys:
            for level in LEVELS:
                row = by_key.get((*key, level))
                if row is None:
                    continue
                for metric, _, _ in METRICS:
                    theirs = _paper_value(paper, row, level, metric)
                    writer.writerow([table, *key, level, metric, f"{row.values[metric]:.6g}",
                                     "" if theirs is None else f"{theirs:g}"])
        return buffer.getvalue()
    blocks = []
    for metric, _, style in METRICS:
        head = ["method", "variant", "points", "tol", *LEVELS]
        lines = [head]
        for key in keys:
            cells = []
            for level in LEVELS:
                row = by_key.get((*key, level))
                if row is None:
                    cells.append("–")
                    continue
                text = style.format(row.values[metric])
                theirs = _paper_value(paper, row, level, metric)
                cells.append(text if theirs is None else f"{text} [{style.format(theirs)}]")
            lines.append([key[0], key[1], key[2], f"{key[3]:g}", *cells])
        title = f"{table or 'runs'} — {metric}" + (" (ours [paper])" if paper else "")
        blocks.append(_layout(title, lines, fmt))
    return "\n\n".join(blocks) + "\n"


def _layout(title: str, lines: list[list[str]], fmt: str) -> str:
    if fmt == "markdown":
        out = [f"**{title}**", "", "| " + " | ".join(lines[0]) + " |",
               "|" + "---|" * len(lines[0])]
        out += ["| " + " | ".join(line) + " |" for line in lines[1:]]
        return "\n".join(out)
    widths = [max(len(line[k]) for line in lines) for k in range(len(lines[0]))]
    text = [title]
    for line in lines:
        text.append("  ".join(cell.ljust(w) if k < 3 else cell.rjust(w)
                              for k, (cell, w) in enumerate(zip(line, widths, strict=True))))
    return "\n".join(text)
