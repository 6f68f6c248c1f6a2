"""The edges' own machinery, each part against an oracle written here: the bounded YAML reader
(expansion counted in closed form), the guarded HDF5 writer (a byte-array model of the file
and a write that fails half-way), all-or-nothing renames, the writers' lock, names that become
paths, numbers every option refuses, and long C3D files written the way readers look for them."""

from __future__ import annotations

import errno
import math
import os
import threading
import time
from dataclasses import fields
from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.core import hdf5_writer
from fccgrb_cli.core.atomic import atomic_path, transaction
from fccgrb_cli.core.errors import InputError
from fccgrb_cli.core.inputs import MAX_DEPTH, MAX_VALUES, check_name, load_yaml, refuse_inputs
from fccgrb_cli.core.lock import exclusive, lock_path
from fccgrb_cli.pipeline.options import SolveOptions

# --- bounded YAML ---------------------------------------------------------------------------


def laughs(width: int, levels: int) -> tuple[str, int]:
    """A document of ``levels`` anchored lists, each holding ``width`` aliases of the one
    before (the first: ``width`` scalars), the last under the key ``top``; and the number of
    values it expands to, in closed form: level k holds s_k = 1 + width·s_(k−1) with s_0 =
    1 + width, and the document counts its mapping, the keys and every level once more where
    the keys name them."""
    lines = [f"a0: &a0 [{', '.join(['x'] * width)}]"]
    for k in range(1, levels):
        lines.append(f"a{k}: &a{k} [{', '.join([f'*a{k - 1}'] * width)}]")
    sizes = [1 + width]
    for _ in range(1, levels):
        sizes.append(1 + width * sizes[-1])
    total = 1 + levels + sum(sizes)  # the mapping, its keys, each anchored list once
    return "\n".join(lines) + "\n", total


@pytest.mark.parametrize("width,levels", [(9, 6), (9, 7), (3, 11), (3, 12), (2, 17), (2, 18)])
def test_alias_expansion_is_refused_exactly_past_the_limit(width: int, levels: int) -> None:
    text, total = laughs(width, levels)
    if total <= MAX_VALUES:
        doc = load_yaml(text, "doc.yaml")
        assert len(doc[f"a{levels - 1}"]) == width
    else:
        with pytest.raises(InputError, match=r"doc.yaml: line \d+: .*aliases"):
            load_yaml(text, "doc.yaml")


def test_nesting_is_refused_past_the_limit_without_recursion() -> None:
    """The document's mapping is the first level; lists under its key the next ones."""
    inner = MAX_DEPTH - 1
    assert load_yaml("x: " + "[" * inner + "]" * inner, "d.yaml") is not None
    with pytest.raises(InputError, match=f"nested at most {MAX_DEPTH}"):
        load_yaml("x: " + "[" * (inner + 1) + "]" * (inner + 1), "d.yaml")
    with pytest.raises(InputError, match=r"d\.yaml: line 1"):
        load_yaml("x: " + "{a: " * 20000 + "1" + "}" * 20000, "d.yaml")


# --- the guarded HDF5 writer ----------------------------------------------------------------


def test_guarded_file_reads_back_every_write_after_the_disk_fills(tmp_path: Path,
                                                                 monkeypatch) -> None:
    """Random writes at random offsets against a bytearray model; from the 3rd write on the
    disk is 'full': writes still 'succeed', reads still see them, the error is recorded."""
    rng = np.random.default_rng(5)
    real_pwrite, calls = os.pwrite, {"n": 0}

    def pwrite(fd, data, offset):
        calls["n"] += 1
        if calls["n"] >= 3:
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_pwrite(fd, data, offset)

    monkeypatch.setattr(hdf5_writer.os, "pwrite", pwrite)
    raw = hdf5_writer.GuardedFile(tmp_path / "g.bin", create=True)
    model = bytearray()
    for _ in range(40):
        offset = int(rng.integers(0, 3000))
        data = rng.integers(0, 256, int(rng.integers(1, 400)), dtype=np.uint8).tobytes()
        raw.seek(offset)
        assert raw.write(data) == len(data)
        model.extend(bytes(max(0, offset + len(data) - len(model))))
        model[offset:offset + len(data)] = data
        start = int(rng.integers(0, len(model)))
        raw.seek(start)
        assert raw.read(len(model) - start) == bytes(model[start:])
    raw.close()
    assert raw.error is not None and raw.error.errno == errno.ENOSPC


