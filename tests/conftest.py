"""Hypothesis profiles for the property-based tests (tests/test_generated.py), and the synthetic
study the batch and clinical-report tests share (made once per session).

``ci`` (the default): derandomized (a fixed seed: every run draws the same cases), no
deadline (solver times vary on a shared machine), no example database written into the tree;
the generated tests scale their own example counts from ``max_examples`` so that they run in
about a minute on two cores. ``long`` (``pytest --hypothesis-profile long``): random seeds,
ten times the examples, for local runs.
"""

import time
from pathlib import Path

import pytest
import yaml
from hypothesis import HealthCheck, settings

SLOW = [HealthCheck.too_slow, HealthCheck.data_too_large]

settings.register_profile("ci", derandomize=True, deadline=None, max_examples=25,
                          database=None, suppress_health_check=SLOW, print_blob=True)
settings.register_profile("long", deadline=None, max_examples=250,
                          suppress_health_check=SLOW, print_blob=True)
settings.load_profile("ci")


@pytest.fixture(scope="session")
def walking_study(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A study file of two synthetic walking subjects (tests/walking.py), five trials."""
    from walking import study_doc, walking_trials

    folder = tmp_path_factory.mktemp("study")
    trials = walking_trials(folder, 4)
    path = folder / "study.yaml"
    path.write_text(yaml.safe_dump(study_doc(trials), sort_keys=False), encoding="utf-8")
    return path


@pytest.fixture(scope="session")
def walking_reference(walking_study: Path) -> Path:
    """That study run uninterrupted by ``fccgrb batch``, in this process."""
    from cli_helpers import run_cli

    out = walking_study.parent / "reference.h5"
    started = time.perf_counter()
    result = run_cli("batch", walking_study, "-o", out)
    print(f"reference batch: {time.perf_counter() - started:.1f} s")
    assert result.exit_code == 0, (result.output, result.stderr, result.exception)
    assert "5 trials solved now, 0 already done, 0 failed" in result.output
    return out
