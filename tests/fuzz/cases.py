"""The generated cases, one generator per class of bad input in ``CLASSES``.

A case is a few setup actions on a copy of the fixtures (``fixtures.py``) and one or more
``fccgrb`` commands, each with what it must do: fail as bad input (``error``: exit 2, one line
naming one of ``names``), succeed (``ok``, writing only ``outputs``), or either (``any``: a
random patch that may leave the file valid). ``generate(seed)`` draws the random parts (bytes
flipped, cut offsets, which values) from ``seed``; the fixed parts are the same for every seed.
"""

from __future__ import annotations

import os
import random
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

from . import c3dpatch

CLASSES = (
    "input overwritten",
    "written outside the folder asked",
    "run names as HDF5 paths",
    "NaN / inf / huge / negative numbers",
    "header values",
    "YAML and files",
    "results files",
    "half-written output",
    "own output unreadable",
    "silently accepted nonsense",
    "C3D bytes",
    "OpenSim XML",
    "OpenSim storage",
    "OpenSim coordinates and setups",
    "every rate",
    "empty sections and grid value types",
    "outputs that exist and are not ours",
)

Action = Callable[[Path], None]
SOLVE = ("solve", "model.yaml", "t.c3d")


@dataclass(frozen=True)
class Step:
    argv: tuple[str, ...]
    expect: str = "error"          # "error", "ok" or "any"
    names: tuple[str, ...] = ()    # an error line must hold one of these
    outputs: tuple[str, ...] = ()  # what a successful step may write (relative to work/)
    timeout: float = 60.0


@dataclass(frozen=True)
class Case:
    klass: str
    name: str
    steps: tuple[Step, ...]
    actions: tuple[Action, ...] = field(default=(), compare=False)

    def setup(self, work: Path) -> None:
        for action in self.actions:
            action(work)


def bad(klass: str, name: str, argv: tuple[str, ...], names: tuple[str, ...],
        *actions: Action, timeout: float = 60.0) -> Case:
    """A one-command case that must fail as bad input."""
    return Case(klass, name, (Step(argv, "error", names, timeout=timeout),), actions)


# --- setup actions ------------------------------------------------------------------------

def write(name: str, content: bytes | str) -> Action:
    def act(work: Path) -> None:
        data = content.encode("utf-8") if isinstance(content, str) else content
        (work / name).parent.mkdir(parents=True, exist_ok=True)
        sandbox = str(work.parent.parent).encode()
        (work / name).write_bytes(data.replace(b"{sandbox}", sandbox))
    return act


def edit(source: str, target: str, change: Callable[[bytes], bytes]) -> Action:
    def act(work: Path) -> None:
        (work / target).write_bytes(change((work / source).read_bytes()))
    return act


def text_edit(source: str, target: str, change: Callable[[str], str]) -> Action:
    return edit(source, target, lambda b: change(b.decode("utf-8")).encode("utf-8"))


def fifo(name: str) -> Action:
    return lambda work: os.mkfifo(work / name)


def symlink(name: str, target: str) -> Action:
    return lambda work: os.symlink(target, work / name)


def hardlink(name: str, target: str) -> Action:
    return lambda work: os.link(work / target, work / name)


def mkdir(name: str) -> Action:
    return lambda work: (work / name).mkdir(parents=True)


def h5(name: str, change: Callable) -> Action:
    """Change an HDF5 file in place (h5py, in the test process)."""
    def act(work: Path) -> None:
        import h5py

        with h5py.File(work / name, "a") as f:
            change(f)
    return act


# --- texts --------------------------------------------------------------------------------

def bomb(levels: int = 9) -> str:
    """A billion-laughs document: 9 aliases of 9 aliases … (9^levels strings when expanded)."""
    lines = ["a0: &a0 [x, x, x, x, x, x, x, x, x]"]
    for k in range(1, levels):
        lines.append(f"a{k}: &a{k} [" + ", ".join([f"*a{k - 1}"] * 9) + "]")
    return "\n".join(lines) + "\n"


def deep(depth: int = 20000) -> str:
    return "[" * depth + "]" * depth


def model_with(key_line: str) -> Callable[[str], str]:
    """The model text with a top-level line replaced or added."""
    def change(text: str) -> str:
        key = key_line.split(":")[0]
        lines = [line for line in text.splitlines() if not line.startswith(key + ":")]
        return "\n".join([*lines, key_line]) + "\n"
    return change


def sweep_text(cells: str = "  - {method: nrm-ls}", head: str = "name: sw",
               trial: str = "trial: {file: t.c3d}") -> str:
    return f"{head}\nmodel: model.yaml\n{trial}\ncells:\n{cells}\n"


# --- 1. input overwritten -------------------------------------------------------------------

def overwritten() -> Iterator[Case]:
    k = "input overwritten"
    names = ("input", "other than")
    for spelling in ("model.yaml", "./model.yaml", "link.yaml", "hard.yaml"):
        acts = (symlink("link.yaml", "model.yaml"), hardlink("hard.yaml", "model.yaml"))
        yield bad(k, f"synth-over-model-{spelling}", ("synth", "model.yaml", "-o", spelling),
                  names, *acts)
    yield bad(k, "synth-truth-is-the-model", ("synth", "model.yaml", "-o", "q.c3d"), names,
              symlink("q.truth.h5", "model.yaml"))
    yield bad(k, "synth-over-model-in-folder", ("synth", "sub/m.yaml", "-o", "sub/../sub/m.yaml"),
              names, mkdir("sub"), edit("model.yaml", "sub/m.yaml", lambda b: b))
    for target in ("ll.yaml", "walk.trc", "./ll.yaml", "lk.yaml"):
        yield bad(k, f"calibrate-over-{target}", ("calibrate", "ll.yaml", "walk.trc", "-o",
                                                  target), names, symlink("lk.yaml", "ll.yaml"))
    yield bad(k, "calibrate-over-map", ("calibrate", "ll.yaml", "walk.trc", "--map", "m.yaml",
                                        "-o", "m.yaml"), names, write("m.yaml", "{}\n"))
    for target in ("model.yaml", "t.c3d", "t.truth.h5", "./t.c3d", "lt.c3d", "map.yaml"):
        yield bad(k, f"solve-over-{target}", (*SOLVE, "--map", "map.yaml", "-o", target), names,
                  symlink("lt.c3d", "t.c3d"))
    yield bad(k, "solve-over-second-trial", ("solve", "model.yaml", "t.c3d", "u.c3d", "-o",
                                             "u.c3d"), names)
    for target in ("t.c3d", "./t.c3d", "lt.c3d", "ht.c3d"):
        yield bad(k, f"perturb-over-{target}", ("perturb", "t.c3d", target, "--level", "1"),
                  names, symlink("lt.c3d", "t.c3d"), hardlink("ht.c3d", "t.c3d"))
    yield bad(k, "perturb-trc-over-itself", ("perturb", "t.trc", "t.trc", "--level", "1"), names)
    for target in ("sweep.yaml", "model.yaml", "t.c3d", "./sweep.yaml"):
        yield bad(k, f"sweep-over-{target}", ("sweep", "sweep.yaml", "-o", target), names)
    yield bad(k, "sweep-default-output-is-config", ("sweep", "sw.h5"), names,
              write("sw.h5", sweep_text()))
    yield bad(k, "plot-over-results", ("plot", "r.png", "-o", "r.png"), names,
              edit("r.h5", "r.png", lambda b: b))
    yield bad(k, "plot-over-normative", ("plot", "r.h5", "--kind", "cycles", "--normative",
                                         "n.png", "-o", "n.png"), names,
              edit("norm.csv", "n.png", lambda b: b))
    for target in ("r.h5", "./r.h5", "t.c3d", "lr.h5"):
        yield bad(k, f"export-over-{target}", ("export", "r.h5", "--format", "csv", "-o", target),
                  names, symlink("lr.h5", "r.h5"))
    yield bad(k, "export-c3d-over-trial", ("export", "r.h5", "--format", "c3d", "-o", "t.c3d"),
              names)
    for target in ("study.yaml", "ll.yaml", "walk.trc", "./study.yaml"):
        yield bad(k, f"batch-over-{target}", ("batch", "study.yaml", "-o", target), names)


