"""A run's Plug-in Gait outputs in the results file, under ``/runs/<name>/plugin_gait/``:
``angles``, ``moments``, ``powers`` (frames × outputs × 3; attributes ``names`` — Plug-in Gait's
``LHipAngles`` ... — and ``units``: deg, N.mm/kg, W/kg; NaN in frames not solved), and the
attribute ``progression`` (the progression frame's axes, 3 × 3, columns x, y, z)."""

from __future__ import annotations

import numpy as np

from fccgrb_cli.core.datasets import put
from fccgrb_cli.plugin_gait.outputs import UNITS, PluginGaitResults


def _strings(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


def write_plugin_gait(group, pig: PluginGaitResults) -> None:
    """``plugin_gait/…`` as laid out above."""
    out = group.create_group("plugin_gait")
    out.attrs["progression"] = pig.progression
    for kind, curves in pig.kinds().items():
        if not curves:
            continue
        put(out, kind, np.stack(list(curves.values()), axis=1))
        out[kind].attrs.update({"names": list(curves), "units": UNITS[kind]})


def read_plugin_gait(group) -> PluginGaitResults:
    """The outputs :func:`write_plugin_gait` stored."""
    kinds = {}
    for kind in UNITS:
        if kind in group:
            values = group[kind][()]
            kinds[kind] = {name: values[:, k] for k, name in
                           enumerate(_strings(group[kind].attrs["names"]))}
        else:
            kinds[kind] = {}
    return PluginGaitResults(kinds["angles"], kinds["moments"], kinds["powers"],
                             np.asarray(group.attrs["progression"]))
