"""The generated bad-input cases (tests/fuzz), a seeded subset: ``PER_CLASS`` cases of every
class of bad input (``fuzz.cases.CLASSES``), run as real ``fccgrb`` processes two at a time. The
whole set (over 600 cases, ~15 min on two cores): ``python -m tests.fuzz --all``; another draw of
its random parts: ``--seed N``; more of them here: ``FCCGRB_FUZZ_PER_CLASS=20 python -m pytest
tests/test_fuzz.py``."""

from __future__ import annotations

import os
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest
from fuzz.cases import CLASSES, generate, subset
from fuzz.fixtures import build
from fuzz.runner import run_case

PER_CLASS = int(os.environ.get("FCCGRB_FUZZ_PER_CLASS", "3"))
SEED = int(os.environ.get("FCCGRB_FUZZ_SEED", "0"))


@pytest.fixture(scope="module")
def outcomes(tmp_path_factory) -> dict:
    base = build(Path(tmp_path_factory.mktemp("fuzz")) / "base")
    cases = subset(generate(SEED, full=False), PER_CLASS, SEED)
    with ThreadPoolExecutor(max_workers=2) as pool:
        results = list(pool.map(lambda case: run_case(case, base), cases))
    return {outcome.case.klass: [o for o in results if o.case.klass == outcome.case.klass]
            for outcome in results}


def test_the_subset_covers_every_class() -> None:
    cases = subset(generate(SEED, full=False), PER_CLASS, SEED)
    assert {c.klass for c in cases} == set(CLASSES)
    assert len(generate(SEED, full=True)) >= 300


@pytest.mark.parametrize("klass", CLASSES)
def test_bad_input_of_each_class(outcomes: dict, klass: str) -> None:
    failed = [f"{o.case.name}: {o.problems[0]}" for o in outcomes[klass] if not o.ok]
    assert not failed, "\n".join(failed)
