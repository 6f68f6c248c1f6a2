"""Joint moments with the whole-trial smoother (docs/formulation.md §12) against central differences
and the Butterworth filter, on the five-bar synthesized at 200 Hz for 3 s.

    python benchmarks/smoothing.py [--orders] [--monte-carlo 100] [--cost 10000]
                                   [--figure docs/x.png] [--no-table]

The reference is the truth-driven inverse dynamics (``--method ad --ad-drivers truth``); the
runs solve NRM-WLS on the truth's markers (double precision) with white noise added (seeded,
per coordinate), and the 7.5 mm soft-tissue artefact of ``--perturb 7.5`` where named. Errors
are the moments' RMS / max (N·m) over frames 10…590 and over every frame.

``--orders``: the same at white 1 mm with priors of order 3 to 6.
``--floor SEEDS``: the artefact case's floor over artefact seeds: each frame's exact fit to the
artefact alone differenced, the smoother on it with white 0.5 mm, and the smoother told the
strength it finds on that noise without the artefact (what a user who knew the motion's band
could set).
``--monte-carlo N``: N noise seeds at white 1 mm; per angle, the smoother's predicted standard
deviation of the angle, its rate, its acceleration and its joint moment against the empirical
one (the RMS error over the seeds; the median over frames of predicted / empirical), and how
often the 95 % band (±1.96 SD) covers the truth. ``--cost FRAMES``: the five-bar over FRAMES
frames at 200 Hz, white 1 mm: ms/frame of the per-frame solve (NRM-WLS, compiled), of the
smoother and of the moments' uncertainty, measured in the same minutes (best of two).
``--figure PATH``: the Qualisys walking trial (calibrated as the README's gait example):
sagittal joint moments around the right heel strike with the 6 Hz filter and with the
smoother (its 95 % band shaded).
``--gait SEEDS``: walking with a known truth, for the default's choice: the Qualisys trial's
per-frame coordinates (NRM-WLS, --smooth none) low-passed at 6, 12 and 20 Hz (zero-lag
Butterworth) and interpolated by a quintic spline (its rates exact) are the truth; the model's
markers there, with the noise the smoother found on the real trial (white on the markers, and
each coordinate's own), seeded, are the trial; its moments are compared with the truth's,
once with the trial's force plates (raw in the truth; each method filters them its own way)
and once without plates (the kinematics alone). RMS / max over every frame, over frames 10…n−10
and over the right heel strike ±0.1 s.
"""

from __future__ import annotations

import fccgrb_cli  # noqa: F401  (first: pins BLAS to one thread before numpy loads)
import argparse
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from pathlib import Path

import numpy as np

import fccgrb_cli as fc
from fccgrb_cli.trial.record import Trial
from fccgrb_cli.trial.truth import read_truth

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
GAIT_TRUTH_HZ = (6.0, 12.0, 20.0)
STRIKE = 0.53  # s: the right foot's strike on plate 2 of Qualisys.c3d (the C3D's events)


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

    def solve(self, white_mm: float, artefact_mm: float, seed: int = 0, artefact_seed: int = 0,
              **options):
        return fc.solve(self.model, self.trial(self.noisy(white_mm, seed)), method="nrm-wls",
                        perturb_mm=artefact_mm, seed=artefact_seed, events="none", **options)


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
        run = bar.solve(1.0, 0.0, seed, smooth="auto")
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


@contextmanager
def strengths_of(run: Callable[[], object]) -> Iterator[None]:
    """Within: the smoother's strength (marker noise, each coordinate's cutoff and own noise)
    is the one it finds on ``run()``, whatever the trial."""
    from fccgrb_cli.solvers.smooth import trial

    kept = trial._estimate
    found = []
    trial._estimate = lambda *args: found.append(kept(*args)) or found[-1]
    try:
        run()
        trial._estimate = lambda *args: found[0]
        yield
    finally:
        trial._estimate = kept


