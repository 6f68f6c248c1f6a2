"""Hostile OpenSim files handed to ``fccgrb solve``: ExternalLoads (``--loads``) and IK task
sets (``--tasks``) as XML from strangers, and the storage files (.mot/.sto) a load set names.
Each must fail as bad input in one line naming the file (and the element, line or header key),
exit status 2, nothing written."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

from .cases import Case, Step, bad, fifo, write

XML_CLASS = "OpenSim XML"
STORAGE_CLASS = "OpenSim storage"
SOLVE = ("solve", "model.yaml", "t.c3d")

LOADS = """<?xml version="1.0" encoding="UTF-8" ?>
<OpenSimDocument Version="40000">
  <ExternalLoads name="loads">
    <objects>
      <ExternalForce name="F">
        <applied_to_body>{body}</applied_to_body>
        <force_expressed_in_body>ground</force_expressed_in_body>
        <point_expressed_in_body>ground</point_expressed_in_body>
        <force_identifier>f_v</force_identifier>
        <point_identifier>f_p</point_identifier>
        <torque_identifier>f_t</torque_identifier>{more}
      </ExternalForce>
    </objects>
    <datafile>{datafile}</datafile>
  </ExternalLoads>
</OpenSimDocument>
"""
COLUMNS = "time\tf_vx\tf_vy\tf_vz\tf_px\tf_py\tf_pz\tf_tx\tf_ty\tf_tz"


def loads_xml(body: str = "B5", more: str = "", datafile: str = "f.mot") -> str:
    return LOADS.format(body=body, more=more, datafile=datafile)


def storage(rows: int = 60, header: str | None = None, row: str | None = None) -> str:
    """A load table over the fixture trial's 0.5 s (100 Hz), or with a header or row changed."""
    head = header if header is not None else \
        f"f\nversion=1\nnRows={rows}\nnColumns=10\ninDegrees=no\nendheader\n"
    lines = [row if (row is not None and k == 3) else
             f"{k / 100:.2f}\t1\t2\t3\t0\t0\t0\t0\t0\t0" for k in range(rows)]
    return head + COLUMNS + "\n" + "\n".join(lines) + "\n"


def tasks_xml(weight: str = "1", extra: str = "") -> str:
    return (f'<IKTaskSet name="t"><objects><IKMarkerTask name="P1"><apply>true</apply>'
            f"<weight>{weight}</weight></IKMarkerTask>{extra}</objects></IKTaskSet>")


LAUGHS = ('<?xml version="1.0"?>\n<!DOCTYPE lolz [<!ENTITY lol "lol">'
          + "".join(f'<!ENTITY lol{k} "{("&lol" + (str(k - 1) if k > 1 else "") + ";") * 10}">'
                    for k in range(1, 10))
          + ']>\n<OpenSimDocument><ExternalLoads name="x"><datafile>&lol9;</datafile>'
          "</ExternalLoads></OpenSimDocument>\n")
EXTERNAL = ('<?xml version="1.0"?>\n<!DOCTYPE x [<!ENTITY e SYSTEM "file:///etc/passwd">]>\n'
            "<OpenSimDocument><ExternalLoads><datafile>&e;</datafile></ExternalLoads>"
            "</OpenSimDocument>\n")


def _loads(name: str, klass: str, names: tuple[str, ...], *actions) -> Case:
    return bad(klass, name, (*SOLVE, "--loads", "L.xml", "-o", "n.h5"), names, *actions)


def sparse(name: str, size: int):
    """A file of ``size`` bytes that takes no disk (a hole): too large to be read."""
    def act(work: Path) -> None:
        with open(work / name, "wb") as handle:
            handle.truncate(size)
    return act


