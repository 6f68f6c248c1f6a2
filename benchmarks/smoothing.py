"""Joint moments with the whole-trial smoother (issue 23) against central differences and the
Butterworth filter, on the five-bar synthesized at 200 Hz for 3 s.

    python benchmarks/smoothing.py [--orders] [--monte-carlo 100] [--cost 10000]
                                   [--figure docs/x.png] [--no-table]

The reference is the truth-driven inverse dynamics (``--method ad --ad-drivers truth``); the
runs solve NRM-WLS on the truth's markers (double precision) with white noise added (seeded,
per coordinate), and the 7.5 mm soft-tissue artefact of ``--perturb 7.5`` where named. Errors
are the moments' RMS / max (N·m) over frames 10…590 and over every frame.

``--orders``: the same at white 1 mm with priors of order 3 to 6.
``--monte-carlo N``: N noise seeds at white 1 mm; per angle, the smoother's predicted standard
deviation of the angle, its rate, its acceleration and its joint moment against the empirical
one (the RMS error over the seeds; the median over frames of predicted / empirical), and how
often the 95 % band (±1.96 SD) covers the truth. ``--cost FRAMES``: the five-bar over FRAMES
frames at 200 Hz, white 1 mm: ms/frame of the per-frame solve (NRM-WLS, compiled), of the
smoother and of the moments' uncertainty, measured in the same minutes (best of two).
``--figure PATH``: the Qualisys walking trial (calibrated as the README's gait example):
sagittal joint moments around the right heel strike with the 6 Hz filter and with the
smoother (its 95 % band shaded).
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import fccgrb_cli as fc
from fccgrb_cli.io.trial import Trial
from fccgrb_cli.io.truth import read_truth

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
QUALISYS = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"
CASES = (("none", 0.0, 0.0), ("white 0.5 mm", 0.5, 0.0), ("white 1 mm", 1.0, 0.0),
         ("white 1 mm + 7.5 mm artefact", 1.0, 7.5), ("white 0.5 mm + 7.5 mm artefact", 0.5, 7.5))
COLUMNS = (("raw differences", {"smooth": "none"}),
           ("Butterworth 6 Hz", {"smooth": "none", "filter_cutoff": 6.0}),
           ("10 Hz", {"smooth": "none", "filter_cutoff": 10.0}),
           ("15 Hz", {"smooth": "none", "filter_cutoff": 15.0}),
           ("--smooth auto", {"smooth": "auto"}))
EDGE = 10


class FiveBar:
    """The synthesized trial (``fccgrb synth``), its truth and the reference moments."""

    def __init__(self, folder: Path, rate: float = 200.0, duration: float = 3.0) -> None:
        path = folder / "five_bar.c3d"
        fccgrb = Path(sys.executable).with_name("fccgrb")
        subprocess.run([str(fccgrb), "synth", str(MODEL), "--rate", f"{rate:g}", "--duration",
                        f"{duration:g}", "-o", str(path)], check=True, capture_output=True)
        self.path, self.rate = path, rate
        self.model = fc.load_model(MODEL)
        self.truth = read_truth(path.with_suffix(".truth.h5"))
        reference = fc.solve(self.model, self.trial(self.truth.markers), method="ad",
                             ad_drivers="truth", events="none")
        self.tau = np.asarray(reference.dynamics.inverse.joint_moments)

    def trial(self, markers: np.ndarray) -> Trial:
        """A trial of these markers at the synthesized file's path (its truth beside it)."""
        return Trial(str(self.path), tuple(self.truth.labels), markers, self.rate)

    def noisy(self, white_mm: float, seed: int) -> np.ndarray:
        rng = np.random.default_rng(seed)
        return self.truth.markers + rng.normal(scale=1e-3 * white_mm,
                                               size=self.truth.markers.shape)

    def solve(self, white_mm: float, artefact_mm: float, seed: int = 0, **options):
        return fc.solve(self.model, self.trial(self.noisy(white_mm, seed)), method="nrm-wls",
                        perturb_mm=artefact_mm, events="none", **options)


def errors(tau: np.ndarray, reference: np.ndarray) -> tuple[float, float, float, float]:
    """RMS and max |error| over frames EDGE…n−EDGE, then over every frame (N·m)."""
    e = tau - reference
    inner = e[EDGE:-EDGE]
    return (float(np.sqrt(np.mean(inner**2))), float(np.abs(inner).max()),
            float(np.sqrt(np.mean(e**2))), float(np.abs(e).max()))


