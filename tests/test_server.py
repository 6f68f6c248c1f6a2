"""The warm server (``fccgrb_cli.cli.server``): a command through it is the command run alone
(results, output, exit status, errors, folder, umask, environment), signals reach the command
and deaths on either side end the other, a changed package is never served, and the server ends
when idle. Real processes: the suite's other tests run with the server turned off
(tests/conftest.py), these turn it on in a private folder of sockets."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import h5py
import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1]
MODEL = ROOT / "configs" / "models" / "five_bar.yaml"
SAMPLE = ROOT / "sample_data" / "five_bar.c3d"
# the command line of `fccgrb`, its exit status and what it said, plus whether a server ran it
ATTEMPT = textwrap.dedent("""
    import os, sys
    from fccgrb_cli.cli import server
    code = server.attempt(["fccgrb", *sys.argv[1:]], dict(os.environ))
    sys.stderr.write("SERVED\\n" if code is not None else "NOT SERVED\\n")
    sys.stderr.flush()
    os._exit(0 if code is None else code)
""")


def served_env(folder: Path, **extra: str) -> dict[str, str]:
    env = {**os.environ, "FCCGRB_SERVER": "1", "XDG_RUNTIME_DIR": str(folder), **extra}
    env.pop("PYTHONUNBUFFERED", None)
    return env


def socket_of(env: dict[str, str]) -> Path:
    code = "import os; from fccgrb_cli.cli import server; print(server.socket_path(os.environ))"
    # from "/", as the servers start: the package installed, not a source tree in the folder
    # (whose place, in the key, names another socket)
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True,
                          text=True, check=True, cwd="/")
    return Path(done.stdout.strip())


def wait_for(condition, seconds: float, what: str) -> None:
    end = time.monotonic() + seconds
    while not condition():
        if time.monotonic() > end:
            raise AssertionError(f"{what}: not within {seconds} s")
        time.sleep(0.05)


def start(env: dict[str, str], body: str | None = None, **options: object) -> subprocess.Popen:
    """A server on ``env``'s socket: the real one (``entry.serve``), or, with ``body``, one
    whose command is that Python code (then its exit status 0) and whose warm-up is nothing,
    ``options`` given to ``server.serve`` (``root``, ``idle``)."""
    path = socket_of(env)
    if body is None:
        code = f"from fccgrb_cli.entry import serve; serve({str(path)!r})"
    else:
        code = "\n".join([
            "import os, sys, time", "from pathlib import Path",
            "from fccgrb_cli.cli import server", "from fccgrb_cli.entry import leave",
            "def command():", textwrap.indent(textwrap.dedent(body).strip(), "    "),
            "    leave(0)",
            f"server.serve({str(path)!r}, command, lambda: None, **{options!r})"])
    process = subprocess.Popen([sys.executable, "-c", code], env=env, cwd="/",
                               start_new_session=True)
    wait_for(lambda: path.exists() or process.poll() is not None, 180, "the server's socket")
    assert process.poll() is None, "the server ended at once"
    return process


def stop(process: subprocess.Popen) -> None:
    if process.poll() is None:
        process.kill()
        process.wait()


def fccgrb(env: dict[str, str], *args: str, cwd: Path, **options) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", ATTEMPT, *args], env=env, cwd=cwd,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            **options)


def finish(process: subprocess.Popen) -> tuple[int, str, str]:
    out, err = process.communicate(timeout=120)
    return process.returncode, out, err


def alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except OSError:
        return False
    return state != "Z"


@pytest.fixture(scope="module")
def warm(tmp_path_factory: pytest.TempPathFactory):
    """The real server, warmed up (every module, every kernel), for the module's tests."""
    pytest.importorskip("numba")
    env = served_env(tmp_path_factory.mktemp("sockets"))
    process = start(env)
    yield env
    stop(process)


def _without_times(path: Path) -> dict[str, np.ndarray]:
    out = {}
    with h5py.File(path) as handle:
        def keep(name, item):
            if isinstance(item, h5py.Dataset) and not name.endswith("time_s"):
                out[name] = item[()]
        handle.visititems(keep)
    return out


