"""The package versions a results file records (io/results.versions, read without importing
importlib.metadata on a solve) against importlib.metadata itself and pyproject.toml, whether
or not the package's module is loaded."""

from __future__ import annotations

import re
import subprocess
import sys
from importlib.metadata import version
from pathlib import Path

import pytest

from fccgrb_cli.results.storage import PACKAGES, _installed_version, versions

ROOT = Path(__file__).resolve().parents[1]


def test_versions_are_the_installed_ones() -> None:
    recorded = versions()
    assert set(recorded) == set(PACKAGES)
    project = re.search(r'^version = "(.+)"$', (ROOT / "pyproject.toml").read_text(),
                        re.MULTILINE).group(1)
    assert recorded["fccgrb-cli"] == project
    for name in PACKAGES:
        if name != "fccgrb-cli":
            assert recorded[name] == version(name), name


@pytest.mark.parametrize("name", [n for n in PACKAGES if n != "fccgrb-cli"])
def test_an_unloaded_package_is_read_from_its_dist_info(name: str) -> None:
    assert _installed_version(name, PACKAGES[name]) == version(name)


def test_a_solve_process_does_not_import_importlib_metadata() -> None:
    code = ("import sys; from fccgrb_cli.results.storage import versions; versions(); "
            "print('importlib.metadata' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert out.stdout.strip() == "False"
