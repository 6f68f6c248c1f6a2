"""A study's tables as text: per subject its strides and spatiotemporal parameters (mean ± SD
over its trusted strides), per group the parameters over its subjects (mean ± between-subject
SD), and the failures."""

from __future__ import annotations

import numpy as np

from fccgrb_cli.gait.cycles import PARAMETERS
from fccgrb_cli.study.store import StudyResults, Table


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


def study_tables(study: StudyResults) -> str:
    """Every subject's table, then every group's, then the failures."""
    parts = []
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