def test_a_served_solve_equals_the_solve_in_its_own_process(warm, tmp_path: Path) -> None:
    args = ["solve", str(MODEL), str(SAMPLE), "--perturb", "30"]
    alone = subprocess.run([sys.executable, "-c", "from fccgrb_cli.entry import run; run()",
                            *args, "-o", "alone.h5"], env={**warm, "FCCGRB_SERVER": "0"},
                           cwd=tmp_path, capture_output=True, text=True, check=True)
    code, out, err = finish(fccgrb(warm, *args, "-o", "served.h5", cwd=tmp_path))
    assert (code, err.splitlines()[-1]) == (0, "SERVED"), err
    # the server loaded the kernels before the command: only a process of its own reports it
    assert "kernels loaded" in alone.stderr and "kernels loaded" not in err
    first, second = _without_times(tmp_path / "alone.h5"), _without_times(tmp_path / "served.h5")
    assert first.keys() == second.keys() and len(first) > 20
    for name, value in first.items():
        assert np.array_equal(value, second[name], equal_nan=value.dtype.kind in "fc"), name
    # the summary's row but its ms/frame, then the same "wrote" line
    row = [line.split() for line in out.splitlines()], [line.split()
                                                        for line in alone.stdout.splitlines()]
    assert row[0][1][:2] + row[0][1][3:] == row[1][1][:2] + row[1][1][3:]
    assert out.splitlines()[-1] == alone.stdout.splitlines()[-1].replace("alone", "served")


def test_a_served_gait_solve_with_dynamics_equals_its_own_process(warm, tmp_path: Path) -> None:
    """The warm server has scipy.signal loaded, so its filters run in lfilter's C loop, a
    command of its own in the numpy loop: the loads', the drive's and the events' filters of
    a real gait trial give the same bits either way."""
    trial = ROOT.parent / "shared" / "data" / "c3d" / "Qualisys.c3d"
    if not trial.exists():
        pytest.skip("the shared data are absent")
    alone_env = {**warm, "FCCGRB_SERVER": "0"}
    entry = [sys.executable, "-c", "from fccgrb_cli.entry import run; run()"]
    subprocess.run([*entry, "calibrate", str(ROOT / "configs" / "models" / "lower_limb.yaml"),
                    str(trial), "--mass", "67", "-o", "personal.yaml"], env=alone_env,
                   cwd=tmp_path, capture_output=True, text=True, check=True)
    args = ["solve", "personal.yaml", str(trial), "--method", "nrm-wls", "--filter-cutoff", "6"]
    alone = subprocess.run([*entry, *args, "-o", "alone.h5"], env=alone_env, cwd=tmp_path,
                           capture_output=True, text=True, check=True)
    assert "kernels loaded" in alone.stderr  # compiled kernels, as in the server
    code, _, err = finish(fccgrb(warm, *args, "-o", "served.h5", cwd=tmp_path))
    assert (code, err.splitlines()[-1]) == (0, "SERVED"), err
    first, second = _without_times(tmp_path / "alone.h5"), _without_times(tmp_path / "served.h5")
    assert first.keys() == second.keys()
    assert any("gait/cycles" in name for name in first) and any("moments" in name
                                                                for name in first)
    for name, value in first.items():
        assert np.array_equal(value, second[name], equal_nan=value.dtype.kind in "fc"), name


def test_a_served_error_is_one_line_and_status_2(warm, tmp_path: Path) -> None:
    code, out, err = finish(fccgrb(warm, "solve", "missing.yaml", str(SAMPLE), cwd=tmp_path))
    lines = err.splitlines()
    assert code == 2 and out == "" and lines[-1] == "SERVED"
    assert len(lines) == 2 and lines[0].startswith("fccgrb: error:") and "missing.yaml" in lines[0]


def test_the_command_has_the_callers_folder_umask_and_environment(warm, tmp_path: Path) -> None:
    process = fccgrb(warm, "solve", str(MODEL), str(SAMPLE), "-o", "here.h5", cwd=tmp_path,
                     preexec_fn=lambda: os.umask(0o077))
    assert finish(process)[0] == 0
    assert (tmp_path / "here.h5").stat().st_mode & 0o777 == 0o600
    for columns in ("50", "160"):  # an environment variable the server's key leaves out
        env = {**warm, "COLUMNS": columns}
        code, out, err = finish(fccgrb(env, "solve", "--help", cwd=tmp_path))
        alone = subprocess.run([sys.executable, "-c", "from fccgrb_cli.entry import run; run()",
                                "solve", "--help"], env={**env, "FCCGRB_SERVER": "0"},
                               capture_output=True, text=True, check=True, cwd=tmp_path)
        assert code == 0 and err.splitlines() == ["SERVED"] and out == alone.stdout


