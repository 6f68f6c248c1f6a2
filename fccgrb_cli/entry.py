"""The ``fccgrb`` program's entry point: the signal handlers first (``fccgrb_cli.core.scratch``), so
that a Ctrl-C while numpy, h5py and click are still loading already ends the program with one
line and status 130, then the command line (``fccgrb_cli.cli.main``)."""

from __future__ import annotations


def run() -> None:
    from fccgrb_cli.core import scratch

    scratch.install()
    from fccgrb_cli.cli.main import main

    main()
