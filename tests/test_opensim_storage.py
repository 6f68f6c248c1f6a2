"""OpenSim storage files (.mot/.sto): every one of opensim-core's test files that the project
holds (../shared/data/opensim, never copied) read to the shapes, times and numbers printed in
it; generated tables written and read back exactly; hostile files refused in one line naming
the file and the line or header key."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.opensim import storage
from fccgrb_cli.opensim.storage import read_storage, storage_text, write_storage

OPENSIM = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim"
needs_data = pytest.mark.skipif(not OPENSIM.is_dir(), reason="../shared/data/opensim absent")

# file: (rows, data columns, first time, last time, in_degrees, (column, first value, last value))
# the numbers as printed in the files (head and tail)
SHARED = {
    "id_gait2392/subject01_walk1_ik.mot":
        (211, 23, 0.5, 4.0, None, ("pelvis_tilt", 4.49855378, 6.15000323)),
    "id_gait2392/arm26_InverseKinematics.mot":
        (121, 11, 0.0, 1.0, None, ("r_elbow_flex", 0.89932091, 90.10762135)),
    "id_gait2392/subject01_walk1_grf.mot":
        (9009, 18, 0.0, 15.0133, None, ("l_ground_force_vy", 20.49185173, 577.1324767)),
    "id_gait2392/std_arm26_InverseDynamics.sto":
        (121, 2, -0.00000020000000500175, 0.99999939999998499, None,
         ("r_shoulder_elev_moment", 0.055583585137658743, 2.7766589517128066)),
    "id_gait2392/std_subject01_InverseDynamics.sto":
        (73, 23, 0.39999934, 1.59999886, None, ("pelvis_tilt_moment", 28.75817773, -5.93910464)),
    "ik_gait2354_synthetic/std_subject01_walk1_ik.mot":
        (73, 23, 0.4, 1.6, None, ("pelvis_tilt", 5.21211788, 6.35307847)),
    "c3d_walking/std_cop_walking2_grfs.sto":
        (101, 18, 0.0, 4.9955, None, ("f1_1", 2.27511001, 0.89219999)),
    "c3d_walking/std_cop_walking5_grfs.sto":
        (90, 18, 0.0, 4.4115, None, ("f1_1", 2.23049998, 2.40894008)),
    "c3d_walking/std_walking2_grfs.sto":
        (101, 18, 0.0, 4.9955, None, ("p1_1", 918.59997559, 918.59997559)),
    "c3d_walking/std_walking5_grfs.sto":
        (90, 18, 0.0, 4.4115, None, ("f1_1", 2.23049998, 2.40894008)),
    "c3d_walking/std_walking2_analog.sto":
        (11, 12, 0.0, 4.9955, None, ("Fx1", 0.8897200226783752, None)),
    "c3d_walking/std_walking5_analog.sto":
        (10, 12, 0.0, 4.4115, None, ("Fx1", 1.24560809135437, 0.8007479906082153)),
}


@needs_data
def test_every_shared_storage_file_is_in_the_table():
    found = {str(p.relative_to(OPENSIM)) for p in OPENSIM.rglob("*") if p.suffix in
             (".mot", ".sto")}
    assert found == set(SHARED)


@needs_data
@pytest.mark.parametrize("name", sorted(SHARED))
def test_shared_files_read_as_printed(name):
    rows, columns, first, last, degrees, (column, head, tail) = SHARED[name]
    table = read_storage(OPENSIM / name)
    assert table.values.shape == (rows, columns) and table.time.shape == (rows,)
    assert len(table.names) == columns and "time" not in table.names
    assert table.time[0] == pytest.approx(first, abs=1e-12)
    assert table.time[-1] == pytest.approx(last, abs=1e-12)
    assert table.in_degrees is degrees
    assert table.column(column)[0] == pytest.approx(head, rel=1e-12)
    if tail is not None:
        assert table.column(column)[-1] == pytest.approx(tail, rel=1e-12)


@needs_data
def test_headers_of_both_layouts():
    simm = read_storage(OPENSIM / "id_gait2392/subject01_walk1_grf.mot")
    assert simm.header["datarows"] == "9009" and simm.header["range"] == "0.000000 15.013300"
    assert simm.title == "subject01_walk1_grf.mot"
    v4 = read_storage(OPENSIM / "c3d_walking/std_walking2_analog.sto")
    assert v4.header["DataRate"] == "2000.000000" and v4.header["version"] == "3"
    both = read_storage(OPENSIM / "ik_gait2354_synthetic/std_subject01_walk1_ik.mot")
    assert both.title == "first trial" and both.header["nRows"] == "73"
    assert both.header["datacolumns"] == "24"


@needs_data
def test_non_uniform_time_is_said_not_refused():
    cop = read_storage(OPENSIM / "c3d_walking/std_cop_walking5_grfs.sto")
    assert len(cop.notes) == 1 and "4.4115 s" in cop.notes[0] and "not uniform" in cop.notes[0]
    # 600 Hz printed to 0.0001 s: steps of 0.0016 and 0.0017 s are one uniform rate
    assert read_storage(OPENSIM / "id_gait2392/subject01_walk1_grf.mot").notes == ()


def _table(rows=7, columns=4, seed=3):
    rng = np.random.default_rng(seed)
    time = 0.25 + np.arange(rows) / 120.0
    values = rng.normal(scale=10.0 ** rng.integers(-6, 6, columns), size=(rows, columns))
    return [f"c{k}" for k in range(columns)], time, values


@pytest.mark.parametrize("degrees", [True, False])
def test_round_trip_is_exact(tmp_path, degrees):
    names, time, values = _table()
    path = tmp_path / "out.sto"
    write_storage(path, names, time, values, degrees, title="trial", header={"units": "N·m"})
    back = read_storage(path)
    assert back.names == tuple(names) and back.in_degrees is degrees
    np.testing.assert_array_equal(back.time, time)
    np.testing.assert_array_equal(back.values, values)
    assert back.title == "trial" and back.header["units"] == "N·m"
    assert back.header["nRows"] == "7" and back.header["nColumns"] == "5"


def test_simm_layout_and_spaces_read_alike(tmp_path):
    _, time, values = _table(rows=5, columns=3)
    body = "\n".join(" ".join(repr(v) for v in row)
                     for row in np.column_stack([time, values]).tolist())
    path = tmp_path / "simm.mot"
    path.write_text(f"name simm\ndatacolumns 4\ndatarows 5\nrange {time[0]} {time[-1]}\n"
                    f"endheader\ntime   c0  c1  c2\n{body}\n")
    back = read_storage(path)
    np.testing.assert_array_equal(back.values, values)
    assert back.names == ("c0", "c1", "c2") and back.title == "simm"


def test_missing_values_only_when_accepted(tmp_path):
    names, time, values = _table()
    values[2, 1] = np.nan
    path = tmp_path / "gaps.sto"
    write_storage(path, names, time, values, True)
    with pytest.raises(InputError, match=r"gaps.sto: line 10, column 3: expected a finite"):
        read_storage(path)
    back = read_storage(path, missing=True)
    assert np.isnan(back.values[2, 1]) and np.isfinite(np.delete(back.values, 9)).all()


HEADER = "t\nversion=1\nnRows=2\nnColumns=3\ninDegrees=yes\nendheader\ntime\ta\tb\n"
HOSTILE = {
    "empty": ("", "expected an OpenSim storage file, got an empty file"),
    "no endheader": ("x\nnRows=1\ntime a\n0 1\n", "ending in a line 'endheader'"),
    "unknown header": ("PathFileType\t4\t(X/Y/Z)\tm.trc\n" + "1 2\n" * 3,
                       "ending in a line 'endheader'"),
    "rows disagree": (HEADER.replace("nRows=2", "nRows=3") + "0 1 2\n1 1 2\n",
                      "header nRows: expected the number of data rows, 2, got 3"),
    "columns disagree": (HEADER.replace("nColumns=3", "nColumns=4") + "0 1 2\n1 1 2\n",
                         "header nColumns: expected the number of columns with time, 3"),
    "count not a number": (HEADER.replace("nRows=2", "nRows=two") + "0 1 2\n1 1 2\n",
                           "header nRows: expected a whole number, got 'two'"),
    "flag not yes or no": (HEADER.replace("=yes", "=maybe") + "0 1 2\n1 1 2\n",
                           "header inDegrees: expected yes or no"),
    "short row": (HEADER + "0 1 2\n1 1\n", "line 9: expected 3 numbers as the column names, got 2"),
    "long row": (HEADER + "0 1 2 3\n1 1 2\n", "line 8: expected 3 numbers"),
    "word": (HEADER + "0 1 2\n1 x 2\n", "line 9, column 2: expected a number, got 'x'"),
    "infinity": (HEADER + "0 1 inf\n1 1 2\n", "line 8, column 3: expected a finite number"),
    "nan time": (HEADER + "nan 1 2\n1 1 2\n", "line 8, column 1: expected a finite number"),
    "huge": (HEADER + "0 1 2\n1 1e300 2\n", "line 9, column 2: expected a finite number of "
                                            "magnitude at most 1e+12, got '1e300'"),
    "time back": (HEADER + "1 1 2\n0.5 1 2\n", "data row 2: expected a time after the "
                                               "previous row's 1 s, got 0.5 s"),
    "time repeated": (HEADER + "1 1 2\n1 1 2\n", "data row 2: expected a time after"),
    "no time column": (HEADER.replace("time\t", "frame\t") + "0 1 2\n1 1 2\n",
                       "line 7: expected column names starting with 'time', got 'frame'"),
    "no rows": (HEADER.replace("nRows=2\n", ""), "expected at least one data row"),
    "no names": ("x\nendheader\n\n", "expected a line of column names after endheader"),
    "not utf-8": (b"x\xff\nendheader\ntime\n0\n", "line 1: expected UTF-8 text"),
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_hostile_files_refused_in_one_line(tmp_path, case):
    text, message = HOSTILE[case]
    path = tmp_path / "bad.sto"
    path.write_bytes(text if isinstance(text, bytes) else text.encode())
    with pytest.raises(InputError) as error:
        read_storage(path)
    assert str(error.value).startswith(f"{path}: ") and "\n" not in str(error.value)
    assert message in str(error.value)


def test_huge_file_refused_before_reading(tmp_path, monkeypatch):
    monkeypatch.setattr(storage, "MAX_BYTES", 1000)
    path = tmp_path / "big.sto"
    path.write_text(HEADER + "0 1 2\n" * 200)
    with pytest.raises(InputError, match=r"big.sto: expected a storage file of at most"):
        read_storage(path)


def test_header_bounded(tmp_path):
    path = tmp_path / "long.sto"
    path.write_text("x\n" * (storage.MAX_HEADER_LINES + 5) + "endheader\ntime\n0\n")
    with pytest.raises(InputError, match="within 1000 lines"):
        read_storage(path)


def test_writer_refuses_names_that_would_break_the_table():
    with pytest.raises(InputError, match="without tabs or line breaks"):
        storage_text(["a\tb"], np.zeros(1), np.zeros((1, 1)), True)


def test_a_name_twice_is_read_and_refused_where_used(tmp_path):
    """A SIMM motion file repeats its plates' column names: the file is read, the repeated
    name said in its notes, and a column of that name refused where it is asked for."""
    path = tmp_path / "twice.sto"
    path.write_text(HEADER.replace("\tb", "\ta") + "0 1 2\n1 1 2\n")
    found = read_storage(path)
    assert any("named more than once" in note and "a" in note for note in found.notes)
    with pytest.raises(InputError, match="expected one column 'a', got 2"):
        found.column("a")
