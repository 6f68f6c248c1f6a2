"""A small sweep: the five-bar at three soft-tissue-artefact levels, by two methods.

The paper's tables compare methods at P0, P7.5 and P30: markers perturbed by up to 0, 7.5 and
30 mm per axis (docs/formulation.md §5). This loop is the same grid on the bundled sample, with
the largest artefact actually added, the largest angle error against the truth file, and the
mean distance from the model's points to the clean markers. For larger grids, with workers and
a results file per cell, use ``fccgrb sweep`` and a YAML file like ``configs/sweeps/table2.yaml``.

    python examples/sweep_levels.py
"""

from pathlib import Path

import numpy as np

import fccgrb_cli as fc

ROOT = Path(__file__).resolve().parents[1]

model = fc.load_model(ROOT / "configs" / "models" / "five_bar.yaml")
trial = fc.read_trial(ROOT / "sample_data" / "five_bar.c3d")

print(f"{'method':>8} {'level mm':>9} {'added mm':>9} {'max angle error deg':>20} "
      f"{'mean ED mm':>11}")
for method in ("nrm-wls", "cno-sqp"):
    for level in (0.0, 7.5, 30.0):
        run = fc.solve(model, trial, method=method, perturb_mm=level, seed=0)
        added = 1e3 * np.abs(run.markers_input - run.reference).max()
        error = np.degrees(np.abs(run.angles.values - run.truth_theta)).max()
        ed = 1e3 * np.nanmean(run.ed)
        print(f"{method:>8} {level:9.1f} {added:9.2f} {error:20.3f} {ed:11.2f}")
