"""OpenSim's external loads: an ExternalLoads ``.xml`` naming, for each ``ExternalForce``, the
body it acts on and the columns of a storage file (``datafile``) that hold its force, point of
application and torque.

A force's columns are found as OpenSim finds them: the three columns whose names begin with
its ``force_identifier`` (``ground_force_v`` → ``ground_force_vx``, ``_vy``, ``_vz``), in the
file's order, and likewise the point's and the torque's. The force acts at the point, the
torque is a free couple on the body (a plate's free moment): on a body of reference point r,
the load's moment about r is (p − r) × f + τ. Units are OpenSim's: N, m, N·m.

Force and point expressed in ground are read. A force or point expressed in a body frame, a
force without a point (OpenSim applies it at the body's origin) or a torque without a force
need the model's body frames and are refused in one line naming the element, as is an
``ExternalForce`` a fccgrb load cannot represent. A disabled force (``appliesForce`` false, or
the 3.x ``isDisabled`` true) is left out."""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import check_name
from fccgrb_cli.core.xml import element_path, parse
from fccgrb_cli.dynamics.loads import ExternalLoad
from fccgrb_cli.model import Model
from fccgrb_cli.opensim.storage import Storage, read_storage
from fccgrb_cli.trial.record import Trial

__all__ = ["BodyLoad", "ExternalForce", "LoadSet", "external_loads", "read_external_loads",
           "trial_loads"]

GROUND = "ground"
_FORCE_FIELDS = {"appliesForce", "isDisabled", "applied_to_body", "force_expressed_in_body",
                 "point_expressed_in_body", "force_identifier", "point_identifier",
                 "torque_identifier", "data_source_name"}
_SET_FIELDS = {"objects", "groups", "datafile", "external_loads_model_kinematics_file",
               "lowpass_cutoff_frequency_for_load_kinematics",
               "defaults"}  # 2.x/3.x: default objects of each type, which OpenSim ignores


@dataclass(frozen=True)
class ExternalForce:
    """One ``ExternalForce``: its ``name``, the body it acts on, the frames its force and point
    are expressed in, and the column prefixes of its force, point and torque (empty: none);
    ``where`` is its path in the file, for messages."""

    name: str
    body: str
    force_frame: str
    point_frame: str
    force_identifier: str
    point_identifier: str
    torque_identifier: str
    data_source: str
    where: str


@dataclass(frozen=True)
class BodyLoad:
    """One force's data at its storage file's times: ``force`` (rows × 3, N) at ``point``
    (rows × 3, m) and a free ``torque`` (rows × 3, N·m), all in ground, acting on ``body``."""

    name: str
    body: str
    time: np.ndarray
    force: np.ndarray
    point: np.ndarray
    torque: np.ndarray

    def at(self, time: np.ndarray, source: str) -> ExternalLoad:
        """The load at ``time`` (frames, s, on the storage file's clock), interpolated linearly
        between the file's rows (OpenSim splines them; at 600 Hz the two agree to far below
        the force's noise). A time outside the file's is an InputError naming ``source``."""
        time = np.asarray(time, dtype=float)
        start, stop = float(self.time[0]), float(self.time[-1])
        slack = 1e-9 * max(1.0, abs(stop))
        if time.size and (time.min() < start - slack or time.max() > stop + slack):
            raise InputError(f"{source}: ExternalForce {self.name}: expected data over the "
                             f"trial's {time.min():.6g}–{time.max():.6g} s, got "
                             f"{start:.6g}–{stop:.6g} s")
        clipped = np.clip(time, start, stop)

        def sample(values: np.ndarray) -> np.ndarray:
            return np.column_stack([np.interp(clipped, self.time, values[:, k])
                                    for k in range(3)])

        return ExternalLoad(self.name, self.body, sample(self.force), sample(self.point),
                            sample(self.torque))


