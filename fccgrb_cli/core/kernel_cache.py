"""Where numba keeps the compiled kernels: a folder named by what they are made of.

numba's own cache (``cache=True``) is keyed by each kernel's source file alone, while a compiled
kernel carries the machine code of every function it calls, from other files too: after an
upgrade or an edit of a helper module, a cached kernel could run the old callee. Here the cache
folder is named by the package's version and a digest of every source file the kernels are made
of (``SOURCES``, under the package), so any change to them starts a fresh folder and the kernels
compile anew; numba's index inside still checks each kernel's own file.

The folder is ``$NUMBA_CACHE_DIR`` (when the user set one) or the user's cache folder
(``$XDG_CACHE_HOME`` or ``~/.cache``) + ``fccgrb/kernels-<version>-<digest>``. Where no such
folder can be made, numba's default stays (beside the sources)."""

from __future__ import annotations

import hashlib
import os
import sys
from pathlib import Path
from typing import Any

__all__ = ["SOURCES", "cache_folder", "compiled_here", "configure", "source_digest"]

PACKAGE = Path(__file__).resolve().parents[1]
# the folders whose modules the compiled kernels are written in or take constants from
SOURCES = ("solvers", "system")
_USER_SET = "FCCGRB_USER_NUMBA_CACHE_DIR"  # the user's own NUMBA_CACHE_DIR, kept for children


def source_digest(root: Path = PACKAGE, folders: tuple[str, ...] = SOURCES) -> str:
    """A digest (16 hex digits) of where ``root`` is and of the relative path and bytes of every
    ``*.py`` file under its ``folders``, in a fixed order. The place counts because numba's
    index inside the folder is keyed by each kernel's file path: another install of the same
    sources (a second virtual environment, a fresh clone) would otherwise find this one's index
    files, count as compiled (:func:`compiled_here`), and compile every kernel in the
    foreground of its first command instead of in the background."""
    digest = hashlib.sha256()
    digest.update(str(Path(root).resolve()).encode())
    digest.update(b"\0")
    for folder in folders:
        for path in sorted((root / folder).rglob("*.py")):
            digest.update(str(path.relative_to(root)).encode())
            digest.update(b"\0")
            digest.update(path.read_bytes())
            digest.update(b"\0")
    return digest.hexdigest()[:16]


def cache_folder(version: str, digest: str, environ: dict[str, str] | None = None) -> Path:
    """The cache folder for this version and digest, under the user's ``NUMBA_CACHE_DIR`` or
    cache home."""
    env = os.environ if environ is None else environ
    base = env[_USER_SET] if _USER_SET in env else env.get("NUMBA_CACHE_DIR")
    if not base:
        home = env.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
        base = str(Path(home) / "fccgrb")
    return Path(base) / f"kernels-{version}-{digest}"


def configure(version: str | None = None, root: Path = PACKAGE,
              folders: tuple[str, ...] = SOURCES) -> Path | None:
    """Point numba's cache at :func:`cache_folder` (before the kernels are defined); the
    folder, or None where it cannot be made (numba's default then stays). Worker processes
    inherit it through the environment. Also gives numba scipy's Cython BLAS and LAPACK without
    the ``scipy.linalg`` package (``core.blas.cython_modules_for_numba``: ~0.3 s less to load
    the first kernel)."""
    from fccgrb_cli.core.blas import cython_modules_for_numba

    cython_modules_for_numba()
    if version is None:
        from fccgrb_cli import __version__

        version = __version__
    if _USER_SET not in os.environ:
        os.environ[_USER_SET] = os.environ.get("NUMBA_CACHE_DIR", "")
    folder = cache_folder(version, source_digest(root, folders))
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    os.environ["NUMBA_CACHE_DIR"] = str(folder)
    config: Any = sys.modules.get("numba.core.config")  # numba's settings, set by name
    if config is not None:  # numba loaded before us: its config read the environment already
        config.CACHE_DIR = str(folder)
    return folder


def compiled_here(folder: Path | None = None) -> bool:
    """Whether the kernels' cache folder (``folder``, else the one :func:`configure` set)
    holds compiled kernels: numba's index files (``*.nbi``) of at least one."""
    base = folder if folder is not None else Path(os.environ.get("NUMBA_CACHE_DIR") or ".")
    if folder is None and not os.environ.get("NUMBA_CACHE_DIR"):
        return False
    return base.is_dir() and next(base.rglob("*.nbi"), None) is not None
