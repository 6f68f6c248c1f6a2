"""Long trials in bounded memory: ``fccgrb solve`` keeps a run's largest per-frame arrays on
disk from the moment the later stages are done with them (``core/spill.py``), computes the model
points and their distances a block of frames at a time, and reads a C3D's parameters without
ezc3d's per-point objects. None of it may change a result: a run solved with a spill folder
writes the same results file, dataset by dataset and bit for bit, as the run held in memory.

The two runs of test_results_storage: the bundled five-bar (perturbed, inverse dynamics,
filtered) and, with the shared data, the real walking trial (plates, clinical, gait)."""

from __future__ import annotations

import gc
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_helpers import one_error_line, run_cli
from test_results_storage import FIVE_BAR, FIVE_BAR_TRIAL, GAIT_TRIAL, ROOT

import fccgrb_cli as fc
from fccgrb_cli.core.spill import Spill, StoredArray
from fccgrb_cli.pipeline.run import summary
from fccgrb_cli.pipeline.solve import distances, points_along, solve_trial
from fccgrb_cli.results.storage import write_run
from fccgrb_cli.system import compile_system
from fccgrb_cli.trial.c3d_header import read_parameters

SPILLED = ("reference", "markers_input", "model_points", "ed", "ed_input")
SPILLED_RESULT = ("q", "qd", "qdd", "theta_d", "theta_dd")
TIMINGS = "time_s"  # wall-clock seconds: two solves never agree on them


def _inputs(case: str):
    if case == "five_bar":
        options = fc.SolveOptions(method="nrm-wls", perturb_mm=30, dynamics=True,
                                  filter_cutoff=6.0)
        return fc.load_model(FIVE_BAR), fc.read_trial(FIVE_BAR_TRIAL), options
    if not GAIT_TRIAL.exists():
        pytest.skip(f"{GAIT_TRIAL}: the shared data are not here")
    from fccgrb_cli.anatomy.calibrate import calibrate
    from fccgrb_cli.model import parse_model

    trial = fc.read_trial(GAIT_TRIAL)
    template = fc.load_model(ROOT / "configs" / "models" / "lower_limb.yaml")
    model = parse_model(calibrate(template, trial, mass=67.0).text, "personal.yaml")
    return model, trial, fc.SolveOptions(method="nrm-wls", dynamics=True, filter_cutoff=6.0)


@pytest.fixture(scope="module", params=["five_bar", "gait"])
def pair(request, tmp_path_factory):
    """The same trial solved in memory and with a spill folder, each written to a file."""
    model, trial, options = _inputs(request.param)
    folder = tmp_path_factory.mktemp(request.param)
    plain = solve_trial(model, trial, options)
    spilled = solve_trial(model, trial, options, spill=folder)
    stored = [getattr(spilled, key) for key in SPILLED] + \
        [getattr(spilled.result, key) for key in SPILLED_RESULT] + \
        [getattr(spilled.dynamics.kinematics, key) for key in ("q", "qd", "qdd")] + \
        [spilled.dynamics.inverse.lam]
    assert all(isinstance(a, StoredArray) for a in stored)
    assert len(list(folder.glob(".fccgrb-spill-*"))) == 1
    write_run(folder / "plain.h5", plain, "test")
    write_run(folder / "spilled.h5", spilled, "test")
    return plain, spilled, folder


def _datasets(path: Path) -> dict[str, h5py.Dataset]:
    out: dict[str, tuple] = {}
    with h5py.File(path) as h5:
        def visit(name: str, item) -> None:
            if isinstance(item, h5py.Dataset):
                out[name] = (item.dtype, item.shape, item.chunks, item.compression,
                             item.shuffle, item[()], dict(item.attrs))
        h5.visititems(visit)
    return out


def test_a_spilled_run_writes_the_same_file_bit_for_bit(pair) -> None:
    plain, _, folder = pair
    a, b = _datasets(folder / "plain.h5"), _datasets(folder / "spilled.h5")
    assert sorted(a) == sorted(b)
    assert len(a) > 30
    differ = []
    for name, (dtype, shape, chunks, compression, shuffle, values, attrs) in a.items():
        other = b[name]
        layout = (dtype, shape, chunks, compression, shuffle, attrs.keys())
        timing = name.rsplit("/", 1)[-1] == TIMINGS
        if layout != (*other[:5], other[6].keys()) or (not timing and not np.array_equal(
                values, other[5], equal_nan=dtype.kind == "f")):
            differ.append(name)
    assert not differ, differ
    # and the file holds the in-memory run's own arrays
    group = f"runs/{plain.name}"
    assert np.array_equal(b[f"{group}/qdd"][5], plain.result.qdd)
    assert np.array_equal(b[f"{group}/classical/q"][5], plain.dynamics.kinematics.q)
    assert np.array_equal(b[f"{group}/lambda"][5], plain.dynamics.inverse.lam)
    assert np.array_equal(b[f"{group}/model_points"][5], plain.model_points)
    assert np.array_equal(b["reference/markers"][5], plain.reference, equal_nan=True)
    assert np.array_equal(b[f"{group}/ed_input"][5], plain.ed_input, equal_nan=True)


