"""Every option of a solve, in one place: its default, unit, allowed values and help text.

``SolveOptions`` is frozen and validated; the command line (``fccgrb solve``), the sweep cells
and the Python API (``fccgrb_cli.solve``) all build one and hand it, unchanged, to
``pipeline.solve_trial``. The command-line flags (:func:`click_options`), the sweep keys
(:meth:`SolveOptions.from_mapping`) and the API's documentation (:func:`describe`) are generated
from the fields below, so an option added here reaches all three. :func:`prepared` applies the
options that change the model (its bodies' form, the tracked markers).
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from dataclasses import Field, dataclass, field, fields, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from fccgrb_cli.anatomy.lab_axes import AXES
from fccgrb_cli.core.bounds import describe_range, in_range
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import check_name, load_yaml, read_text, shown

if TYPE_CHECKING:
    from fccgrb_cli.model import Model

METHODS = ("ad", "nrm-ls", "nrm-wls", "cno-sqp", "cno-ip", "mo-tc", "mo-ed")
PARALLEL_METHODS = ("cno-sqp", "cno-ip", "mo-tc", "mo-ed")  # the methods --parallel changes
# Processes beyond the CPUs gain nothing; a pool of 100,000 forks until the machine stops.
WORKERS_MAX = max(8, 4 * (os.cpu_count() or 1))
SEED_MAX = 2**32 - 1  # numpy's seeds


REPEATABLE = ("mapping", "plates")  # options given once per value on the command line
_META = {"flag": None, "unit": "", "choices": (), "low": None, "low_open": False, "high": None,
         "sweep": None, "names": False, "cli": True, "metavar": None}


def _option(default: Any, help: str, **meta: Any) -> Any:
    """A field with the metadata the CLI, the sweep and the docs read: ``flag`` (the CLI
    spelling when it differs from the field's), ``unit``, ``choices``, ``low``/``high`` (with
    ``low_open`` for a strict bound), ``sweep`` (the sweep key when it differs), ``names`` (a
    comma-separated list of names on the CLI, a list in a sweep), ``cli`` (False: API and
    sweep only) and ``metavar``."""
    unknown = set(meta) - set(_META)
    if unknown:
        raise TypeError(f"_option: unknown metadata {sorted(unknown)}")
    return field(default=default, metadata={**_META, **meta, "help": help})


@dataclass(frozen=True)
class SolveOptions:
    """The options of one solve (SI inside; the perturbation level in mm as users state it).

    Frozen and validated: every field is a keyword (``SolveOptions(method="cno-sqp")``), and
    ``help(fccgrb_cli.solve)`` or :func:`describe` lists each with its unit, default and
    meaning; the command line's flags and a sweep's keys are the same fields.
    :meth:`from_mapping` builds one from a mapping of field names or sweep keys.
    """

    # --- kinematics ------------------------------------------------------------------------
    method: str = _option(
        "nrm-wls", choices=METHODS,
        help="ad: the classical kinematic analysis with angular drivers computed from the "
             "markers (segment frames fitted, then the angles; see {filter_cutoff}); nrm-ls / "
             "nrm-wls: mixed coordinates by Newton–Raphson on least squares / weighted least "
             "squares; cno-sqp / cno-ip: min of the tracking objective ({objective}) subject to "
             "the topological equations, by SQP or an interior point ({optimizer}); mo-tc / "
             "mo-ed: goal attainment over each tracking component / each point's Euclidean "
             "distance.")
    optimizer: str = _option(
        "auto", choices=("auto", "structured", "scipy"),
        help="structured: the engine's own optimizers — cno-sqp / cno-ip with the tc objective "
             "by a stabilized SQP (Newton on the KKT conditions with the exact Lagrangian "
             "Hessian) or that SQP with a primal-dual barrier on the bounds, mo-tc / mo-ed by "
             "an active-set SQP (a frame either cannot solve goes to scipy); scipy: SLSQP / "
             "trust-constr for every frame (the paper's reference); auto: structured for CNO, "
             "scipy for MO (whose optimum on noisy markers is not a point: the structured "
             "method's smoother path along it escapes the jump flag on some frames).")
    objective: str = _option(
        "tc", choices=("tc", "ed"),
        help="CNO objective: weighted sum of squared tracking residuals (tc, m²) or of "
             "Euclidean distances (ed, m).")
    tol: float = _option(1e-10, unit="m and rad", low=0.0, low_open=True, high=1.0,
                         help="Newton–Raphson tolerance on ‖Δq‖∞; the optimizers' tolerance.")
    max_iter: int | None = _option(
        None, low=1, high=10_000, help="Iteration cap per frame [default: 50 for NRM, 500 for the "
                          "optimizers].")
    tracking_weight: float = _option(
        1e-3, low=0.0, low_open=True, high=1e6,
        help="WLS weight of the tracking equations (topological equations weigh 1); a tracked "
             "point's own 'weight' in the model overrides it.")
    warm_start: str = _option(
        "extrapolate", choices=("extrapolate", "previous"),
        help="Each frame starts from a polynomial extrapolation of the last solutions, or from "
             "the previous solution (the paper's choice).")
    hessian: str = _option(
        "auto", choices=("auto", "gauss-newton", "exact"),
        help="NRM iteration matrix: gauss-newton (Φ_qᵀWΦ_q, the paper's NRM), exact (adds "
             "Σ wΦ∇²Φ: Newton on the weighted least squares), or auto: Gauss–Newton until a "
             "step is below 1 mm / 1 mrad, then exact.")
    engine: str = _option(
        "auto", choices=("auto", "compiled", "numpy"),
        help="Per-frame arithmetic of NRM and of the structured optimizers: compiled kernels "
             "(numba), the same iteration in numpy (equal to 1e-12; goal attainment's to 1e-8), "
             "or auto: compiled wherever numba is installed and no body is reduced (loading "
             "the kernels, ~0.3 s once per process, is reported apart from ms/frame; the first "
             "run after an install compiles them: 'fccgrb compile').")
    skip_unsolvable: bool = _option(
        False, help="Report frames whose remaining markers cannot determine the model as "
                    "unsolved and go on, instead of stopping with an error.")
    parallel: bool = _option(
        False, help="Optimizers only: solve frames independently over a process pool (the "
                    "paper's parallel mode; see {parallel_init}).")
    workers: int | None = _option(None, low=1, high=WORKERS_MAX,
                                  help="Processes for {parallel} [default: the number of CPUs].")
    parallel_init: str = _option(
        "nrm", choices=("same", "chunks", "nrm"),
        help="With {parallel}: NRM-WLS positions as each frame's guess (nrm), or contiguous "
             "chunks solved sequentially within each worker (chunks); both then re-solve, in "
             "order from a trusted neighbour, every frame that failed, jumped or left its "
             "neighbours' assembly branch, and give the sequential answer. 'same' is the "
             "paper's parallel mode: every frame from the same guess, no re-solve (its wrong "
             "frames are flagged).")
    ad_drivers: str = _option(
        "markers", choices=("markers", "truth"),
        help="With {method} ad: angles from the markers, or the true angles of a trial made by "
             "'fccgrb synth' (its TRIAL.truth.h5).")
    form: str = _option("model", choices=("model", "full", "reduced"),
                        help="Body form for every body (fully-defined or reduced), or as the "
                             "model says.")
    track: tuple[str, ...] = _option(
        (), names=True, metavar="NAMES", sweep="track",
        help="Model marker names to track [default: all the model's].")
    mapping: tuple[tuple[str, str], ...] = _option(
        (), flag="map", metavar="NAME=LABEL|FILE", sweep="map",
        help="Model marker name → trial label, where they differ (CLI: repeatable NAME=LABEL, "
             "comma-separated pairs, or a YAML file of NAME: LABEL lines); a label may be a "
             "virtual marker, mid(A,B) or mean(A,B,...) of trial labels.")
    tasks: tuple[tuple[str, float], ...] = _option(
        (), metavar="TASKS.xml",
        help="An OpenSim IK task set (an IKTaskSet file, or an IK setup holding one): track "
             "only the markers of its applied IKMarkerTasks of weight above 0, each weighted "
             "by its task's weight times {tracking_weight} (OpenSim's weights are relative); "
             "its IKCoordinateTasks of dominant weight (10 × the heaviest marker's) hold their "
             "coordinates ({hold}), lighter ones are left out with a note. In a sweep or the "
             "API: the file, or a list of [marker, weight] pairs.")
    hold: tuple[str, ...] = _option(
        (), names=True, metavar="NAME=VALUE",
        help="Hold coordinates of an imported OpenSim model fixed during the solve "
             "(comma-separated NAME=VALUE, degrees for a rotation and metres for a "
             "translation, or NAME=default for the model's default value), as an IK "
             "coordinate task of dominant weight does; {tasks} with such tasks, or an IK setup, "
             "gives them.")
    # --- perturbation ----------------------------------------------------------------------
    perturb_mm: float = _option(
        0.0, flag="perturb", unit="mm", low=0.0, high=1000.0, sweep="level",
        help="Soft-tissue-artefact level: the largest deviation per axis (0: none).")
    perturb_markers: tuple[str, ...] = _option(
        (), names=True, metavar="NAMES",
        help="Model marker names to perturb [default: all tracked].")
    seed: int = _option(0, low=0, high=SEED_MAX,
                        help="Seed of the perturbation (same seed, same artefact).")
    # --- filtering -------------------------------------------------------------------------
    filter_cutoff: float | None = _option(
        None, unit="Hz", low=0.0, low_open=True, high=1e5, metavar="HZ",
        help="Low-pass the angles (zero-lag Butterworth, forward and backward) before they "
             "drive the classical model: the AD baseline's drivers, and the solved angles "
             "converted for inverse dynamics. Off by default; 6 Hz is the gait standard. An "
             "imported OpenSim model's coordinates are low-passed as OpenSim's ID tool does "
             "(third order, the rows padded by half their number; {filter_order} unused).")
    filter_order: int = _option(2, low=1, high=8,
                                help="Order of that Butterworth filter (each pass).")
    # --- the lab ---------------------------------------------------------------------------
    vertical: str = _option(
        "auto", choices=("auto", *AXES),
        help="The lab's up, for a model of floating bodies (a subject): auto finds it from the "
             "trial (force plates' normals signed by their force, the model's pose fitted to "
             "the markers; POINT:Y_SCREEN reported beside them) and turns the model's gravity "
             "onto it; an axis states it. A model tied to its ground keeps its own frame.")
    smooth: str = _option(
        "none", choices=("auto", "none"),
        help="auto: smooth the whole trial at once (mixed-coordinate methods): every frame's "
             "angles, a floating base's pose and their first two derivatives from all frames' "
             "markers, the topology kept at every frame, the smoothing strength estimated from "
             "the data (marker noise from the residuals, each coordinate's cutoff by maximum "
             "likelihood); the inverse dynamics is driven by the smoothed rates, force plates "
             "are smoothed alike, and every angle, rate and joint moment gets its standard "
             "deviation. Not with {method} ad (the paper's baseline) nor with "
             "{filter_cutoff} (the paper's Butterworth filter). none (the default): each "
             "frame's own solution, rates by central differences.")
    smooth_cutoff: float | None = _option(
        None, unit="Hz", low=0.0, low_open=True, high=1e4, metavar="HZ",
        help="With {smooth} auto: every coordinate's equivalent cutoff as given (the smoother's "
             "gain is 1/2 there), instead of estimated.")
    smooth_noise: float | None = _option(
        None, unit="mm", low=0.0, low_open=True, high=1000.0, metavar="MM",
        help="With {smooth} auto: the markers' noise (standard deviation per coordinate; the "
             "heaviest markers' where the model weighs its tracked points) as given, instead "
             "of estimated from the residuals.")
    # --- gait ----------------------------------------------------------------------------
    events: str = _option(
        "auto", choices=("auto", "c3d", "plates", "kinematic", "none"),
        help="Gait events (foot strike, foot off) for the cycles and spatiotemporal parameters "
             "of a lower-limb model: the C3D's EVENT section, force plates (normal force "
             "above 20 N, edges moved to the plate's noise level), or the markers (Zeni et al. "
             "2008); auto: the file's, else the plates' when both feet have a stride, else the "
             "markers'. Every source found is stored beside the one used.")
    # --- dynamics --------------------------------------------------------------------------
    dynamics: bool | None = _option(
        None, help="Inverse dynamics (joint moments in N·m, multipliers, energies) on the "
                   "classical model driven by the solved angles [default: on when every body "
                   "has mass and inertia].")
    reduce_residuals: bool = _option(
        False, help="Residual reduction (dynamic consistency) for a model with one floating "
                    "base and force plates: segment masses (within ±25 %) and centres of mass "
                    "(within ±10 % of each segment's size) fitted to the base's residual over "
                    "the frames where every ground contact is measured, then a small rigid "
                    "correction of the whole body's trajectory that trades the residual against "
                    "the markers' misfit; the run's dynamics are then the adjusted model's, the "
                    "first model's residual kept beside them (fccgrb_cli/dynamics/reduction.py).")
    loads: str | None = _option(
        None, metavar="LOADS.xml",
        help="An OpenSim ExternalLoads file (each ExternalForce's applied_to_body and its "
             "force, point and torque columns in the .mot/.sto it names) as the inverse "
             "dynamics' external loads, in place of the trial's force plates; the times of "
             "its data are the trial's clock (a TRC's Time column, a C3D's first frame).")
    plates: tuple[str, ...] = _option(
        (), flag="plate", names=True, metavar="N=BODY",
        help="Force plate N of a C3D trial acts on BODY, as an OpenSim ExternalLoads file "
             "names a body for each plate (repeatable or comma-separated: --plate 1=calcn_r "
             "--plate 2=calcn_l); replaces the model's loads.force_plates, and plates left "
             "out go to the model's contact bodies, if any, by proximity.")
    time_from: float | None = _option(
        None, flag="from", unit="s", low=-1e9, high=1e9, metavar="S",
        help="Analyse from this time on (s, on the trial's or coordinates file's own clock: a "
             "TRC's Time column, a C3D's first frame; OpenSim's time_range) [default: the "
             "first frame]. With --coordinates the whole file is still low-passed, as "
             "OpenSim's ID tool does.")
    time_to: float | None = _option(
        None, flag="to", unit="s", low=-1e9, high=1e9, metavar="S",
        help="Analyse up to this time (s, the same clock) [default: the last frame].")
    name: str | None = _option(
        None, help="Run name inside the results file [default: the method, then -truth, "
                   "-f<cutoff>Hz, -smooth[<cutoff>Hz|-n<mm>mm] and -P<mm> where they apply, "
                   "e.g. ad-f6Hz-P30, nrm-wls-smooth].")

    def __post_init__(self) -> None:
        for f in fields(self):
            _check(f.name, getattr(self, f.name), f.metadata)
        if self.time_from is not None and self.time_to is not None and \
                self.time_to < self.time_from:
            raise InputError(f"time_to: expected a time at or after --from {self.time_from:g} s, "
                             f"got {self.time_to:g}")
        if self.loads is not None and self.plates:
            raise InputError("plates: expected the trial's plates assigned or an OpenSim load "
                             "set (--loads) in their place, got both")
        if self.parallel and self.method not in PARALLEL_METHODS:
            raise InputError(f"parallel: expected only with a method that solves its frames in "
                             f"parallel ({', '.join(PARALLEL_METHODS)}); {self.method} solves "
                             "them in sequence and would ignore it")

    @property
    def perturb_level_m(self) -> float:
        return self.perturb_mm * 1e-3

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], where: str = "options") -> SolveOptions:
        """Options from a mapping keyed by field names or sweep keys (e.g. ``level`` for
        ``perturb_mm``); lists become tuples; an unknown key is an InputError naming it."""
        by_key = {f.metadata["sweep"] or f.name: f for f in fields(cls)}
        by_key |= {f.name: f for f in fields(cls)}
        out: dict[str, Any] = {}
        for key, value in values.items():
            if key not in by_key:
                raise InputError(f"{where}.{key}: expected one of {', '.join(sorted(by_key))}")
            f = by_key[key]
            out[f.name] = _coerce(f.name, value, f.metadata)
        _task_holds(values.get("tasks"), out)
        try:
            return cls(**out)
        except InputError as error:
            raise InputError(f"{where}.{error}") from None

    def to_json(self) -> str:
        """The options as JSON (the results file keeps them with each run)."""
        import json

        return json.dumps({f.name: getattr(self, f.name) for f in fields(self)})

    @classmethod
    def from_json(cls, text: str) -> SolveOptions:
        import json

        return cls.from_mapping(json.loads(text), "options")

    def with_(self, **changes: Any) -> SolveOptions:
        """A copy with some options changed (validated)."""
        return replace(self, **changes)


def _coerce(name: str, value: Any, meta: Mapping[str, Any]) -> Any:
    if name == "tasks":
        return _tasks(value)
    if name == "mapping" and isinstance(value, Mapping):
        return tuple((str(k), str(v)) for k, v in value.items())
    if name == "mapping" and isinstance(value, str):
        return _pairs((value,))
    if isinstance(value, list):
        if name == "mapping":
            return tuple(tuple(pair) for pair in value)
        return tuple(str(v) for v in value)
    if meta["names"] and isinstance(value, str):
        return tuple(part.strip() for part in value.split(",") if part.strip())
    return value


def _task_holds(file: Any, out: dict[str, Any]) -> None:
    """``--tasks FILE``'s coordinate tasks of dominant weight as ``hold`` items
    (``TaskSet.holds``), unless holds are given."""
    if isinstance(file, str) and file.strip() and not out.get("hold"):
        from fccgrb_cli.opensim.setups import read_task_set

        out["hold"] = read_task_set(file.strip()).holds()[0]


def _tasks(value: Any) -> tuple[tuple[str, float], ...]:
    """``--tasks``: an IK task set file read into (marker, weight) pairs, or the pairs."""
    if isinstance(value, str):
        if not value.strip():
            return ()
        from fccgrb_cli.opensim.setups import read_task_set

        return tuple(read_task_set(value.strip()).marker_weights().items())
    if isinstance(value, (list, tuple)) and all(
            isinstance(pair, (list, tuple)) and len(pair) == 2 and isinstance(pair[0], str)
            and in_range(pair[1], float, 0.0, True, 1e12) for pair in value):
        return tuple((name, float(weight)) for name, weight in value)
    raise InputError(f"tasks: expected an IK task set file or [marker, weight] pairs with "
                     f"weights above 0, got {shown(value)}")


def _kind(name: str) -> type:
    """The type a field holds, from its annotation (``int | None`` → int)."""
    annotation = next(f.type for f in fields(SolveOptions) if f.name == name)
    return {"bool": bool, "int": int, "float": float, "str": str,
            "tuple": tuple}[annotation.split("[")[0].split(" ")[0]]


def _check(name: str, value: Any, meta: Mapping[str, Any]) -> None:
    """A one-line InputError naming the option and what it expects."""
    default = next(f.default for f in fields(SolveOptions) if f.name == name)
    if value is None and default is None:
        return
    if meta["choices"]:
        if value not in meta["choices"]:
            raise InputError(f"{name}: expected one of {', '.join(meta['choices'])}, "
                             f"got {shown(value)}")
        return
    kind = _kind(name)
    if kind is tuple:
        if not isinstance(value, tuple):
            raise InputError(f"{name}: expected a list, got {shown(value)}")
        return
    if kind is bool:
        if not isinstance(value, bool):
            raise InputError(f"{name}: expected true or false, got {shown(value)}")
        return
    if kind is str:
        if not isinstance(value, str):
            raise InputError(f"{name}: expected a text, got {shown(value)}")
        if name == "name":
            check_name(value, name)
        return
    bounds = (meta["low"], meta["low_open"], meta["high"])
    if not in_range(value, kind, *bounds):
        expected = describe_range(kind, *bounds, meta["unit"])
        raise InputError(f"{name}: expected {expected}, got {shown(value)}")


def _help(meta: Mapping[str, Any], spell: Callable[[Field[Any]], str]) -> str:
    """A field's help with its references to other options ({name}) spelt for the reader."""
    return meta["help"].format(**{f.name: spell(f) for f in fields(SolveOptions)})


