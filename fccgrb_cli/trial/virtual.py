"""Virtual markers added to a trial: each ``mid(A, B)`` / ``mean(A, B, …)`` (model/virtual.py)
named by a label map (``--map 'SACR=mid(LPSI,RPSI)'``) or a model file's ``virtual_markers:``
section, computed frame by frame from the trial's markers (missing where any of them is) and
added under its canonical text, to which the model marker is then mapped as to any label.
A marker the trial lacks wholly and that neither defines gets Plug-in Gait's stand-in
(io/stand_ins.py: SACR ← mid(LPSI,RPSI)), said among the trial's warnings.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.model.virtual import canonical, is_expression, parse
from fccgrb_cli.trial.record import Trial
from fccgrb_cli.trial.stand_ins import stand_in_warning, stand_ins


def with_virtual(trial: Trial, expressions: dict[str, str]) -> Trial:
    """``trial`` with a marker for each expression (``where`` → text: the option or key path
    that gives it) added under its :func:`canonical` label; an unknown label is an InputError
    naming it and where the expression came from."""
    labels, columns = list(trial.labels), []
    for where, text in expressions.items():
        label = canonical(text, where)
        if label in labels:
            continue
        _, args = parse(text, where)
        found = []
        for arg in args:
            hit = trial.find(arg)
            if hit is None:
                raise InputError(f"{trial.path}: expected the marker {arg} (used by {where}: "
                                 f"{text})")
            found.append(hit)
        columns.append(trial.select(found).mean(axis=1))
        labels.append(label)
    if not columns:
        return trial
    markers = np.concatenate([trial.markers, np.stack(columns, axis=1)], axis=1)
    return replace(trial, labels=tuple(labels), markers=markers)


def resolved(model: Model, trial: Trial, mapping: dict[str, str], names: set[str]
             ) -> tuple[Trial, dict[str, str]]:
    """The trial with every virtual marker the label map defines and those the model file
    defines for the ``names`` the caller reads (its tracked markers, say), and the label map
    with each marker so defined mapped to its point (the map's definition winning); a name
    neither defines and the trial lacks wholly gets its stand-in (io/stand_ins.py), said in
    the returned trial's warnings."""
    own = {name: text for name, text in model.virtual_markers.items()
           if name in names and name not in mapping}
    expressions = {f"{model.source}: virtual_markers.{name}": text for name, text in own.items()}
    standing = stand_ins(trial, names - set(mapping) - set(own))
    expressions.update({f"the stand-in for {name}": text for name, text in standing.items()})
    own.update(standing)
    if standing:
        trial = replace(trial, warnings=(*trial.warnings, *(
            stand_in_warning(trial, name, text) for name, text in standing.items())))
    expressions.update({f"--map {name}": text for name, text in mapping.items()
                        if is_expression(text)})
    out = {name: canonical(text, f"{model.source}: virtual_markers.{name}")
           for name, text in own.items()}
    out.update({name: canonical(text, f"--map {name}") if is_expression(text) else text
                for name, text in mapping.items()})
    return with_virtual(trial, expressions), out
