"""A first command does not wait for the kernels: with none compiled on the machine, ``fccgrb
solve`` (engine auto) runs in numpy, says so, records it, and starts one detached background
compile for the next runs; with kernels compiled, or a compile under way, it starts none."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import pytest

import fccgrb_cli.solvers  # noqa: F401  (the kernels' cache named now, from the real environment)
from fccgrb_cli.cli.main import _first_run_engine
from fccgrb_cli.pipeline.options import SolveOptions
from tests.cli_helpers import run_cli

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = (ROOT / "configs" / "models" / "five_bar.yaml", ROOT / "sample_data" / "five_bar.c3d")


@pytest.fixture
def cold(tmp_path, monkeypatch):
    """An empty kernel cache, the background path allowed, and a Popen that records calls."""
    folder = tmp_path / "kernels"
    folder.mkdir()
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(folder))
    monkeypatch.delenv("FCCGRB_BACKGROUND_COMPILE", raising=False)
    calls = []

    class Recorder:
        def __init__(self, args, **kwargs):
            calls.append((args, kwargs))

    monkeypatch.setattr("subprocess.Popen", Recorder)
    return folder, calls


def _engine(results: Path) -> str:
    with h5py.File(results, "r") as h5:
        run = next(iter(h5["runs"].values()))
        return json.loads(run.attrs["options"])["engine"]


def test_a_first_run_solves_in_numpy_and_compiles_in_the_background(cold, tmp_path):
    folder, calls = cold
    done = run_cli("solve", *SAMPLE, "-o", tmp_path / "a.h5")
    assert done.exit_code == 0, done.output
    assert "not built on this machine yet" in done.stderr and "numpy" in done.stderr
    assert _engine(tmp_path / "a.h5") == "numpy"
    assert len(calls) == 1
    args, kwargs = calls[0]
    assert kwargs["start_new_session"] and kwargs["env"]["FCCGRB_BACKGROUND_COMPILE"] == "0"
    assert "background_main" in args[-1] and (folder / ".compiling").exists()
    # a second command while it compiles: numpy again, no second compile
    done = run_cli("solve", *SAMPLE, "-o", tmp_path / "b.h5")
    assert done.exit_code == 0 and len(calls) == 1 and _engine(tmp_path / "b.h5") == "numpy"
    # the compile has written its first kernel and goes on: still numpy (taking the kernels
    # then would compile the rest in this command, ~45 s), and once the lock is gone, compiled
    (folder / "solvers").mkdir()
    (folder / "solvers" / "kernels.nrm-1.py311.nbi").write_bytes(b"")
    assert _first_run_engine(SolveOptions()).engine == "numpy" and len(calls) == 1
    (folder / ".compiling").unlink()
    assert _first_run_engine(SolveOptions()).engine == "auto" and len(calls) == 1


def test_compiled_kernels_or_a_stated_engine_start_nothing(cold, tmp_path):
    folder, calls = cold
    done = run_cli("solve", *SAMPLE, "--engine", "numpy", "-o", tmp_path / "n.h5")
    assert done.exit_code == 0 and not calls and "not built" not in done.stderr
    (folder / "solvers").mkdir()
    (folder / "solvers" / "kernels.nrm-1.py311.nbi").write_bytes(b"")
    assert _first_run_engine(SolveOptions()).engine == "auto" and not calls


def test_the_background_compile_removes_its_lock(tmp_path, monkeypatch):
    """The detached process compiles every kernel, then removes its lock, even when the
    compile fails (a stale lock would keep every later first run in numpy)."""
    from fccgrb_cli.pipeline import precompile

    lock = tmp_path / ".compiling"
    lock.write_text("1")

    def failing() -> float:
        raise RuntimeError("compile failed")

    monkeypatch.setattr(precompile, "precompile", failing)
    with pytest.raises(RuntimeError):
        precompile.background_main(str(lock))
    assert not lock.exists()


def test_the_background_compile_builds_this_package_whatever_the_folder(tmp_path):
    """The background compile's program imports the package this process runs, not another
    copy in the current folder (the README's first command runs from the repository's root,
    next to the sources, while the installed package is what ``fccgrb`` runs)."""
    import subprocess
    import sys

    import fccgrb_cli
    from fccgrb_cli.pipeline.precompile import background_code

    decoy = tmp_path / "fccgrb_cli"
    decoy.mkdir()
    (decoy / "__init__.py").write_text("")
    prelude = background_code(tmp_path / ".compiling").split("; from ")[0]
    done = subprocess.run([sys.executable, "-c", f"{prelude}; import fccgrb_cli; "
                           "print(fccgrb_cli.__file__)"], capture_output=True, text=True,
                          cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert Path(done.stdout.strip()) == Path(fccgrb_cli.__file__)
    assert "background_main" in background_code(tmp_path / ".compiling")
