"""The gait analysis as text: events by source side by side, spatiotemporal parameters per side,
and the cycles' key clinical values."""

from __future__ import annotations

import numpy as np

from fccgrb_cli.gait.analysis import GaitResults
from fccgrb_cli.gait.cycles import PARAMETERS, SideCycles
from fccgrb_cli.gait.events import agreement


def events_table(gait: GaitResults, start: float = 0.0) -> str:
    """One row per event of the source used, with the other sources' difference (ms); times
    on the trial file's clock (``start``: its first frame's time, s, as the exports count it
    and a C3D's EVENT:TIMES does)."""
    others = [s for s in gait.found if s != gait.events.source]
    head = f"{'event':<14}{'t s (' + gait.events.source + ')':>14}" + "".join(
        f"{s + ' Δms':>15}" for s in others)
    rows = [head]
    deltas = {s: agreement(gait.events, gait.found[s]) for s in others}
    for k, (t, side, kind) in enumerate(zip(gait.events.time, gait.events.side,
                                            gait.events.kind, strict=True)):
        cells = [f"{side + ' ' + kind:<14}", f"{t + start:14.3f}"]
        for s in others:
            d = deltas[s][k][3]
            cells.append(f"{'–' if d is None else f'{1e3 * d:+.1f}':>15}")
        rows.append("".join(cells))
    return "\n".join(rows)


def parameters_table(cycles: dict[str, SideCycles]) -> str:
    """Spatiotemporal parameters: mean over each side's trusted strides (and how many of how
    many)."""
    sides = list(cycles)
    rows = [f"{'parameter':<24}" + "".join(f"{s:>16}" for s in sides)]
    for k, (name, unit) in enumerate(PARAMETERS):
        cells = [f"{name.replace('_', ' ') + ' (' + unit + ')':<24}"]
        for side in sides:
            values = cycles[side].parameters[cycles[side].trusted, k]
            finite = values[np.isfinite(values)]
            cells.append(f"{np.mean(finite):16.3g}" if len(finite) else f"{'–':>16}")
        rows.append("".join(cells))
    rows.append(f"{'strides (trusted)':<24}" + "".join(
        f"{f'{c.n} ({int(c.trusted.sum())})':>16}" for c in cycles.values()))
    return "\n".join(rows)


def cycles_table(cycles: dict[str, SideCycles]) -> str:
    """Each side's mean cycle of every clinical angle (deg) over its trusted strides: its value
    at foot strike (0 %), its minimum and maximum, and the % of the cycle where the maximum
    falls."""
    rows = [f"{'mean cycle':<24}{'side':>6}{'at 0 %':>9}{'min':>9}{'max':>9}{'max at %':>10}"]
    for side, c in cycles.items():
        mean = c.mean()
        for k, (name, unit) in enumerate(zip(c.names, c.units, strict=True)):
            if unit != "deg" or not np.isfinite(mean[:, k]).all():
                continue
            curve = mean[:, k]
            rows.append(f"{name:<24}{side:>6}{curve[0]:9.1f}{curve.min():9.1f}{curve.max():9.1f}"
                        f"{int(curve.argmax()):10d}")
    return "\n".join(rows)


def gait_report(gait: GaitResults, start: float = 0.0) -> str:
    """The gait analysis as text; event times on the trial file's clock (``start``: its first
    frame's time, s), which the report names."""
    notes = "".join(f"\n  ({note})" for note in gait.notes)
    return (f"gait events (used: {gait.events.source}; others: difference to the nearest of "
            f"the same foot and kind; times on the trial file's clock, its first frame at "
            f"{start:.3f} s, as the exports' time column){notes}\n"
            f"{events_table(gait, start)}\n\n"
            f"spatiotemporal parameters (mean over strides)\n{parameters_table(gait.cycles)}\n\n"
            f"{cycles_table(gait.cycles)}")


def subject_report(runs: list[str], cycles: dict[str, SideCycles]) -> str:
    """The pooled strides of several trials: parameters and mean cycles."""
    return (f"subject: {len(runs)} trials pooled ({', '.join(runs)})\n"
            f"spatiotemporal parameters (mean over every trial's strides)\n"
            f"{parameters_table(cycles)}\n\n{cycles_table(cycles)}")
