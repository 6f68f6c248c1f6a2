"""The clinical report's pages, from a study file: one per subject (header, kinematic and kinetic
cycle plots per side with normative bands, events, spatiotemporal table with norms, the quality
and trust of each trial, options and versions) and one for the study (each group's curves and
table over its subjects, the subjects, the failures, the study file).

Pages are self-contained HTML: the stylesheet inline, the plots inline SVG, no script, nothing
fetched. Every number of a table carries its full value in ``data-*`` attributes beside the
rounded text (``data-mean``, ``data-sd``, ``data-n``, ``data-value``), so that a reader — or a
test — can check the page against the results file.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from html import escape

import numpy as np

from fccgrb_cli import __version__
from fccgrb_cli.batch.study.store import (
    GroupResults,
    StudyResults,
    SubjectResults,
    Table,
    TrialResults,
)
from fccgrb_cli.gait.cycles import PARAMETERS, SUFFIX, SideCycles
from fccgrb_cli.gait.normative import Norms
from fccgrb_cli.presentation.clinical_report.style import CSS
from fccgrb_cli.presentation.clinical_report.svg import Curve, cycle_plot

SIDES = ("left", "right")
BAD = ' class="bad"'


def subject_file(name: str) -> str:
    return f"subject-{name}.html"


def _stem(name: str) -> str:
    for suffix in SUFFIX.values():
        if name.endswith(suffix):
            return name[: -len(suffix)]
    return name


def _title(stem: str) -> str:
    return stem.replace("_", " ").replace(" moment", "").capitalize() + \
        (" moment" if stem.endswith("_moment") else "")


def _number(value: float, digits: int = 3) -> str:
    return "–" if not math.isfinite(value) else f"{value:.{digits}g}"


def _attr(value: float) -> str:
    return repr(float(value))


def _spread_cell(mean: float, sd: float, n: int) -> str:
    text = "–" if n == 0 or not math.isfinite(mean) else _number(mean) + (
        f" ± {_number(sd, 2)}" if math.isfinite(sd) else "")
    return (f'<td data-mean="{_attr(mean)}" data-sd="{_attr(sd)}" data-n="{int(n)}">'
            f"{text} <span class=\"note\">({int(n)})</span></td>")


def _page(title: str, nav: str, body: str) -> str:
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f'<meta name="generator" content="fccgrb {escape(__version__)}">'
            f"<title>{escape(title)}</title><style>{CSS}</style></head>"
            f"<body>{nav}{body}<footer>Made by fccgrb {escape(__version__)} "
            "(<code>fccgrb report --html</code>). Curves: mean ± SD per side; dashed: mean "
            "toe-off; grey: the normative band given.</footer></body></html>\n")


# --- plots ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class SidePlot:
    """What one side contributes to a variable's plot: mean and SD (101), how many, toe-off."""

    mean: np.ndarray
    sd: np.ndarray
    n: int
    toe_off: float


def _variables(names_by_side: dict[str, tuple[str, ...]], units_by_side: dict[str, tuple]
               ) -> list[tuple[str, str]]:
    """(stem, unit) of every variable of either side, in order of appearance."""
    out: dict[str, str] = {}
    for side, names in names_by_side.items():
        for name, unit in zip(names, units_by_side[side], strict=True):
            out.setdefault(_stem(name), unit)
    return list(out.items())


def _plot_grid(variables: list[tuple[str, str]], sides: dict[str, dict[str, SidePlot]],
               norms: Norms | None) -> str:
    """One plot per variable: each side's curve, the norm's band where the CSV has one."""
    plots = []
    for stem, unit in variables:
        curves = [Curve(side, p.mean, p.sd, p.n, p.toe_off) for side, per in sides.items()
                  if (p := per.get(stem)) is not None]
        norm = norms.curves.get(stem) if norms is not None else None
        plots.append(f'<figure class="cycle" data-variable="{escape(stem)}" style="margin:0">'
                     f"{cycle_plot(_title(stem), unit, curves, norm)}</figure>")
    return f'<div class="plots">{"".join(plots)}</div>'


def _subject_sides(cycles: dict[str, SideCycles]) -> dict[str, dict[str, SidePlot]]:
    out: dict[str, dict[str, SidePlot]] = {}
    for side, c in cycles.items():
        stance = c.parameter("stance")[c.trusted]
        toe_off = float(np.nanmean(stance)) if np.isfinite(stance).any() else math.nan
        mean, sd = c.mean(), c.sd()
        out[side] = {_stem(name): SidePlot(mean[:, j], sd[:, j], int(c.trusted.sum()), toe_off)
                     for j, name in enumerate(c.names)}
    return out