def xml_cases() -> Iterator[Case]:
    k = XML_CLASS
    good = write("f.mot", storage())
    yield _loads("loads-billion-laughs", k, ("L.xml",), write("L.xml", LAUGHS), good)
    yield _loads("loads-external-entity", k, ("L.xml",), write("L.xml", EXTERNAL), good)
    deep = "<a>" * 5000 + "</a>" * 5000
    yield _loads("loads-deep-nesting", k, ("L.xml",), write("L.xml", deep), good)
    yield _loads("loads-not-xml", k, ("L.xml",), write("L.xml", "<OpenSimDocument><Ext"), good)
    yield _loads("loads-empty", k, ("L.xml",), write("L.xml", ""), good)
    yield _loads("loads-fifo", k, ("L.xml",), fifo("L.xml"), good)
    yield _loads("loads-huge", k, ("L.xml",), sparse("L.xml", 65 << 20), good)
    yield _loads("loads-unknown-element", k, ("L.xml", "PrescribedForce"),
                 write("L.xml", loads_xml().replace("<ExternalForce name=\"F\">",
                                                    "<PrescribedForce name=\"P\"/>"
                                                    "<ExternalForce name=\"F\">")), good)
    yield _loads("loads-unknown-property", k, ("L.xml", "mass"),
                 write("L.xml", loads_xml(more="<mass>3</mass>")), good)
    yield _loads("loads-unknown-body", k, ("L.xml", "applied_to_body"),
                 write("L.xml", loads_xml(body="calcn_r")), good)
    yield _loads("loads-body-frame", k, ("L.xml", "force_expressed_in_body"),
                 write("L.xml", loads_xml().replace(
                     "<force_expressed_in_body>ground", "<force_expressed_in_body>B1")), good)
    yield _loads("loads-datafile-outside", k, ("f.mot", "L.xml"),
                 write("L.xml", loads_xml(datafile="../../nowhere/f.mot")), good)
    for weight in ("nan", "inf", "1e400", "-3", "heavy"):
        yield bad(k, f"tasks-weight-{weight}", (*SOLVE, "--tasks", "T.xml", "-o", "n.h5"),
                  ("T.xml",), write("T.xml", tasks_xml(weight)))
    yield bad(k, "tasks-unknown-task", (*SOLVE, "--tasks", "T.xml", "-o", "n.h5"),
              ("T.xml", "IKOrientationTask"),
              write("T.xml", tasks_xml(extra="<IKOrientationTask name='x'/>")))
    yield bad(k, "tasks-billion-laughs", (*SOLVE, "--tasks", "T.xml", "-o", "n.h5"),
              ("T.xml",), write("T.xml", LAUGHS))
    yield bad(k, "tasks-no-marker-of-the-model", (*SOLVE, "--tasks", "T.xml", "-o", "n.h5"),
              ("--tasks",), write("T.xml", tasks_xml().replace('"P1"', '"Head"')))


def storage_cases() -> Iterator[Case]:
    k = STORAGE_CLASS
    xml = write("L.xml", loads_xml())
    header = "f\nversion=1\nnRows=60\nnColumns=10\ninDegrees=no\nendheader\n"
    for name, text in (
            ("short-row", storage(row="0.03\t1\t2\t3\t0\t0\t0\t0\t0")),
            ("long-row", storage(row="0.03\t1\t2\t3\t0\t0\t0\t0\t0\t0\t9")),
            ("word", storage(row="0.03\t1\tx\t3\t0\t0\t0\t0\t0\t0")),
            ("nan", storage(row="0.03\tnan\t2\t3\t0\t0\t0\t0\t0\t0")),
            ("infinity", storage(row="0.03\t1\tInfinity\t3\t0\t0\t0\t0\t0\t0")),
            ("huge-number", storage(row="0.03\t1e300\t2\t3\t0\t0\t0\t0\t0\t0")),
            ("time-back", storage(row="0.01\t1\t2\t3\t0\t0\t0\t0\t0\t0")),
            ("rows-disagree", storage(header=header.replace("nRows=60", "nRows=61"))),
            ("columns-disagree", storage(header=header.replace("nColumns=10", "nColumns=9"))),
            ("no-endheader", storage(header="f\nnRows=60\n")),
            ("bad-flag", storage(header=header.replace("=no", "=sometimes"))),
            ("trc-as-mot", "PathFileType\t4\t(X/Y/Z)\tx.trc\nDataRate\t100\n1\t2\n"),
            ("empty", ""),
            ("missing-columns", storage().replace("f_tz", "g_tz")),
            ("too-short", storage(rows=20))):
        yield _loads(f"storage-{name}", k, ("f.mot", "L.xml"), xml, write("f.mot", text))
    yield _loads("storage-huge", k, ("f.mot",), xml, sparse("f.mot", (256 << 20) + 1))
    yield _loads("storage-fifo", k, ("f.mot",), xml, fifo("f.mot"))
    yield Case(k, "storage-good-is-valid", (
        Step((*SOLVE, "--loads", "L.xml", "-o", "n.h5"), "ok", outputs=("n.h5",)),),
        (xml, write("f.mot", storage())))


COORDINATES_CLASS = "OpenSim coordinates and setups"


def _knee_osim() -> str:
    """A small imported model (tests/osim_text.py) without the ForceSet its note would name."""
    import re

    from tests.osim_text import knee_model

    return re.sub(r"<ForceSet>.*?</ForceSet>", "", knee_model(), flags=re.S)


KNEE_COORDINATES = ("rx", "ry", "rz", "tx", "ty", "tz", "knee", "patella")


def coordinates_mot(rows: int = 30, row: str | None = None, header: str | None = None,
                    step: float = 0.01) -> str:
    """The knee model's coordinates over ``rows`` rows (degrees, metres), a row changed."""
    head = header if header is not None else \
        f"c\nversion=1\nnRows={rows}\nnColumns=9\ninDegrees=yes\nendheader\n"
    values = "\t".join(["5", "-3", "2", "0.1", "0.9", "-0.05", "-30", "0"])
    lines = [row if (row is not None and k == 3) else f"{k * step:.4f}\t{values}"
             for k in range(rows)]
    return head + "time\t" + "\t".join(KNEE_COORDINATES) + "\n" + "\n".join(lines) + "\n"


