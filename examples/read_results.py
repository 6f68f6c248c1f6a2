"""Reading a results file: what ``fccgrb solve -o`` writes, read back as the same Run objects.

The command line solves the bundled five-bar twice (two methods) into ``results.h5``;
``fc.read_results`` then gives every run by name, with its options, its summary row, and the
named arrays the solve produced. The file's layout is documented in
``fccgrb_cli/results/storage.py`` and can be read by any HDF5 reader.

    python examples/read_results.py
"""

import subprocess
import sys
from pathlib import Path

import numpy as np

import fccgrb_cli as fc

ROOT = Path(__file__).resolve().parents[1]
FCCGRB = Path(sys.executable).with_name("fccgrb")  # the command installed beside this Python
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
TRIAL = ROOT / "sample_data" / "five_bar.c3d"

for method in ("nrm-wls", "cno-sqp"):
    subprocess.run([str(FCCGRB), "solve", str(MODEL), str(TRIAL), "--method", method,
                    "--perturb", "7.5", "-o", "results.h5"], check=True, stdout=subprocess.DEVNULL)

runs = fc.read_results("results.h5")
print(f"results.h5 (format {fc.RESULTS_FORMAT}): runs {', '.join(sorted(runs))}")
for name, run in sorted(runs.items()):
    summary = run.summary()
    knee = np.degrees(run.angles["J3_w"])
    print(f"{name}: method {run.options.method}, {run.result.n_frames} frames, "
          f"mean ED {summary['mean ED mm']:.3f} mm, J3_w mean {knee.mean():.4f}°, "
          f"peak |τ J3_w| {np.abs(run.moments['J3_w']).max():.3f} N·m")