# --- 2. written outside the folder asked ----------------------------------------------------

def outside() -> Iterator[Case]:
    k = "written outside the folder asked"
    for name in ("../x", "../../x", "{sandbox}/x", "a/b", "{sandbox}/"):
        yield bad(k, f"sweep-name-{name.replace('/', '_')}", ("sweep", "s.yaml"),
                  ("s.yaml", "name"), write("s.yaml", sweep_text(head=f"name: '{name}'")))
        yield bad(k, f"study-name-{name.replace('/', '_')}", ("batch", "b.yaml"),
                  ("b.yaml", "name"), text_edit("study.yaml", "b.yaml",
                                                lambda t, n=name: t.replace("name: st",
                                                                            f"name: '{n}'")))
    for argv in (("sweep", "sweep.yaml", "-o", "missing/dir/s.h5"),
                 (*SOLVE, "-o", "missing/r.h5"),
                 ("synth", "model.yaml", "-o", "missing/x.c3d"),
                 ("perturb", "t.c3d", "missing/x.c3d", "--level", "1"),
                 ("export", "r.h5", "--format", "csv", "-o", "missing/x.csv"),
                 ("plot", "r.h5", "-o", "missing/x.png"),
                 ("calibrate", "ll.yaml", "walk.trc", "-o", "missing/p.yaml"),
                 ("batch", "study.yaml", "-o", "missing/b.h5")):
        yield bad(k, f"{argv[0]}-into-missing-folder", argv, ("missing",))


# --- 3. run names as HDF5 paths -------------------------------------------------------------

def run_names() -> Iterator[Case]:
    k = "run names as HDF5 paths"
    for value in ("/reference", "/truth", "a/b", "../../x", ".", "..", "/", "", " ", "x/",
                  "runs/x", "a" * 300, "x\ty"):
        for output in ("r.h5", "n.h5"):
            label = value.replace("/", "_")[:12] or "empty"
            yield bad(k, f"solve-name-{label}-{output}", (*SOLVE, "--name", value, "-o", output),
                      ("--name", "name"))
    for value in ("/reference", "a/b", ".", ""):
        label = value.replace("/", "_") or "empty"
        yield bad(k, f"sweep-cell-name-{label}", ("sweep", "s.yaml"), ("name", "s.yaml"),
                  write("s.yaml", sweep_text(cells=f"  - {{method: nrm-ls, name: '{value}'}}")))


# --- 4. numbers -----------------------------------------------------------------------------

@dataclass(frozen=True)
class Numeric:
    prefix: tuple[str, ...]
    option: str
    kind: type
    low: float | None
    low_open: bool
    high: float | None
    extra: tuple[str, ...] = ()


NUMERIC = (
    Numeric(("synth", "model.yaml", "-o", "n.c3d"), "--duration", float, 0, True, None,
            ("1e7", "1e-9")),
    Numeric(("synth", "model.yaml", "-o", "n.c3d"), "--rate", float, 0, True, 1e5),
    Numeric(("synth", "model.yaml", "-o", "n.c3d"), "--tol", float, 0, True, 1),
    Numeric((*SOLVE, "-o", "n.h5"), "--tol", float, 0, True, 1),
    Numeric((*SOLVE, "-o", "n.h5"), "--max-iter", int, 1, False, 10000),
    Numeric((*SOLVE, "-o", "n.h5"), "--tracking-weight", float, 0, True, 1e6),
    Numeric((*SOLVE, "-o", "n.h5"), "--perturb", float, 0, False, 1000),
    Numeric((*SOLVE, "-o", "n.h5"), "--seed", int, 0, False, 2**32 - 1),
    Numeric((*SOLVE, "-o", "n.h5"), "--filter-cutoff", float, 0, True, None, ("60", "50")),
    Numeric((*SOLVE, "-o", "n.h5"), "--filter-order", int, 1, False, 8),
    Numeric((*SOLVE, "-o", "n.h5", "--method", "cno-sqp", "--parallel"), "--workers", int, 1,
            False, None, ("100000",)),
    Numeric(("perturb", "t.c3d", "p.c3d"), "--level", float, 0, False, 1000),
    Numeric(("perturb", "t.c3d", "p.c3d", "--level", "1"), "--seed", int, 0, False, 2**32 - 1),
    Numeric(("calibrate", "ll.yaml", "walk.trc", "-o", "p.yaml"), "--mass", float, 0, True, 500),
    Numeric(("calibrate", "ll.yaml", "walk.trc", "-o", "p.yaml"), "--knee-width", float, 0, True,
            500),
    Numeric(("calibrate", "ll.yaml", "walk.trc", "-o", "p.yaml"), "--ankle-width", float, 0,
            True, 500),
    Numeric(("calibrate", "ll.yaml", "walk.trc", "-o", "p.yaml"), "--marker-diameter", float, 0,
            True, 500),
    Numeric(("sweep", "sweep.yaml", "-o", "s.h5"), "--workers", int, 1, False, None,
            ("100000",)),
    Numeric(("batch", "study.yaml", "-o", "b.h5"), "--workers", int, 1, False, None,
            ("100000",)),
)