def test_once_written_the_stored_arrays_read_the_results_file(pair) -> None:
    plain, spilled, folder = pair
    assert not list(folder.glob(".fccgrb-spill-*"))  # the scratch file is gone
    assert spilled.result.qd.spill.path == folder / "spilled.h5"
    for key in SPILLED:
        assert np.array_equal(np.asarray(getattr(spilled, key)), getattr(plain, key),
                              equal_nan=True), key
    for key in SPILLED_RESULT:
        assert np.array_equal(np.asarray(getattr(spilled.result, key)),
                              getattr(plain.result, key)), key
    assert np.array_equal(spilled.result.theta, plain.result.theta)
    assert spilled.result.theta.base is None  # not a view keeping q's memory alive
    one, other = summary(plain), summary(spilled)
    del one["ms/frame"], other["ms/frame"]
    assert one == other
    # written again elsewhere: copied from the results file, the same bytes
    write_run(folder / "again.h5", spilled, "test")
    with h5py.File(folder / "again.h5") as h5:
        assert np.array_equal(h5[f"runs/{plain.name}/q"][()], plain.result.q)


def test_a_spill_is_deleted_with_its_last_reference(tmp_path: Path) -> None:
    spill = Spill(tmp_path)
    stored = spill.keep("classical/q", np.arange(12.0).reshape(4, 3))
    assert stored.shape == (4, 3) and len(stored) == 4 and stored.ndim == 2
    assert np.array_equal(stored[1:3], [[3, 4, 5], [6, 7, 8]])
    path = spill.path
    assert path.exists()
    del spill, stored
    gc.collect()
    assert not path.exists()