def _flag(f) -> str:
    return "--" + (f.metadata["flag"] or f.name).replace("_", "-")


def describe() -> str:
    """Every option with its default, unit and help: the docs of the API's ``solve``."""
    lines = []
    for f in fields(SolveOptions):
        meta = f.metadata
        unit = f" [{meta['unit']}]" if meta["unit"] else ""
        choices = f" One of: {', '.join(meta['choices'])}." if meta["choices"] else ""
        text = _help(meta, lambda g: g.name)
        lines.append(f"{f.name}{unit} (default {f.default!r}): {text}{choices}")
    return "\n".join(lines)


def click_options(command: Callable) -> Callable:
    """Decorate a click command with one CLI option per field (``--method``, ``--perturb``, …);
    the command receives them as keyword arguments named after the fields, which
    :func:`from_cli` turns into a SolveOptions."""
    import click

    from fccgrb_cli.core.params import Bounded

    for f in reversed(fields(SolveOptions)):
        meta = f.metadata
        if not meta["cli"]:
            continue
        unit = f" Unit: {meta['unit']}." if meta["unit"] else ""
        kwargs: dict[str, Any] = {"help": _help(meta, _flag) + unit, "metavar": meta["metavar"]}
        decls = [_flag(f), f.name]
        if meta["choices"]:
            kwargs |= {"type": click.Choice(list(meta["choices"])), "default": f.default,
                       "show_default": True}
        elif _kind(f.name) is bool and f.default is None:
            decls = [f"{_flag(f)}/--no-{_flag(f)[2:]}", f.name]
            kwargs["default"] = None
        elif _kind(f.name) is bool:
            kwargs |= {"is_flag": True, "default": False}
        elif f.name in REPEATABLE:
            kwargs |= {"multiple": True}
        elif _kind(f.name) in (tuple, str):
            kwargs["default"] = None
        else:
            kwargs |= {"type": Bounded(_kind(f.name), meta["low"], meta["low_open"],
                                       meta["high"], meta["unit"]),
                       "default": f.default, "show_default": f.default is not None}
        command = click.option(*decls, **kwargs)(command)
    return command


