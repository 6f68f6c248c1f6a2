"""The residual report as text: what ``fccgrb solve`` prints after its summary row and ``fccgrb
report`` prints from a results file (``dynamics.residuals``, ``dynamics.reduction``)."""

from __future__ import annotations

import numpy as np

from fccgrb_cli.dynamics.reduction import Reduction
from fccgrb_cli.dynamics.residuals import STANDARD_GRAVITY, ResidualReport, ResidualSummary

HEAD = ("frames", "F RMS N", "F RMS %BW", "F peak N", "F peak %BW", "M RMS N·m", "M peak N·m")


def _row(label: str, s: ResidualSummary) -> list[str]:
    if not s.frames:
        return [label, "0", *(["–"] * 6)]
    return [label, str(s.frames), f"{s.force_rms:.1f}", f"{s.force_rms_bw:.2f}",
            f"{s.force_peak:.1f}", f"{s.force_peak_bw:.2f}", f"{s.moment_rms:.1f}",
            f"{s.moment_peak:.1f}"]


def _columns(rows: list[list[str]]) -> str:
    widths = [max(len(r[k]) for r in rows) for k in range(len(rows[0]))]
    return "\n".join("  ".join(c.ljust(w) if k == 0 else c.rjust(w)
                               for k, (c, w) in enumerate(zip(r, widths, strict=True)))
                     for r in rows)


def residual_table(report: ResidualReport, reduction: Reduction | None = None) -> str:
    """The residual's peak and RMS (force N and % body weight, moment N·m) over the frames where
    every ground contact is measured and over the single-support ones among them; with a
    reduction, the first model's beside the adjusted one's, the markers' misfit, the largest
    whole-body correction and each segment's mass."""
    s = report.over_measured
    weight = (f"body weight from the plates {s.weight:.0f} N "
              f"({s.weight / STANDARD_GRAVITY:.1f} kg)" if report.weighed
              else f"body weight (the model's) {s.weight:.0f} N"
              + ("" if not np.isfinite(report.plates_estimate) else
                 f": the plates' estimate, {report.plates_estimate:.0f} N, is not a body weight"
                 " (the measured frames' vertical accelerations: noise without a low-pass?)"))
    lines = [f"residual of {report.base} over the {s.frames} frames where every ground contact "
             f"is measured ({s.single} in single support on a plate; not reported elsewhere); "
             f"{weight}, model {s.model_mass:.2f} kg"]
    rows = [["", *HEAD]]
    if reduction is not None:
        b = reduction.before
        rows += [_row("first model, measured", b.over_measured),
                 _row("first model, single support", b.over_single)]
        rows += [_row("reduced, measured", report.over_measured),
                 _row("reduced, single support", report.over_single)]
    else:
        rows += [_row("measured", report.over_measured),
                 _row("single support", report.over_single)]
    lines.append(_columns(rows))
    if reduction is None:
        return "\n".join(lines)
    before, after = (1e3 * np.array(x) for x in (reduction.markers_before,
                                                   reduction.markers_after))
    c = reduction.correction
    lines.append(f"marker misfit RMS of the motion the dynamics used: measured frames "
                 f"{before[0]:.2f} → {after[0]:.2f} mm, all frames {before[1]:.2f} → "
                 f"{after[1]:.2f} mm; whole-body correction at most "
                 f"{1e3 * np.abs(c.translation).max():.1f} mm, "
                 f"{np.degrees(np.abs(c.rotation).max()):.2f} deg")
    fit = reduction.fit
    masses = ", ".join(f"{n} {m0:.2f} → {m:.2f} ({100 * (m / m0 - 1):+.1f} %)"
                       for n, m0, m in zip(fit.names, fit.mass0, fit.mass, strict=True))
    shift = 1e3 * np.linalg.norm(fit.com - fit.com0, axis=1)
    lines.append(f"segment masses, first → adjusted (kg): {masses}; total "
                 f"{fit.mass0.sum():.2f} → {fit.mass.sum():.2f} kg; centres of mass moved "
                 f"{shift.max():.0f} mm at most ({fit.names[int(shift.argmax())]})")
    return "\n".join(lines)
