"""Helpers the CLI tests share: a runner with stdout and stderr apart, and the one-line error
contract (exit status 2, one ``fccgrb: error: …`` line on stderr, no traceback)."""

from __future__ import annotations

from click.testing import CliRunner, Result

from fccgrb_cli.cli.main import main


def runner() -> CliRunner:
    try:  # click < 8.2 mixes stderr into stdout unless told not to
        return CliRunner(mix_stderr=False)  # type: ignore[call-arg]
    except TypeError:  # click >= 8.2: stdout and stderr are always separate
        return CliRunner()


def run_cli(*args: object) -> Result:
    return runner().invoke(main, [str(a) for a in args])


def one_error_line(result: Result, *fragments: str) -> str:
    """Exit status 2, one stderr line ``fccgrb: error: …`` holding every fragment, no traceback,
    nothing of it on stdout."""
    assert result.exit_code == 2, (result.exit_code, result.output, result.exception)
    assert result.exception is None or isinstance(result.exception, SystemExit), \
        repr(result.exception)
    assert "Traceback" not in result.output
    lines = result.stderr.splitlines()
    assert len(lines) == 1, result.stderr
    line = lines[0]
    assert line.startswith("fccgrb: error: "), line
    for fragment in fragments:
        assert fragment in line, (fragment, line)
    assert "fccgrb: error:" not in result.stdout
    return line
