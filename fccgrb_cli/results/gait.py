"""A run's gait analysis in the results file, under ``/runs/<name>/gait/``:

* ``events/<source>/time`` (s from the trial's first frame), ``side``, ``kind`` — every source
  found (c3d, plates, kinematic); the group's attribute ``used`` names the one the cycles use;
* ``cycles/<side>/curves`` (strides × 101 × variables; attributes ``names``, ``units``),
  ``start``, ``stop`` (s), ``trusted`` (per stride, its kinematics), ``trusted_curves``
  (strides × variables: a moment can be untrusted on a trusted stride), ``mean`` and ``sd``
  (101 × variables, each over its trusted strides), ``parameters`` (strides × parameters;
  attributes ``names``, ``units``);
* attributes ``forward`` (the direction of walking) and ``notes``;

and, when ``fccgrb solve`` is given several trials, ``/subject/cycles/<side>/`` the same
cycles with every trial's strides pooled (attribute ``runs``: the runs they come from).
"""

from __future__ import annotations

import numpy as np

from fccgrb_cli.core.datasets import open_results, put
from fccgrb_cli.gait.analysis import GaitResults
from fccgrb_cli.gait.cycles import PARAMETERS, SideCycles
from fccgrb_cli.gait.events import Events
from fccgrb_cli.results.format import reading, runs_group


def _strings(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


def write_cycles(group, cycles: dict[str, SideCycles]) -> None:
    """``cycles/<side>/…`` as laid out above."""
    out = group.create_group("cycles")
    for side, c in cycles.items():
        s = out.create_group(side)
        put(s, "curves", c.curves)
        for key in ("curves", "mean", "sd"):
            if key != "curves":
                put(s, key, getattr(c, key)())
            s[key].attrs.update({"names": list(c.names), "units": list(c.units)})
        for key in ("start", "stop", "trusted", "parameters"):
            put(s, key, getattr(c, key))
        put(s, "trusted_curves", c.trusted_per_variable)
        s["parameters"].attrs.update({"names": [p for p, _ in PARAMETERS],
                                      "units": [u for _, u in PARAMETERS]})


def read_cycles(group) -> dict[str, SideCycles]:
    return {side: SideCycles(side, s["start"][()], s["stop"][()], s["trusted"][()],
                             _strings(s["curves"].attrs["names"]),
                             _strings(s["curves"].attrs["units"]), s["curves"][()],
                             s["parameters"][()],
                             s["trusted_curves"][()] if "trusted_curves" in s else None)
            for side, s in group["cycles"].items()}


def write_subject(h5, runs: list[str], cycles: dict[str, SideCycles]) -> None:
    """``/subject/`` of an open results file: the strides of several trials' runs (attribute
    ``runs``) pooled per side, under ``cycles/<side>/`` as for one run (``start``/``stop`` are
    each trial's own times)."""
    import h5py

    if "subject" in h5:
        del h5["subject"]
    group = h5.create_group("subject")
    group.attrs.create("runs", runs, dtype=h5py.string_dtype(encoding="utf-8"))
    write_cycles(group, cycles)


def write_gait(g, gait: GaitResults) -> None:
    import h5py

    text = h5py.string_dtype(encoding="utf-8")
    out = g.create_group("gait")
    out.attrs["forward"] = gait.forward
    out.attrs.create("notes", list(gait.notes), dtype=text)
    events = out.create_group("events")
    events.attrs["used"] = gait.events.source
    for source, found in gait.found.items():
        e = events.create_group(source)
        put(e, "time", found.time)
        e.create_dataset("side", data=list(found.side), dtype=text)
        e.create_dataset("kind", data=list(found.kind), dtype=text)
    write_cycles(out, gait.cycles)


def read_gait(g) -> GaitResults:
    found = {source: Events(source, e["time"][()], _strings(e["side"][()]),
                            _strings(e["kind"][()])) for source, e in g["events"].items()}
    return GaitResults(found[str(g["events"].attrs["used"])], found, read_cycles(g),
                       np.asarray(g.attrs["forward"], dtype=float), _strings(g.attrs["notes"]))


def read_all_gait(path) -> dict[str, GaitResults]:
    """The gait analysis of every run of a results file that has one, by run name."""
    with open_results(path) as h5:
        if "runs" not in h5:
            return {}
        out = {}
        for name, g in runs_group(h5, path).items():
            if "gait" in g:
                with reading(path, f"/runs/{name}/gait"):
                    out[name] = read_gait(g["gait"])
        return out
