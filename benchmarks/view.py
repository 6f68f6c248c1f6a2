"""``fccgrb view``: the page's size and its playback rate in headless Chromium, for the shared
gait trial (../shared/data/c3d/Qualisys.c3d, 340 frames, lower limbs and plates) and a
10,000-frame whole-body synthesis (tests/synthetic_body.py's full_body.yaml with motions, 100 s
at 100 Hz). Goals: at least 30 frames drawn per second while playing, at most 15 MB per page.

    python benchmarks/view.py [--gait GAIT.h5] [--long LONG.h5] [--seconds 5] [--keep DIR]

Without --gait / --long the results are made first (calibrate and solve the gait trial; synth
and solve the whole body: several minutes). The rate is counted in the page: draws (one per
requestAnimationFrame while playing) over the page's own clock; the time to open is from
navigation to the load event. Report the load average beside the figures: the machine may be
shared. Speed goals live here, never in tests.
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))
from browser import Browser, chromium_binary  # noqa: E402

from fccgrb_cli.view.command import view  # noqa: E402

SHARED = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"


def fccgrb(*args: object) -> None:
    code = "import sys; from fccgrb_cli.entry import run; sys.argv[0] = 'fccgrb'; run()"
    subprocess.run([sys.executable, "-c", code, *map(str, args)], check=True, cwd=ROOT,
                   env={**os.environ, "PYTHONPATH": str(ROOT)})


def gait_results(folder: Path) -> Path:
    model, results = folder / "personal.yaml", folder / "gait.h5"
    fccgrb("calibrate", ROOT / "configs/models/lower_limb.yaml", SHARED, "--mass", 67, "-o", model)
    fccgrb("solve", model, SHARED, "--method", "nrm-wls", "--filter-cutoff", 6, "-o", results)
    return results


def long_results(folder: Path) -> Path:
    from synthetic_body import full_body_text

    model, trial, results = folder / "body.yaml", folder / "long.c3d", folder / "long.h5"
    model.write_text(full_body_text(0), encoding="utf-8")
    fccgrb("synth", model, "--duration", 100, "--rate", 100, "-o", trial)
    fccgrb("solve", model, trial, "-o", results)
    return results


def measure(browser: Browser, results: Path, page: Path, seconds: float) -> dict:
    started = time.perf_counter()
    view(str(results), str(page))
    written = time.perf_counter() - started
    started = time.perf_counter()
    browser.open(page)
    opened = time.perf_counter() - started
    shown = browser.evaluate("fccgrbView.frames.length")
    frames = browser.evaluate("fccgrbView.time.length")
    before = browser.evaluate("fccgrbView.play(true), [fccgrbView.state.draws, "
                              "performance.now()]")
    time.sleep(seconds)
    after = browser.evaluate("[fccgrbView.state.draws, performance.now()]")
    browser.evaluate("fccgrbView.play(false)")
    rate = (after[0] - before[0]) / ((after[1] - before[1]) / 1000)
    return {"trial": results.name, "frames": frames, "shown": shown,
            "MB": page.stat().st_size / 1e6, "write s": written, "open s": opened,
            "frames/s": rate}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--gait", type=Path)
    parser.add_argument("--long", type=Path)
    parser.add_argument("--seconds", type=float, default=5.0)
    parser.add_argument("--keep", type=Path, help="keep the results and pages here")
    args = parser.parse_args()
    if chromium_binary() is None:
        sys.exit("no chromium binary (apt-get install chromium)")
    with tempfile.TemporaryDirectory() as tmp:
        folder = args.keep or Path(tmp)
        folder.mkdir(parents=True, exist_ok=True)
        cases = [args.gait or gait_results(folder), args.long or long_results(folder)]
        rows = []
        with Browser(timeout=180) as browser:
            for results in cases:
                rows.append(measure(browser, results, folder / f"{results.stem}.html",
                                    args.seconds))
        load = os.getloadavg()
        print(f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on {os.cpu_count()} "
              "cores")
        print(f"{'trial':>12} {'frames':>7} {'shown':>6} {'MB':>6} {'write s':>8} "
              f"{'open s':>7} {'frames/s':>9}")
        for r in rows:
            print(f"{r['trial']:>12} {r['frames']:>7} {r['shown']:>6} {r['MB']:>6.2f} "
                  f"{r['write s']:>8.2f} {r['open s']:>7.2f} {r['frames/s']:>9.1f}")


if __name__ == "__main__":
    main()
