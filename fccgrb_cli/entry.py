"""The ``fccgrb`` program's entry point: the signal handlers first (``fccgrb_cli.core.scratch``), so
that a Ctrl-C while numpy, h5py and click are still loading already ends the program with one
line and status 130; then the command, in this install's warm server when one is up
(``fccgrb_cli.cli.server``), else here (``fccgrb_cli.cli.main``), leaving a server for the next
commands; then the exit without the interpreter's teardown (:func:`leave`)."""

from __future__ import annotations

import atexit
import contextlib
import os
import sys


def run() -> None:
    _open_closed_descriptors()
    environ = dict(os.environ)
    from fccgrb_cli.core import scratch

    scratch.install()
    from fccgrb_cli.cli import server
    from fccgrb_cli.core.errors import InputError

    try:
        served = server.attempt(sys.argv, environ)
    except InputError as error:  # FCCGRB_SERVER's value: one line, status 2, nothing run
        sys.stderr.write(f"fccgrb: error: {error}\n")
        served = 2
    if served is not None:
        leave(served)
    code = command()
    server.offer(environ)
    leave(code)


def _open_closed_descriptors() -> None:
    """Standard descriptors closed when the program started (``>&-``, ``2>&-``, a daemon's)
    opened on the null device, with their Python streams (None until then): what the command
    says there is dropped, as it would be on /dev/null, instead of failing it (status 1, no
    results), and no file the command opens takes their number (a library writing to its
    stderr would write into that file)."""
    for descriptor, name in enumerate(("stdin", "stdout", "stderr")):
        try:
            os.fstat(descriptor)
        except OSError:
            null = os.open(os.devnull, os.O_RDWR)
            if null != descriptor:
                os.dup2(null, descriptor)
                os.close(null)
            if getattr(sys, name) is None:  # the process's own stream, open until it ends
                stream = open(descriptor, "r" if descriptor == 0 else "w",  # noqa: SIM115
                              closefd=False)
                setattr(sys, name, stream)


def command() -> object:
    """The command line's command in this process: its exit code (SystemExit's)."""
    from fccgrb_cli.core import scratch

    scratch.install()
    from fccgrb_cli.cli.main import main

    try:
        main()
    except SystemExit as done:
        return done.code
    return 0


def serve(path: str) -> None:
    """The process of a server of commands (``fccgrb_cli.cli.server``) on the socket
    ``path``: each command it forks ends as :func:`run`'s do (:func:`leave`)."""
    from fccgrb_cli.cli import server

    server.serve(path, lambda: leave(command()), server.warm_up)


def leave(code: object) -> None:
    """End the program with ``code`` (SystemExit's: None is 0, a text is said on stderr and is
    1) once the command is done: stdout and stderr flushed and the ``atexit`` handlers run (a
    temporary folder still open is removed, as at any exit), then ``os._exit``. The interpreter's
    own teardown, which frees every module's objects one by one, is skipped: after a solve it
    takes ~0.2 s (numba's types and LLVM's modules), a sixth of the whole command, and
    everything the command writes is closed before it returns (atomic writes, context
    managers, pools shut down). Where ``atexit`` cannot run its handlers on demand (not
    CPython), the ordinary exit."""
    if isinstance(code, str):
        sys.stderr.write(f"{code}\n")
        code = 1
    status = 0 if code is None else code if isinstance(code, int) else 1
    run_handlers = getattr(atexit, "_run_exitfuncs", None)
    if run_handlers is None:
        sys.exit(status)
    for stream in (sys.stdout, sys.stderr):
        # a closed pipe (| head) or stream: nothing left to say
        with contextlib.suppress(OSError, ValueError):
            stream.flush()
    run_handlers()
    os._exit(status)
