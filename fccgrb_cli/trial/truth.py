"""The truth sidecar of a synthesized trial: ``TRIAL.truth.h5`` beside ``TRIAL.c3d``.

Layout (SI units, double precision):
  /time (frames,) s
  /theta, /theta_d, /theta_dd (frames × coordinates) rad, rad/s, rad/s² (m, m/s, m/s² for a
           distance coordinate); attribute ``names``, in the model's order (angles, distances)
  /q (frames × nq) the AD solution; attribute ``form``
  /markers (frames × markers × 3) m, exactly (the C3D stores them as 32-bit floats);
           attribute ``labels``
  root attributes: ``rate`` (Hz), ``model`` (the YAML text), ``fccgrb_version``.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from fccgrb_cli import __version__
from fccgrb_cli.core.atomic import atomic_path
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.hdf5_writer import writing
from fccgrb_cli.core.inputs import regular_file


@dataclass(frozen=True)
class Truth:
    time: np.ndarray
    theta: np.ndarray
    theta_d: np.ndarray
    theta_dd: np.ndarray
    angle_names: tuple[str, ...]
    q: np.ndarray
    form: str
    markers: np.ndarray
    labels: tuple[str, ...]
    rate: float
    model_text: str


def truth_path(trial: str | Path) -> Path:
    """Where the sidecar of a trial lives."""
    trial = Path(trial)
    return trial.with_name(trial.stem + ".truth.h5")


def write_truth(path: str | Path, truth: Truth) -> None:
    with atomic_path(path) as tmp, writing(tmp) as h5:
        h5.attrs["rate"] = truth.rate
        h5.attrs["model"] = truth.model_text
        h5.attrs["fccgrb_version"] = __version__
        h5["time"] = truth.time
        for key in ("theta", "theta_d", "theta_dd", "q", "markers"):
            h5.create_dataset(key, data=getattr(truth, key), compression="gzip")
        for key in ("theta", "theta_d", "theta_dd"):
            h5[key].attrs["names"] = list(truth.angle_names)
        h5["q"].attrs["form"] = truth.form
        h5["markers"].attrs["labels"] = list(truth.labels)


def read_truth(path: str | Path) -> Truth:
    import h5py

    path = Path(path)
    if not path.exists():
        raise InputError(f"{path}: truth file not found (made by 'fccgrb synth' beside the trial)")
    regular_file(path, "truth file")
    try:
        with h5py.File(path, "r") as h5:
            return Truth(
                time=h5["time"][()], theta=h5["theta"][()], theta_d=h5["theta_d"][()],
                theta_dd=h5["theta_dd"][()],
                angle_names=tuple(str(n) for n in h5["theta"].attrs["names"]),
                q=h5["q"][()], form=str(h5["q"].attrs["form"]), markers=h5["markers"][()],
                labels=tuple(str(n) for n in h5["markers"].attrs["labels"]),
                rate=float(h5.attrs["rate"]), model_text=str(h5.attrs["model"]))
    except (OSError, KeyError, ValueError, TypeError, IndexError) as exc:
        reason = str(exc).splitlines()[0] if str(exc) else exc.__class__.__name__
        raise InputError(f"{path}: not a readable truth file ({reason})") from None