@dataclass(frozen=True)
class LoadSet:
    """An ExternalLoads file: its forces (the applied ones, in the file's order), the storage
    file they read (``datafile`` resolved against the XML's folder, as OpenSim does) and its
    ``external_loads_model_kinematics_file`` (resolved likewise; None when empty)."""

    source: str
    forces: tuple[ExternalForce, ...]
    datafile: Path
    kinematics_file: Path | None
    data: Storage

    def body_loads(self) -> list[BodyLoad]:
        """Each force's columns as a :class:`BodyLoad` at the data's times."""
        return [_body_load(force, self.data, self.source) for force in self.forces]

    @property
    def bodies(self) -> tuple[str, ...]:
        """The bodies the forces act on, each once, in the file's order."""
        return tuple(dict.fromkeys(force.body for force in self.forces))


def read_external_loads(path: str | Path) -> LoadSet:
    """The ExternalLoads file ``path`` and its ``datafile``.

    Parameters
    ----------
    path
        An OpenSim ExternalLoads ``.xml`` (under ``OpenSimDocument`` or as the root).

    Returns
    -------
    LoadSet
        The applied forces, their storage file read, the kinematics file's path.

    Raises
    ------
    InputError
        One line naming the file and the element: not an ExternalLoads document, a missing or
        unreadable datafile, an unknown element, a force expressed in a body frame, columns
        that are not three per identifier.
    """
    path = Path(path)
    source = str(path)
    root = parse(path)
    loads, parents = _loads_element(root, source)
    where = element_path(parents, loads)
    _known(loads, _SET_FIELDS, where, source)
    objects = loads.find("objects")
    forces = []
    for element in (objects if objects is not None else ()):
        assert objects is not None  # the elements come from it
        here = element_path([*parents, loads, objects], element)
        if element.tag != "ExternalForce":
            raise InputError(f"{source}: {here}: expected an ExternalForce (fccgrb reads no "
                             f"other external load), got {element.tag}")
        force = _force(element, here, source)
        if force is not None:
            forces.append(force)
    names = [f.name for f in forces]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"{source}: {where}/objects: expected each ExternalForce named once, "
                         f"got {twice[0]!r} more than once")
    if not forces:
        raise InputError(f"{source}: {where}/objects: expected at least one applied "
                         "ExternalForce, got none")
    datafile = _relative(loads.findtext("datafile"), path)
    if datafile is None:
        raise InputError(f"{source}: {where}/datafile: expected the storage file (.mot/.sto) "
                         "of the forces' data, got none")
    kinematics = _relative(loads.findtext("external_loads_model_kinematics_file"), path)
    data = read_storage(datafile)
    found = LoadSet(source, tuple(forces), datafile, kinematics, data)
    found.body_loads()  # every identifier's three columns are there
    return found


def external_loads(loads: LoadSet, time: np.ndarray, bodies: Iterable[str]) -> list[ExternalLoad]:
    """The load set's forces at ``time`` (frames, s on the data file's clock) as fccgrb's
    external loads, each on its ``applied_to_body``, which must be one of ``bodies`` (the
    model's).

    Parameters
    ----------
    loads
        A load set from :func:`read_external_loads`.
    time
        The frames' times (frames, s).
    bodies
        The model's body names.

    Returns
    -------
    list of ExternalLoad
        One per applied force: force (frames × 3, N), point (frames × 3, m), free moment
        (frames × 3, N·m), in ground.
    """
    known = set(bodies)
    for force in loads.forces:
        if force.body not in known:
            raise InputError(f"{loads.source}: {force.where}/applied_to_body: expected a body "
                             f"of the model ({', '.join(sorted(known))[:200]}), got "
                             f"{force.body!r}")
    return [load.at(time, loads.source) for load in loads.body_loads()]


def _loads_element(root: ET.Element, source: str) -> tuple[ET.Element, list[ET.Element]]:
    if root.tag == "ExternalLoads":
        return root, []
    inner = root.find("ExternalLoads") if root.tag == "OpenSimDocument" else None
    if inner is None:
        raise InputError(f"{source}: {root.tag}: expected an OpenSim ExternalLoads document "
                         "(OpenSimDocument/ExternalLoads)")
    return inner, [root]


def _known(element: ET.Element, allowed: set[str], where: str, source: str) -> None:
    for child in element:
        if child.tag not in allowed:
            raise InputError(f"{source}: {where}/{child.tag}: expected one of "
                             f"{', '.join(sorted(allowed))}, got an unknown element")


