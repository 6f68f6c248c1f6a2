"""A gait trial: personalize the lower-limb template on a walking trial, then solve it.

The Qualisys walking trial of the shared data (200 Hz, 340 frames, two force plates) is not
bundled with fccgrb. When ``../shared/data/c3d/Qualisys.c3d`` (next to the repository) is
absent, this script says so and stops. ``configs/models/lower_limb.yaml`` is a template: a
floating pelvis, thighs, shanks and feet, with 12 joint angles. ``fc.calibrate`` fits its segment
frames, joint centres and markers to the trial, and gives it de Leva's inertia for a 67 kg
subject (as ``fccgrb calibrate --mass 67`` does). The solve then gives clinical angles in degrees
and internal joint moments in N·m/kg, with the angles low-passed at 6 Hz before the dynamics.

    python examples/gait_trial.py
"""

import sys
from pathlib import Path

import fccgrb_cli as fc

ROOT = Path(__file__).resolve().parents[1]
TRIAL = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"

if not TRIAL.is_file():
    print(f"skipped: the shared walking trial {TRIAL} is not on this machine")
    sys.exit(0)

trial = fc.read_trial(TRIAL)
template = fc.load_model(ROOT / "configs" / "models" / "lower_limb.yaml")
subject = fc.calibrate(template, trial, mass=67.0)
print(f"trial: {trial.n_frames} frames at {trial.rate:g} Hz; personal model "
      f"{sum(body.inertia.mass for body in subject.bodies):.1f} kg of segments")

run = fc.solve(subject, trial, method="nrm-wls", filter_cutoff=6.0)
print(run)

angles, moments = run.clinical_angles, run.clinical_moments
trusted = run.moments_trusted  # frames × the model's angles: where each moment can be used
print(f"{'clinical angle':>20} {'min deg':>8} {'max deg':>8} {'min N·m/kg':>11} {'max N·m/kg':>11}")
for name in angles.names:
    moment = moments[name][trusted[:, run.angles.names.index(name)]]
    print(f"{name:>20} {angles[name].min():8.1f} {angles[name].max():8.1f} "
          f"{moment.min():11.2f} {moment.max():11.2f}")
print(f"right knee flexion peak: {angles['knee_flexion_r'].max():.1f}° (walking: about 55–70°)")
print(f"moments trusted on {int(trusted.all(axis=1).sum())} of {trial.n_frames} frames "
      "(elsewhere a foot stands off the force plates)")
