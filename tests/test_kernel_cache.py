"""The compiled kernels' cache cannot go stale: its folder is named by the package's version and
a digest of every source file the kernels are made of (``core.kernel_cache``), so an edited
helper module, or an upgrade, compiles anew. The control case shows numba's own cache, keyed by
the kernel's file alone, running an edited callee's old code."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from fccgrb_cli.core.kernel_cache import cache_folder, source_digest

ROOT = Path(__file__).resolve().parents[1]


def _package(tmp_path: Path) -> Path:
    """pkg/solvers/kern.py: a cached kernel calling pkg/solvers/helper.py's compiled helper."""
    root = tmp_path / "pkg"
    (root / "solvers").mkdir(parents=True)
    (root / "__init__.py").write_text("")
    (root / "solvers" / "__init__.py").write_text("")
    (root / "solvers" / "helper.py").write_text(textwrap.dedent("""
        from numba import njit

        @njit(cache=True)
        def value():
            return 1
        """))
    (root / "solvers" / "kern.py").write_text(textwrap.dedent("""
        from numba import njit

        from pkg.solvers.helper import value

        @njit(cache=True)
        def run():
            return 10 * value()
        """))
    return root


def _run(root: Path, env: dict[str, str], keyed: bool) -> int:
    """The kernel's answer in a fresh process, with our cache folder or numba's own."""
    configure = (f"from fccgrb_cli.core.kernel_cache import configure; "
                 f"configure('9.9', Path({str(root)!r}), ('solvers',)); " if keyed else "")
    code = (f"import sys; from pathlib import Path; sys.path.insert(0, {str(root.parent)!r}); "
            f"{configure}from pkg.solvers.kern import run; print(run())")
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, check=True, cwd=ROOT)
    return int(done.stdout.strip())


def _edit_helper(root: Path) -> None:
    helper = root / "solvers" / "helper.py"
    helper.write_text(helper.read_text().replace("return 1", "return 2"))


@pytest.fixture
def env(tmp_path: Path) -> dict[str, str]:
    out = {k: v for k, v in os.environ.items()
           if k not in ("NUMBA_CACHE_DIR", "FCCGRB_USER_NUMBA_CACHE_DIR")}
    out["XDG_CACHE_HOME"] = str(tmp_path / "cache")
    out["PYTHONPATH"] = str(ROOT)
    return out


def test_an_edited_helper_recompiles_the_kernel_that_calls_it(tmp_path, env):
    root = _package(tmp_path)
    assert _run(root, env, keyed=True) == 10
    assert _run(root, env, keyed=True) == 10  # from the cache
    _edit_helper(root)
    assert _run(root, env, keyed=True) == 20
    folders = sorted(p.name for p in (tmp_path / "cache" / "fccgrb").iterdir())
    assert len(folders) == 2 and all(f.startswith("kernels-9.9-") for f in folders)


def test_numbas_own_cache_runs_the_old_helper_which_is_why_the_key_exists(tmp_path, env):
    root = _package(tmp_path)
    assert _run(root, env, keyed=False) == 10
    _edit_helper(root)
    assert _run(root, env, keyed=False) == 10  # stale: kern.py's own file did not change


def test_the_digest_follows_every_source_file_and_its_path(tmp_path):
    root = tmp_path / "pkg"
    (root / "solvers" / "sub").mkdir(parents=True)
    (root / "other").mkdir()
    (root / "solvers" / "a.py").write_text("A = 1\n")
    (root / "solvers" / "sub" / "b.py").write_text("B = 2\n")
    (root / "other" / "c.py").write_text("C = 3\n")
    first = source_digest(root, ("solvers",))
    assert source_digest(root, ("solvers",)) == first
    (root / "other" / "c.py").write_text("C = 4\n")  # not a source of the kernels
    assert source_digest(root, ("solvers",)) == first
    (root / "solvers" / "sub" / "b.py").write_text("B = 3\n")
    assert source_digest(root, ("solvers",)) != first
    (root / "solvers" / "sub" / "b.py").write_text("B = 2\n")
    assert source_digest(root, ("solvers",)) == first
    (root / "solvers" / "sub" / "b.py").rename(root / "solvers" / "b.py")
    assert source_digest(root, ("solvers",)) != first


def test_the_folder_is_under_the_users_choice_then_the_cache_home():
    assert cache_folder("1.0", "ab", {"NUMBA_CACHE_DIR": "/n"}) == Path("/n/kernels-1.0-ab")
    assert cache_folder("1.0", "ab", {"XDG_CACHE_HOME": "/x"}) == Path(
        "/x/fccgrb/kernels-1.0-ab")
    assert cache_folder("2.0", "ab", {"XDG_CACHE_HOME": "/x"}) != cache_folder(
        "1.0", "ab", {"XDG_CACHE_HOME": "/x"})
    # a child process sees our folder as NUMBA_CACHE_DIR: the user's own is kept apart
    assert cache_folder("1.0", "cd", {"NUMBA_CACHE_DIR": "/x/fccgrb/kernels-1.0-ab",
                                      "FCCGRB_USER_NUMBA_CACHE_DIR": "/n"}) == Path(
        "/n/kernels-1.0-cd")
    assert cache_folder("1.0", "cd", {"NUMBA_CACHE_DIR": "/x/fccgrb/kernels-1.0-ab",
                                      "FCCGRB_USER_NUMBA_CACHE_DIR": "",
                                      "XDG_CACHE_HOME": "/x"}) == Path("/x/fccgrb/kernels-1.0-cd")


def test_another_install_of_the_same_sources_has_its_own_folder(tmp_path):
    """numba keys its index by each kernel's file path: a second install of the very same
    sources (another environment, a fresh clone) must not find the first one's kernels and
    count as compiled, or its first command compiles them all in the foreground."""
    import shutil

    root = tmp_path / "one" / "pkg"
    (root / "solvers").mkdir(parents=True)
    (root / "solvers" / "a.py").write_text("A = 1\n")
    other = tmp_path / "two" / "pkg"
    shutil.copytree(root, other)
    assert source_digest(root, ("solvers",)) != source_digest(other, ("solvers",))
    assert source_digest(root, ("solvers",)) == source_digest(root, ("solvers",))