def _flag(element: ET.Element, tag: str, default: bool, where: str, source: str) -> bool:
    text = element.findtext(tag)
    if text is None or not text.strip():
        return default
    value = text.strip().lower()
    if value not in ("true", "false"):
        raise InputError(f"{source}: {where}/{tag}: expected true or false, got {text!r:.40}")
    return value == "true"


def _force(element: ET.Element, where: str, source: str) -> ExternalForce | None:
    """The ExternalForce ``element``, None when disabled."""
    _known(element, _FORCE_FIELDS, where, source)
    applies = _flag(element, "appliesForce", True, where, source) and \
        not _flag(element, "isDisabled", False, where, source)
    if not applies:
        return None
    name = check_name(element.get("name") or "", f"{source}: {where}: the name='…' attribute")

    def text(tag: str, default: str = "") -> str:
        return (element.findtext(tag) or "").strip() or default

    body = text("applied_to_body")
    if not body:
        raise InputError(f"{source}: {where}/applied_to_body: expected the name of the body "
                         "the force acts on, got none")
    force = ExternalForce(name, body,
                          text("force_expressed_in_body", GROUND),
                          text("point_expressed_in_body", GROUND), text("force_identifier"),
                          text("point_identifier"), text("torque_identifier"),
                          text("data_source_name"), where)
    for tag, frame in (("force_expressed_in_body", force.force_frame),
                       ("point_expressed_in_body", force.point_frame)):
        if frame != GROUND:
            raise InputError(f"{source}: {where}/{tag}: expected ground (fccgrb reads loads "
                             f"expressed in ground only), got {frame!r}")
    if not force.force_identifier:
        raise InputError(f"{source}: {where}/force_identifier: expected the force's column "
                         "prefix (fccgrb reads no torque-only ExternalForce), got none")
    if not force.point_identifier:
        raise InputError(f"{source}: {where}/point_identifier: expected the point's column "
                         "prefix (a force without one acts at the body's origin, which fccgrb "
                         "does not read), got none")
    return force


def _relative(text: str | None, setup: Path) -> Path | None:
    """A file named in ``setup``, resolved against the setup's folder (OpenSim's rule)."""
    name = (text or "").strip()
    if not name or name.lower() == "unassigned":
        return None
    named = Path(name)
    return named if named.is_absolute() else setup.parent / named


def _columns(data: Storage, identifier: str, where: str, source: str) -> np.ndarray:
    """The three columns of ``data`` whose names begin with ``identifier`` (rows × 3)."""
    found = [k for k, name in enumerate(data.names) if name.startswith(identifier)]
    if len(found) != 3:
        shown = ", ".join(data.names[k] for k in found) or "none"
        raise InputError(f"{source}: {where}: expected 3 columns of {data.source} beginning "
                         f"with {identifier!r}, got {len(found)} ({shown[:120]})")
    return data.values[:, found]


def _body_load(force: ExternalForce, data: Storage, source: str) -> BodyLoad:
    f = _columns(data, force.force_identifier, f"{force.where}/force_identifier", source)
    p = _columns(data, force.point_identifier, f"{force.where}/point_identifier", source)
    torque = _columns(data, force.torque_identifier, f"{force.where}/torque_identifier",
                     source) if force.torque_identifier else np.zeros_like(f)
    return BodyLoad(force.name, force.body, data.time, f, p, torque)


def trial_loads(path: str | Path, model: Model, trial: Trial
                ) -> tuple[list[ExternalLoad], list[str]]:
    """The ExternalLoads file ``path`` at the frames of ``trial`` (its times on the file's
    clock: ``trial.start`` + frame / rate), each force on its model body, and the notes to
    report (which force went to which body, what the data file's reader noticed)."""
    loads = read_external_loads(path)
    time = trial.start + trial.time
    out = external_loads(loads, time, [body.name for body in model.bodies])
    said = ", ".join(f"{force.name} → {force.body}" for force in loads.forces)
    return out, [f"external loads from {path} ({loads.datafile.name}): {said}",
                 *loads.data.notes]
