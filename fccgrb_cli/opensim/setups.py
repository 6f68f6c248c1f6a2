"""OpenSim's tool setups: the inverse kinematics' (``InverseKinematicsTool``, with its
``IKTaskSet`` inline or in a file) and the inverse dynamics' (``InverseDynamicsTool``).

Files named in a setup are resolved as OpenSim resolves them: a relative path against the
setup's folder, the ID tool's output file against the ``results_directory`` (itself against the
setup's folder), the IK tool's ``output_motion_file`` against the setup's folder (OpenSim 4.6
writes it there and puts only its marker reports in the results directory). OpenSim reads a
setup's one tool element whatever its tag (opensim-core's own IK test setup spells it
``InverseKinemtaticsTool``); so does this reader, and the properties decide: an element that is
not a property of the tool is refused in one line naming it, as are a number that is not
finite, a flag that is not true or false, a time range that is not two increasing times and a
task weight below zero."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.xml import MAX_MAGNITUDE, element_path, number, numbers, parse

__all__ = ["CoordinateTask", "IDSetup", "IKSetup", "MarkerTask", "TaskSet", "read_id_setup",
           "read_ik_setup", "read_setup", "read_task_set"]

# every property of OpenSim 4's tools (and 3.3's), used or not
_IK_PROPERTIES = {"model_file", "constraint_weight", "accuracy", "IKTaskSet", "marker_file",
                  "coordinate_file", "time_range", "report_errors", "output_motion_file",
                  "report_marker_locations", "results_directory", "input_directory",
                  "defaults"}  # 2.x/3.x: default objects of each type, which OpenSim ignores
_ID_PROPERTIES = {"model_file", "time_range", "forces_to_exclude", "external_loads_file",
                  "coordinates_file", "coordinates_in_degrees",
                  "lowpass_cutoff_frequency_for_coordinates", "output_gen_force_file",
                  "joints_to_report_body_forces", "output_body_forces_file",
                  "results_directory", "input_directory", "defaults"}
_TASK_PROPERTIES = {"apply", "weight", "value_type", "value"}
VALUE_TYPES = ("default_value", "manual_value", "from_file")
HOLD_RATIO = 10.0  # a coordinate task this many times the heaviest marker's weight is a hold


@dataclass(frozen=True)
class MarkerTask:
    """An ``IKMarkerTask``: the model marker ``name``, whether IK uses it, its weight."""

    name: str
    apply: bool
    weight: float


@dataclass(frozen=True)
class CoordinateTask:
    """An ``IKCoordinateTask``: the coordinate ``name``, whether IK uses it, its weight, and
    the value it is drawn to: the model's default, ``value`` (manual, in the coordinate's
    unit as the file writes it: degrees for a rotation), or the setup's ``coordinate_file``."""

    name: str
    apply: bool
    weight: float
    value_type: str
    value: float | None


@dataclass(frozen=True)
class TaskSet:
    """An ``IKTaskSet``: its marker and coordinate tasks in the file's order."""

    markers: tuple[MarkerTask, ...]
    coordinates: tuple[CoordinateTask, ...]
    source: str

    def marker_weights(self) -> dict[str, float]:
        """The markers IK uses (applied, weight above zero) and their weights."""
        return {t.name: t.weight for t in self.markers if t.apply and t.weight > 0}

    def holds(self) -> tuple[tuple[str, ...], tuple[str, ...]]:
        """The coordinate tasks fccgrb keeps, as ``--hold`` items (``NAME=default`` or
        ``NAME=VALUE`` in the file's unit: degrees for a rotation, metres for a translation),
        and a note for each it leaves out. A task is kept when its weight dominates the
        markers' (at least ``HOLD_RATIO`` times the largest marker weight, as OpenSim's
        examples weigh subtalar and toe angles at 1000 beside markers of 1–20): IK then holds
        the coordinate at its value to within a fraction of a degree, which fccgrb does
        exactly. A lighter task (a soft pull towards a value), or one whose value comes from a
        coordinates file, is left out with a note."""
        heaviest = max(self.marker_weights().values(), default=1.0)
        kept, left = [], []
        for task in self.coordinates:
            if not task.apply or task.weight <= 0:
                continue
            if task.value_type == "from_file":
                left.append(f"{task.name} (its value from the coordinates file)")
            elif task.weight < HOLD_RATIO * heaviest:
                left.append(f"{task.name} (weight {task.weight:g} beside markers' up to "
                            f"{heaviest:g}: a soft pull, not a hold)")
            else:
                value = "default" if task.value is None else f"{task.value:.10g}"
                kept.append(f"{task.name}={value}")
        notes = (f"{self.source}: IKCoordinateTask left out: {', '.join(left)}",) if left \
            else ()
        return tuple(kept), notes


