"""The marker weights of an OpenSim IK task set (``IKTaskSet``: ``IKMarkerTask`` s).

Only the markers are read here: each task's name, whether it applies and its weight. A marker
task that does not apply leaves its marker untracked. Coordinate tasks (``IKCoordinateTask``)
are counted so that a caller can say they were not used; the IK setup itself (time range,
files, coordinate tasks) is read by the setup reader.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.xml import element_path, number, parse

__all__ = ["MarkerTasks", "read_marker_tasks"]


@dataclass(frozen=True)
class MarkerTasks:
    """``weights``: marker name → weight for the tasks that apply; ``skipped``: the markers whose
    task does not apply; ``coordinate_tasks``: the coordinate tasks' names (not used)."""

    weights: dict[str, float]
    skipped: tuple[str, ...]
    coordinate_tasks: tuple[str, ...]


def read_marker_tasks(path: str | Path) -> MarkerTasks:
    """Read an ``IKTaskSet`` file.

    Parameters
    ----------
    path
        The task set (``<IKTaskSet><objects><IKMarkerTask name=…>``).

    Returns
    -------
    MarkerTasks
        The applied markers' weights (dimensionless, ≥ 0), the markers left out, the coordinate
        tasks' names.

    Raises
    ------
    InputError
        One line naming the file and the element: not a task set, a task without a name, a
        marker named twice, a weight that is negative or not a finite number.
    """
    root = parse(path)
    source = str(path)
    holder = root.find("objects") if root.tag == "IKTaskSet" else None
    if holder is None:
        raise InputError(f"{source}: {root.tag}: expected an IKTaskSet with <objects>")
    parents = [root, holder]
    weights: dict[str, float] = {}
    skipped, coordinates = [], []
    for task in holder:
        where = element_path(parents, task)
        name = (task.get("name") or "").strip()
        if not name:
            raise InputError(f"{source}: {where}: a task without a name")
        if task.tag == "IKCoordinateTask":
            coordinates.append(name)
            continue
        if task.tag != "IKMarkerTask":
            raise InputError(f"{source}: {where}: expected an IKMarkerTask or IKCoordinateTask")
        if name in weights or name in skipped:
            raise InputError(f"{source}: {where}: marker {name!r} has two tasks")
        apply = (task.findtext("apply") or "true").strip().lower()
        if apply not in ("true", "false"):
            raise InputError(f"{source}: {where}/apply: expected true or false, got "
                             f"{apply!r:.40}")
        weight = number(task.findtext("weight") or "1", f"{source}: {where}/weight")
        if weight < 0:
            raise InputError(f"{source}: {where}/weight: expected a weight ≥ 0, got {weight:g}")
        if apply == "true" and weight > 0:
            weights[name] = weight
        else:
            skipped.append(name)
    return MarkerTasks(weights, tuple(skipped), tuple(coordinates))
