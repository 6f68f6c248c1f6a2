"""A study's tables as text: per subject its strides and spatiotemporal parameters (mean ± SD
over its trusted strides), per group the parameters over its subjects (mean ± between-subject
SD), and the failures."""

from __future__ import annotations

import numpy as np

from fccgrb_cli.batch.study.store import StudyResults, Table
from fccgrb_cli.gait.cycles import PARAMETERS


def spread(mean: float, sd: float, n: int) -> str:
    """'1.23 ± 0.05 (n)', '1.23 (1)', '– (0)'."""
    if n == 0 or not np.isfinite(mean):
        return f"– ({n})"
    if not np.isfinite(sd):
        return f"{mean:.3g} ({n})"
    return f"{mean:.3g} ± {sd:.2g} ({n})"


def _parameters(tables: dict[str, Table]) -> str:
    sides = list(tables)
    rows = [f"{'parameter':<28}" + "".join(f"{s:>24}" for s in sides)]
    for k, (name, unit) in enumerate(PARAMETERS):
        cells = "".join(f"{spread(t.mean[k], t.sd[k], int(t.n[k])):>24}"
                        for t in tables.values())
        rows.append(f"{name.replace('_', ' ') + ' (' + unit + ')':<28}{cells}")
    return "\n".join(rows)


def _any(tables: dict[str, Table]) -> bool:
    """Whether any side has a parameter over at least one stride (or subject)."""
    return any(int(t.n.max(initial=0)) > 0 for t in tables.values())


def trials_table(study: StudyResults) -> str:
    """One row per solved trial: method, frames, trusted frames, frames carrying each flag the
    file declares that some trial carries, mean distance of the model points to the markers,
    strides (trusted); then the line naming the declared flags no frame of any trial carries
    (a column of zeros each, left out so that the table stays readable)."""
    trials = [t for s in study.subjects for t in s.solved]
    declared = list(dict.fromkeys(f.label for t in trials for f in t.flags))
    carried = {f.label for t in trials for f in t.flags if f.frames}
    names = [n for n in declared if n in carried]
    clear = [n for n in declared if n not in carried]
    head = ["trial", "method", "frames", "trusted", *names, "mean ED mm", "strides L", "R"]
    rows = [head]
    for t in trials:
        counts = {f.label: f.frames for f in t.flags}
        strides = {side: f"{c.n} ({int(c.trusted.sum())})"
                   for side, c in (t.gait.cycles.items() if t.gait is not None else ())}
        rows.append([t.name, t.method, str(t.frames), str(t.trusted),
                     *(str(counts.get(n, 0)) for n in names), f"{t.mean_ed_mm:.3g}",
                     strides.get("left", "–"), strides.get("right", "–")])
    widths = [max(len(r[k]) for r in rows) for k in range(len(head))]
    table = "\n".join("  ".join(c.ljust(w) if k == 0 else c.rjust(w)
                                for k, (c, w) in enumerate(zip(r, widths, strict=True)))
                      for r in rows)
    return table + (f"\nno frame of any trial flagged by: {', '.join(clear)}" if clear else "")


def study_tables(study: StudyResults) -> str:
    """The trials, every subject's table, then every group's, then the failures."""
    parts = [trials_table(study)] if any(s.solved for s in study.subjects) else []
    for s in study.subjects:
        strides = ", ".join(f"{side} {c.n} ({int(c.trusted.sum())} trusted)"
                            for side, c in s.cycles.items()) or "none"
        head = (f"subject {s.name} (group {s.group}): {len(s.runs)} of {len(s.trials)} trials "
                f"solved; strides {strides}; mean ± SD over the trusted strides (how many)")
        body = _parameters(s.spatiotemporal) if _any(s.spatiotemporal) else \
            "no trusted stride: no spatiotemporal parameters"
        parts.append(f"{head}\n{body}")
    for g in study.groups:
        head = (f"group {g.name}: {len(g.subjects)} subjects ({', '.join(g.subjects)}); mean ± "
                "between-subject SD of the means of the subjects with trusted strides (how "
                "many)")
        body = _parameters(g.spatiotemporal) if _any(g.spatiotemporal) else \
            "no subject with a trusted stride: no spatiotemporal parameters"
        parts.append(f"{head}\n{body}")
    if study.errors:
        parts.append(f"failed ({len(study.errors)}):\n" + "\n".join(
            f"  {where}: {text}" for where, text in study.errors))
    return "\n\n".join(parts)