def _group_sides(g: GroupResults) -> dict[str, dict[str, SidePlot]]:
    out: dict[str, dict[str, SidePlot]] = {}
    stance = [p for p, _ in PARAMETERS].index("stance")
    for side in g.mean:
        table = g.spatiotemporal.get(side)
        toe_off = float(table.mean[stance]) if table is not None else math.nan
        out[side] = {_stem(name): SidePlot(g.mean[side][:, j], g.sd[side][:, j],
                                           int(g.n[side][j]), toe_off)
                     for j, name in enumerate(g.names[side])}
    return out


def _split(variables: list[tuple[str, str]]) -> tuple[list, list]:
    """Kinematics (deg) and kinetics (the rest: moments)."""
    return [v for v in variables if v[1] == "deg"], [v for v in variables if v[1] != "deg"]


def _curves_sections(variables: list[tuple[str, str]], sides: dict, norms: Norms | None,
                     over: str, level: int = 2) -> str:
    """The kinematic and the kinetic plots under headings of ``level``; a note instead when no
    side has a trusted stride."""
    if not any(p.n > 0 for per in sides.values() for p in per.values()):
        return (f'<section><h{level}>Cycles</h{level}><p class="note">No trusted strides: no '
                f"cycle plots.</p></section>")
    kinematics, kinetics = _split(variables)
    out = ""
    for title, chosen in (("Kinematics", kinematics), ("Kinetics", kinetics)):
        if chosen:
            out += (f'<section class="curves"><h{level}>{title}</h{level}><p class="note">'
                    f"{over}</p>{_plot_grid(chosen, sides, norms)}</section>")
    return out


# --- tables --------------------------------------------------------------------------------

def _parameters_table(tables: dict[str, Table], norms: Norms | None, what: str) -> str:
    sides = [s for s in SIDES if s in tables]
    head = "".join(f"<th>{s} <span class=\"note\">{what}</span></th>" for s in sides)
    rows = []
    for k, (name, unit) in enumerate(PARAMETERS):
        cells = "".join(_spread_cell(float(tables[s].mean[k]), float(tables[s].sd[k]),
                                     int(tables[s].n[k])) for s in sides)
        norm = norms.values.get(name) if norms is not None else None
        norm_cell = ('<td class="norm">–</td>' if norm is None else
                     f'<td class="norm" data-mean="{_attr(norm[0])}" data-sd="{_attr(norm[1])}">'
                     f"{_number(norm[0])} ± {_number(norm[1], 2)}</td>")
        rows.append(f'<tr data-parameter="{name}"><td>{escape(name.replace("_", " "))} '
                    f"({escape(unit)})</td>{cells}{norm_cell}</tr>")
    return (f'<table class="spatiotemporal"><thead><tr><th>parameter</th>{head}'
            f"<th>norm</th></tr></thead><tbody>{''.join(rows)}</tbody></table>")


def _events_table(trials: tuple[TrialResults, ...]) -> str:
    rows = []
    for t in trials:
        if t.gait is None:
            continue
        e = t.gait.events
        for time, side, kind in zip(e.time, e.side, e.kind, strict=True):
            rows.append(f'<tr><td>{escape(t.name)}</td><td class="text">{escape(e.source)}</td>'
                        f'<td class="text">{escape(side)}</td><td class="text">{escape(kind)}'
                        f'</td><td data-value="{_attr(time)}">{time:.3f}</td></tr>')
    if not rows:
        return '<p class="note">No gait events.</p>'
    return ('<table class="events"><thead><tr><th>trial</th><th>source</th><th>side</th>'
            f"<th>event</th><th>time (s)</th></tr></thead><tbody>{''.join(rows)}</tbody></table>")


