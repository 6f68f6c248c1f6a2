"""A run's residual report and residual reduction in the results file (layout below), and back.

    residuals/                 the run's residual (its floating base's), attributes ``base``,
                               ``weight`` (N, the body weight the percentages refer to),
                               ``weighed`` (whether the plates measured it),
                               ``plates_estimate`` (N: the plates' estimate where they load
                               the measured frames, NaN where not; refused when implausible)
      measured, single         per frame: every ground contact measured (a plate under it or
                               in the air); of those, exactly one on a plate
      states/<body>            per frame and contact body: 0 air, 1 on a plate, 2 on the
                               ground unmeasured
      over_measured, over_single   groups of attributes: frames, single, force_peak,
                               force_rms (N), moment_peak, moment_rms (N·m), weight (N),
                               model_mass (kg)
    with --reduce-residuals, beside them:
      residuals/first_model/   the first model's report, as above
      residuals/reduction/     attributes ``adjusted_model`` (YAML), ``markers_before`` and
                               ``markers_after`` (RMS m: measured frames, all frames),
                               ``fit_success``, ``fit_message``; datasets ``bodies``,
                               ``mass_first``, ``mass`` (kg), ``com_first``, ``com`` (m, local),
                               ``size`` (m), ``translation``, ``rotation`` (frames × 3: the
                               whole-body correction, m and rad about ``centre``), ``centre``
    residual_force_first_model, residual_moment_first_model   frames × 3 (beside the run's
                               residual_force and residual_moment, the adjusted model's)
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np

from fccgrb_cli.core.datasets import put
from fccgrb_cli.dynamics.residuals import STATES, ResidualReport, ResidualSummary

if TYPE_CHECKING:  # the reduction's modules load where a reduction is read back
    from fccgrb_cli.dynamics.reduction import Reduction

SUMMARY_FIELDS = ("frames", "single", "force_peak", "force_rms", "moment_peak", "moment_rms",
                  "weight", "model_mass")


def _strings(values) -> tuple[str, ...]:
    return tuple(v.decode() if isinstance(v, bytes) else str(v) for v in values)


def _write_report(out, report: ResidualReport, arrays: bool = True) -> None:
    out.attrs["base"] = report.base
    out.attrs["weight"] = report.over_measured.weight
    out.attrs["weighed"] = report.weighed
    out.attrs["plates_estimate"] = report.plates_estimate
    out.attrs["states"] = list(STATES)
    put(out, "measured", report.measured)
    put(out, "single", report.single)
    states = out.create_group("states")
    for body, state in report.states.items():
        put(states, body, state)
    for key in ("over_measured", "over_single"):
        summary = getattr(report, key)
        out.create_group(key).attrs.update({f: getattr(summary, f) for f in SUMMARY_FIELDS})
    if arrays:
        put(out, "force", report.force)
        put(out, "moment", report.moment)


def write_residuals(g, report: ResidualReport, reduction: Reduction | None) -> None:
    """The run's residual report (and reduction) into its results group ``g``."""
    import h5py

    out = g.create_group("residuals")
    _write_report(out, report)
    if reduction is None:
        return
    _write_report(out.create_group("first_model"), reduction.before, arrays=False)
    put(g, "residual_force_first_model", reduction.before.force)
    put(g, "residual_moment_first_model", reduction.before.moment)
    r = out.create_group("reduction")
    fit, c = reduction.fit, reduction.correction
    r.attrs.update({"adjusted_model": reduction.text, "fit_success": fit.success,
                    "fit_message": fit.message,
                    "markers_before": list(reduction.markers_before),
                    "markers_after": list(reduction.markers_after)})
    r.create_dataset("bodies", data=list(fit.names), dtype=h5py.string_dtype(encoding="utf-8"))
    for key, values in (("mass_first", fit.mass0), ("mass", fit.mass), ("com_first", fit.com0),
                        ("com", fit.com), ("size", fit.size), ("K", fit.K),
                        ("translation", c.translation), ("rotation", c.rotation),
                        ("centre", c.centre)):
        put(r, key, values)


def _summary(attrs) -> ResidualSummary:
    """A summary from its group's attributes: the frame counts int, the rest float."""
    values: dict[str, Any] = {f: (int if f in ("frames", "single") else float)(attrs[f])
                              for f in SUMMARY_FIELDS}
    return ResidualSummary(**values)


def _read_report(out, force: np.ndarray, moment: np.ndarray) -> ResidualReport:
    over_measured, over_single = (_summary(out[key].attrs)
                                  for key in ("over_measured", "over_single"))
    return ResidualReport(str(out.attrs["base"]),
                          {body: state[()] for body, state in out["states"].items()},
                          out["measured"][()], out["single"][()], force, moment, over_measured,
                          over_single, weighed=bool(out.attrs["weighed"]),
                          plates_estimate=float(out.attrs.get("plates_estimate", np.nan)))


def read_residuals(g) -> tuple[ResidualReport | None, Reduction | None]:
    """The report and reduction a results group holds (None where absent)."""
    from fccgrb_cli.dynamics.inertia_fit import InertiaFit
    from fccgrb_cli.dynamics.kinematic_correction import RigidCorrection
    from fccgrb_cli.dynamics.reduction import Reduction

    if "residuals" not in g:
        return None, None
    out = g["residuals"]
    report = _read_report(out, out["force"][()], out["moment"][()])
    if "reduction" not in out:
        return report, None
    r = out["reduction"]
    fit = InertiaFit(_strings(r["bodies"][()]), r["mass_first"][()], r["mass"][()],
                     r["com_first"][()], r["com"][()], r["K"][()], r["size"][()],
                     bool(r.attrs["fit_success"]), str(r.attrs["fit_message"]))
    before = _read_report(out["first_model"], g["residual_force_first_model"][()],
                          g["residual_moment_first_model"][()])
    reduction = Reduction(str(r.attrs["adjusted_model"]), fit,
                          RigidCorrection(r["translation"][()], r["rotation"][()],
                                          r["centre"][()]), before,
                          _pair(r.attrs["markers_before"]), _pair(r.attrs["markers_after"]))
    return report, reduction


def _pair(values) -> tuple[float, float]:
    """Two numbers written as an attribute (the markers' RMS and maximum, mm)."""
    first, second = (float(x) for x in values)
    return first, second


def read_all_residuals(path) -> dict[str, tuple[ResidualReport, Reduction | None]]:
    """The residual report and reduction of every run of a results file that has one."""
    import h5py

    with h5py.File(path, "r") as h5:
        out = {}
        for name, g in h5.get("runs", {}).items():
            if "residuals" in g:
                report, reduction = read_residuals(g)
                assert report is not None  # the group holds residuals
                out[name] = (report, reduction)
        return out
