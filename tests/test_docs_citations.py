"""The repository stands alone: code, tests and docs cite the project's own formulation page,
each citation names a section that page has, and nothing points at a tracker or a note users
never see."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FORMULATION = ROOT / "docs" / "formulation.md"
CITING = ("fccgrb_cli", "tests", "benchmarks", "docs", "examples")
CITATION = re.compile(r"formulation\.md\s+§(\d+(?:\.\d+)?)(?:[–-](\d+))?")
OUTSIDE = re.compile(r"\bFORMULATION §|\bissues? #?\d+|\bissue's\b|\bthe issue\b", re.IGNORECASE)


def sources() -> list[Path]:
    return sorted(p for folder in CITING for p in (ROOT / folder).rglob("*")
                  if p.suffix in (".py", ".md") and "__pycache__" not in p.parts
                  and p != Path(__file__).resolve())


def sections() -> set[str]:
    """The section numbers of docs/formulation.md's headings (``## §4 …``, ``### §3.1 …``)."""
    return set(re.findall(r"^#{2,3} §(\d+(?:\.\d+)?) ", FORMULATION.read_text(), re.MULTILINE))


def test_the_formulation_has_the_sections_the_code_cites_in_order() -> None:
    numbers = re.findall(r"^#{2,3} §(\d+(?:\.\d+)?) ", FORMULATION.read_text(), re.MULTILINE)
    assert numbers[:8] == ["1", "2", "3", "3.1", "4", "5", "6", "7"]
    assert [int(n) for n in numbers if "." not in n] == list(range(1, len(numbers)))


def test_every_citation_names_a_section_that_exists() -> None:
    known, cited, missing = sections(), 0, []
    for path in sources():
        for match in CITATION.finditer(path.read_text(encoding="utf8")):
            first, last = match.group(1), match.group(2)
            wanted = [first] if last is None else [str(n) for n in range(int(first), int(last) + 1)]
            cited += 1
            missing += [f"{path.relative_to(ROOT)}: §{n}" for n in wanted if n not in known]
    assert cited > 60
    assert not missing


def test_nothing_cites_a_tracker_or_an_outside_note() -> None:
    found = [f"{path.relative_to(ROOT)}:{number}: {line.strip()}"
             for path in sources()
             for number, line in enumerate(path.read_text(encoding="utf8").splitlines(), 1)
             if OUTSIDE.search(line)]
    assert not found