def table(bar: FiveBar) -> None:
    n = len(bar.truth.time)
    print(f"five-bar synthesized at {bar.rate:g} Hz, {n} frames; reference: truth-driven "
          f"moments (peak {np.abs(bar.tau).max():.1f} N·m, RMS {np.sqrt(np.mean(bar.tau**2)):.1f}"
          f" N·m); moment error RMS / max (N·m), frames {EDGE}…{n - EDGE} | every frame")
    width = max(len(c) for c, _, _ in CASES)
    print(f"{'marker noise':<{width}}  " + "  ".join(f"{name:>21}" for name, _ in COLUMNS))
    for label, white, artefact in CASES:
        cells = []
        for _, options in COLUMNS:
            run = bar.solve(white, artefact, **options)
            r, m, ra, ma = errors(np.asarray(run.dynamics.inverse.joint_moments), bar.tau)
            cells.append(f"{r:.3f}/{m:.2f} | {ra:.3f}/{ma:.2f}")
        print(f"{label:<{width}}  " + "  ".join(f"{c:>21}" for c in cells), flush=True)
    cno = fc.solve(bar.model, bar.trial(bar.truth.markers), method="cno-sqp", perturb_mm=7.5,
                   events="none", smooth="none")
    r, m, ra, ma = errors(np.asarray(cno.dynamics.inverse.joint_moments), bar.tau)
    print(f"the artefact alone (7.5 mm, no white noise), each frame's exact fit (CNO-SQP), raw "
          f"differences: {r:.3f}/{m:.2f} | {ra:.3f}/{ma:.2f}: what no smoother can remove")


def monte_carlo(bar: FiveBar, seeds: int) -> None:
    truth = {"θ": bar.truth.theta, "θ̇": bar.truth.theta_d, "θ̈": bar.truth.theta_dd,
             "τ": bar.tau}
    err = {k: [] for k in truth}
    sd = {k: [] for k in truth}
    for seed in range(seeds):
        run = bar.solve(1.0, 0.0, seed)
        u = run.uncertainty
        r = run.result
        values = {"θ": r.theta, "θ̇": r.theta_d, "θ̈": r.theta_dd,
                  "τ": np.asarray(run.dynamics.inverse.joint_moments)}
        for key, s in (("θ", u.theta_sd), ("θ̇", u.theta_d_sd), ("θ̈", u.theta_dd_sd),
                       ("τ", u.moments_sd)):
            err[key].append(values[key] - truth[key])
            sd[key].append(s)
    names = bar.truth.angle_names
    print(f"\nMonte Carlo, {seeds} seeds at white 1 mm: predicted / empirical standard deviation "
          "(median over frames) and coverage of the 95 % band (every frame)")
    print(f"{'angle':>8}  " + "  ".join(f"{k + ' sd ratio':>12} {k + ' cover':>9}" for k in truth))
    summary = {k: [] for k in truth}
    for j, name in enumerate(names):
        cells = []
        for key in truth:
            e, s = np.array(err[key])[:, :, j], np.array(sd[key])[:, :, j]
            ratio = float(np.median(np.sqrt(np.mean(s**2, axis=0))
                                    / np.sqrt(np.mean(e**2, axis=0))))
            cover = float(np.mean(np.abs(e) <= 1.96 * s))
            summary[key].append((ratio, cover))
            cells.append(f"{ratio:12.2f} {100 * cover:8.1f}%")
        print(f"{name:>8}  " + "  ".join(cells))
    for key, rows in summary.items():
        ratios, covers = np.array(rows).T
        print(f"{key}: sd ratio {ratios.min():.2f}–{ratios.max():.2f}, coverage "
              f"{100 * covers.min():.1f}–{100 * covers.max():.1f} %")


def orders(bar: FiveBar) -> None:
    """The moments' errors at white 1 mm with priors of order 3 to 6 (the smoother's ORDER)."""
    from fccgrb_cli.solvers.smooth import trial

    print("\nthe prior's order, white 1 mm (RMS / max N·m, frames 10…590 | every frame):")
    kept = trial.ORDER
    try:
        for order in (3, 4, 5, 6):
            trial.ORDER = order
            run = bar.solve(1.0, 0.0)
            r, m, ra, ma = errors(np.asarray(run.dynamics.inverse.joint_moments), bar.tau)
            print(f"  order {order}: {r:.3f}/{m:.2f} | {ra:.3f}/{ma:.2f}"
                  + ("  (the smoother's)" if order == kept else ""), flush=True)
    finally:
        trial.ORDER = kept


