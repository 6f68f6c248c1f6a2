"""``fccgrb view``: a results file's runs, or a model file, as a 3D page or a still SVG."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fccgrb_cli.core.atomic import atomic_path, check_target
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import refuse_inputs, regular_file
from fccgrb_cli.view.camera import PRESETS
from fccgrb_cli.view.page import page
from fccgrb_cli.view.scene import Scene, model_scene
from fccgrb_cli.view.still import svg

RESULTS_SUFFIXES = (".h5", ".hdf5")
MODEL_SUFFIXES = (".yaml", ".yml")


def view(source: str, output: str, runs: tuple[str, ...] = (), frame: int | None = None,
         camera: str = "orbit", curve: str | None = None) -> str:
    """Write the view of ``source`` (a results file or a model file) to ``output`` (.html, or
    .svg for a still of one frame) and say what was written.

    Parameters
    ----------
    source : a results file (.h5) or a model (.yaml).
    output : the page (.html) or the still picture (.svg).
    runs : the runs to draw, one or two (results only) [default: the file's one or two].
    frame : the frame index of a still picture (results, .svg only).
    camera : the camera preset the page opens on and the still is seen from.
    curve : the angle drawn under the motion with its joint moment (results only).

    Returns
    -------
    One line for the terminal.
    """
    suffix = Path(output).suffix.lower()
    if suffix not in (".html", ".svg"):
        raise InputError(f"-o: expected a .html page or an .svg still, got {output} (for a "
                         "PNG, take a screenshot of the page)")
    if camera not in PRESETS:
        raise InputError(f"--camera: expected one of {', '.join(PRESETS)}, got {camera}")
    regular_file(source, "results or model file")
    kind = Path(source).suffix.lower()
    refuse_inputs(output, [source])
    check_target(output)
    if kind in MODEL_SUFFIXES:
        if runs or frame is not None or curve is not None:
            raise InputError(f"{source}: a model has no runs, frames or curves; --run, "
                             "--frame and --curve are for a results file")
        from fccgrb_cli.model import load_model

        scene = model_scene(load_model(source))
        k = 0
    elif kind in RESULTS_SUFFIXES:
        scene, k = _results_scene(source, runs, frame, curve, suffix)
    else:
        raise InputError(f"{source}: expected a results file (.h5) or a model file (.yaml)")
    text = page(scene, camera) if suffix == ".html" else svg(scene, k, camera)
    with atomic_path(output) as tmp:
        Path(tmp).write_text(text, encoding="utf-8")
    return _summary(output, scene, len(text.encode("utf-8")))


def _results_scene(source: str, runs: tuple[str, ...], frame: int | None, curve: str | None,
                   suffix: str) -> tuple[Scene, int]:
    from fccgrb_cli.view.runs import motion_scene

    if suffix == ".html":
        if frame is not None:
            raise InputError("--frame: a still picture's frame; write it to an .svg")
        return motion_scene(source, runs, curve), 0
    if frame is None:
        raise InputError("--frame: expected the frame index a still picture shows (0 for "
                         "the first)")
    return motion_scene(source, runs, curve, frames=np.array([frame])), 0


def _summary(output: str, scene: Scene, size: int) -> str:
    what = "model" if scene.model_view else \
        f"{len(scene.layers)} run(s), {len(scene.time)} frames"
    shown = "" if scene.model_view or len(scene.frames) == len(scene.time) or \
        Path(output).suffix.lower() == ".svg" else \
        f", every {scene.stride}th shown"
    return f"wrote {output}: {scene.title} ({what}{shown}), {size / 1e6:.2f} MB"