@pytest.fixture
def toy(tmp_path: Path):
    """Start servers whose command is given code; all are stopped after the test."""
    started = []
    env = served_env(tmp_path / "sockets")
    (tmp_path / "sockets").mkdir()

    def make(body: str, **options: object) -> subprocess.Popen:
        started.append(start(env, body, **options))
        return started[-1]

    make.env = env  # type: ignore[attr-defined]
    yield make
    for process in started:
        stop(process)


def test_streams_and_exit_status_are_the_command_lines(toy, tmp_path: Path) -> None:
    toy("""
        data = sys.stdin.read()
        print(f"read {len(data)} characters in {os.getcwd()}")
        sys.stderr.write("to stderr\\n")
        leave(3)
    """)
    process = fccgrb(toy.env, cwd=tmp_path, stdin=subprocess.PIPE)
    out, err = process.communicate("x" * 100_000, timeout=60)
    assert process.returncode == 3
    assert out == f"read 100000 characters in {tmp_path}\n"
    assert err == "to stderr\nSERVED\n"


@pytest.mark.parametrize("name", ["SIGINT", "SIGTERM", "SIGHUP"])
def test_a_signal_to_the_command_line_reaches_the_command(toy, tmp_path: Path,
                                                          name: str) -> None:
    toy("""
        from fccgrb_cli.core import scratch
        scratch.install()
        scratch.create(os.getcwd(), "being-written-", ".h5")
        print("ready", flush=True)
        time.sleep(60)
    """)
    process = fccgrb(toy.env, cwd=tmp_path)
    assert process.stdout.readline() == "ready\n"
    process.send_signal(getattr(signal, name))
    code, _, err = finish(process)
    number = getattr(signal, name)
    assert code == 128 + number, err
    assert f"interrupted by {name}" in err
    assert not list(tmp_path.glob("being-written-*"))  # removed, as without a server


def test_a_command_killed_by_a_signal_kills_its_command_line(toy, tmp_path: Path) -> None:
    toy("os.kill(os.getpid(), 9)")
    code, _, _ = finish(fccgrb(toy.env, cwd=tmp_path))
    assert code == -9


def sleeping(toy, folder: Path) -> tuple[subprocess.Popen, subprocess.Popen, int]:
    """A server whose command writes its pid then sleeps a minute, a command line running it
    in ``folder``, and the command's pid."""
    server = toy("""
        Path('pid').write_text(str(os.getpid()))
        time.sleep(60)
    """)
    process = fccgrb(toy.env, cwd=folder)
    wait_for((folder / "pid").exists, 30, "the command's pid")
    return server, process, int((folder / "pid").read_text())


def test_a_dead_command_line_ends_its_command(toy, tmp_path: Path) -> None:
    _, process, pid = sleeping(toy, tmp_path)
    process.kill()
    process.wait()
    wait_for(lambda: not alive(pid), 10, "the command's end")


def test_a_dead_server_ends_its_commands_and_the_command_line_says_so(toy,
                                                                    tmp_path: Path) -> None:
    server, process, pid = sleeping(toy, tmp_path)
    server.kill()
    code, _, err = finish(process)
    assert code == 1 and "the fccgrb server ended before the command did" in err
    wait_for(lambda: not alive(pid), 10, "the command's end")


def test_a_changed_package_is_never_served(toy, tmp_path: Path) -> None:
    package = tmp_path / "package"
    package.mkdir()
    (package / "module.py").write_text("x = 1\n")
    server = toy("print('served')", root=str(package))
    code, out, err = finish(fccgrb(toy.env, cwd=tmp_path))
    assert (code, out, err) == (0, "served\n", "SERVED\n")
    (package / "module.py").write_text("x = 2\n")  # an edit, an upgrade
    code, out, err = finish(fccgrb(toy.env, cwd=tmp_path))
    assert (code, out, err) == (0, "", "NOT SERVED\n")
    assert server.wait(timeout=30) == 0  # and it ended: the next command starts a fresh one
    assert not socket_of(toy.env).exists()


