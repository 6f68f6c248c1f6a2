"""IK task sets: marker weights read, tasks that do not apply left out, bad files refused in one
line naming the file and the task; OpenSim's own task set (a stray end tag after its root, which
OpenSim's reader ignores) read as OpenSim reads it."""

from __future__ import annotations

from pathlib import Path

import pytest

from fccgrb_cli.core.errors import InputError
from fccgrb_cli.opensim.tasks import read_marker_tasks

IK_DIR = Path(__file__).resolve().parents[2] / "shared" / "data" / "opensim" / \
    "ik_gait2354_synthetic"


def task_set(body: str) -> str:
    return f'<?xml version="1.0"?><IKTaskSet name="t"><objects>{body}</objects></IKTaskSet>'


def marker(name: str, weight: str = "1", apply: str = "true") -> str:
    return (f'<IKMarkerTask name="{name}"><apply>{apply}</apply><weight>{weight}</weight>'
            f"</IKMarkerTask>")


def test_weights_applied_and_left_out(tmp_path):
    path = tmp_path / "tasks.xml"
    path.write_text(task_set(marker("A", "0.5") + marker("B", "2", "false") + marker("C", "0")
                             + '<IKCoordinateTask name="knee"><apply>true</apply>'
                               "</IKCoordinateTask>"))
    tasks = read_marker_tasks(path)
    assert tasks.weights == {"A": 0.5}
    assert tasks.skipped == ("B", "C") and tasks.coordinate_tasks == ("knee",)


@pytest.mark.parametrize("body, message", [
    (marker("A", "-1"), "IKMarkerTask[name=A]/weight: expected a weight ≥ 0"),
    (marker("A", "inf"), "IKMarkerTask[name=A]/weight: expected a finite number"),
    (marker("A") + marker("A"), "marker 'A' has two tasks"),
    (marker("A", apply="maybe"), "IKMarkerTask[name=A]/apply: expected true or false"),
    ('<IKMarkerTask><weight>1</weight></IKMarkerTask>', "a task without a name"),
    ('<Marker name="A"/>', "Marker[name=A]: expected an IKMarkerTask or IKCoordinateTask"),
])
def test_bad_task_sets_are_refused_in_one_line(tmp_path, body, message):
    path = tmp_path / "tasks.xml"
    path.write_text(task_set(body))
    with pytest.raises(InputError) as caught:
        read_marker_tasks(path)
    assert str(caught.value).startswith(str(path)) and message in str(caught.value)


def test_a_document_broken_before_its_root_closes_is_still_refused(tmp_path):
    path = tmp_path / "tasks.xml"
    path.write_text(task_set(marker("A")).replace("</objects>", "</object>"))
    with pytest.raises(InputError, match="not well-formed XML"):
        read_marker_tasks(path)


@pytest.mark.skipif(not IK_DIR.is_dir(), reason="../shared/data/opensim not here")
def test_opensims_weighted_task_set_reads_as_opensim_reads_it():
    tasks = read_marker_tasks(IK_DIR / "gait2354_IK_Tasks.xml")
    assert len(tasks.weights) == 31 and tasks.weights["R.Acromium"] == 0.75
    assert tasks.weights["Top.Head"] == 0.5 and len(tasks.coordinate_tasks) == 4
