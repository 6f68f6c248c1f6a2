"""The clinical report of a study (``fccgrb report study.h5 --html FOLDER``): ``index.html``
for the study and ``subject-<name>.html`` per subject, self-contained HTML with inline SVG plots
(``clinical_report.pages``), written as a whole: the pages are made in a scratch folder beside
FOLDER and swapped in, so a failed report leaves FOLDER as it was."""

from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from fccgrb_cli.core import scratch as registry
from fccgrb_cli.core.errors import InputError

MARK = '<meta name="generator" content="fccgrb'


def write_report(results: str | Path, folder: str | Path, normative: str | Path | None = None
                 ) -> list[Path]:
    """Write the study's pages into ``folder`` (created; a folder holding anything but an
    earlier report's pages is refused, since it is replaced whole); the pages' paths, study
    page first."""
    from fccgrb_cli.batch.study.store import read_study
    from fccgrb_cli.gait.normative import read_norms
    from fccgrb_cli.presentation.clinical_report.pages import study_page, subject_file, subject_page

    folder = Path(folder)
    _check_folder(folder)
    study = read_study(results)
    norms = read_norms(normative) if normative is not None else None
    pages = {"index.html": study_page(study, norms)}
    for s in study.subjects:
        pages[subject_file(s.name)] = subject_page(study, s, norms)
    parent = folder.parent if str(folder.parent) else Path(".")
    scratch = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=parent))
    registry.register(scratch)  # a signal removes it (fccgrb_cli.core.scratch)
    try:
        for name, text in pages.items():
            (scratch / name).write_text(text, encoding="utf-8")
        scratch.chmod(0o755)
        if folder.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{folder.name}.old.", dir=parent))
            os.replace(folder, old / folder.name)
            os.replace(scratch, folder)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(scratch, folder)
    finally:
        shutil.rmtree(scratch, ignore_errors=True)
        registry.release(scratch)
    return [folder / name for name in pages]


def _check_folder(folder: Path) -> None:
    parent = folder.parent if str(folder.parent) else Path(".")
    if not parent.is_dir():
        raise InputError(f"--html: expected a folder whose parent exists, got {folder}")
    if folder.exists() and not folder.is_dir():
        raise InputError(f"--html: expected a folder, got the file {folder}")
    if folder.is_dir() and any(folder.iterdir()):
        index = folder / "index.html"
        ours = index.is_file() and MARK in index.read_text(encoding="utf-8", errors="replace")
        pages = all(p.is_file() and (p.name == "index.html" or (
            p.name.startswith("subject-") and p.suffix == ".html")) for p in folder.iterdir())
        if not (ours and pages):
            raise InputError(f"--html: {folder} holds files that are not an fccgrb report's "
                             "pages (it is replaced as a whole); choose a new or empty folder")