def test_a_package_changed_during_the_warm_up_is_never_served(tmp_path: Path) -> None:
    """A file edited after the warm-up imported it but before the server listens: the
    server must not take the edited files for those it runs."""
    (tmp_path / "sockets").mkdir()
    env = served_env(tmp_path / "sockets")
    package = tmp_path / "package"
    package.mkdir()
    (package / "module.py").write_text("x = 1\n")
    path = socket_of(env)
    edit = f"lambda: Path({str(package / 'module.py')!r}).write_text('x = 22\\n')"
    server = subprocess.Popen(
        [sys.executable, "-c", "from pathlib import Path; from fccgrb_cli.cli import server; "
         f"server.serve({str(path)!r}, lambda: print('stale'), {edit}, "
         f"root={str(package)!r})"], env=env, cwd="/", start_new_session=True)
    try:
        wait_for(lambda: path.exists() or server.poll() is not None, 60, "the server's socket")
        code, out, err = finish(fccgrb(env, cwd=tmp_path))
        assert (code, out, err) == (0, "", "NOT SERVED\n")
        assert server.wait(timeout=30) == 0
    finally:
        stop(server)


def test_an_idle_server_ends_and_a_second_one_does_not_start(toy, tmp_path: Path) -> None:
    server = toy("print('first')", idle=3.0)
    path = socket_of(toy.env)
    second = subprocess.run([sys.executable, "-c", "from fccgrb_cli.cli import server; "
                             f"server.serve({str(path)!r}, print, print)"], env=toy.env,
                            timeout=60, check=True, capture_output=True, text=True, cwd="/")
    assert second.stdout == ""  # neither warmed up nor served: the lock is held
    assert int(path.with_suffix(".lock").read_text()) == server.pid
    assert finish(fccgrb(toy.env, cwd=tmp_path))[1] == "first\n"
    assert server.wait(timeout=30) == 0
    assert not path.exists()


def test_the_key_names_what_is_read_before_a_command_runs(tmp_path: Path) -> None:
    from fccgrb_cli.cli import server

    base = {"PATH": "/usr/bin", "HOME": "/home/someone", "TERM": "xterm"}
    first = server.key(base)
    for name, value in (("NUMBA_CACHE_DIR", "/x"), ("PYTHONHASHSEED", "0"), ("LANG", "C"),
                        ("OPENBLAS_NUM_THREADS", "2"), ("FCCGRB_SPILL_MB", "1"),
                        ("HOME", "/home/other"), ("XDG_CACHE_HOME", "/c"), ("LD_PRELOAD", "x")):
        assert server.key({**base, name: value}) != first, name
    for name, value in (("TERM", "dumb"), ("COLUMNS", "50"), ("PWD", "/tmp"), ("PATH", "/bin")):
        assert server.key({**base, name: value}) == first, name
    # a folder of sockets others may open is not used
    env = {"XDG_RUNTIME_DIR": str(tmp_path)}
    assert server.folder(env) == tmp_path / f"fccgrb-{os.getuid()}"
    (tmp_path / f"fccgrb-{os.getuid()}").chmod(0o755)
    assert server.folder(env) is None
    # a socket path too long to listen on: no server is tried nor left (it would warm up
    # and fail to listen, after every command)
    beside = len(f"/fccgrb-{os.getuid()}/{server.key({})}.sock")
    deep = tmp_path / ("x" * (108 - len(str(tmp_path)) - 1 - beside))  # a 108-byte path
    shallower = Path(str(deep)[:-1])
    deep.mkdir()
    shallower.mkdir()
    assert server.socket_path({"XDG_RUNTIME_DIR": str(deep)}) is None
    assert len(str(server.socket_path({"XDG_RUNTIME_DIR": str(shallower)}))) == 107
    assert not server.enabled({"FCCGRB_SERVER": "0"}) and not server.enabled(
        {"FCCGRB_SERVER": "off"})