def invalid(n: Numeric) -> list[str]:
    """Values the option must refuse."""
    values = ["nan", "NaN", "inf", "-inf", "1e999", "abc", ""]
    if n.kind is int:
        values = ["nan", "1.5", "abc", "", "1e3", "99999999999999999999999"]
    if n.low is not None:
        values.append(str(n.low - 1 if n.kind is int else -1.0))
        if n.low_open:
            values.append("0")
    if n.high is not None:
        values.append(str(int(n.high) + 1) if n.kind is int else "1e300")
    return values + list(n.extra)


def numbers() -> Iterator[Case]:
    k = "NaN / inf / huge / negative numbers"
    for n in NUMERIC:
        for value in invalid(n):
            label = f"{n.prefix[0]}{n.option}={value or 'empty'}"[:60]
            # a pool of 100,000 workers forks until killed: short timeouts keep the machine
            yield bad(k, label, (*n.prefix, n.option, value), (n.option,),
                      timeout=15 if n.option == "--workers" else 120)
    cells = {"tol": [".nan", ".inf", "-1", "abc", "2"], "level": [".nan", "-1", "1e300", ".inf"],
             "seed": ["-1", "1.5", ".nan", "4294967296"], "max_iter": ["0", "-3", "1.5"],
             "tracking_weight": [".inf", "0", "-1"], "filter_cutoff": ["-1", ".nan", "0"],
             "filter_order": ["0", "9"]}
    for key, values in cells.items():
        for value in values:
            yield bad(k, f"sweep-cell-{key}={value}", ("sweep", "s.yaml"), (key, "s.yaml"),
                      write("s.yaml", sweep_text(cells=f"  - {{method: nrm-ls, {key}: {value}}}")))
    for value in ("0", "-1", "100000"):
        yield bad(k, f"sweep-cell-workers={value}", ("sweep", "s.yaml"), ("workers", "s.yaml"),
                  write("s.yaml", sweep_text(
                      cells=f"  - {{method: cno-sqp, parallel: true, workers: {value}}}")),
                  timeout=15)
    for key, value in (("duration", ".nan"), ("duration", "-1"), ("duration", "1e9"),
                       ("rate", ".inf"), ("rate", "0"), ("rate", "1e300")):
        trial = "trial: {synth: {duration: 0.5, rate: 100}}".replace(
            f"{key}: {'0.5' if key == 'duration' else '100'}", f"{key}: {value}")
        yield bad(k, f"sweep-synth-{key}={value}", ("sweep", "s.yaml"), (key, "s.yaml"),
                  write("s.yaml", sweep_text(trial=trial)))
    yield bad(k, "sweep-top-seed=-1", ("sweep", "s.yaml"), ("seed", "s.yaml"),
              write("s.yaml", sweep_text(head="name: sw\nseed: -1")))
    for path, value in (("frequency", "1e300"), ("frequency", ".nan"), ("amplitude", "1e308"),
                        ("mean", ".inf"), ("phase", "1e308")):
        def change(text: str, path=path, value=value) -> str:
            return text.replace(f"{path}: ", f"{path}: {value} #", 1)
        yield bad(k, f"model-{path}={value}", ("synth", "m.yaml", "-o", "n.c3d"),
                  ("m.yaml",), text_edit("model.yaml", "m.yaml", change))
    for value in ("1e308", "-1e308", "1e200"):
        yield Case(k, f"model-mass={value}", (Step(("check", "m.yaml"), "error", ("m.yaml",)),),
                   (text_edit("model.yaml", "m.yaml",
                              lambda t, v=value: t.replace("mass: 2.0", f"mass: {v}")),))


# --- 5. header values -----------------------------------------------------------------------

def c3d_case(name: str, change: Callable[[bytes], bytes], expect: str = "error",
             names: tuple[str, ...] = ("x.c3d",)) -> Case:
    return Case("header values", name, (Step(("solve", "model.yaml", "x.c3d", "-o", "x.h5"),
                                             expect, names, ("x.h5",)),),
                (edit("t.c3d", "x.c3d", change),))


def header_values() -> Iterator[Case]:
    p = c3dpatch
    for value in (float("inf"), float("-inf"), float("nan"), 0.0, -100.0, -3e38):
        yield c3d_case(f"c3d-POINT:RATE={value}",
                       lambda b, v=value: p.set_header(p.set_parameter(b, "POINT:RATE", v),
                                                       "rate", v))
        yield c3d_case(f"c3d-param-only-POINT:RATE={value}",
                       lambda b, v=value: p.set_parameter(b, "POINT:RATE", v))
    for value in (float("nan"), float("inf"), -5.0):
        yield c3d_case(f"c3d-ANALOG:RATE={value}",
                       lambda b, v=value: p.set_parameter(b, "ANALOG:RATE", v))
    for value in (float("nan"), float("inf"), 0.0):
        yield c3d_case(f"c3d-POINT:SCALE={value}",
                       lambda b, v=value: p.set_header(p.set_parameter(b, "POINT:SCALE", v),
                                                       "scale", v))
    for value in (0, -1, 1000, 10):
        yield c3d_case(f"c3d-POINT:USED={value}",
                       lambda b, v=value: p.set_header(p.set_parameter(b, "POINT:USED", v),
                                                       "points", v & 0xFFFF))
    for value in (1, 10, -2, 49):
        yield c3d_case(f"c3d-POINT:FRAMES={value}",
                       lambda b, v=value: p.set_header(p.set_parameter(b, "POINT:FRAMES", v),
                                                       "last_frame", v & 0xFFFF))
    for field_name, value in (("first_frame", 60), ("first_frame", 0), ("last_frame", 0),
                              ("data_block", 0), ("data_block", 1), ("data_block", 60000)):
        yield c3d_case(f"c3d-header-{field_name}={value}",
                       lambda b, f=field_name, v=value: p.set_header(b, f, v), "any")
    for units in ("furlong", "  ", "km"):
        yield c3d_case(f"c3d-POINT:UNITS={units.strip() or 'blank'}",
                       lambda b, u=units: p.set_parameter(b, "POINT:UNITS", u.ljust(2)),
                       names=("x.c3d", "POINT:UNITS"))
    for value in (float("inf"), float("-inf")):
        def coordinate(b: bytes, v=value) -> bytes:
            out = bytearray(b)
            struct.pack_into("<f", out, p.data_offset(b) + 16 * 9 * 7 + 4, v)  # frame 7, y of P1
            return bytes(out)
        yield c3d_case(f"c3d-coordinate={value}", coordinate)
    # TRC headers: line 3 holds DataRate CameraRate NumFrames NumMarkers Units ...
    columns = {"DataRate": 0, "NumFrames": 2, "NumMarkers": 3, "Units": 4}
    values = {"DataRate": ["0", "-100", "nan", "inf", "abc", "", "1e999"],
              "NumFrames": ["10", "49", "51", "-1", "abc", "1e3", "0"],
              "NumMarkers": ["0", "-1", "10", "abc", "8"],
              "Units": ["furlong", "", "km"]}
    for key, options in values.items():
        for value in options:
            def change(text: str, key=key, value=value) -> str:
                lines = text.split("\n")
                cells = lines[2].split("\t")
                cells[columns[key]] = value
                lines[2] = "\t".join(cells)
                return "\n".join(lines)
            yield Case("header values", f"trc-{key}={value or 'empty'}",
                       (Step(("solve", "model.yaml", "x.trc", "-o", "x.h5"), "error",
                             ("x.trc",)),), (text_edit("t.trc", "x.trc", change),))
    for value in ("inf", "-inf", "1e999"):
        yield Case("header values", f"trc-coordinate={value}",
                   (Step(("solve", "model.yaml", "x.trc", "-o", "x.h5"), "error", ("x.trc",)),),
                   (text_edit("t.trc", "x.trc", lambda t, v=value: _trc_value(t, 9, 4, v)),))


