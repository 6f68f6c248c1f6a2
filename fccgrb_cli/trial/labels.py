"""Which of a trial's labels each tracked marker and tracked vector of a model follows."""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.model import Model
from fccgrb_cli.trial.record import Trial


def match_labels(model: Model, trial: Trial, mapping: dict[str, str]) -> list[str]:
    """The file label each tracked marker follows: the CLI mapping, else the YAML's marker name;
    a file label 'Subject:NAME' matches NAME when NAME itself is absent. A label not found is an
    error naming, for each, the file's closest labels."""
    unknown = sorted(set(mapping) - set(model.marker_labels))
    if unknown:
        raise InputError(f"--map: expected marker names of the model "
                         f"({', '.join(model.marker_labels)}), got "
                         f"{_with_closest(unknown, model.marker_labels)}")
    out: list[str | None] = []
    missing: list[str] = []
    for name in model.marker_labels:
        wanted = mapping.get(name, name)
        label = trial.find(wanted)
        if label is None:
            missing.append(wanted)
        out.append(label)
    if missing and not trial.labels:
        raise InputError(f"{trial.path}: the file holds no marker trajectories (no 3D point "
                         f"labels); expected the markers tracked by {model.source}: "
                         f"{', '.join(missing[:12])}{' …' if len(missing) > 12 else ''}")
    if missing:
        free = [label for label in trial.labels if label not in out]
        shown = ", ".join(free[:12]) + (" …" if len(free) > 12 else "")
        raise InputError(f"{trial.path}: expected the labels tracked by {model.source}; not "
                         f"found: {_with_closest(missing, free)}; the file's labels no marker "
                         f"follows: {shown or 'none'} (map names with --map NAME=LABEL or "
                         "--map FILE.yaml)")
    labels = [label for label in out if label is not None]  # all: none is missing
    one_label_each(dict(zip(model.marker_labels, labels, strict=True)), "marker")
    return labels


def _with_closest(names: list[str], known: tuple[str, ...] | list[str]) -> str:
    """'A (closest: B, C), D (closest: none)': each name with the nearest of ``known``."""
    from difflib import get_close_matches

    bare = {k.split(":")[-1].lower(): k for k in known}
    parts = []
    for name in names:
        near = get_close_matches(name.split(":")[-1].lower(), list(bare), n=3, cutoff=0.4)
        parts.append(f"{name} (closest: {', '.join(bare[n] for n in near) or 'none'})")
    return ", ".join(parts)


def vector_targets(model: Model, trial: Trial, markers: dict[str, np.ndarray]) -> np.ndarray:
    """The unit vectors the model's tracked vectors follow, per frame (frames × vectors × 3):
    from each one's first marker to its second, read from ``markers`` (model name → frames × 3)
    or else from the trial, where each one read is added to ``markers``."""
    out = []
    for tv in model.tracked_vectors:
        ends = []
        for label in (tv.from_marker, tv.to_marker):
            if label not in markers:
                if label not in trial.labels:
                    raise InputError(f"{trial.path}: expected the label {label} used by a "
                                     f"tracked vector of {model.source}")
                markers[label] = trial.select([label])[:, 0]
            ends.append(markers[label])
        d = ends[1] - ends[0]
        out.append(d / np.linalg.norm(d, axis=1, keepdims=True))
    return np.stack(out, axis=1) if out else np.zeros((trial.n_frames, 0, 3))


def one_label_each(labels: Mapping[str, str], what: str) -> None:
    """An InputError when two names follow one label (``labels``: name → the label it follows
    once mapped): two markers, or two landmarks, would read the same data."""
    by_label: dict[str, list[str]] = {}
    for name, label in labels.items():
        by_label.setdefault(label, []).append(name)
    shared = {label: names for label, names in by_label.items() if len(names) > 1}
    if shared:
        label, names = next(iter(sorted(shared.items())))
        raise InputError(f"--map: expected one {what} per trial label, got {' and '.join(names)} "
                         f"on the label {label}")