@pytest.mark.parametrize("setting", [None, "auto", "1", "0", "AUTO", " 1 ", "Off"])
def test_by_default_only_commands_at_a_terminal_use_a_server(setting: str | None) -> None:
    """Unset (or auto): a command whose stderr is a terminal may use and leave a server; one
    whose stderr is a pipe (a script, CI, a harness) runs in its own process, its workers its
    own children, and leaves nothing; FCCGRB_SERVER=1 or 0 decides either way."""
    import pty

    code = "from fccgrb_cli.cli import server; print(server.enabled())"
    env = {k: v for k, v in os.environ.items() if k != "FCCGRB_SERVER"}
    if setting is not None:
        env["FCCGRB_SERVER"] = setting
    said = {}
    for where in ("pipe", "terminal"):
        leader, follower = pty.openpty()
        try:
            done = subprocess.run([sys.executable, "-c", code], env=env, cwd="/", text=True,
                                  stdout=subprocess.PIPE,
                                  stderr=follower if where == "terminal" else subprocess.PIPE,
                                  check=True)
        finally:
            os.close(leader)
            os.close(follower)
        said[where] = done.stdout.strip()
    expected = {None: ("False", "True"), "auto": ("False", "True"), "1": ("True", "True"),
                "0": ("False", "False"), "AUTO": ("False", "True"), " 1 ": ("True", "True"),
                "Off": ("False", "False")}[setting]
    assert (said["pipe"], said["terminal"]) == expected


@pytest.mark.parametrize("setting", ["2", "force", "auto-on"])
def test_another_server_setting_is_one_line_and_status_2(setting: str) -> None:
    """A value that is none of on, off or auto (a typo, or a number other than 0 and 1) is
    refused before the command runs, rather than taken for one of them."""
    from fccgrb_cli.cli import server
    from fccgrb_cli.core.errors import InputError

    with pytest.raises(InputError, match="FCCGRB_SERVER"):
        server.enabled({"FCCGRB_SERVER": setting})
    done = subprocess.run([sys.executable, "-c", "from fccgrb_cli.entry import run; run()",
                           "--version"], env={**os.environ, "FCCGRB_SERVER": setting},
                          cwd="/", capture_output=True, text=True, timeout=60)
    assert (done.returncode, done.stdout) == (2, ""), done.stderr
    assert done.stderr == ("fccgrb: error: FCCGRB_SERVER: expected 1, 0 or auto (on/off, "
                           f"yes/no, true/false), got {setting!r}\n")


def test_a_command_leaves_a_server_unless_turned_off(tmp_path: Path) -> None:
    pytest.importorskip("numba")
    run = [sys.executable, "-c", "from fccgrb_cli.entry import run; run()", "solve",
           str(MODEL), str(SAMPLE), "-o", "out.h5", "--replace"]
    off = served_env(tmp_path / "off", FCCGRB_SERVER="0")
    subprocess.run(run, env=off, cwd=tmp_path, check=True, capture_output=True)
    assert not (tmp_path / "off").exists() or not list((tmp_path / "off").rglob("*.sock"))
    env = served_env(tmp_path / "on")
    (tmp_path / "on").mkdir()
    first = subprocess.run(run, env=env, cwd=tmp_path, check=True, capture_output=True,
                           text=True)
    assert "kernels loaded" in first.stderr  # in its own process
    path = socket_of(env)
    wait_for(path.exists, 180, "the server left by the command")
    pid = int(path.with_suffix(".lock").read_text())
    try:
        code, _, err = finish(fccgrb(env, *run[3:], cwd=tmp_path))
        assert (code, err.splitlines()[-1]) == (0, "SERVED"), err
        assert alive(pid)
    finally:
        os.kill(pid, signal.SIGKILL)


def test_stop_lets_running_commands_finish_then_ends_the_server(toy, tmp_path: Path) -> None:
    from fccgrb_cli.cli import server

    process = toy("""
        print("started", flush=True)
        time.sleep(1.0)
        print("finished")
    """)
    running = fccgrb(toy.env, cwd=tmp_path)
    assert running.stdout.readline() == "started\n"
    assert [pid for pid, _ in server.servers(toy.env)] == [process.pid]
    assert server.stop(toy.env) == [process.pid]
    code, out, err = finish(running)
    assert (code, out, err) == (0, "finished\n", "SERVED\n")
    assert process.wait(timeout=30) == 0
    assert server.servers(toy.env) == [] and not socket_of(toy.env).exists()
    assert finish(fccgrb(toy.env, cwd=tmp_path))[2] == "NOT SERVED\n"


def test_an_ignored_signal_stays_ignored(toy, tmp_path: Path) -> None:
    toy("""
        print("started", flush=True)
        time.sleep(1.0)
        print("finished")
    """)
    running = fccgrb(toy.env, cwd=tmp_path,
                     preexec_fn=lambda: signal.signal(signal.SIGHUP, signal.SIG_IGN))  # nohup
    assert running.stdout.readline() == "started\n"
    running.send_signal(signal.SIGHUP)
    assert finish(running) == (0, "finished\n", "SERVED\n")


