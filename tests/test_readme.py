"""The README's and docs/'s figures against a fresh run of the commands that make them.

docs/generate.py makes every figure; here its cheap part runs again (the five-bar session, the
gait trial when ../shared is present, and a sweep of the AD and NRM cells of Tables 1 and 2)
and each generated block must agree with the README and docs/ in every number but the timing
figures. A failure names the block and shows the lines that differ; after a deliberate change,
regenerate with ``python docs/generate.py --part all`` (or the part named in the message).
"""

from __future__ import annotations

import importlib.util
import re
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]


def _load_generator():
    spec = importlib.util.spec_from_file_location("docs_generate", ROOT / "docs" / "generate.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


gen = _load_generator()
README = (ROOT / "README.md").read_text(encoding="utf-8")
REGENERATE = "\nafter a deliberate change: python docs/generate.py --part {part}"


def _made(block: str):
    with gen.Workspace() as ws:
        return gen.BLOCKS[block].make(ws)


@pytest.fixture(scope="module")
def session():
    return _made("example-session")


def _agree(artifacts, readme: str = README) -> list[str]:
    return [line for a in artifacts for line in gen.differences(a, readme)]


# --- the comparison itself: timing ignored, every other number kept -------------------------

SUMMARY = """\
```console
$ fccgrb solve configs/models/five_bar.yaml trial.c3d --method nrm-wls --perturb 30
        run   method  ms/frame  iter/frame  mean |Phi|  max |Phi_top|  failed
nrm-wls-P30  nrm-wls      1.27        8.18      0.0579       7.61e-05       0
wrote run 'nrm-wls-P30' (300 frames) to results.h5
```"""


def _same(a: str, b: str) -> bool:
    return gen.normalize(a) == gen.normalize(b)


def test_console_timing_columns_are_ignored_and_the_rest_kept():
    assert _same(SUMMARY, SUMMARY.replace("     1.27", "     0.93"))
    assert _same(SUMMARY, SUMMARY.replace("     1.27", "     10.5"))  # wider: spacing ignored
    assert not _same(SUMMARY, SUMMARY.replace("8.18", "8.19"))
    assert not _same(SUMMARY, SUMMARY.replace("7.61e-05", "7.6e-05"))
    assert not _same(SUMMARY, SUMMARY.replace("0\nwrote", "1\nwrote"))
    assert not _same(SUMMARY, SUMMARY.replace("(300 frames)", "(299 frames)"))


def test_rounding_residues_are_compared_as_such_and_larger_numbers_digit_by_digit():
    exact = SUMMARY.replace("7.61e-05", "4.44e-16")
    assert _same(exact, exact.replace("4.44e-16", "6.66e-16"))
    assert _same(exact, exact.replace("4.44e-16", "2.5e-13"))
    assert not _same(exact, exact.replace("4.44e-16", "2.5e-12"))  # not rounding any more
    assert not _same(SUMMARY, SUMMARY.replace("7.61e-05", "7.61e-15"))


def test_free_text_and_markdown_timing_are_ignored_and_the_rest_kept():
    text = "AD analysis: 2.98 iterations/frame, 0.225 ms/frame; (39 cells, 41 s)"
    assert _same(text, text.replace("0.225", "0.31").replace("41 s", "177 s"))
    assert not _same(text, text.replace("2.98", "2.99"))
    assert not _same(text, text.replace("39 cells", "40 cells"))
    table = ("**table2 — {} (ours [paper])**\n\n| method | variant | points | tol | P0 | P30 |\n"
             "|---|---|---|---|---|---|\n| CNO | SQP | 8 | 1e-10 | 15 [1.2e+03] | 14.6 [38] |")
    timing, iterations = table.format("ms/frame"), table.format("iterations/frame")
    assert _same(timing, timing.replace("| 15 [", "| 16.2 ["))
    assert not _same(timing, timing.replace("[1.2e+03]", "[1.3e+03]"))
    assert not _same(iterations, iterations.replace("| 15 [", "| 16.2 ["))
    bench = ("| model | P0 ms/frame | iterations | paper P0 ms/frame |\n|---|---|---|---|\n"
             "| pendulum, AD | 0.22 | 2.9 | 8.6 |")
    assert _same(bench, bench.replace("0.22", "0.3"))
    assert not _same(bench, bench.replace("2.9", "3.0"))
    assert not _same(bench, bench.replace("8.6", "8.7"))


# --- the README against a fresh run ----------------------------------------------------------


def test_example_session_matches_a_fresh_run(session):
    found = _agree(session)
    assert not found, "\n".join(found) + REGENERATE.format(part="cheap")


def _edit_row(readme: str, run: str, column: str, new: str) -> str:
    """The README with one value of the example session's summary row of ``run`` replaced."""
    block = gen.readme_blocks(readme)["example-session"]
    lines = block.splitlines()
    k = next(i for i, line in enumerate(lines) if line.split()[:1] == [run])
    header, row = lines[k - 1], lines[k]
    end = header.index(column) + len(column)  # right-aligned under its header
    start = row.rindex(" ", 0, end) + 1
    edited = row[:start] + new.rjust(end - start) + row[end:]
    assert edited != row
    return readme.replace(block, block.replace(row, edited))


def test_a_number_edited_by_hand_is_caught_and_a_timing_is_not(session):
    found = _agree(session, _edit_row(README, "nrm-wls-P30", "iter/frame", "7.77"))
    assert found and any("7.77" in line for line in found)
    assert _agree(session, _edit_row(README, "nrm-ls-P30", "max |Phi_top|", "0.0158"))
    assert _agree(session, _edit_row(README, "cno-sqp-P30", "flagged", "3"))
    assert not _agree(session, _edit_row(README, "nrm-wls-P30", "ms/frame", "99.9"))


@pytest.mark.skipif(not gen.QUALISYS.exists(), reason=f"{gen.QUALISYS} is absent")
def test_gait_trial_matches_a_fresh_run():
    found = _agree(_made("gait-trial"))
    assert not found, "\n".join(found) + REGENERATE.format(part="cheap")


def test_docs_tables_agree_with_a_sweep_of_their_fast_cells():
    """The AD and NRM rows of docs/table1.md and docs/table2.md (34 of their 82 cells, seconds
    to run) against a sweep of just those cells; the optimizers' cells take minutes."""
    made = _made("table-subset")
    assert {a.path for a in made} == {"docs/table1.md", "docs/table2.md"}
    rows = [line for a in made for line in a.text.splitlines()
            if re.match(r"\| (KA|NRM) \|", line)]
    assert len(rows) >= 8 * (6 + 8)  # each metric's table: 6 such rows in Table 1, 8 in Table 2
    found = _agree(made)
    assert not found, "\n".join(found) + REGENERATE.format(part="tables")


def test_cli_reference_matches_every_commands_help():
    found = _agree(_made("cli-reference"))
    assert not found, "\n".join(found) + REGENERATE.format(part="cheap")


def test_the_readme_is_a_front_page_and_its_links_lead_somewhere():
    """At most 300 lines; every relative link of the README and of docs/*.md names a file or
    folder of the repository (a guide moved or renamed leaves no dead link)."""
    assert len(README.splitlines()) <= 300
    dead = []
    for page in gen.pages(ROOT):
        text = re.sub(r"```.*?```|`[^`\n]*`", "", page.read_text(encoding="utf-8"), flags=re.S)
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text):
            if re.match(r"[a-z]+:", target):
                continue
            if not (page.parent / target).exists():
                dead.append(f"{page.relative_to(ROOT)}: {target}")
    assert dead == []