@dataclass(frozen=True)
class IKSetup:
    """An ``InverseKinematicsTool`` setup: the files it names (resolved; None when empty),
    its time range (s; None when absent), task set, ``accuracy`` and ``constraint_weight``
    (None when absent; OpenSim's constraint weight ``Infinity`` is None too: constraints kept
    exactly, as fccgrb keeps its topology)."""

    name: str
    source: str
    model_file: Path | None
    marker_file: Path | None
    coordinate_file: Path | None
    time_range: tuple[float, float] | None
    tasks: TaskSet
    accuracy: float | None
    constraint_weight: float | None
    output_motion_file: Path | None


@dataclass(frozen=True)
class IDSetup:
    """An ``InverseDynamicsTool`` setup: the files it names (resolved; None when empty), its
    time range (s), the coordinates' low-pass cutoff (Hz; None when absent or negative, which
    OpenSim reads as no filter), ``coordinates_in_degrees`` (None when absent: the coordinates
    file's own ``inDegrees`` then decides) and the forces it leaves out (names or groups)."""

    name: str
    source: str
    model_file: Path | None
    coordinates_file: Path | None
    external_loads_file: Path | None
    time_range: tuple[float, float] | None
    lowpass_cutoff: float | None
    coordinates_in_degrees: bool | None
    forces_to_exclude: tuple[str, ...]
    output_gen_force_file: Path | None


class _Tool:
    """One tool element being read: its properties by tag, and names for messages."""

    def __init__(self, path: Path, expected: str, properties: set[str]) -> None:
        self.path = path
        self.source = str(path)
        root = parse(path)
        if root.tag != "OpenSimDocument":
            raise InputError(f"{path}: {root.tag}: expected an OpenSim setup "
                             f"(OpenSimDocument/{expected})")
        tools = list(root)
        if len(tools) != 1:
            raise InputError(f"{path}: OpenSimDocument: expected one tool element "
                             f"({expected}), got {len(tools)}")
        self.root, self.element = root, tools[0]
        self.where = element_path([root], self.element)
        for child in self.element:
            if child.tag not in properties:
                raise InputError(f"{path}: {self.where}/{child.tag}: expected a property of "
                                 f"{expected} ({', '.join(sorted(properties))}), got an "
                                 "unknown element")
        self.name = self.element.get("name") or path.stem

    def text(self, tag: str) -> str:
        return (self.element.findtext(tag) or "").strip()

    def here(self, tag: str) -> str:
        return f"{self.source}: {self.where}/{tag}"

    def file(self, tag: str, folder: Path | None = None) -> Path | None:
        """A file property resolved against ``folder`` (the setup's own by default)."""
        name = self.text(tag)
        if not name or name.lower() == "unassigned":
            return None
        named = Path(name)
        return named if named.is_absolute() else (folder or self.path.parent) / named

    def output(self, tag: str) -> Path | None:
        results = self.file("results_directory") or self.path.parent
        return self.file(tag, results)

    def number(self, tag: str) -> float | None:
        text = self.text(tag)
        if not text:
            return None
        if text.lower() in ("inf", "infinity"):
            return None
        return number(text, self.here(tag))

    def flag(self, tag: str) -> bool | None:
        text = self.text(tag).lower()
        if not text:
            return None
        if text not in ("true", "false"):
            raise InputError(f"{self.here(tag)}: expected true or false, got "
                             f"{self.text(tag)!r:.40}")
        return text == "true"

    def time_range(self) -> tuple[float, float] | None:
        text = self.text("time_range")
        if not text:
            return None
        start, stop = numbers(text, self.here("time_range"), 2)
        if not start <= stop:
            raise InputError(f"{self.here('time_range')}: expected a start time before the "
                             f"end time, got {start:g} {stop:g}")
        return start, stop