def id_setup(model: str = "knee.osim", coordinates: str = "c.mot", more: str = "",
             tool: str = "InverseDynamicsTool") -> str:
    return (f'<?xml version="1.0"?>\n<OpenSimDocument Version="40000"><{tool} name="s">'
            f"<model_file>{model}</model_file><coordinates_file>{coordinates}"
            f"</coordinates_file><lowpass_cutoff_frequency_for_coordinates>6"
            f"</lowpass_cutoff_frequency_for_coordinates>{more}</{tool}></OpenSimDocument>\n")


def coordinates_cases() -> Iterator[Case]:
    """``solve MODEL.osim --coordinates FILE`` and ``solve --opensim-setup SETUP.xml`` with
    bad coordinates files, setups and option combinations."""
    k = COORDINATES_CLASS
    model = write("knee.osim", _knee_osim())
    good = write("c.mot", coordinates_mot())
    run = ("solve", "knee.osim", "--coordinates", "c.mot", "-o", "n.h5")
    for name, text in (
            ("nan", coordinates_mot(row="0.03\t5\tnan\t2\t0.1\t0.9\t-0.05\t-30\t0")),
            ("huge", coordinates_mot(row="0.03\t5\t1e300\t2\t0.1\t0.9\t-0.05\t-30\t0")),
            ("time-back", coordinates_mot(row="0.0\t5\t-3\t2\t0.1\t0.9\t-0.05\t-30\t0")),
            ("no-model-column", coordinates_mot().replace("\trx\t", "\tother\t")
             .replace("\try\t", "\tb\t").replace("\trz\t", "\tc\t").replace("\ttx\t", "\td\t")
             .replace("\tty\t", "\te\t").replace("\ttz\t", "\tf\t")
             .replace("\tknee\t", "\tg\t").replace("\tpatella\n", "\th\n")),
            ("too-few-rows", coordinates_mot(rows=4)),
            ("trc", "PathFileType\t4\t(X/Y/Z)\tx.trc\nDataRate\t100\n1\t2\n"),
            ("empty", ""),
            ("a-column-twice", coordinates_mot().replace("\tpatella\n", "\tknee\n"))):
        yield bad(k, f"coordinates-{name}", run, ("c.mot",), model, write("c.mot", text))
    uneven = coordinates_mot().replace("\n0.0300\t", "\n0.0370\t")
    yield bad(k, "coordinates-uneven-with-cutoff", (*run, "--filter-cutoff", "6"),
              ("c.mot", "--filter-cutoff"), model, write("c.mot", uneven))
    yield bad(k, "coordinates-window-outside", (*run, "--from", "9"), ("--from/--to",),
              model, good)
    yield bad(k, "coordinates-window-reversed", (*run, "--from", "0.2", "--to", "0.1"),
              ("--to",), model, good)
    yield bad(k, "coordinates-beside-a-trial",
              ("solve", "knee.osim", "t.c3d", "--coordinates", "c.mot", "-o", "n.h5"),
              ("--coordinates",), model, good)
    yield bad(k, "coordinates-yaml-model",
              ("solve", "model.yaml", "--coordinates", "c.mot", "-o", "n.h5"),
              ("--coordinates", "model.yaml"), good)
    yield bad(k, "coordinates-hold-unknown", (*run, "--hold", "nope=3"), ("--hold",), model,
              good)
    setup = ("solve", "--opensim-setup", "S.xml", "-o", "n.h5")
    for name, text, names in (
            ("setup-billion-laughs", LAUGHS, ("S.xml",)),
            ("setup-external-entity", EXTERNAL, ("S.xml",)),
            ("setup-not-xml", "<OpenSimDocument><Inverse", ("S.xml",)),
            ("setup-other-tool", id_setup(tool="ScaleTool").replace(
                "<coordinates_file>c.mot</coordinates_file>", ""), ("S.xml",)),
            ("setup-missing-model", id_setup(model="none.osim"), ("none.osim",)),
            ("setup-missing-coordinates", id_setup(coordinates="none.mot"), ("none.mot",)),
            ("setup-no-coordinates", id_setup(coordinates=""), ("S.xml", "coordinates_file")),
            ("setup-unknown-property", id_setup(more="<speed>3</speed>"), ("S.xml", "speed")),
            ("setup-bad-time-range", id_setup(more="<time_range>2 1</time_range>"),
             ("S.xml", "time_range")),
            ("setup-bad-cutoff", id_setup().replace(">6<", ">fast<"), ("S.xml",))):
        yield bad(k, name, setup, names, model, good, write("S.xml", text))
    yield Case(k, "coordinates-good-is-valid", (
        Step(run, "ok", outputs=("n.h5",)),
        Step(("solve", "--opensim-setup", "S.xml", "-o", "m.h5"), "ok", outputs=("m.h5",))),
        (model, good, write("S.xml", id_setup())))