def test_a_block_in_a_guide_is_found_there_and_a_missing_one_is_named(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "README.md").write_text("front page\n")
    (tmp_path / "docs" / "guide.md").write_text(
        "<!-- generated: walk -->\nold 1.5 ms/frame\n<!-- /generated -->\n")
    assert gen.page_of("walk", tmp_path) == tmp_path / "docs" / "guide.md"
    same = gen.ReadmeBlock("walk", "old 9.9 ms/frame")
    assert gen.differences(same, "front page\n", tmp_path) == []
    assert gen.differences(gen.ReadmeBlock("walk", "new 1.5 ms/frame"), "", tmp_path)
    assert "no page" in gen.differences(gen.ReadmeBlock("run", "x"), "", tmp_path)[0]
    gen.write(gen.ReadmeBlock("walk", "new"), tmp_path)
    assert "<!-- generated: walk -->\nnew\n<!-- /generated -->" in (
        tmp_path / "docs" / "guide.md").read_text()


@pytest.mark.skipif(not (gen.SHARED / "data" / "opensim").is_dir(),
                    reason="../shared/data/opensim is absent")
def test_opensim_agreement_matches_a_fresh_run():
    found = _agree(_made("opensim-agreement"))
    assert not found, "\n".join(found) + REGENERATE.format(part="cheap")