def floor(bar: FiveBar, seeds: int) -> None:
    """The 7.5 mm artefact's floor over artefact seeds (white 0.5 mm, noise seed 0)."""
    n = len(bar.truth.time)
    print(f"\nthe 7.5 mm artefact over {seeds} artefact seeds, moment error RMS / max (N·m), "
          f"frames {EDGE}…{n - EDGE} | every frame: each frame's exact fit to the artefact "
          "alone (CNO-SQP, no white noise) differenced; --smooth auto on it with white 0.5 mm; "
          "the same with the strength --smooth auto finds on that noise without the artefact "
          "(cutoffs told from the motion, which the data cannot tell)")
    print(f"{'seed':>4}  {'exact fit, raw differences':>28}  {'--smooth auto':>28}  "
          f"{'cutoffs without the artefact':>28}")
    rows = []
    for seed in range(seeds):
        exact = fc.solve(bar.model, bar.trial(bar.truth.markers), method="cno-sqp",
                         perturb_mm=7.5, seed=seed, events="none", smooth="none")
        runs = [exact, bar.solve(0.5, 7.5, artefact_seed=seed, smooth="auto")]
        with strengths_of(lambda: bar.solve(0.5, 0.0, smooth="auto")):
            runs.append(bar.solve(0.5, 7.5, artefact_seed=seed, smooth="auto"))
        cells = [errors(np.asarray(run.dynamics.inverse.joint_moments), bar.tau)
                 for run in runs]
        rows.append(cells)
        print(f"{seed:>4}  " + "  ".join(f"{f'{r:.3f}/{m:.2f} | {ra:.3f}/{ma:.2f}':>28}"
                                        for r, m, ra, ma in cells), flush=True)
    every = np.array(rows)[:, :, 2]  # seeds × (fit, auto, told): every frame's RMS
    gap = every[:, 1] - every[:, 0]
    print(f"every frame's RMS over the seeds: the exact fit {every[:, 0].min():.3f}–"
          f"{every[:, 0].max():.3f}, --smooth auto {every[:, 1].min():.3f}–"
          f"{every[:, 1].max():.3f} (auto minus the fit {gap.min():+.3f} to {gap.max():+.3f});"
          f" the exact fit above 0.35 N·m on {int((every[:, 0] > 0.35).sum())} of {seeds} "
          "seeds")


def orders(bar: FiveBar) -> None:
    """The moments' errors at white 1 mm with priors of order 3 to 6 (the smoother's ORDER)."""
    from fccgrb_cli.solvers.smooth import trial

    print("\nthe prior's order, white 1 mm (RMS / max N·m, frames 10…590 | every frame):")
    kept = trial.ORDER
    try:
        for order in (3, 4, 5, 6):
            trial.ORDER = order
            run = bar.solve(1.0, 0.0, smooth="auto")
            r, m, ra, ma = errors(np.asarray(run.dynamics.inverse.joint_moments), bar.tau)
            print(f"  order {order}: {r:.3f}/{m:.2f} | {ra:.3f}/{ma:.2f}"
                  + ("  (the smoother's)" if order == kept else ""), flush=True)
    finally:
        trial.ORDER = kept


def cost(frames: int) -> None:
    from fccgrb_cli.dynamics.uncertainty import moment_uncertainty
    from fccgrb_cli.pipeline.smoothing import smooth, settings_of
    from fccgrb_cli.pipeline.options import SolveOptions
    from fccgrb_cli.solvers.nrm.solve import NrmSettings, solve_nrm
    from fccgrb_cli.pipeline.synth import synthesize
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
    smooth(model, nrm, markers[warm], settings_of(options, model))
    best = {"solve": np.inf, "smoother": np.inf, "uncertainty": np.inf}
    for _ in range(2):
        started = time.perf_counter()
        nrm = solve_nrm(mixed, time_, markers, settings)
        t1 = time.perf_counter()
        s = smooth(model, nrm, markers, settings_of(options, model))
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

    from fccgrb_cli.presentation.plot import save

    template = fc.load_model(ROOT / "configs" / "models" / "lower_limb.yaml")
    trial = fc.read_trial(QUALISYS)
    model = fc.calibrate(template, trial, mass=67)
    filtered = fc.solve(model, trial, filter_cutoff=6.0)
    smoothed = fc.solve(model, trial, smooth="auto")
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


class Walking:
    """The Qualisys trial calibrated as the README's gait example, its per-frame solution, the
    noise the smoother finds on it, and truths made from it (see the module's docstring)."""

    def __init__(self) -> None:
        from fccgrb_cli.solvers.smooth.coordinates import Coordinates
        from fccgrb_cli.system import compile_system

        template = fc.load_model(ROOT / "configs" / "models" / "lower_limb.yaml")
        self.measured = fc.read_trial(QUALISYS)
        self.model = fc.calibrate(template, self.measured, mass=67)
        self.per_frame = fc.solve(self.model, self.measured, smooth="none").result
        self.found = fc.solve(self.model, self.measured, smooth="auto").uncertainty
        self.system = compile_system(self.model, angles="driver")
        self.co = Coordinates.build(self.system, self.per_frame.q,
                                    np.arange(self.per_frame.n_frames))
        self.labels = tuple(self.measured.find(m) for m in self.model.marker_labels)

    def truth(self, cutoff: float) -> tuple[np.ndarray, ...]:
        """d, ḋ, d̈ and q of the per-frame coordinates low-passed at ``cutoff`` Hz."""
        from scipy.interpolate import make_interp_spline
        from scipy.signal import butter, filtfilt

        t = self.measured.time
        b, a = butter(2, cutoff / (self.measured.rate / 2))
        d = filtfilt(b, a, self.co.from_mixed(self.per_frame.q), axis=0)
        spline = make_interp_spline(t, d, k=5)
        d, d_d, d_dd = spline(t), spline(t, 1), spline(t, 2)
        n_body = self.system.layout.n_body_q
        return d, d_d, d_dd, self.co.positions(d, self.per_frame.q[:, :n_body])

    def plates(self, q: np.ndarray) -> list:
        """The trial's force plates as loads on the model at q (raw)."""
        from fccgrb_cli.dynamics.plate_loads import plate_loads
        from fccgrb_cli.pipeline.solve import points_along

        model = self.model
        contact = {body: points_along(self.system, q, [(body, p)
                                                       for p in model.body(body).points])
                   for body in model.contact_bodies}
        return plate_loads(model, self.measured, [], contact)

    def noisy(self, d: np.ndarray, q: np.ndarray, seed: int) -> np.ndarray:
        """The model's markers at d with the coordinates' own noise, plus the markers'."""
        rng = np.random.default_rng(seed)
        moved = self.co.positions(d + rng.normal(size=d.shape) * self.found.extra_sd, q)
        markers = self.co.markers(moved)
        return markers + rng.normal(scale=self.found.noise_m, size=markers.shape)


