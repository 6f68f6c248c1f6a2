"""Outputs written whole or not at all.

Each output is written to a scratch file beside it (the same folder, so the same disk: the
final rename is atomic), ``.NAME.PID.XXXXXXXX.tmp``, registered with ``fccgrb_cli.core.scratch``
(a signal removes it), and renamed over NAME when complete. Inside ``transaction()`` the
renames of every output wait for the end of the block, so that a command writing several files
(a trial and its truth) leaves all of them or none. Writing nothing but a scratch file, a full
disk or a file-size limit is one InputError naming the output: the scratch file removed, an
existing file left as it was. A scratch file whose process no longer runs (a kill -9) is removed
the next time the same output is written (``remove_stale``).
"""

from __future__ import annotations

import contextlib
import errno
import glob
import os
import re
import threading
from collections.abc import Iterator
from pathlib import Path

from fccgrb_cli.core import scratch
from fccgrb_cli.core.errors import InputError

FULL = {errno.ENOSPC, errno.EFBIG, errno.EDQUOT}
_PENDING = threading.local()  # the open transaction's staged (scratch, target) pairs


def reason(error: OSError) -> str:
    """Why a write failed, in words."""
    words = {errno.ENOSPC: "the disk is full", errno.EDQUOT: "the disk quota is exceeded",
             errno.EFBIG: "the file size limit was reached"}
    if error.errno is not None and error.errno in words:
        return words[error.errno]
    return str(error.strerror)  # "None" where the system gave no words, as printed before


def cannot_write(target: str | Path, error: OSError) -> InputError:
    """The one-line error of a failed write of ``target``."""
    target = Path(target)
    why = reason(error)
    kept = "; the existing file is unchanged" if target.exists() else ""
    return InputError(f"{target}: cannot write it ({why}); nothing was written{kept}")


def check_target(target: str | Path) -> Path:
    """``target`` if it can be written: its folder exists (none is made), it is not a folder."""
    target = Path(target)
    folder = target.parent
    if not folder.is_dir():
        raise InputError(f"{target}: the output folder {folder} does not exist")
    if target.is_dir():
        raise InputError(f"{target}: expected an output file, got a folder")
    return target


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


STAGED = re.compile(r"^\..+\.(\d+)\.(?:[A-Za-z0-9_]{8}|bak)\.tmp")


def remove_stale(where: str | Path) -> None:
    """Delete the scratch files (``.NAME.PID.XXXXXXXX.tmp``, and what a writer stages beside
    one) of the output ``where``, or of every output in the folder ``where``, whose writing
    process is gone."""
    where = Path(where)
    name = "*" if where.is_dir() else glob.escape(where.name)
    folder = where if where.is_dir() else where.parent
    for found in glob.glob(os.path.join(glob.escape(str(folder)), f".{name}.*.tmp*")):
        match = STAGED.match(Path(found).name)
        if match and int(match.group(1)) != os.getpid() and not alive(int(match.group(1))):
            with contextlib.suppress(OSError):
                os.unlink(found)


def _stage(target: Path) -> Path:
    remove_stale(target)
    try:
        return scratch.create(target.parent, f".{target.name}.{os.getpid()}.", ".tmp")
    except OSError as error:
        raise cannot_write(target, error) from None


def _discard(tmp: Path) -> None:
    with contextlib.suppress(OSError):
        tmp.unlink()
    scratch.release(tmp)


def _commit(pairs: list[tuple[Path, Path]]) -> None:
    """Rename every scratch file over its target; if one rename fails, put back the targets
    already replaced (from hard-link backups) so that all or none change."""
    done: list[tuple[Path, Path | None]] = []
    backups: list[Path] = []
    try:
        for tmp, target in pairs:
            backup = None
            if len(pairs) > 1 and target.is_file():
                backup = target.with_name(f".{target.name}.{os.getpid()}.bak.tmp")
                with contextlib.suppress(OSError):
                    os.unlink(backup)
                scratch.register(backup)
                os.link(target, backup)
                backups.append(backup)
            os.replace(tmp, target)
            scratch.release(tmp)
            done.append((target, backup))
    except OSError as error:
        for target, backup in reversed(done):
            with contextlib.suppress(OSError):
                if backup is not None:
                    os.replace(backup, target)
                else:
                    os.unlink(target)
        raise cannot_write(pairs[len(done)][1], error) from None
    finally:
        for backup in backups:
            _discard(backup)


@contextlib.contextmanager
def atomic_path(target: str | Path) -> Iterator[Path]:
    """Yield a scratch path beside ``target``; rename it to ``target`` when the block ends
    without an error (inside a ``transaction``: when the transaction ends)."""
    target = check_target(target)
    tmp = _stage(target)
    pending = getattr(_PENDING, "pairs", None)
    handed_over = False
    try:
        try:
            yield tmp
        except OSError as error:
            if error.errno in FULL:
                raise cannot_write(target, error) from None
            raise
        if pending is not None:
            pending.append((tmp, target))
            handed_over = True
        else:
            _commit([(tmp, target)])
    finally:
        if not handed_over:
            _discard(tmp)


@contextlib.contextmanager
def transaction() -> Iterator[None]:
    """Every ``atomic_path`` inside the block is renamed into place at its end, all together,
    or none is (an error in the block discards them all)."""
    if getattr(_PENDING, "pairs", None) is not None:  # nested: the outer one decides
        yield
        return
    pairs: list[tuple[Path, Path]] = []
    _PENDING.pairs = pairs
    try:
        yield
        _PENDING.pairs = None
        _commit(pairs)
    finally:
        _PENDING.pairs = None
        for tmp, _ in pairs:
            if tmp.exists():
                _discard(tmp)