def from_cli(values: Mapping[str, Any]) -> SolveOptions:
    """The options from the keyword arguments :func:`click_options` gave a command."""
    out: dict[str, Any] = {}
    for f in fields(SolveOptions):
        if not f.metadata["cli"] or f.name not in values:
            continue
        value = values[f.name]
        if f.name == "mapping":
            value = _pairs(value)
        elif f.name in REPEATABLE:
            value = _coerce(f.name, ",".join(value or ()), f.metadata)
        elif isinstance(f.default, tuple):
            value = _coerce(f.name, value or "", f.metadata)
        out[f.name] = value
    _task_holds(values.get("tasks"), out)
    try:
        return SolveOptions(**out)
    except InputError as error:  # named as the command line spells it: --name, not name
        field_name, _, rest = str(error).partition(":")
        flags = {f.name: _flag(f) for f in fields(SolveOptions)}
        raise InputError(f"{flags.get(field_name, field_name)}:{rest}") from None


def _pairs(items: tuple[str, ...]) -> tuple[tuple[str, str], ...]:
    """``--map`` values: NAME=LABEL pairs (repeatable, comma-separated) or a YAML file of them;
    a name given twice is an error (which label would it follow?)."""
    out: list[tuple[str, str]] = []
    for item in items:
        if item.strip().lower().endswith((".yaml", ".yml")) and "=" not in item:
            out += label_map_file(item.strip())
            continue
        for pair in (p.strip() for p in _outside_parentheses(item) if p.strip()):
            if pair.count("=") != 1 or not all(p.strip() for p in pair.split("=")):
                raise InputError(f"--map: expected MODEL_NAME=FILE_LABEL or a FILE.yaml, got "
                                 f"{pair!r}")
            name, label = (p.strip() for p in pair.split("="))
            out.append((name, label))
    names = [name for name, _ in out]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise InputError(f"--map: expected each name mapped once, got {', '.join(twice)} more "
                         "than once")
    return tuple(out)