def test_a_failed_hdf5_write_is_an_oserror_after_a_clean_close(tmp_path: Path,
                                                              monkeypatch) -> None:
    """What crashed HDF5 (its close after a failed write) is now an OSError once closed."""
    real_pwrite, written = os.pwrite, {"bytes": 0}

    def pwrite(fd, data, offset):
        if written["bytes"] > 50_000:
            raise OSError(errno.EFBIG, "File too large")
        written["bytes"] += len(data)
        return real_pwrite(fd, data, offset)

    monkeypatch.setattr(hdf5_writer.os, "pwrite", pwrite)
    with pytest.raises(OSError) as caught, hdf5_writer.writing(tmp_path / "f.h5") as h5:
        for k in range(20):
            h5.create_dataset(f"d{k}", data=np.random.default_rng(k).random(20000),
                              chunks=True, compression="gzip")
    assert caught.value.errno == errno.EFBIG


def test_guarded_hdf5_file_reads_back_what_was_written(tmp_path: Path) -> None:
    import h5py

    values = {f"d{k}": np.random.default_rng(k).random((300, k + 1)) for k in range(6)}
    with hdf5_writer.writing(tmp_path / "f.h5") as h5:
        for key, data in values.items():
            h5.create_dataset(key, data=data, chunks=True, compression="gzip")
    with hdf5_writer.writing(tmp_path / "f.h5", "r+") as h5:
        h5["extra"] = [1, 2, 3]
    with h5py.File(tmp_path / "f.h5", "r") as h5:
        for key, data in values.items():
            np.testing.assert_array_equal(h5[key][()], data)
        assert list(h5["extra"][()]) == [1, 2, 3]


# --- all or nothing -------------------------------------------------------------------------


def test_a_transaction_renames_every_file_or_none(tmp_path: Path) -> None:
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old a")
    with pytest.raises(RuntimeError), transaction():
        with atomic_path(a) as tmp:
            tmp.write_text("new a")
        with atomic_path(b) as tmp:
            tmp.write_text("new b")
        raise RuntimeError("the command fails after writing both")
    assert a.read_text() == "old a" and not b.exists()
    with transaction():
        for path, text in ((a, "new a"), (b, "new b")):
            with atomic_path(path) as tmp:
                tmp.write_text(text)
    assert (a.read_text(), b.read_text()) == ("new a", "new b")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]


def test_a_failed_rename_puts_back_the_files_already_renamed(tmp_path: Path) -> None:
    a, b = tmp_path / "a.txt", tmp_path / "b.txt"
    a.write_text("old a")
    with pytest.raises(InputError, match=r"b\.txt: cannot write it"), transaction():
        with atomic_path(a) as tmp:
            tmp.write_text("new a")
        with atomic_path(b) as tmp:
            tmp.write_text("new b")
        b.mkdir()  # appears before the renames: a's is done, b's fails
        (b / "inside").write_text("x")
    assert a.read_text() == "old a"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.txt"]


def test_a_full_disk_while_writing_is_one_line_naming_the_output(tmp_path: Path) -> None:
    target = tmp_path / "x.txt"
    target.write_text("kept")
    with pytest.raises(InputError, match=r"x.txt: cannot write it \(the disk is full\); "
                                         r"nothing was written; the existing file is "
                                         r"unchanged"), atomic_path(target):
        raise OSError(errno.ENOSPC, "No space left on device")
    assert target.read_text() == "kept" and len(list(tmp_path.iterdir())) == 1


# --- the writers' lock ----------------------------------------------------------------------