def _quality_table(trials: tuple[TrialResults, ...]) -> str:
    """Per trial: frames, trusted frames, the frames carrying every flag any trial's file
    declares (``study.flags``), the fit, the strides per side (trusted) and the warnings; then
    what each flag means and why each trial has it, as the files say."""
    declared = {f.label: f for t in trials for f in t.flags}
    head = "".join(f'<th data-flag="{escape(label)}">{escape(label)} <span class="note">'
                   f"(bit {f.bit})</span></th>" for label, f in declared.items())
    rows = []
    for t in trials:
        counts = {f.label: f.frames for f in t.flags}
        flags = "".join(
            f'<td data-flag="{escape(label)}" data-value="{counts.get(label, 0)}"'
            f"{BAD if counts.get(label, 0) else ''}>{counts.get(label, 0)}</td>"
            for label in declared)
        strides = " · ".join(
            f"{side[0].upper()} {c.n} ({int(c.trusted.sum())})"
            for side, c in (t.gait.cycles.items() if t.gait is not None else ()))
        warnings = "".join(f"<li>{escape(w)}</li>" for w in t.warnings)
        rows.append(
            f'<tr data-trial="{escape(t.name)}"><td>{escape(t.name)}</td>'
            f'<td class="text">{escape(t.method)}</td><td data-value="{t.frames}">{t.frames}</td>'
            f'<td data-value="{t.trusted}"{BAD if t.trusted < t.frames else ""}>'
            f"{t.trusted}</td>{flags}"
            f'<td data-value="{_attr(t.mean_ed_mm)}">{_number(t.mean_ed_mm)}</td>'
            f'<td data-value="{_attr(t.max_ed_mm)}">{_number(t.max_ed_mm)}</td>'
            f'<td class="text">{strides or "–"}</td>'
            f'<td class="text">{f"<ul>{warnings}</ul>" if warnings else "none"}</td></tr>')
    meanings = "".join(f"<li><code>{escape(label)}</code>: {escape(f.meaning)}</li>"
                       for label, f in declared.items() if f.meaning)
    details = "".join(f"<li>{escape(t.name)}, <code>{escape(f.label)}</code>: "
                      f"{escape(f.detail)}</li>" for t in trials for f in t.flags
                      if f.detail and f.frames)
    notes = sorted({(key, text) for t in trials for key, text in t.flag_notes})
    described = "".join(f"<li><code>{escape(k)}</code>: {escape(v)}</li>" for k, v in notes)
    listed = "".join(f'<ul class="note">{items}</ul>' for items in (meanings, details, described)
                     if items)
    return ('<table class="quality"><thead><tr><th>trial</th><th>method</th><th>frames</th>'
            f"<th>trusted</th>{head}<th>mean ED (mm)</th><th>max ED (mm)</th>"
            "<th>strides (trusted)</th><th>warnings</th></tr></thead>"
            f"<tbody>{''.join(rows)}</tbody></table>"
            '<p class="note">Frames carrying each flag of the results file (a bit of a run\'s '
            "<code>flags</code>, per frame, or of another flag dataset, such as "
            "<code>moment_flags</code>, in any column; a frame flagged in <code>flags</code> is "
            "not trusted and stays out of the means); ED: distance of the model points to the "
            f"markers over the trusted frames.</p>{listed}")


def _options_and_versions(trials: tuple[TrialResults, ...], study: StudyResults) -> str:
    options = [t.options for t in trials]
    same = all(o == options[0] for o in options) if options else True
    keys = sorted({k for o in options for k in o})
    if options and same:
        head, cols = "<th>value</th>", [options[0]]
    else:
        head = "".join(f"<th>{escape(t.name)}</th>" for t in trials)
        cols = options
    rows = "".join(f"<tr><td>{escape(k)}</td>" + "".join(
        f'<td class="text">{escape(json.dumps(o.get(k)))}</td>' for o in cols) + "</tr>"
        for k in keys)
    packages = sorted({k for t in trials for k in t.versions} | set(study.versions))
    vhead = "".join(f"<th>{escape(t.name)}</th>" for t in trials)
    vrows = "".join(f"<tr><td>{escape(p)}</td>" + "".join(
        f'<td class="text">{escape(str(t.versions.get(p, "–")))}</td>' for t in trials)
        + f'<td class="text">{escape(str(study.versions.get(p, "–")))}</td></tr>'
        for p in packages)
    return (f'<section><h2>Options and versions</h2><h3>Solve options</h3>'
            f'<table class="options"><thead><tr><th>option</th>{head}</tr></thead>'
            f"<tbody>{rows}</tbody></table>"
            f'<h3>Versions</h3><table class="versions"><thead><tr><th>package</th>{vhead}'
            f"<th>study file</th></tr></thead><tbody>{vrows}</tbody></table></section>")


# --- pages ---------------------------------------------------------------------------------

def _nav(study: StudyResults, here: str) -> str:
    links = [f'<a href="index.html">study {escape(study.name)}</a>'] + [
        f'<a href="{subject_file(s.name)}">{escape(s.name)}</a>' if s.name != here else
        f"<strong>{escape(s.name)}</strong>" for s in study.subjects]
    return f"<nav>{''.join(links)}</nav>"