def _outside_parentheses(text: str) -> list[str]:
    """``text`` split at the commas outside parentheses (a virtual marker's own commas,
    ``SACR=mid(LPSI,RPSI)``, stay)."""
    parts, depth, start = [], 0, 0
    for k, char in enumerate(text):
        depth += {"(": 1, ")": -1}.get(char, 0)
        if char == "," and depth == 0:
            parts.append(text[start:k])
            start = k + 1
    return [*parts, text[start:]]


MAP_MAX = 1 << 20  # bytes: a label map is a line per marker, a few hundred at most


def label_map_file(path: str) -> list[tuple[str, str]]:
    """A lab's naming written once: a YAML mapping ``model marker name: trial label``."""
    data = load_yaml(read_text(path, "label map", limit=MAP_MAX), path)
    if not isinstance(data, dict) or not data or not all(
            isinstance(k, str) and isinstance(v, str) and k and v for k, v in data.items()):
        raise InputError(f"{path}: expected a mapping of model marker names to trial labels "
                         "(NAME: LABEL per line)")
    return list(data.items())


SWEEP_KEYS = tuple(f.metadata["sweep"] or f.name for f in fields(SolveOptions))


def _weighted(model: Model, options: SolveOptions) -> Model:
    """The model tracking the markers ``--tasks`` weighs, each point's weight that weight times
    ``--tracking-weight``."""
    weights = dict(options.tasks)
    keep = tuple(name for name in model.marker_labels if name in weights)
    if not keep:
        raise InputError(f"--tasks: expected marker tasks naming markers of {model.source} "
                         f"({', '.join(model.marker_labels)[:200]}), got none of them")
    model = model.with_tracked(keep)
    points = tuple(replace(tp, weight=options.tracking_weight * weights[tp.marker])
                   for tp in model.tracked_points)
    return replace(model, tracked_points=points)


