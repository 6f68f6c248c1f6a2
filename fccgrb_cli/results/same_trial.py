"""Whether a trial file holds the markers a run was solved from: an export that adds a run's
outputs to a C3D (``export --format c3d``) writes them beside that file's own markers, so a
file of another trial (its frames as many, its labels the same) would carry outputs that are
not its own."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.pipeline.run import Run
from fccgrb_cli.trial.labels import match_labels
from fccgrb_cli.trial.record import read_trial
from fccgrb_cli.trial.virtual import resolved

READ_TOLERANCE_M = 1e-6  # a C3D's float32 millimetres, or a TRC's 9 digits, read back


def check_same_trial(run: Run, source: str | Path) -> None:
    """An InputError naming ``source`` unless its markers, labelled as the run's options map
    them, are the ones the run saw: equal where the run added no artefact, within √3 × the
    artefact level (its largest deviation per axis, per marker) where it did.

    Parameters
    ----------
    run : Run
        A solved run (its model, options and the markers its solver saw, m).
    source : str or Path
        The trial file to check (C3D or TRC).
    """
    trial = read_trial(source)
    model = run.model
    trial, mapping = resolved(model, trial, dict(run.options.mapping),
                              set(model.marker_labels))
    try:
        labels = match_labels(model, trial, mapping)
    except InputError as error:
        raise InputError(f"{source}: expected the trial run {run.name!r} was solved from; its "
                         f"markers are not all here ({error})") from None
    markers = trial.select(labels)
    seen = np.asarray(run.markers_input)
    if markers.shape != seen.shape:
        raise InputError(f"{source}: {markers.shape[0]} frames, but run {run.name!r} has "
                         f"{seen.shape[0]}: expected the trial it was solved from")
    both = np.isfinite(markers) & np.isfinite(seen)
    apart = float(np.abs(markers - seen)[both].max(initial=0.0))
    allowed = np.sqrt(3.0) * run.options.perturb_level_m + READ_TOLERANCE_M
    if apart > allowed or (np.isfinite(markers) != np.isfinite(seen)).any():
        raise InputError(f"{source}: its markers are up to {1e3 * apart:.3g} mm from the ones "
                         f"run {run.name!r} was solved from (or have gaps elsewhere): expected "
                         "the trial it was solved from")