def _trc_value(text: str, row: int, column: int, value: str) -> str:
    lines = text.split("\n")
    cells = lines[5 + row].split("\t")
    cells[column] = value
    lines[5 + row] = "\t".join(cells)
    return "\n".join(lines)


# --- 6. YAML and files ----------------------------------------------------------------------

READERS = {  # an input file of each kind: the command, and where the file goes
    "model": (("check", "{f}"), "m.yaml"),
    "synth-model": (("synth", "{f}", "-o", "n.c3d"), "m.yaml"),
    "trial-c3d": (("solve", "model.yaml", "{f}", "-o", "n.h5"), "x.c3d"),
    "trial-trc": (("solve", "model.yaml", "{f}", "-o", "n.h5"), "x.trc"),
    "sweep": (("sweep", "{f}", "-o", "n.h5"), "s.yaml"),
    "map": (("solve", "model.yaml", "t.c3d", "--map", "{f}", "-o", "n.h5"), "m.yaml"),
    "calibrate-map": (("calibrate", "ll.yaml", "walk.trc", "--map", "{f}", "-o", "p.yaml"),
                      "m.yaml"),
    "normative": (("plot", "r.h5", "--kind", "cycles", "--normative", "{f}", "-o", "n.png"),
                  "n.csv"),
    "results": (("report", "{f}"), "x.h5"),
    "export-results": (("export", "{f}", "--format", "csv", "-o", "n.csv"), "x.h5"),
    "template": (("calibrate", "{f}", "walk.trc", "-o", "p.yaml"), "m.yaml"),
    "study": (("batch", "{f}", "-o", "n.h5"), "s.yaml"),
}
YAML_READERS = ("model", "synth-model", "sweep", "map", "calibrate-map", "template", "study")


def reader_case(kind: str, label: str, *actions_for: Callable[[str], Action],
                expect: str = "error", timeout: float = 60.0) -> Case:
    argv, name = READERS[kind]
    return Case("YAML and files", f"{kind}-{label}",
                (Step(tuple(a.replace("{f}", name) for a in argv), expect, (name,),
                      timeout=timeout),),
                tuple(make(name) for make in actions_for))


def yaml_files() -> Iterator[Case]:
    for kind in YAML_READERS:
        yield reader_case(kind, "alias-bomb", lambda n: write(n, bomb()), timeout=30)
        place = "name" if kind in ("model", "synth-model", "template") else "x"
        yield reader_case(kind, "alias-bomb-in-a-value",
                          lambda n, p=place: write(n, bomb() + f"{p}: *a8\n"), timeout=30)
        yield reader_case(kind, "deep-nesting", lambda n: write(n, f"x: {deep()}\n"), timeout=30)
        yield reader_case(kind, "deep-mapping",
                          lambda n: write(n, "x: " + "{a: " * 5000 + "1" + "}" * 5000 + "\n"),
                          timeout=30)
        yield reader_case(kind, "python-tag",
                          lambda n: write(n, "x: !!python/object/apply:os.system ['touch pwned']"
                                             "\n"))
        yield reader_case(kind, "not-utf8", lambda n: write(n, b"name: caf\xe9\n\xff\xfe\n"))
        yield reader_case(kind, "binary", lambda n: write(n, bytes(range(256)) * 8))
        yield reader_case(kind, "a-list", lambda n: write(n, "- a\n- b\n"))
        yield reader_case(kind, "empty", lambda n: write(n, b""))
        yield reader_case(kind, "huge", lambda n: write(n, b"# x\n" * (5 << 20)), timeout=60)
    for kind in READERS:
        yield reader_case(kind, "fifo", fifo, timeout=30)
        yield reader_case(kind, "dev-zero", lambda n: symlink(n, "/dev/zero"), timeout=30)
        yield reader_case(kind, "dev-null", lambda n: symlink(n, "/dev/null"))
        yield reader_case(kind, "a-folder", mkdir)
        yield reader_case(kind, "dangling-link", lambda n: symlink(n, "nowhere"))
    for kind in ("trial-trc", "normative"):
        yield reader_case(kind, "not-utf8", lambda n: write(n, b"\xff\xfe" + b"caf\xe9\n" * 8))
    yield reader_case("model", "frequency-1e300", lambda n: text_edit(
        "model.yaml", n, lambda t: t.replace("frequency: ", "frequency: 1e300 #", 1)))


# --- 7. results files -----------------------------------------------------------------------

def _empty_run(f) -> None:
    del f["runs"][next(iter(f["runs"]))]
    f["runs"].create_group("x")


def _runs_dataset(f) -> None:
    del f["runs"]
    f["runs"] = [1, 2, 3]


def _format_1(f) -> None:
    del f.attrs["format_version"]


def _format_3(f) -> None:
    f.attrs["format_version"] = 3


def _no_theta(f) -> None:
    run = f["runs"][next(iter(f["runs"]))]
    del run["theta"]