def _held(model: Model, items: tuple[str, ...]) -> Model:
    """The model with each ``--hold`` coordinate fixed (a coupling to a constant)."""
    from fccgrb_cli.model.elements import in_metres
    from fccgrb_cli.model.observed import Fixed
    from fccgrb_cli.model.spatial import Coupling, JointCoordinate

    if not model.moving_joints:
        raise InputError(f"--hold: {model.source}: expected an imported OpenSim model (a YAML "
                         "model's angles are held by its drivers)")
    coordinates = {c.name: c for c in model.angles}
    held = []
    for item in items:
        name, _, text = item.partition("=")
        coordinate = coordinates.get(name.strip())
        if coordinate is None:
            raise InputError(f"--hold {item}: expected a coordinate of {model.source} "
                             f"({', '.join(coordinates)[:200]})")
        text = text.strip()
        if text == "default":
            assert isinstance(coordinate, JointCoordinate)  # an imported model's are all
            value = coordinate.default
        else:
            try:
                value = float(text)
            except ValueError:
                raise InputError(f"--hold {item}: expected NAME=VALUE (degrees or metres) or "
                                 "NAME=default") from None
            if not np.isfinite(value):
                raise InputError(f"--hold {item}: expected a finite value")
            value = value if in_metres(coordinate) else float(np.radians(value))
        held.append(Coupling(f"{coordinate.name} held", coordinate.name, None, Fixed(value)))
    taken = {c.dependent for c in model.couplings}
    twice = [c.dependent for c in held if c.dependent in taken]
    if twice:
        raise InputError(f"--hold: {', '.join(twice)}: expected a coordinate the model does "
                         "not already lock or couple")
    return replace(model, couplings=model.couplings + tuple(held))


def prepared(model: Model, options: SolveOptions) -> Model:
    """The model as the options ask: every body in one form, only some markers tracked (and
    weighted, ``--tasks``), the force plates on the bodies ``--plate`` names."""
    if options.form != "model":
        assert options.form in ("full", "reduced")  # the option's choices, checked
        model = model.with_form("full" if options.form == "full" else "reduced")
    if options.track:
        unknown = sorted(set(options.track) - set(model.marker_labels))
        if unknown:
            raise InputError(f"--track: expected marker names of {model.source} "
                             f"({', '.join(model.marker_labels)}), got {', '.join(unknown)}")
        model = model.with_tracked(options.track)
    if options.tasks:
        model = _weighted(model, options)
    if options.hold:
        model = _held(model, options.hold)
    if options.plates:
        from fccgrb_cli.opensim.plates import assigned

        model = assigned(model, options.plates)
    return model