def test_a_command_with_interpreter_flags_leaves_a_server_with_them(tmp_path: Path) -> None:
    """The flags are in the key: the server left for them must run with them (-X dev, -O,
    -W error, -X utf8), and leaving it says nothing (no ResourceWarning under -X dev)."""
    pytest.importorskip("numba")
    flags = ["-X", "dev", "-W", "error::ResourceWarning"]
    run = [sys.executable, *flags, "-c", "from fccgrb_cli.entry import run; run()", "solve",
           str(MODEL), str(SAMPLE), "-o", "out.h5", "--replace"]
    env = served_env(tmp_path / "on")
    (tmp_path / "on").mkdir()
    first = subprocess.run(run, env=env, cwd=tmp_path, check=True, capture_output=True,
                           text=True)
    assert "Warning" not in first.stderr, first.stderr
    code = "import os; from fccgrb_cli.cli import server; print(server.socket_path(os.environ))"
    path = Path(subprocess.run([sys.executable, *flags, "-c", code], env=env, text=True,
                               capture_output=True, check=True, cwd="/").stdout.strip())
    wait_for(path.exists, 180, "the server left by the command")
    pid = int(path.with_suffix(".lock").read_text())
    try:
        arguments = Path(f"/proc/{pid}/cmdline").read_text().split("\0")
        assert {"-Werror::ResourceWarning", "dev"} <= set(arguments), arguments
        args = run[len(flags) + 3:]
        done = subprocess.run([sys.executable, *flags, "-c", ATTEMPT, *args], env=env,
                              cwd=tmp_path, capture_output=True, text=True, timeout=120)
        assert (done.returncode, done.stderr.splitlines()[-1]) == (0, "SERVED"), done.stderr
    finally:
        os.kill(pid, signal.SIGKILL)


def test_a_server_serves_only_the_socket_of_its_own_key(tmp_path: Path) -> None:
    (tmp_path / "sockets").mkdir()
    env = served_env(tmp_path / "sockets")
    path = socket_of(env).with_name("0123456789abcdef.sock")  # another interpreter's, flags'
    subprocess.run([sys.executable, "-c", "from fccgrb_cli.cli import server; "
                    f"server.serve({str(path)!r}, print, lambda: print('warm'))"],
                   env=env, timeout=60, check=True, capture_output=True, text=True, cwd="/")
    assert not path.exists() and not path.with_suffix(".lock").exists()