def cost(frames: int) -> None:
    from fccgrb_cli.dynamics.uncertainty import moment_uncertainty
    from fccgrb_cli.smoothing import smooth, settings_of
    from fccgrb_cli.options import SolveOptions
    from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm
    from fccgrb_cli.synth import synthesize
    from fccgrb_cli.system import compile_system

    model = fc.load_model(MODEL)
    syn = synthesize(model, duration=frames / 200.0, rate=200.0)
    markers = syn.markers + np.random.default_rng(0).normal(scale=1e-3, size=syn.markers.shape)
    mixed = compile_system(model, angles="coordinate", track=True)
    time_ = syn.result.time
    settings = NrmSettings(engine="compiled")
    options = SolveOptions(engine="compiled")
    warm = slice(0, 1200)
    nrm = solve_nrm(mixed, time_[warm], markers[warm], settings)  # loads the kernels
    smooth(model, nrm, markers[warm], settings_of(options))
    best = {"solve": np.inf, "smoother": np.inf, "uncertainty": np.inf}
    for _ in range(2):
        started = time.perf_counter()
        nrm = solve_nrm(mixed, time_, markers, settings)
        t1 = time.perf_counter()
        s = smooth(model, nrm, markers, settings_of(options))
        t2 = time.perf_counter()
        m = s.motion
        lin = m.coordinates.linearize(m.d, m.q, True)
        moment_uncertainty(m.coordinates, lin.q, lin.S, m.d, m.d_d, m.d_dd, m.covariance)
        t3 = time.perf_counter()
        for key, seconds in (("solve", t1 - started), ("smoother", t2 - t1),
                             ("uncertainty", t3 - t2)):
            best[key] = min(best[key], seconds)
    per = {k: 1e3 * v / frames for k, v in best.items()}
    print(f"\n{frames} frames of the five-bar at 200 Hz, white 1 mm (ms/frame, best of 2):")
    print(f"  per-frame solve (NRM-WLS, compiled, positions and rates)  {per['solve']:.3f}")
    print(f"  smoother (every iteration, the covariance)               {per['smoother']:.3f}"
          f"   {per['smoother'] / per['solve']:.2f}× the solve")
    print(f"  moments' uncertainty (numpy)                             {per['uncertainty']:.3f}"
          f"   {per['uncertainty'] / per['solve']:.2f}× the solve")


def figure(output: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from fccgrb_cli.plot import save

    template = fc.load_model(ROOT / "configs" / "models" / "lower_limb.yaml")
    trial = fc.read_trial(QUALISYS)
    model = fc.calibrate(template, trial, mass=67)
    filtered = fc.solve(model, trial, filter_cutoff=6.0)
    smoothed = fc.solve(model, trial)
    t = trial.time
    strike = 0.53  # s: the right foot's strike on plate 2 (the C3D's events)
    window = (t > strike - 0.12) & (t < strike + 0.25)
    fig, axes = plt.subplots(1, 3, figsize=(12, 3.4), sharex=True)
    m_sd = smoothed.clinical_sd[1]
    for ax, joint in zip(axes, ("hip_flexion_r", "knee_flexion_r", "ankle_dorsiflexion_r"),
                         strict=True):
        for run, style, label in ((filtered, "--", "Butterworth 6 Hz (kinematics and plates)"),
                                  (smoothed, "-", "--smooth auto")):
            moments = run.clinical_moments
            ax.plot(t[window], moments[joint][window], style, color="k" if style == "--"
                    else "tab:red", lw=1.4, label=label)
        values, sd = smoothed.clinical_moments[joint], m_sd[joint]
        ax.fill_between(t[window], (values - 1.96 * sd)[window], (values + 1.96 * sd)[window],
                        color="tab:red", alpha=0.25, lw=0, label="95 % band")
        ax.axvline(strike, color="0.5", lw=0.8, ls=":")
        ax.set_title(joint.replace("_", " ") + " moment", fontsize=10)
        ax.set_xlabel("time (s); dotted: right heel strike")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("N·m/kg")
    axes[0].legend(fontsize=7, loc="best")
    u = smoothed.uncertainty
    fig.suptitle(f"Qualisys walking trial: marker noise {1e3 * u.noise_m:.2g} mm, equivalent "
                 f"cutoffs {u.cutoffs_hz.min():.0f}–{u.cutoffs_hz.max():.0f} Hz (maximum "
                 "likelihood)", fontsize=9)
    fig.tight_layout()
    save(fig, output)
    print(f"wrote {output}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--monte-carlo", type=int, default=0, metavar="SEEDS")
    parser.add_argument("--cost", type=int, default=0, metavar="FRAMES")
    parser.add_argument("--figure", type=Path, default=None)
    parser.add_argument("--orders", action="store_true")
    parser.add_argument("--no-table", action="store_true")
    args = parser.parse_args()
    if args.figure is not None:
        figure(args.figure)
    if not (args.no_table and not args.monte_carlo and not args.orders):
        with tempfile.TemporaryDirectory(prefix="fccgrb-smoothing-") as folder:
            bar = FiveBar(Path(folder))
            if not args.no_table:
                table(bar)
            if args.orders:
                orders(bar)
            if args.monte_carlo:
                monte_carlo(bar, args.monte_carlo)
    if args.cost:
        cost(args.cost)


if __name__ == "__main__":
    main()
