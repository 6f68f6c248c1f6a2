"""A warm fccgrb server for a benchmark's commands (``fccgrb_cli.cli.server``), in a private
folder of sockets, stopped at the end; and the environment of commands that run in their own
process (``FCCGRB_SERVER=0``), as every command did before the server.

    with warm_server() as env:   # commands run with env=env are served
        ...
"""

from __future__ import annotations

import contextlib
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

ALONE = {**os.environ, "FCCGRB_SERVER": "0"}


@contextlib.contextmanager
def warm_server(python: str = sys.executable, timeout: float = 300.0) -> Iterator[dict]:
    """Start this install's server (as a command leaves it: ``entry.serve``) for an
    environment whose socket folder is private to the benchmark; yield that environment once
    the server listens; stop it at the end."""
    with tempfile.TemporaryDirectory(prefix="fccgrb-sockets-") as folder:
        env = {**os.environ, "FCCGRB_SERVER": "1", "XDG_RUNTIME_DIR": folder}
        code = "import os; from fccgrb_cli.cli import server; print(server.socket_path(os.environ))"
        # from "/", as the server starts: the installed package, not a source tree here
        path = Path(subprocess.run([python, "-c", code], env=env, capture_output=True,
                                   text=True, check=True, cwd="/").stdout.strip())
        server = subprocess.Popen(
            [python, "-c", f"from fccgrb_cli.entry import serve; serve({str(path)!r})"],
            env=env, cwd="/", stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
            start_new_session=True)
        end = time.monotonic() + timeout
        while not path.exists():
            if server.poll() is not None or time.monotonic() > end:
                server.kill()
                sys.exit("the fccgrb server did not start")
            time.sleep(0.05)
        try:
            yield env
        finally:
            server.terminate()
            server.wait()