def subject_page(study: StudyResults, s: SubjectResults, norms: Norms | None) -> str:
    failures = [(w, m) for w, m in study.errors
                if w == f"{s.name} (calibration)" or w.startswith(f"{s.name}-")]
    facts = [("group", s.group), ("study", study.name),
             ("body mass", f"{s.mass:g} kg" if s.mass is not None else "not given"),
             ("template", s.template), ("static trial", s.static),
             ("trials solved", f"{len(s.runs)} of {len(s.trials)}")]
    strides = ", ".join(f"{side} {c.n} ({int(c.trusted.sum())} trusted)"
                        for side, c in s.cycles.items())
    facts.append(("strides", strides or "none"))
    header_lines = [line[1:].strip() for line in s.model.splitlines()[:8] if line.startswith("#")]
    if header_lines:  # what the calibration says it did (methods, measurements used)
        facts.append(("calibration", " ".join(header_lines)))
    header = (f"<header><h1>{escape(s.name)}</h1><p>Gait report · subject of study "
              f"{escape(study.name)} · {len(s.runs)} trials</p></header>")
    dl = "".join(f"<dt>{escape(k)}</dt><dd>{escape(str(v))}</dd>" for k, v in facts)
    body = f'{header}<section><h2>Subject</h2><dl class="facts">{dl}</dl>'
    if failures:
        body += "<h3 class=\"bad\">Not solved</h3><ul>" + "".join(
            f"<li><strong>{escape(w)}</strong>: {escape(m)}</li>" for w, m in failures) + "</ul>"
    body += "</section>"
    names = {side: c.names for side, c in s.cycles.items()}
    units = {side: c.units for side, c in s.cycles.items()}
    body += _curves_sections(_variables(names, units), _subject_sides(s.cycles), norms,
                             "Mean ± SD over the subject's trusted strides of every trial.")
    body += ("<section><h2>Spatiotemporal parameters</h2>"
             + (_parameters_table(s.spatiotemporal, norms, "mean ± SD (strides)")
                if s.spatiotemporal else '<p class="note">No strides.</p>')
             + f"<h3>Events</h3>{_events_table(s.solved)}</section>")
    body += ("<section><h2>Quality and trust</h2>"
             + (_quality_table(s.solved) if s.solved else '<p class="note">No trial solved.</p>')
             + "</section>")
    body += _options_and_versions(s.solved, study)
    body += (f'<section><h2>Personalized model</h2><details><summary>{escape(s.template)} '
             f"calibrated from {escape(s.static)}</summary><pre>{escape(s.model)}</pre>"
             "</details></section>")
    return _page(f"{s.name} — gait report", _nav(study, s.name), body)


def study_page(study: StudyResults, norms: Norms | None) -> str:
    header = (f"<header><h1>Study {escape(study.name)}</h1><p>{len(study.subjects)} subjects · "
              f"{sum(len(s.runs) for s in study.subjects)} trials solved · "
              f"{len(study.errors)} failures</p></header>")
    rows = []
    for s in study.subjects:
        strides = " · ".join(f"{side[0].upper()} {c.n} ({int(c.trusted.sum())})"
                             for side, c in s.cycles.items())
        rows.append(f'<tr data-subject="{escape(s.name)}"><td><a href="{subject_file(s.name)}">'
                    f'{escape(s.name)}</a></td><td class="text">{escape(s.group)}</td>'
                    f'<td data-value="{len(s.runs)}">{len(s.runs)} of {len(s.trials)}</td>'
                    f'<td class="text">{strides or "–"}</td></tr>')
    body = (f"{header}<section><h2>Subjects</h2><table class=\"subjects\"><thead><tr>"
            "<th>subject</th><th>group</th><th>trials solved</th><th>strides (trusted)</th>"
            f"</tr></thead><tbody>{''.join(rows)}</tbody></table></section>")
    for g in study.groups:
        body += (f'<section class="group" data-group="{escape(g.name)}"><h2>Group '
                 f"{escape(g.name)}</h2><p>{len(g.subjects)} subjects: "
                 f"{escape(', '.join(g.subjects))}</p>")
        body += _curves_sections(_variables(g.names, g.units), _group_sides(g), norms,
                                 "Mean ± between-subject SD of the subjects' mean curves (n: "
                                 "subjects).", level=3)
        body += ("<h3>Spatiotemporal parameters</h3>"
                 + (_parameters_table(g.spatiotemporal, norms, "mean ± SD (subjects)")
                    if g.spatiotemporal else '<p class="note">No strides.</p>') + "</section>")
    if study.errors:
        body += ("<section><h2 class=\"bad\">Failures</h2><ul>" + "".join(
            f"<li><strong>{escape(w)}</strong>: {escape(m)}</li>" for w, m in study.errors)
            + "</ul></section>")
    body += (f"<section><h2>Study file</h2><p class=\"note\">{escape(study.command)}</p>"
             f"<pre>{escape(study.text)}</pre></section>")
    return _page(f"Study {study.name} — gait report", _nav(study, ""), body)