def _flat_theta(f) -> None:
    run = f["runs"][next(iter(f["runs"]))]
    names = run["theta"].attrs["names"]
    del run["theta"]
    run["theta"] = [1.0, 2.0]
    run["theta"].attrs["names"] = names


def _no_runs(f) -> None:
    del f["runs"]


def _labels_int(f) -> None:
    run = f["runs"][next(iter(f["runs"]))]
    run.attrs["labels"] = 7


def _time_strings(f) -> None:
    run = f["runs"][next(iter(f["runs"]))]
    del run["time"]
    run["time"] = ["a", "b"]


DAMAGES = {"empty-run": _empty_run, "runs-dataset": _runs_dataset, "format-1": _format_1,
           "format-3": _format_3, "no-theta": _no_theta, "flat-theta": _flat_theta,
           "no-runs": _no_runs, "labels-int": _labels_int, "time-strings": _time_strings}
CONSUMERS = {
    "report": ("report", "x.h5"),
    "export": ("export", "x.h5", "--format", "csv", "-o", "n.csv"),
    "export-mot": ("export", "x.h5", "--format", "mot", "-o", "n.mot"),
    "plot": ("plot", "x.h5", "-o", "n.png"),
    "plot-angle": ("plot", "x.h5", "--kind", "angle", "-o", "n.png"),
    "solve-into": (*SOLVE, "-o", "x.h5"),
}