def _state(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(")")[-1].split()[0]
    except OSError:
        return "gone"


def test_ctrl_z_stops_the_command_and_fg_resumes_it(toy, tmp_path: Path) -> None:
    """Ctrl-Z (SIGTSTP) stops the command line; the command, running in the server's fork,
    must stop with it (not write on while the shell says the job is stopped), and continue
    with it (SIGCONT, `fg`)."""
    toy("""
        Path('pid').write_text(str(os.getpid()))
        for tick in range(100):
            print(tick, flush=True)
            time.sleep(0.05)
    """)
    # its own process group in the test's session: not orphaned, so SIGTSTP stops it
    process = fccgrb(toy.env, cwd=tmp_path, preexec_fn=os.setpgrp)
    assert process.stdout.readline() == "0\n"
    pid = int((tmp_path / "pid").read_text())
    process.send_signal(signal.SIGTSTP)
    wait_for(lambda: _state(process.pid) == "T", 10, "the command line stopped")
    wait_for(lambda: _state(pid) == "T", 10, "the command stopped")
    process.send_signal(signal.SIGCONT)
    code, out, err = finish(process)
    assert (code, out.split(), err) == (0, [str(tick) for tick in range(1, 100)], "SERVED\n")


def test_a_socket_of_another_user_is_never_given_the_command(toy, tmp_path: Path) -> None:
    """The folder's checks can be raced (a parent folder another user may write in): the
    command line itself checks whose process listens before it sends its descriptors and
    environment."""
    toy("print('served')")
    code = ATTEMPT.replace("from fccgrb_cli.cli import server",
                           "from fccgrb_cli.cli import server\n"
                           "server._peer_uid = lambda link: os.getuid() + 1")
    done = subprocess.run([sys.executable, "-c", code], env=toy.env, cwd=tmp_path,
                          capture_output=True, text=True, timeout=60)
    assert (done.returncode, done.stdout, done.stderr) == (0, "", "NOT SERVED\n")


def test_the_temporary_folder_is_the_commands_not_the_warm_ups(tmp_path: Path) -> None:
    """tempfile caches its folder on first use (say in the warm-up); TMP and TEMP are not in
    the key, and a command must use its own, as it would alone."""
    (tmp_path / "sockets").mkdir()
    env = served_env(tmp_path / "sockets")
    for name in ("TMP", "TEMP", "TMPDIR"):
        env.pop(name, None)
    path = socket_of(env)
    server = subprocess.Popen(
        [sys.executable, "-c", "import tempfile; from fccgrb_cli.cli import server; "
         "from fccgrb_cli.entry import leave; "
         f"server.serve({str(path)!r}, lambda: leave(print(tempfile.gettempdir())), "
         "tempfile.gettempdir)"], env=env, cwd="/", start_new_session=True)
    try:
        wait_for(lambda: path.exists() or server.poll() is not None, 60, "the server's socket")
        (tmp_path / "mine").mkdir()
        code, out, err = finish(fccgrb({**env, "TMP": str(tmp_path / "mine")}, cwd=tmp_path))
        assert (code, out, err) == (0, f"{tmp_path / 'mine'}\n", "SERVED\n")
    finally:
        stop(server)


def test_a_command_outliving_its_killed_server_lets_a_new_one_start(toy,
                                                                    tmp_path: Path) -> None:
    first = toy("""
        import signal
        signal.signal(signal.SIGTERM, signal.SIG_IGN)  # outlives its server's death
        Path('pid').write_text(str(os.getpid()))
        time.sleep(30)
    """)
    process = fccgrb(toy.env, cwd=tmp_path)
    wait_for((tmp_path / "pid").exists, 30, "the command's pid")
    pid = int((tmp_path / "pid").read_text())
    try:
        first.kill()
        first.wait()
        assert process.wait(timeout=30) == 1  # its stdout stays open: the command holds it
        assert alive(pid)
        socket_of(toy.env).unlink()  # the killed server's, left behind
        toy("print('second')")  # its socket appears: the lock was free
        assert finish(fccgrb(toy.env, cwd=tmp_path))[1] == "second\n"
    finally:
        os.kill(pid, signal.SIGKILL)


@pytest.mark.parametrize("how", ["terminal", "-u"])
def test_stdout_is_buffered_as_the_command_lines(toy, tmp_path: Path, how: str) -> None:
    """On a terminal stdout is line-buffered, under -u not buffered: a line printed shows at
    once, not when the command ends."""
    import select

    toy("""
        sys.stdout.write("early" + chr(10))
        Path('wrote').write_text('')
        time.sleep(5)
    """)
    flags = ["-u"] if how == "-u" else []
    if how == "terminal":
        reader, writer = os.openpty()
    else:
        reader, writer = os.pipe()
    process = subprocess.Popen([sys.executable, *flags, "-c", ATTEMPT], env=toy.env,
                               cwd=tmp_path, stdout=writer, stderr=subprocess.PIPE)
    os.close(writer)
    try:
        wait_for((tmp_path / "wrote").exists, 30, "the command's line")
        assert select.select([reader], [], [], 2.0)[0], "the line waits for the command's end"
        assert os.read(reader, 100).replace(b"\r", b"") == b"early\n"
    finally:
        process.kill()
        process.wait()
        process.stderr.close()
        os.close(reader)


def test_a_command_line_that_gave_up_waiting_is_not_served_too(tmp_path: Path) -> None:
    """A server held up (here by connections that say nothing) past the command line's wait:
    the command line runs the command itself, and the server must not run it a second time
    when it gets to the request."""
    import socket

    (tmp_path / "sockets").mkdir()
    env = served_env(tmp_path / "sockets")
    path = socket_of(env)
    server = subprocess.Popen(
        [sys.executable, "-c", "from fccgrb_cli.cli import server; "
         "from fccgrb_cli.entry import leave; server.FIRST_REPLY = 4.0; "
         "run = lambda: leave(open('runs', 'a').write('served' + chr(10))); "
         f"server.serve({str(path)!r}, run, lambda: None)"],
        env=env, cwd="/", start_new_session=True)
    silent = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    try:
        wait_for(lambda: path.exists() or server.poll() is not None, 60, "the server's socket")
        silent.connect(str(path))  # holds the server for its FIRST_REPLY
        code = ATTEMPT.replace("from fccgrb_cli.cli import server",
                               "from fccgrb_cli.cli import server; server.FIRST_REPLY = 0.5")
        done = subprocess.run([sys.executable, "-c", code], env=env, cwd=tmp_path,
                              capture_output=True, text=True, timeout=60)
        assert done.stderr == "NOT SERVED\n"  # it runs the command itself
        time.sleep(5.0)  # the server has read the request meanwhile
        assert not (tmp_path / "runs").exists()
    finally:
        silent.close()
        stop(server)


def test_a_nice_command_is_not_served_by_a_server_of_another_niceness(toy,
                                                                      tmp_path: Path) -> None:
    """`nice fccgrb ...`: the command runs at the caller's niceness, as it would alone (a fork
    of the server had the server's, and no process may lower its niceness back)."""
    toy("print(os.nice(0))")
    process = fccgrb(toy.env, cwd=tmp_path, preexec_fn=lambda: os.nice(5))
    code, out, err = finish(process)
    assert (code, out, err) in ((0, "", "NOT SERVED\n"), (0, f"{os.nice(0) + 5}\n", "SERVED\n"))
    assert finish(fccgrb(toy.env, cwd=tmp_path))[1:] == (f"{os.nice(0)}\n", "SERVED\n")


def test_the_command_has_what_the_warm_up_set_in_its_environment(tmp_path: Path) -> None:
    """The package sets variables for itself at import (the kernels' cache folder, BLAS's
    threads): a command alone has them, so a served command keeps the warm-up's, over the
    command line's environment."""
    (tmp_path / "sockets").mkdir()
    env = served_env(tmp_path / "sockets")
    path = socket_of(env)
    warm_up = "lambda: os.environ.update(FCCGRB_SET_AT_IMPORT='yes')"
    server = subprocess.Popen(
        [sys.executable, "-c", "import os; from fccgrb_cli.cli import server; "
         "from fccgrb_cli.entry import leave; "
         "show = lambda: leave(print(os.environ.get('FCCGRB_SET_AT_IMPORT'))); "
         f"server.serve({str(path)!r}, show, {warm_up})"], env=env, cwd="/",
        start_new_session=True)
    try:
        wait_for(lambda: path.exists() or server.poll() is not None, 60, "the server's socket")
        assert finish(fccgrb(env, cwd=tmp_path)) == (0, "yes\n", "SERVED\n")
    finally:
        stop(server)


def test_a_stopped_command_ends_when_its_command_line_is_killed(toy, tmp_path: Path) -> None:
    """Ctrl-Z, then `kill -9 %1`: the command, stopped with its command line, must end (a
    SIGTERM waits while a process is stopped) rather than stay stopped forever."""
    toy("""
        Path('pid').write_text(str(os.getpid()))
        time.sleep(60)
    """)
    process = fccgrb(toy.env, cwd=tmp_path, preexec_fn=os.setpgrp)
    wait_for((tmp_path / "pid").exists, 30, "the command's pid")
    pid = int((tmp_path / "pid").read_text())
    process.send_signal(signal.SIGTSTP)
    wait_for(lambda: _state(pid) == "T", 10, "the command stopped")
    process.kill()
    process.wait()
    wait_for(lambda: not alive(pid), 10, "the command's end")


def test_an_upgraded_dependency_is_never_served(toy, tmp_path: Path) -> None:
    """A library the commands run on (numpy's ``__init__.py`` by default) rewritten in place,
    as ``pip install -U`` does: the server refuses and ends."""
    package, library = tmp_path / "package", tmp_path / "library.py"
    package.mkdir()
    (package / "module.py").write_text("x = 1\n")
    library.write_text("version = 1\n")
    server = toy("print('served')", root=str(package), also=(str(library),))
    assert finish(fccgrb(toy.env, cwd=tmp_path))[1:] == ("served\n", "SERVED\n")
    library.unlink()
    library.write_text("version = 2\n")  # a new file in its place
    assert finish(fccgrb(toy.env, cwd=tmp_path))[1:] == ("", "NOT SERVED\n")
    assert server.wait(timeout=30) == 0


def test_the_libraries_watched_are_those_a_command_imports() -> None:
    from fccgrb_cli.cli import server

    watched = server.dependencies()
    for name in ("numpy", "numba", "h5py", "click"):
        assert any(f"{os.sep}{name}{os.sep}__init__.py" in path for path in watched), name
