"""Files this process is writing and will delete unless it finishes them; the signals that end
it; worker processes that end with their parent.

Every output is written to a scratch file beside it and renamed into place at the end
(``core.atomic``); a long solve keeps its largest arrays in a scratch HDF5 file (``core.spill``);
a writer holds a lock file (``core.lock``). Each registers its path here while it exists.

The command line (``install``) makes SIGINT (Ctrl-C), SIGTERM and SIGHUP delete the registered
files and end the process at once with status 128 + the signal (130 for Ctrl-C), printing one
line. It does not rely on KeyboardInterrupt reaching the top: Python runs a signal's handler
wherever the main thread is, and an exception raised inside a finalizer (h5py closing an
object, a ``weakref.finalize`` callback, a ``__del__``) is printed as "Exception ignored" and
dropped: a Ctrl-C during a long compiled solve landed in ``WeakValueDictionary``'s removal
callback ("Exception ignored in: <function WeakValueDictionary.__init__.<locals>.remove>"), and
the solve went on to write its results and exit 0. A signal ignored when the process started
(``nohup``, a job a script put in the background) stays ignored.

Workers started by a pool call ``die_with_parent`` first: on Linux the kernel sends them
SIGTERM when the parent dies (``prctl(PR_SET_PDEATHSIG)``), however it dies (SIGKILL
included); elsewhere a thread checks the parent every second.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sys
import threading
from collections.abc import Callable
from pathlib import Path
from types import FrameType
from typing import Any, TypeAlias

_SCRATCH: set[str] = set()
_QUIET = False  # a pool's worker ends without a word: its parent speaks
SIGNALS = ("SIGINT", "SIGTERM", "SIGHUP")
# what signal.signal installs and returns: a function, SIG_DFL / SIG_IGN, or None (not set from
# Python)
Handler: TypeAlias = Callable[[int, FrameType | None], Any] | int | signal.Handlers | None
PR_SET_PDEATHSIG = 1


def register(path: str | Path) -> None:
    _SCRATCH.add(os.fspath(path))


def create(folder: str | Path, prefix: str, suffix: str) -> Path:
    """A new empty file ``folder/prefix + 8 random characters + suffix``, registered before it
    exists (a signal between the two would otherwise leave it behind); mode 0o666 less the
    umask, as an output's. OSError as os.open raises it."""
    import secrets
    import string

    alphabet = string.ascii_lowercase + string.digits
    while True:
        name = os.path.join(folder, prefix + "".join(secrets.choice(alphabet) for _ in range(8))
                            + suffix)
        register(name)
        try:
            os.close(os.open(name, os.O_RDWR | os.O_CREAT | os.O_EXCL, 0o666))
            return Path(name)
        except FileExistsError:
            release(name)
        except OSError:
            release(name)
            raise


def release(path: str | Path) -> None:
    _SCRATCH.discard(os.fspath(path))


def remove_all() -> None:
    """Delete every registered file (what a signal's handler does before the process ends)."""
    for path in list(_SCRATCH):
        if os.path.isdir(path) and not os.path.islink(path):
            shutil.rmtree(path, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                os.unlink(path)
    _SCRATCH.clear()


def _end(signum: int, frame) -> None:
    remove_all()
    if _QUIET:
        os._exit(128 + signum)
    name = signal.Signals(signum).name
    # Nothing stdout does may replace the interruption: the handler can run inside its own
    # flush (Python checks for signals between a buffered writer's raw writes, holding its
    # lock: flushing again raises RuntimeError, "reentrant call"), it may be closed or a
    # broken pipe, or None (the command started with descriptor 1 closed, ``>&-``).
    if sys.stdout is not None:
        with contextlib.suppress(OSError, ValueError, RuntimeError):
            sys.stdout.flush()
    with contextlib.suppress(OSError):
        os.write(2, f"fccgrb: error: interrupted by {name}; the files being written were "
                    "removed\n".encode())
    os._exit(128 + signum)


def install() -> dict[int, Handler]:
    """Install the command line's handlers (main thread only; a no-op elsewhere); the handlers
    they replace, for ``restore``."""
    previous: dict[int, Handler] = {}
    if threading.current_thread() is not threading.main_thread():
        return previous
    for name in SIGNALS:
        number = getattr(signal, name, None)
        # a signal ignored when the process started stays ignored (nohup, a background job)
        if number is not None and signal.getsignal(number) is not signal.SIG_IGN:
            previous[number] = signal.signal(number, _end)
    return previous


def restore(previous: dict[int, Handler]) -> None:
    """Put back the handlers ``install`` replaced (a test's process keeps its own)."""
    for number, handler in previous.items():
        signal.signal(number, handler)


def die_with_parent(parent: int) -> None:
    """In a worker process (a pool's initializer): end when ``parent`` ends, removing this
    worker's scratch files; its SIGINT/SIGTERM handlers as the command line's. The files the
    parent had registered when it forked stay the parent's (a worker ending alone must not
    delete the parent's lock)."""
    global _QUIET
    _QUIET = True
    _SCRATCH.clear()
    install()
    if not terminated_with_parent():
        _watch(parent)
    if os.getppid() != parent:  # the parent died before the request took effect
        _end(signal.SIGTERM, None)


def terminated_with_parent() -> bool:
    """Ask the kernel to send this process SIGTERM when its parent dies, however it dies
    (Linux's ``prctl(PR_SET_PDEATHSIG)``); whether it could."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        return libc.prctl(PR_SET_PDEATHSIG, signal.SIGTERM, 0, 0, 0) == 0
    except (OSError, AttributeError):
        return False


def _watch(parent: int) -> None:
    def watch() -> None:
        import time

        while os.getppid() == parent:
            time.sleep(1.0)
        remove_all()
        os._exit(128 + signal.SIGTERM)

    threading.Thread(target=watch, daemon=True, name="fccgrb-parent-watch").start()