def read_ik_setup(path: str | Path) -> IKSetup:
    """The inverse kinematics setup ``path`` (``OpenSimDocument/InverseKinematicsTool``).

    Parameters
    ----------
    path
        The setup ``.xml``.

    Returns
    -------
    IKSetup
        Its files resolved against its folder, its time range, task set (inline, or the file
        its ``IKTaskSet file=`` names, resolved likewise), accuracy and constraint weight.

    Raises
    ------
    InputError
        One line naming the file and the element.
    """
    tool = _Tool(Path(path), "InverseKinematicsTool", _IK_PROPERTIES)
    element = tool.element.find("IKTaskSet")
    if element is None:
        tasks = TaskSet((), (), tool.source)
    elif element.get("file"):
        named = Path(element.get("file", "").strip())
        tasks = read_task_set(named if named.is_absolute() else tool.path.parent / named)
    else:
        tasks = _task_set(element, [tool.root, tool.element], tool.source)
    accuracy = tool.number("accuracy")
    if accuracy is not None and not 0 < accuracy <= 1:
        raise InputError(f"{tool.here('accuracy')}: expected a positive accuracy of at most 1 "
                         f"(m and rad: the solve's tolerance on ‖Δq‖∞), got {accuracy:g}")
    weight = tool.number("constraint_weight")
    if weight is not None and weight < 0:
        raise InputError(f"{tool.here('constraint_weight')}: expected a weight of at least "
                         f"0, got {weight:g}")
    return IKSetup(tool.name, tool.source, tool.file("model_file"), tool.file("marker_file"),
                   tool.file("coordinate_file"), tool.time_range(), tasks, accuracy, weight,
                   tool.file("output_motion_file"))


def read_id_setup(path: str | Path) -> IDSetup:
    """The inverse dynamics setup ``path`` (``OpenSimDocument/InverseDynamicsTool``).

    Parameters
    ----------
    path
        The setup ``.xml``.

    Returns
    -------
    IDSetup
        Its files resolved against its folder, time range, the coordinates' low-pass cutoff
        (Hz), ``coordinates_in_degrees`` and the forces to exclude.

    Raises
    ------
    InputError
        One line naming the file and the element.
    """
    tool = _Tool(Path(path), "InverseDynamicsTool", _ID_PROPERTIES)
    cutoff = tool.number("lowpass_cutoff_frequency_for_coordinates")
    if cutoff is not None and cutoff <= 0:
        cutoff = None  # OpenSim's "-1": no filter
    excluded = tuple(tool.text("forces_to_exclude").split())
    return IDSetup(tool.name, tool.source, tool.file("model_file"),
                   tool.file("coordinates_file"), tool.file("external_loads_file"),
                   tool.time_range(), cutoff, tool.flag("coordinates_in_degrees"), excluded,
                   tool.output("output_gen_force_file"))


def read_task_set(path: str | Path) -> TaskSet:
    """The ``IKTaskSet`` of ``path``: a task set file (the set as the root, or under
    ``OpenSimDocument``), or an IK setup whose task set it is.

    Parameters
    ----------
    path
        The ``.xml`` file.

    Returns
    -------
    TaskSet

    Raises
    ------
    InputError
        One line naming the file and the element: not a task set, an unknown task, a task named
        twice, a weight below zero or not finite, an ``apply`` that is not true or false.
    """
    path = Path(path)
    root = parse(path)
    if root.tag == "IKTaskSet":
        return _task_set(root, [], str(path))
    found = root.find("IKTaskSet") if root.tag == "OpenSimDocument" else None
    if found is not None:
        return _task_set(found, [root], str(path))
    if root.tag == "OpenSimDocument" and len(root) == 1 and root[0].find("IKTaskSet") is not None:
        return read_ik_setup(path).tasks
    raise InputError(f"{path}: {root.tag}: expected an IKTaskSet (or an IK setup holding one)")


