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