def gait(seeds: int) -> None:
    """The default's choice on walking with a known truth (see the module's docstring)."""
    from fccgrb_cli.dynamics.uncertainty import moments_at

    walk = Walking()
    t = walk.measured.time
    strike = np.abs(t - STRIKE) < 0.1
    methods = (("raw differences", {"smooth": "none"}),
               ("Butterworth 6 Hz", {"filter_cutoff": 6.0}),
               ("--smooth auto", {"smooth": "auto"}))
    print(f"\nwalking with a known truth: the Qualisys trial's coordinates low-passed at "
          f"{', '.join(f'{c:g}' for c in GAIT_TRUTH_HZ)} Hz, the model's {len(walk.labels)} "
          f"markers there with the noise found on the real trial (white "
          f"{1e3 * walk.found.noise_m:.2g} mm, the coordinates' own up to "
          f"{np.degrees(walk.found.extra_sd.max()):.2g} deg), {seeds} seeds; joint moment "
          f"error RMS / max (N·m, mean over the seeds), every frame | frames "
          f"{EDGE}…{len(t) - EDGE} | the right heel strike ±0.1 s")
    for cutoff in GAIT_TRUTH_HZ:
        d, d_d, d_dd, q = walk.truth(cutoff)
        for title, path, loads in (("with the force plates", str(QUALISYS), walk.plates(q)),
                                   ("without plates", "walking.trc", [])):
            truth = moments_at(walk.co, q, d, d_d, d_dd, loads)
            print(f"  truth at {cutoff:g} Hz, {title} (RMS {_rms(truth):.1f} N·m, peak "
                  f"{_largest(truth):.0f} N·m)")
            rows = {name: [] for name, _ in methods}
            for seed in range(seeds):
                trial = Trial(path, walk.labels, walk.noisy(d, q, seed), walk.measured.rate)
                for name, options in methods:
                    run = fc.solve(walk.model, trial, **options)
                    e = np.asarray(run.dynamics.inverse.joint_moments) - truth
                    rows[name].append([f(part) for part in (e, e[EDGE:-EDGE], e[strike])
                                       for f in (_rms, _largest)])
            for name, values in rows.items():
                cells = np.mean(values, axis=0).reshape(3, 2)
                print(f"    {name:<18} " + " | ".join(f"{r:7.2f}/{m:<7.1f}" for r, m in cells),
                      flush=True)


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2)))


def _largest(e: np.ndarray) -> float:
    return float(np.abs(e).max())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--monte-carlo", type=int, default=0, metavar="SEEDS")
    parser.add_argument("--cost", type=int, default=0, metavar="FRAMES")
    parser.add_argument("--figure", type=Path, default=None)
    parser.add_argument("--orders", action="store_true")
    parser.add_argument("--gait", type=int, default=0, metavar="SEEDS")
    parser.add_argument("--floor", type=int, default=0, metavar="SEEDS")
    parser.add_argument("--no-table", action="store_true")
    args = parser.parse_args()
    if args.figure is not None:
        figure(args.figure)
    if not (args.no_table and not args.monte_carlo and not args.orders and not args.floor):
        with tempfile.TemporaryDirectory(prefix="fccgrb-smoothing-") as folder:
            bar = FiveBar(Path(folder))
            if not args.no_table:
                table(bar)
            if args.floor:
                floor(bar, args.floor)
            if args.orders:
                orders(bar)
            if args.monte_carlo:
                monte_carlo(bar, args.monte_carlo)
    if args.gait:
        gait(args.gait)
    if args.cost:
        cost(args.cost)


if __name__ == "__main__":
    main()
