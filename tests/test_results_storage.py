"""The results file's storage for long trials: large arrays are written chunked and
compressed, and reading a file back gives every array of the run that wrote it bit for bit —
so ``fccgrb report``, ``fccgrb export`` and ``read_results`` see exactly what was solved.

Two runs: the bundled five-bar (perturbed, a truth file, inverse dynamics) and, when the shared
data are here, the real walking trial Qualisys.c3d on the calibrated lower-limb model (force
plates as loads, clinical angles and moments, gait events and cycles)."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import h5py
import numpy as np
import pytest

import fccgrb_cli as fc
from fccgrb_cli.core import datasets
from fccgrb_cli.pipeline.run import summary
from fccgrb_cli.presentation.tables import collect
from fccgrb_cli.results.export import write_csv
from fccgrb_cli.results.runs import read_runs
from fccgrb_cli.results.storage import write_run

ROOT = Path(__file__).resolve().parents[1]
FIVE_BAR = ROOT / "configs" / "models" / "five_bar.yaml"
FIVE_BAR_TRIAL = ROOT / "sample_data" / "five_bar.c3d"
GAIT_TRIAL = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"


def five_bar_run() -> fc.Run:
    return fc.solve(fc.load_model(FIVE_BAR), fc.read_trial(FIVE_BAR_TRIAL), method="nrm-wls",
                    perturb_mm=30, dynamics=True, filter_cutoff=6.0)


def gait_run() -> fc.Run:
    if not GAIT_TRIAL.exists():
        pytest.skip(f"{GAIT_TRIAL}: the shared data are not here")
    from fccgrb_cli.anatomy.calibrate import calibrate
    from fccgrb_cli.model import parse_model

    trial = fc.read_trial(GAIT_TRIAL)
    template = fc.load_model(ROOT / "configs" / "models" / "lower_limb.yaml")
    model = parse_model(calibrate(template, trial, mass=67.0).text, "personal.yaml")
    return fc.solve(model, trial, method="nrm-wls", dynamics=True, filter_cutoff=6.0)


def leaves(value, path: str = "run") -> dict[str, object]:
    """Every array, number and string inside a Run (dataclasses, tuples and dicts followed),
    by its attribute path."""
    if dataclasses.is_dataclass(value):
        out = {}
        for field in dataclasses.fields(value):
            out.update(leaves(getattr(value, field.name), f"{path}.{field.name}"))
        return out
    if isinstance(value, dict):
        out = {}
        for key, item in value.items():
            out.update(leaves(item, f"{path}[{key!r}]"))
        return out
    if isinstance(value, tuple) and any(isinstance(v, np.ndarray) or dataclasses.is_dataclass(v)
                                        for v in value):
        out = {}
        for k, item in enumerate(value):
            out.update(leaves(item, f"{path}[{k}]"))
        return out
    return {path: value}


def same(a, b) -> bool:
    """Equal bit for bit: arrays in shape, dtype kind and every value (NaN where NaN)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape or a.dtype.kind != b.dtype.kind:
            return False
        return bool(np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))
    if isinstance(a, float) and isinstance(b, float):
        return a == b or (np.isnan(a) and np.isnan(b))
    return a == b


LARGE = 1 << 16  # bytes: the size from which the fixture's runs are compressed


@pytest.fixture(scope="module", params=["five_bar", "gait"])
def written(request, tmp_path_factory) -> tuple[fc.Run, Path]:
    run = five_bar_run() if request.param == "five_bar" else gait_run()
    path = tmp_path_factory.mktemp(request.param) / "results.h5"
    # these short trials' arrays fall below the default size for compression: a smaller one
    # makes some of them large, so that both ways of storing are written and read back
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(datasets, "LARGE", LARGE)
        write_run(path, run, "fccgrb solve (test)")
    return run, path


def test_every_array_reads_back_bit_for_bit(written):
    run, path = written
    back = read_runs(path)[run.name]
    solved, read = leaves(run), leaves(back)
    arrays = [key for key, value in solved.items() if isinstance(value, np.ndarray)]
    assert len(arrays) > 25
    assert {"run.result.q", "run.result.qdd", "run.dynamics.inverse.lam",
            "run.dynamics.kinematics.qd", "run.model_points", "run.ed_input"} <= set(arrays)
    missing = sorted(set(solved) - set(read))
    assert not missing, f"not read back: {missing}"
    differ = [key for key in solved if not same(solved[key], read[key])]
    assert not differ, f"read back differently: {differ}"


def test_large_arrays_are_chunked_and_compressed_small_ones_contiguous(written):
    run, path = written
    large = small = 0
    with h5py.File(path) as h5:
        def check(name: str, item) -> None:
            nonlocal large, small
            if not isinstance(item, h5py.Dataset) or item.dtype.kind not in "biuf":
                return
            if item.size * item.dtype.itemsize >= LARGE:
                large += 1
                assert item.chunks is not None and item.compression == "gzip", name
                assert item.shuffle, name
            else:
                small += 1
                assert item.chunks is None and item.compression is None, name
        h5.visititems(check)
        q = h5[f"runs/{run.name}/q"]
        assert q.shape == run.result.q.shape and q.nbytes >= LARGE
        # a stretch of frames is read without the rest, and equals the run's
        assert np.array_equal(q[100:110], run.result.q[100:110])
    assert large >= 3 and small >= 3


def test_report_and_export_read_the_chunked_file(written, tmp_path):
    run, path = written
    _, (row,) = collect(path)
    expected = summary(run)
    assert row.values["iterations/frame"] == expected["iter/frame"]
    assert row.values["mean ED (mm)"] == pytest.approx(expected["mean ED mm"], rel=1e-12)
    assert row.values["max |Φ_top|"] == expected["max |Phi_top|"]
    csv = tmp_path / "run.csv"
    write_csv(read_runs(path)[run.name], csv)
    direct = tmp_path / "direct.csv"
    write_csv(run, direct)
    assert csv.read_text(encoding="utf-8") == direct.read_text(encoding="utf-8")