def test_the_lock_serializes_writers_and_names_the_holder(tmp_path: Path) -> None:
    target = tmp_path / "r.h5"
    order: list[str] = []
    held = threading.Event()

    def first() -> None:
        with exclusive(target):
            held.set()
            order.append("first in")
            time.sleep(0.3)
            order.append("first out")

    thread = threading.Thread(target=first)
    thread.start()
    held.wait()
    with pytest.raises(InputError, match=f"pid {os.getpid()} is writing it"), \
            exclusive(target, wait=0):
        pass
    told: list[str] = []
    with exclusive(target, wait=10, waiting=told.append):
        order.append("second in")
    thread.join()
    assert order == ["first in", "first out", "second in"]
    assert len(told) == 1 and "waiting for" in told[0]
    assert not lock_path(target).exists()


# --- names and outputs ----------------------------------------------------------------------


@pytest.mark.parametrize("name", ["/reference", "a/b", "../../x", ".", "..", "....", "", " ",
                                  "x\ty", "a\\b", " lead", "x" * 201, 7])
def test_names_that_would_leave_their_group_are_refused(name) -> None:
    with pytest.raises(InputError, match="--name: expected"):
        check_name(name, "--name")


@pytest.mark.parametrize("name", ["nrm-wls-P30", "walk 01-ad", "ü", "x" * 200, "reference"])
def test_plain_names_pass(name: str) -> None:
    assert check_name(name, "--name") == name


def test_an_output_that_is_an_input_by_another_spelling_is_refused(tmp_path: Path) -> None:
    model = tmp_path / "m.yaml"
    model.write_text("x")
    os.symlink(model, tmp_path / "link.yaml")
    os.link(model, tmp_path / "hard.yaml")
    (tmp_path / "sub").mkdir()
    for output in (model, tmp_path / "link.yaml", tmp_path / "hard.yaml",
                   tmp_path / "sub" / ".." / "m.yaml"):
        with pytest.raises(InputError, match="inputs are never modified"):
            refuse_inputs(output, [model])
    refuse_inputs(tmp_path / "other.yaml", [model])


# --- numbers --------------------------------------------------------------------------------

NUMERIC = [f.name for f in fields(SolveOptions) if f.metadata["low"] is not None]


@pytest.mark.parametrize("name", NUMERIC)
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf, 1e308, -1e308, True])
def test_every_numeric_option_refuses_nan_infinity_and_out_of_range(name: str,
                                                                    value: float) -> None:
    with pytest.raises(InputError, match=f"^{name}: expected"):
        SolveOptions(**{name: value})


@pytest.mark.parametrize("value", ["no", "yes", 1, 0, "false"])
def test_a_switch_is_true_or_false(value) -> None:
    with pytest.raises(InputError, match="dynamics: expected true or false"):
        SolveOptions.from_mapping({"dynamics": value}, "cell")


# --- long C3D files -------------------------------------------------------------------------


def test_a_long_trial_written_by_fccgrb_is_read_back_whole(tmp_path: Path) -> None:
    """Past 65,535 frames the count goes to TRIAL:ACTUAL_START/END_FIELD and
    POINT:LONG_FRAMES (io.c3d), both read here from the file's own bytes."""
    from fccgrb_cli.trial.c3d import write_markers
    from fccgrb_cli.trial.c3d_header import read_layout, read_parameters
    from fccgrb_cli.trial.record import read_trial

    n = 70_001
    markers = np.zeros((n, 1, 3))
    markers[:, 0, 0] = np.arange(n) * 1e-5
    markers[66_000, 0] = np.nan
    path = tmp_path / "long.c3d"
    write_markers(path, ["A"], markers, 250.0)
    params = read_parameters(path)
    start, end = params["TRIAL:ACTUAL_START_FIELD"].values, params["TRIAL:ACTUAL_END_FIELD"].values
    assert int(start[0]) + 65536 * int(start[1]) == 1
    assert (int(end[0]) & 0xFFFF) + 65536 * int(end[1]) == n
    assert params["POINT:LONG_FRAMES"].values[0] == n
    assert read_layout(path).frames == n
    trial = read_trial(path)
    assert trial.markers.shape == (n, 1, 3) and trial.rate == 250.0
    assert np.isnan(trial.markers[66_000]).all()
    ok = ~np.isnan(markers)
    assert np.max(np.abs(trial.markers[ok] - markers[ok])) < 1e-7