def results_files() -> Iterator[Case]:
    k = "results files"
    for damage, change in DAMAGES.items():
        for consumer, argv in CONSUMERS.items():
            yield Case(k, f"{consumer}-{damage}", (Step(argv, "error", ("x.h5",)),),
                       (edit("r.h5", "x.h5", lambda b: b), h5("x.h5", change)))
    for consumer, argv in CONSUMERS.items():
        yield Case(k, f"{consumer}-cut-in-half", (Step(argv, "error", ("x.h5",)),),
                   (edit("r.h5", "x.h5", lambda b: b[:len(b) // 2]),))
        yield Case(k, f"{consumer}-garbage", (Step(argv, "error", ("x.h5",)),),
                   (write("x.h5", b"\x89HDF\r\n\x1a\n" + b"\0" * 600),))


# --- 8. half-written output -----------------------------------------------------------------

def _blank_markers(text: str) -> str:
    """Every coordinate of markers P4..P9 blank: no frame can be solved."""
    lines = text.split("\n")
    for k in range(5, len(lines)):
        cells = lines[k].split("\t")
        if len(cells) >= 2 + 27:
            cells[2 + 9:2 + 27] = [""] * 18
            lines[k] = "\t".join(cells)
    return "\n".join(lines)


def half_written() -> Iterator[Case]:
    k = "half-written output"
    bad_trial = write("bad.c3d", b"garbage" * 100)
    for output in ("n.h5", "r.h5"):
        yield bad(k, f"solve-good-then-bad-into-{output}",
                  ("solve", "model.yaml", "t.c3d", "bad.c3d", "-o", output), ("bad.c3d",),
                  bad_trial)
        yield bad(k, f"solve-good-then-unlabelled-into-{output}",
                  ("solve", "model.yaml", "t.c3d", "v.c3d", "-o", output), ("v.c3d", "P1"),
                  edit("t.c3d", "v.c3d",
                       lambda b: c3dpatch.set_parameter(b, "POINT:LABELS", "Q1")))
    yield bad(k, "synth-truth-path-is-a-folder", ("synth", "model.yaml", "-o", "q.c3d"),
              ("q.truth.h5",), mkdir("q.truth.h5"))
    yield bad(k, "synth-output-is-a-folder", ("synth", "model.yaml", "-o", "q.c3d"),
              ("q.c3d",), mkdir("q.c3d"))
    yield bad(k, "synth-unknown-ending", ("synth", "model.yaml", "-o", "q.xyz"), ("q.xyz",))
    yield Case(k, "synth-trc-is-trc", (
        Step(("synth", "model.yaml", "-o", "s.trc", "--duration", "0.5"), "ok",
             outputs=("s.trc", "s.truth.h5")),
        Step(("solve", "model.yaml", "s.trc", "-o", "s.h5"), "ok", outputs=("s.h5",))))
    yield bad(k, "skip-unsolvable-nothing-solvable",
              ("solve", "model.yaml", "b.trc", "--skip-unsolvable", "-o", "n.h5"),
              ("b.trc", "frame"), text_edit("t.trc", "b.trc", _blank_markers))
    yield bad(k, "perturb-unknown-ending", ("perturb", "t.c3d", "p.xyz", "--level", "1"),
              ("p.xyz",))
    yield bad(k, "perturb-unknown-marker", ("perturb", "t.c3d", "p.c3d", "--level", "1",
                                            "--markers", "ZZ"), ("--markers",))
    yield bad(k, "perturb-truth-target-is-a-folder", ("perturb", "t.c3d", "p.c3d", "--level",
                                                      "1"), ("p.truth.h5",), mkdir("p.truth.h5"))
    yield bad(k, "export-into-a-folder", ("export", "r.h5", "--format", "csv", "-o", "d"),
              ("d",), mkdir("d"))
    yield bad(k, "export-c3d-without-trial", ("export", "r.h5", "--format", "c3d", "-o",
                                              "n.c3d", "--trial", "none.c3d"), ("none.c3d",))
    yield bad(k, "calibrate-into-a-folder", ("calibrate", "ll.yaml", "walk.trc", "-o", "d"),
              ("d",), mkdir("d"))
    yield bad(k, "sweep-with-a-bad-second-cell", ("sweep", "s.yaml", "-o", "n.h5"),
              ("s.yaml", "cells"),
              write("s.yaml", sweep_text(cells="  - {method: nrm-ls}\n  - {method: nrm-ls, "
                                               "tol: -1}")))
    yield bad(k, "sweep-bad-trial", ("sweep", "s.yaml", "-o", "n.h5"), ("bad.c3d",),
              bad_trial, write("s.yaml", sweep_text(trial="trial: {file: bad.c3d}")))
    yield bad(k, "plot-missing-marker", ("plot", "r.h5", "--marker", "ZZ", "-o", "n.png"),
              ("ZZ", "--marker"))


# --- 9. own output unreadable ---------------------------------------------------------------

def own_output(full: bool) -> Iterator[Case]:
    k = "own output unreadable"
    yield Case(k, "synth-70000-frames-read-back", (
        Step(("synth", "pend.yaml", "-o", "long.c3d", "--duration", "70", "--rate", "1000"),
             "ok", outputs=("long.c3d", "long.truth.h5"), timeout=300),
        Step(("perturb", "long.c3d", "long2.c3d", "--level", "0"), "ok",
             outputs=("long2.c3d", "long2.truth.h5"), timeout=300),
        Step(("perturb", "long2.c3d", "long3.trc", "--level", "0"), "ok",
             outputs=("long3.trc", "long3.truth.h5"), timeout=300)))
    if full:
        yield Case(k, "synth-1000-s-solves", (
            Step(("synth", "pend.yaml", "-o", "long.c3d", "--duration", "1000"), "ok",
                 outputs=("long.c3d", "long.truth.h5"), timeout=600),
            Step(("solve", "pend.yaml", "long.c3d", "-o", "long.h5"), "ok",
                 outputs=("long.h5",), timeout=900)))
    for units in ("m", "mm"):
        for ending in ("c3d", "trc"):
            yield Case(k, f"synth-{units}-{ending}-solves", (
                Step(("synth", "model.yaml", "-o", f"s.{ending}", "--duration", "0.3",
                      "--units", units), "ok", outputs=(f"s.{ending}", "s.truth.h5")),
                Step(("solve", "model.yaml", f"s.{ending}", "-o", "s.h5"), "ok",
                     outputs=("s.h5",))))
    for source, target in (("t.c3d", "p.trc"), ("t.trc", "p.c3d"), ("t.c3d", "p.c3d")):
        yield Case(k, f"perturb-{source}-{target}-solves", (
            Step(("perturb", source, target, "--level", "3"), "ok",
                 outputs=(target, "p.truth.h5")),
            Step(("solve", "model.yaml", target, "-o", "p.h5"), "ok", outputs=("p.h5",))))
    yield Case(k, "export-c3d-reads-back", (
        Step(("export", "r.h5", "--format", "c3d", "-o", "e.c3d"), "ok", outputs=("e.c3d",)),
        Step(("perturb", "e.c3d", "e2.trc", "--level", "0"), "ok", outputs=("e2.trc",))))
    yield Case(k, "batch-output-reports", (
        Step(("batch", "study.yaml", "-o", "b.h5"), "ok", outputs=("b.h5", "b.h5.cells"),
             timeout=300),
        Step(("report", "b.h5"), "ok")))
    yield Case(k, "calibrate-output-checks", (
        Step(("calibrate", "ll.yaml", "walk.trc", "-o", "p.yaml", "--mass", "70"), "ok",
             outputs=("p.yaml",)),
        Step(("check", "p.yaml"), "ok"),
        Step(("solve", "p.yaml", "walk.trc", "-o", "p.h5"), "ok", outputs=("p.h5",),
             timeout=180)))


# --- 10. silently accepted nonsense ---------------------------------------------------------

FREE_BODY = """  FREE:
    points: {F1: [0.1, 0, 0], F2: [0, 0.1, 0], F3: [0, 0, 0.1]}
    pose: {r: [0, 1, 0], u: [1, 0, 0], v: [0, 1, 0], w: [0, 0, 1]}
"""


def _with_free_body(tracked: tuple[str, ...]) -> Callable[[str], str]:
    def change(text: str) -> str:
        text = text.replace("\nbodies:\n", "\nbodies:\n" + FREE_BODY, 1)
        lines = "".join(f"    - {{marker: {m}, point: FREE.{m}}}\n" for m in tracked)
        return text.replace("  points:\n    - {marker: P1,", "  points:\n" + lines +
                            "    - {marker: P1,", 1)
    return change


def nonsense() -> Iterator[Case]:
    k = "silently accepted nonsense"
    for tracked in ((), ("F1",), ("F1", "F2")):
        yield bad(k, f"check-free-body-{len(tracked)}-markers", ("check", "m.yaml"),
                  ("FREE",), text_edit("model.yaml", "m.yaml", _with_free_body(tracked)))
    yield Case(k, "check-free-body-3-markers-is-valid",
               (Step(("check", "m.yaml"), "ok"),),
               (text_edit("model.yaml", "m.yaml", _with_free_body(("F1", "F2", "F3"))),))
    for mapping in ("P1=P2", "P1=P3", "P1=P2,P2=P2", "P1=P9", "P1=P1,P1=P2"):
        yield bad(k, f"solve-map-{mapping}", (*SOLVE, "--map", mapping, "-o", "n.h5"),
                  ("--map",))
    yield Case(k, "solve-map-swap-is-valid",
               (Step((*SOLVE, "--map", "P1=P2,P2=P1", "-o", "n.h5"), "ok", outputs=("n.h5",)),))
    yield bad(k, "calibrate-map-unknown-landmark", ("calibrate", "ll.yaml", "walk.trc", "--map",
                                                    "NOPE=R_IAS", "-o", "p.yaml"), ("NOPE",))
    yield bad(k, "calibrate-map-two-on-one", ("calibrate", "ll.yaml", "walk.trc", "--map",
                                              "LASI=RASI", "-o", "p.yaml"), ("--map",))
    for table in ("table9", "Table1", "", "../x"):
        yield bad(k, f"report-table-{table or 'empty'}", ("report", "r.h5", "--table", table),
                  ("--table",))
    yield bad(k, "sweep-table9", ("sweep", "s.yaml", "-o", "n.h5"), ("table", "s.yaml"),
              write("s.yaml", sweep_text(head="name: sw\ntable: table9")))
    for key, value in (("tol", ".nan"), ("dynamics", '"no"'), ("dynamics", "'false'"),
                       ("parallel", '"yes"'), ("skip_unsolvable", "1"), ("events", "always")):
        yield bad(k, f"sweep-{key}={value}", ("sweep", "s.yaml", "-o", "n.h5"),
                  (key, "s.yaml"),
                  write("s.yaml", sweep_text(cells=f"  - {{method: nrm-ls, {key}: {value}}}")))
    for frames in ("10:5", "0:100000", "5:5", "-1:4"):
        yield bad(k, f"calibrate-frames-{frames}", ("calibrate", "ll.yaml", "walk.trc",
                                                    "--frames", frames, "-o", "p.yaml"),
                  ("--frames",))
    yield bad(k, "export-unknown-run", ("export", "r.h5", "--format", "csv", "--run", "zz"),
              ("zz", "--run"))
    yield bad(k, "solve-perturb-markers-untracked", (*SOLVE, "--track", "P1,P2,P3,P4,P5,P6,P7,"
                                                     "P8", "--perturb-markers", "P9", "-o",
                                                     "n.h5"), ("P9",))


# --- 11. C3D bytes --------------------------------------------------------------------------

def c3d_bytes(rng: random.Random, count: int) -> Iterator[Case]:
    """Random single-byte changes of the header and parameter section, and random cuts."""
    k = "C3D bytes"
    size, data_start = 9216, 1536  # the fixture's layout (50 frames × 9 points × 16 bytes)
    data_end = data_start + 50 * 9 * 16
    for n in range(count):
        offset = rng.randrange(0, data_start)
        value = rng.randrange(256)
        yield Case(k, f"byte-{offset}={value}-{n}", (
            Step(("solve", "model.yaml", "x.c3d", "-o", "x.h5"), "any", ("x.c3d",), ("x.h5",)),),
            (edit("t.c3d", "x.c3d", lambda b, o=offset, v=value: b[:o] + bytes([v]) + b[o + 1:]),))
        cut = rng.randrange(1, size)
        yield Case(k, f"cut-at-{cut}-{n}", (
            Step(("solve", "model.yaml", "x.c3d", "-o", "x.h5"),
                 "error" if cut < data_end else "any", ("x.c3d",), ("x.h5",)),),
            (edit("t.c3d", "x.c3d", lambda b, c=cut: b[:c]),))


# --- random draws (another seed, other cases) ----------------------------------------------

NOT_FINITE = ("nan", "NaN", "+nan", "-nan", "inf", "+Inf", "-inf", "Infinity", "-Infinity",
              "1e309", "-1e309", " nan", "inf ")


def drawn(rng: random.Random, count: int) -> Iterator[Case]:
    """Cases whose values ``rng`` draws: spellings of NaN and infinity, values beyond a range,
    names with a path in them, C3D parameters and header words, YAML past its limits."""
    numbers_class, names_class = "NaN / inf / huge / negative numbers", "run names as HDF5 paths"
    for n in range(count):
        option = rng.choice(NUMERIC)
        if option.high is not None and rng.random() < 0.4:
            value = option.high * 10 ** rng.uniform(0.01, 6)
            text = str(int(value) + 1) if option.kind is int else f"{value:.6g}"
        elif option.low is not None and rng.random() < 0.5:
            text = str(-rng.randint(1, 10**6)) if option.kind is int else \
                f"{-10 ** rng.uniform(-6, 6):.6g}"
        else:
            text = rng.choice(NOT_FINITE)
        yield bad(numbers_class, f"drawn-{n}-{option.prefix[0]}{option.option}={text.strip()}",
                  (*option.prefix, option.option, text), (option.option,),
                  timeout=15 if option.option == "--workers" else 120)
        name = "".join(rng.choice(["a", "/", ".", "..", "-", " ", "\t", "é", "runs"])
                       for _ in range(rng.randint(1, 6)))
        if "/" not in name and name.strip(". ") and name == name.strip() and "\t" not in name:
            name = name[:2] + "/" + name[2:]
        yield bad(names_class, f"drawn-{n}-name", (*SOLVE, "--name", name, "-o", "n.h5"),
                  ("--name",))
        key, values = rng.choice([("POINT:RATE", (float("nan"), float("inf"), -rng.random())),
                                  ("POINT:SCALE", (float("nan"), 0.0)),
                                  ("ANALOG:RATE", (float("nan"), -rng.uniform(1, 1e4))),
                                  ("POINT:USED", (-rng.randint(1, 100),)),
                                  ("POINT:FRAMES", (rng.randint(1, 40),))])
        value = rng.choice(values)
        yield c3d_case(f"drawn-{n}-c3d-{key}={value:g}",
                       lambda b, k=key, v=value: c3dpatch.set_parameter(b, k, v))
        kind = rng.choice(YAML_READERS)
        width, levels = rng.randint(4, 12), rng.randint(8, 12)
        yield reader_case(kind, f"drawn-{n}-bomb-{width}x{levels}",
                          lambda f, w=width, lv=levels: write(f, _bomb(w, lv)), timeout=30)


def _bomb(width: int, levels: int) -> str:
    lines = [f"a0: &a0 [{', '.join(['x'] * width)}]"]
    for k in range(1, levels):
        lines.append(f"a{k}: &a{k} [" + ", ".join([f"*a{k - 1}"] * width) + "]")
    return "\n".join(lines) + f"\nname: *a{levels - 1}\n"


# --- 12. every rate --------------------------------------------------------------------------

RATES = ("1e30", "0", "-5", "nan", "inf", "200000")


def _trc_rate(value: str) -> Callable[[str], str]:
    """The TRC with DataRate (and CameraRate) ``value``."""
    def change(text: str) -> str:
        lines = text.split("\n")
        fields = lines[2].split("\t")
        fields[0] = fields[1] = value
        lines[2] = "\t".join(fields)
        return "\n".join(lines)
    return change


def _c3d_rate(source: str, target: str, key: str, value: float) -> Action:
    """A copy of a C3D with the rate parameter ``key`` (and the header's rate, for POINT:RATE)
    set to ``value``, byte by byte."""
    def change(data: bytes) -> bytes:
        data = c3dpatch.set_parameter(data, key, value)
        return c3dpatch.set_header(data, "rate", value) if key == "POINT:RATE" else data
    return edit(source, target, change)


def _trc_rows_removed(text: str) -> str:
    """Rows 10–12 of the TRC taken out and NumFrames made to agree: the clock skips."""
    lines = text.split("\n")
    fields = lines[2].split("\t")
    fields[2] = str(int(fields[2]) - 3)
    lines[2] = "\t".join(fields)
    return "\n".join(lines[:14] + lines[17:])


def rates() -> Iterator[Case]:
    k = "every rate"
    for value in RATES:
        yield bad(k, f"trc-datarate-{value}", ("solve", "model.yaml", "r.trc", "-o", "n.h5"),
                  ("r.trc", "DataRate"), text_edit("t.trc", "r.trc", _trc_rate(value)))
        yield bad(k, f"c3d-point-rate-{value}", ("solve", "model.yaml", "r.c3d", "-o", "n.h5"),
                  ("r.c3d", "POINT:RATE"),
                  _c3d_rate("t.c3d", "r.c3d", "POINT:RATE", float(value)))
        yield bad(k, f"calibrate-trc-datarate-{value}", ("calibrate", "ll.yaml", "w.trc", "-o",
                                                         "p.yaml"), ("w.trc", "DataRate"),
                  text_edit("walk.trc", "w.trc", _trc_rate(value)))
    yield bad(k, "c3d-analog-rate-huge", ("solve", "model.yaml", "r.c3d", "-o", "n.h5"),
              ("ANALOG:RATE",), _c3d_rate("t.c3d", "r.c3d", "ANALOG:RATE", 1e30))
    yield bad(k, "trc-rows-removed-numframes-fixed", ("solve", "model.yaml", "g.trc", "-o",
                                                      "n.h5"), ("g.trc", "Time"),
              text_edit("t.trc", "g.trc", _trc_rows_removed))


# --- 13. empty sections and grid value types --------------------------------------------------

def _tracking(section: str) -> Callable[[str], str]:
    def change(text: str) -> str:
        return text[:text.index("\ntracking:")] + ("\n" + section if section else "") + "\n"
    return change


def empty_and_types() -> Iterator[Case]:
    k = "empty sections and grid value types"
    methods = ("ad", "nrm-ls", "nrm-wls", "cno-sqp", "cno-ip", "mo-tc", "mo-ed")
    for label, section in (("empty-list", "tracking:\n  points: []"),
                           ("empty-mapping", "tracking: {}"), ("absent", "")):
        for method in methods:
            yield bad(k, f"solve-tracking-{label}-{method}", ("solve", "e.yaml", "t.c3d",
                                                              "--method", method, "-o", "n.h5"),
                      ("e.yaml", "tracking"), text_edit("model.yaml", "e.yaml",
                                                        _tracking(section)))
    for key, value in (("seed", "{a: 1}"), ("seed", "[[1, 2]]"), ("level", "-5"),
                       ("level", ".inf"), ("level", ".nan"), ("level", "{a: 1}"),
                       ("tol", "[[1.0e-9]]"), ("tol", "-1"), ("method", "{a: 1}"),
                       ("perturb_markers", "{a: 1}"), ("perturb_markers", "[[P1, {a: 1}]]"),
                       ("filter_cutoff", "[[6]]"), ("points", "{a: 1}")):
        label = "".join(c if c.isalnum() else "_" for c in value)
        yield bad(k, f"sweep-grid-{key}-{label}", ("sweep", "s.yaml", "-o", "n.h5"),
                  ("s.yaml",), write("s.yaml", sweep_text(
                      cells=f"  - {{method: nrm-ls, {key}: {value}}}" if key != "method" else
                      f"  - {{method: {value}}}")))
    for method in ("ad", "nrm-ls", "nrm-wls"):
        yield bad(k, f"solve-parallel-with-{method}", (*SOLVE, "--method", method,
                                                       "--parallel", "-o", "n.h5"),
                  ("--parallel",))
        yield bad(k, f"sweep-parallel-with-{method}", ("sweep", "s.yaml", "-o", "n.h5"),
                  ("s.yaml",), write("s.yaml", sweep_text(
                      cells=f"  - {{method: {method}, parallel: true}}")))


# --- 14. outputs that exist and are not ours ---------------------------------------------------

def _bomb_in(key: str) -> Callable[[str], str]:
    """The model with ``key``'s value a billion laughs (the anchors inside the value)."""
    row = "[" + ", ".join(["x"] * 30) + "]"
    value = f"[&b0 {row}" + "".join(
        f", &b{n} [" + ", ".join([f"*b{n - 1}"] * 30) + "]" for n in range(1, 6)) + "]"
    return model_with(f"{key}: {value}")


def not_ours() -> Iterator[Case]:
    k = "outputs that exist and are not ours"
    for target, content in (("notes.txt", "my notes\n"), ("other.h5", "not HDF5\n")):
        yield bad(k, f"sweep-over-{target}", ("sweep", "sweep.yaml", "-o", target), (target,),
                  write(target, content))
    yield bad(k, "sweep-over-solve-results", ("sweep", "sweep.yaml", "-o", "r.h5"), ("r.h5",))
    yield Case(k, "sweep-over-another-sweep", (
        Step(("sweep", "sweep.yaml", "-o", "o.h5"), "ok", outputs=("o.h5", "o.h5.cells")),
        Step(("sweep", "s2.yaml", "-o", "o.h5"), "error", ("o.h5",))),
        (write("s2.yaml", sweep_text(head="name: other")),))
    yield bad(k, "export-c3d-onto-another-trial", ("export", "r.h5", "--format", "c3d",
                                                   "--trial", "u.c3d", "-o", "x.c3d"),
              ("u.c3d",))
    yield bad(k, "solve-into-a-taken-run-name", ("solve", "model.yaml", "t.c3d", "--method",
                                                 "nrm-ls", "-o", "r.h5"), ("r.h5", "--replace"))
    yield Case(k, "solve-replace-a-taken-run-name", (
        Step(("solve", "model.yaml", "t.c3d", "--method", "nrm-ls", "--replace", "-o", "r.h5"),
             "ok", outputs=("r.h5",)),))
    for key in ("name", "gravity"):
        yield bad(k, f"yaml-bomb-inside-{key}", ("check", "b.yaml"), (f": {key}[",),
                  text_edit("model.yaml", "b.yaml", _bomb_in(key)))
    yield bad(k, "label-map-of-2-mib", (*SOLVE, "--map", "big.yaml", "-o", "n.h5"),
              ("big.yaml",), write("big.yaml", "P1: P1\n" * (300 * 1024)))
    yield bad(k, "sweep-failing-leaves-no-cells", ("sweep", "s.yaml", "-o", "n.h5"),
              ("e.yaml",), text_edit("model.yaml", "e.yaml", _tracking("")),
              write("s.yaml", sweep_text().replace("model: model.yaml", "model: e.yaml")))


# --- all ------------------------------------------------------------------------------------

def generate(seed: int = 0, full: bool = True) -> list[Case]:
    """Every case, the random parts drawn from ``seed``."""
    from .opensim_cases import coordinates_cases, storage_cases, xml_cases

    rng = random.Random(seed)
    cases = [*overwritten(), *outside(), *run_names(), *numbers(), *header_values(),
             *yaml_files(), *results_files(), *half_written(), *own_output(full), *nonsense(),
             *c3d_bytes(rng, 20 if full else 8), *drawn(rng, 15 if full else 3), *rates(),
             *empty_and_types(), *not_ours(), *xml_cases(), *storage_cases(),
             *coordinates_cases()]
    names = [c.name for c in cases]
    twice = {n for n in names if names.count(n) > 1}
    if twice:
        raise ValueError(f"case names given twice: {sorted(twice)}")
    return cases


def subset(cases: list[Case], per_class: int, seed: int = 0) -> list[Case]:
    """``per_class`` cases of every class, drawn by ``seed``."""
    rng = random.Random(seed)
    out = []
    for klass in CLASSES:
        members = [c for c in cases if c.klass == klass]
        out += rng.sample(members, min(per_class, len(members)))
    return out