def test_a_missing_results_folder_is_one_line_before_the_solve(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere"
    result = run_cli("solve", FIVE_BAR, FIVE_BAR_TRIAL, "-o", missing / "results.h5")
    one_error_line(result, str(missing), "does not exist")


def test_points_and_distances_by_blocks_equal_all_frames_at_once() -> None:
    model = fc.load_model(FIVE_BAR)
    trial = fc.read_trial(FIVE_BAR_TRIAL)
    run = fc.solve(model, trial, method="nrm-wls", perturb_mm=30, dynamics=False)
    system = compile_system(run.model, angles="coordinate", track=True)
    which = [(tp.body, tp.point) for tp in run.model.tracked_points]
    whole = points_along(system, run.result.q, which, block=len(trial.markers))
    assert np.array_equal(points_along(system, run.result.q, which, block=7), whole)
    # each point from its body's own frame (Eq. 2): r + l1 u + l2 v + l3 w, at frame 123
    locals_ = []
    for k, (body, point) in enumerate(which):
        coordinates = run.result.q[123, system.layout.q_slice(body)].reshape(-1, 3)
        r, u, v = coordinates[:3]
        w = coordinates[3] if len(coordinates) == 4 else np.cross(u, v)  # reduced: w = u × v
        local = run.model.body(body).points[point].local
        locals_.append(local)
        assert np.allclose(whole[123, k], r + local[0] * u + local[1] * v + local[2] * w,
                           rtol=0, atol=1e-15)
    assert (np.abs(locals_) > 0).any(axis=0).all()  # every term of Eq. 2 is exercised
    reference = run.reference
    assert np.array_equal(distances(whole, reference, block=7),
                          np.linalg.norm(whole - reference, axis=2))


@pytest.mark.parametrize("path", [FIVE_BAR_TRIAL, GAIT_TRIAL], ids=["five_bar", "gait"])
def test_the_parameter_section_reads_as_ezc3d_reads_it(path: Path) -> None:
    if not path.exists():
        pytest.skip(f"{path}: the shared data are not here")
    import ezc3d

    ours = read_parameters(path)
    theirs = ezc3d.c3d(str(path))["parameters"]
    compared = texts = 0
    for group, params in theirs.items():
        if group.startswith("__"):
            continue
        for name, param in params.items():
            if name.startswith("__") or f"{group}:{name}" not in ours:
                continue
            mine, value = ours[f"{group}:{name}"], param["value"]
            if mine.kind == -1:
                assert list(mine.values) == [str(v) for v in value], (group, name)
                texts += 1
            else:
                flat = np.asarray(value, dtype=float).ravel(order="F")
                assert np.array_equal(mine.values, flat), (group, name)
            compared += 1
    assert compared >= 20 and texts >= 3
    labels = ours["POINT:LABELS"]
    assert labels.dims[1:] == (len(labels.values),)


def test_a_tracked_vector_reads_its_markers_from_the_lighter_trial(tmp_path: Path) -> None:
    """A body followed by the unit vector between two markers the model does not track (as
    test_generated's): the trial ``solve_trial`` keeps after the selection holds them."""
    from generated_models import Structure
    from test_generated import vector_case
    from yaml import safe_dump

    from fccgrb_cli.model import parse_model

    _, spec, trial = vector_case(Structure((-1, 0, 1), ("revolute", "spherical",
                                                        "revolute"), "reduced", 7))
    model = parse_model(safe_dump(spec, sort_keys=False), "vectors.yaml")
    assert model.tracked_vectors and not {
        label for tv in model.tracked_vectors for label in (tv.from_marker, tv.to_marker)
    } <= set(model.marker_labels)
    options = fc.SolveOptions(method="nrm-wls", tol=1e-12, events="none", dynamics=False)
    plain = solve_trial(model, trial, options)
    spilled = solve_trial(model, trial, options, spill=tmp_path)
    assert np.array_equal(np.asarray(spilled.result.q), plain.result.q)
    assert np.array_equal(spilled.result.theta, plain.result.theta)


def test_the_dynamics_stage_by_blocks_of_frames(monkeypatch) -> None:
    """x, ẋ (Stacked.expand, expand_rate) and ‖Φ‖, max |Φ_top| (ad._result) go a block of
    frames at a time: with blocks of 7 over 50 frames they equal the per-frame x (Eq. 5), the
    central difference of x along q̇, and the reductions of all frames at once, bit for bit
    where nothing but the blocks changed (a block skipped or shifted leaves frames unset)."""
    from fccgrb_cli.solvers import batched
    from fccgrb_cli.solvers.ad.solve import _result, stacked_drives
    from fccgrb_cli.solvers.kernel_arrays import DrivenMotion

    system = compile_system(fc.load_model(FIVE_BAR).with_form("reduced"), angles="driver")
    assert len(system.layout.reduced_w)
    rng = np.random.default_rng(3)
    n = 50
    q, qd = rng.normal(size=(2, n, system.nq))
    phi = rng.normal(size=(n, system.n_rows))
    monkeypatch.setattr(batched, "BLOCK", 7)
    stacked = batched.Stacked(system)
    assert np.array_equal(stacked.expand(q), [system.layout.expand(f) for f in q])
    h = 1e-6
    central = (stacked.expand(q + h * qd) - stacked.expand(q - h * qd)) / (2 * h)
    assert np.allclose(stacked.expand_rate(q, qd), central, rtol=0, atol=1e-8)
    theta = np.zeros((n, len(system.model.angles)))
    motion = DrivenMotion(q, qd, qd, phi, np.zeros(n, dtype=int), np.ones(n, dtype=bool))
    result = _result(system, np.arange(n) / 100.0,
                     stacked_drives(system, theta, theta, theta, None), motion, np.zeros(n),
                     1e-10)
    topology = system.masks()["topology"]
    assert topology.any()
    assert np.array_equal(result.phi_norm, np.linalg.norm(phi, axis=1))
    assert np.array_equal(result.phi_top_max, np.abs(phi[:, topology]).max(axis=1))


def test_only_a_long_trial_spills_by_default(monkeypatch) -> None:
    """Below FCCGRB_SPILL_MB (64 MiB of estimated arrays by default) a run stays in memory: the
    five-bar's 300 frames do; an hour at 1 kHz does not; 0 spills every run."""
    from fccgrb_cli.core.errors import InputError
    from fccgrb_cli.pipeline import solve as stage

    model, trial, _ = _inputs("five_bar")
    monkeypatch.delenv(stage.SPILL_SETTING, raising=False)
    assert not stage._worth_spilling(model, trial)
    hour = trial.__class__(trial.path, trial.labels, np.zeros((3_600_000, 1, 3)), 1000.0,
                           trial.warnings, trial.start)
    assert stage._worth_spilling(model, hour)
    monkeypatch.setenv(stage.SPILL_SETTING, "0")
    assert stage._worth_spilling(model, trial)
    monkeypatch.setenv(stage.SPILL_SETTING, "lots")
    with pytest.raises(InputError, match="FCCGRB_SPILL_MB"):
        stage._worth_spilling(model, trial)