def _task_set(element: ET.Element, parents: list[ET.Element], source: str) -> TaskSet:
    where = element_path(parents, element)
    for child in element:
        if child.tag not in ("objects", "groups"):
            raise InputError(f"{source}: {where}/{child.tag}: expected objects or groups, got "
                             "an unknown element")
    objects = element.find("objects")
    markers: list[MarkerTask] = []
    coordinates: list[CoordinateTask] = []
    seen: set[tuple[str, str]] = set()
    for task in (objects if objects is not None else ()):
        assert objects is not None  # the tasks come from it
        here = f"{source}: {element_path([*parents, element, objects], task)}"
        if task.tag not in ("IKMarkerTask", "IKCoordinateTask"):
            raise InputError(f"{here}: expected an IKMarkerTask or IKCoordinateTask, got an "
                             "unknown task")
        name = (task.get("name") or "").strip()
        if not name:
            raise InputError(f"{here}: expected a name='…' attribute (the marker or "
                             "coordinate), got none")
        if (task.tag, name) in seen:
            raise InputError(f"{here}: expected each {task.tag} named once, got {name!r} "
                             "again")
        seen.add((task.tag, name))
        for child in task:
            if child.tag not in _TASK_PROPERTIES:
                raise InputError(f"{here}/{child.tag}: expected one of "
                                 f"{', '.join(sorted(_TASK_PROPERTIES))}, got an unknown "
                                 "element")
        apply, weight = _apply(task, here), _weight(task, here)
        if task.tag == "IKMarkerTask":
            markers.append(MarkerTask(name, apply, weight))
            continue
        kind = (task.findtext("value_type") or "default_value").strip()
        if kind not in VALUE_TYPES:
            raise InputError(f"{here}/value_type: expected one of {', '.join(VALUE_TYPES)}, "
                             f"got {kind!r:.40}")
        value = None
        if kind == "manual_value":
            value = number(task.findtext("value") or "0", f"{here}/value")
        coordinates.append(CoordinateTask(name, apply, weight, kind, value))
    return TaskSet(tuple(markers), tuple(coordinates), source)


def _apply(task: ET.Element, here: str) -> bool:
    text = (task.findtext("apply") or "true").strip().lower()
    if text not in ("true", "false"):
        raise InputError(f"{here}/apply: expected true or false, got "
                         f"{task.findtext('apply')!r:.40}")
    return text == "true"


def _weight(task: ET.Element, here: str) -> float:
    weight = number(task.findtext("weight") or "1", f"{here}/weight")
    if weight < 0 or weight > MAX_MAGNITUDE:
        raise InputError(f"{here}/weight: expected a weight of at least 0, got {weight:g}")
    return weight


def read_setup(path: str | Path) -> IKSetup | IDSetup:
    """An IK or ID setup, by its tool element (``InverseKinematicsTool`` or
    ``InverseDynamicsTool``; a misspelt tag is judged by its properties, as OpenSim reads it)."""
    root = parse(Path(path))
    tools = list(root) if root.tag == "OpenSimDocument" else []
    if len(tools) == 1 and (tools[0].tag == "InverseDynamicsTool" or
                            tools[0].find("coordinates_file") is not None or
                            tools[0].find("external_loads_file") is not None):
        return read_id_setup(path)
    if len(tools) == 1 and (tools[0].tag.startswith("InverseKinem") or
                            tools[0].find("marker_file") is not None):
        return read_ik_setup(path)
    raise InputError(f"{path}: {root.tag}: expected an OpenSim IK or ID setup "
                     "(OpenSimDocument/InverseKinematicsTool or InverseDynamicsTool)")
