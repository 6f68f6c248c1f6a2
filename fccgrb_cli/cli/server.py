"""A warm process that runs ``fccgrb`` commands for this install: the start-up paid once.

Every command pays ~0.75 s before its first frame: the interpreter, numpy, numba (0.2 s),
the compiled kernels' machine code (0.2–0.3 s), h5py and the package. After a command has run
in a process of its own, ``fccgrb`` leaves a server behind (:func:`offer`): a process of the
same interpreter and package, detached, that imports everything, loads every compiled kernel
(``fccgrb compile``'s passes on the built-in pendulum), then waits on a Unix socket. The next
command (:func:`attempt`) sends it its arguments, folder, environment, umask and its own
stdin, stdout and stderr (the descriptors themselves), and the server forks: the child becomes
that command, in a process that has everything loaded but has run nothing, writes to the
user's terminal or pipes, and ends as the command ends. The command line waits for it, passes
it Ctrl-C, SIGTERM, SIGHUP and SIGQUIT, stops and continues it with itself (Ctrl-Z, ``fg``),
and exits with its status (a signal's death as the same signal). Gradle's daemon and Julia's
DaemonMode do the same for the same reason.

What makes a server serve a command, and nothing else:

- its socket is named by a digest (:func:`key`) of the interpreter, the package's place and
  version, the user, the interpreter's flags, the resource limits, the niceness and CPU
  affinity (``nice``, ``taskset``) and every environment
  variable that is read before a command runs (numba's, BLAS's, Python's, the locale, the
  cache folders, ``FCCGRB_*``); a command with another of these finds no server and runs in
  its own process (and leaves one for its own digest);
- before each fork the server compares its package's files and its libraries' entry files
  (path, size, modification time, inode) with those it imported: after an upgrade or an edit
  it refuses (the command runs in its own process) and ends, and the next command leaves a
  fresh one;
- the child takes the command's environment as a whole (with the kernels' cache folder the
  package sets for itself), folder, umask and descriptors; it ends when the server dies
  (``PR_SET_PDEATHSIG``), and the server ends it (SIGTERM: its files being written removed,
  as for Ctrl-C) when the command line dies first;
- the server runs with the interpreter flags of the command that left it, and serves only
  on the socket its own digest names;
- the socket is in a folder only the user can open (``$XDG_RUNTIME_DIR`` or the temporary
  folder, ``fccgrb-<uid>``), the server serves only its own user and the command line talks
  only to a server of its own user (``SO_PEERCRED``, both ends);
- a request the server gets to later than half the command line's wait is not run (the
  command line may have run it itself).

Anything that stops a command from reaching a server (none running, another user's folder, a
socket path too long, a closed descriptor, a refusal) runs it in its own process, as without
one. The server ends after :data:`IDLE` seconds without a command. Linux only (``fork`` after
numba and LLVM, ``pidfd``). By default only commands typed at a terminal (stderr a terminal)
use and leave servers: a script's or CI's commands keep the usual process tree (their workers
their children) and leave nothing running; ``FCCGRB_SERVER=1`` serves them too,
``FCCGRB_SERVER=0`` turns servers off (the tests do)."""

from __future__ import annotations

import contextlib
import hashlib
import json
import os
import signal
import socket
import struct
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from fccgrb_cli.core import scratch
from fccgrb_cli.core.errors import InputError

__all__ = ["IDLE", "SETTING", "attempt", "key", "offer", "serve", "source_stamp"]

# "0"/"off"/"no"/"false": never use nor leave a server; "1"/"on"/"yes"/"true": always;
# unset or "auto": for commands whose stderr is a terminal (:func:`enabled`); else an error
SETTING = "FCCGRB_SERVER"
OFF, ON = ("0", "off", "no", "false"), ("1", "on", "yes", "true")
IDLE = 600.0  # s without a command before the server ends
MOST = 3  # servers of one user at once (each environment its own, ~200 MB each)
PACKAGE = Path(__file__).resolve().parents[1]
# environment variables read before a command runs (imports, numba's and BLAS's set-up,
# the interpreter's start, the cache folders): a server serves commands that agree on them
KEYED_PREFIXES = ("NUMBA_", "FCCGRB_", "PYTHON", "LC_", "OPENBLAS_", "OMP_", "MKL_", "HDF5_",
                  "LD_", "NUMPY_", "VECLIB_", "GOTO_", "BLIS_", "KMP_")
KEYED_NAMES = ("LANG", "LANGUAGE", "HOME", "XDG_CACHE_HOME", "TMPDIR", "TZ", "USER")
FORWARDED = ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT")
FIRST_REPLY = 10.0  # s the command line waits for the server to say it started the command
_HEADER = struct.Struct("!I")
_STARTED, _REFUSED, _ENDED = b"P", b"S", b"X"
_REPLY = struct.Struct("!ci")  # (kind, pid or wait status)
warm = False  # this process is a warm server or one of its commands (set by warm_up)
SOCKET_PATH_MOST = 108  # bytes of a Unix socket's path on Linux, the closing NUL included


def enabled(environ: dict[str, str] | os._Environ = os.environ) -> bool:
    """Whether this command may use (and leave) a server: on Linux, when ``FCCGRB_SERVER`` is
    on, or unset (or ``auto``) and the command line's stderr is a terminal. The commands a
    user types are served; a script's, a pipeline's, CI's or a test harness's (stderr a pipe
    or a file) each run in a process of their own, a child of their caller, and leave no
    process behind, unless they ask for the server (``FCCGRB_SERVER=1``). InputError for any
    other value, never taken silently for one of these."""
    setting = environ.get(SETTING, "").strip().lower()
    if setting not in (*OFF, *ON, "", "auto"):
        raise InputError(f"{SETTING}: expected 1, 0 or auto (on/off, yes/no, true/false), "
                         f"got {environ[SETTING]!r}")
    if not (sys.platform.startswith("linux") and hasattr(os, "pidfd_open")
            and hasattr(socket, "AF_UNIX")):
        return False
    if setting in OFF:
        return False
    if setting in ON:
        return True
    try:
        return os.isatty(2)
    except OSError:
        return False


def key(environ: dict[str, str] | os._Environ = os.environ) -> str:
    """The digest (16 hex digits) naming the server that may run a command started with
    ``environ`` by this interpreter and package (see the module's docstring)."""
    import resource

    from fccgrb_cli import __version__

    limits = [resource.getrlimit(getattr(resource, name)) for name in dir(resource)
              if name.startswith("RLIMIT_")]
    keyed = sorted((name, value) for name, value in environ.items()
                   if name.startswith(KEYED_PREFIXES) or name in KEYED_NAMES)
    # the scheduling a command would have (nice, taskset), inherited by a fork as it is
    scheduling = [os.getpriority(os.PRIO_PROCESS, 0), sorted(os.sched_getaffinity(0))]
    what = [os.path.realpath(sys.executable), sys.version, str(PACKAGE), __version__,
            os.getuid(), os.getgid(), sorted(os.getgroups()), repr(sys.flags),
            sorted(sys._xoptions.items(), key=repr), sys.warnoptions, limits, scheduling,
            keyed]
    return hashlib.sha256(json.dumps(what, default=repr).encode()).hexdigest()[:16]


def folder(environ: dict[str, str] | os._Environ = os.environ) -> Path | None:
    """The user's private folder of sockets (made 0700 if missing), or None where it is not
    safely the user's (another owner, a link, open to others)."""
    import stat

    base = environ.get("XDG_RUNTIME_DIR") or environ.get("TMPDIR") or "/tmp"
    place = Path(base) / f"fccgrb-{os.getuid()}"
    try:
        place.mkdir(mode=0o700, exist_ok=True)
        info = os.lstat(place)
    except OSError:
        return None
    if (not stat.S_ISDIR(info.st_mode) or info.st_uid != os.getuid()
            or info.st_mode & 0o077):
        return None
    return place


def socket_path(environ: dict[str, str] | os._Environ = os.environ) -> Path | None:
    """The socket of the server for ``environ``; None where there is none to be had (no
    private folder, or a path longer than a Unix socket's: no server could listen on it, and
    one started would warm up in vain)."""
    place = folder(environ)
    if place is None:
        return None
    path = place / f"{key(environ)}.sock"
    return path if len(os.fsencode(path)) < SOCKET_PATH_MOST else None


# --- the command line's side ----------------------------------------------------------------
def attempt(argv: list[str], environ: dict[str, str]) -> int | None:
    """Run the command ``argv`` in this install's server, if one is up for ``environ``: its
    exit status, or None where no server took it (the caller runs it itself). InputError for
    a ``FCCGRB_SERVER`` value that is none of :func:`enabled`'s."""
    if not enabled(environ):
        return None
    path = socket_path(environ)
    if path is None:
        return None
    try:
        for descriptor in (0, 1, 2):
            os.fstat(descriptor)
        link = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    except OSError:
        return None
    with link:
        try:
            link.settimeout(FIRST_REPLY)
            link.connect(str(path))
            if _peer_uid(link) != os.getuid():
                return None  # never give another user our descriptors and environment
        except OSError:  # no server up
            return None
        command = _Forward()
        try:
            mask = os.umask(0)
            os.umask(mask)
            unbuffered = bool(getattr(sys.__stdout__, "write_through", False))  # -u
            request = json.dumps({"argv": argv, "cwd": os.getcwd(), "env": environ,
                                  "umask": mask, "unbuffered": unbuffered,
                                  "sent": time.monotonic()}).encode()
            socket.send_fds(link, [_HEADER.pack(len(request)) + request], [0, 1, 2])
            kind, pid = _reply(link)
        except (OSError, ValueError):  # a server that died or hangs
            kind, pid = b"", 0
        if kind != _STARTED:
            command.restore()
            return None
        command.started(pid)
        return _follow(link)


class _Forward:
    """The signals that end a command, passed to it: installed before the request is sent
    (the command may start before the reply comes), kept until then, sent once its pid is
    known."""

    def __init__(self) -> None:
        self.pid = 0
        self.pending: list[int] = []
        # a signal this process ignores (nohup, a background job) stays ignored: the command
        # would have ignored it
        self.previous = {name: signal.signal(getattr(signal, name), self.forward)
                         for name in FORWARDED
                         if signal.getsignal(getattr(signal, name)) is not signal.SIG_IGN}
        if signal.getsignal(signal.SIGTSTP) is not signal.SIG_IGN:
            self.previous["SIGTSTP"] = signal.signal(signal.SIGTSTP, self.stop)

    def stop(self, signum: int, frame) -> None:
        """Ctrl-Z: the command stops with this process (as it would, being this process),
        and continues with it (``fg``, ``bg``); where the kernel drops the stop (an orphaned
        process group), neither stops."""
        if not self.pid:
            self.pending.append(signum)
            return
        with contextlib.suppress(OSError):
            os.kill(self.pid, signal.SIGSTOP)
        signal.signal(signal.SIGTSTP, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGTSTP)  # stopped here until SIGCONT
        signal.signal(signal.SIGTSTP, self.stop)
        with contextlib.suppress(OSError):
            os.kill(self.pid, signal.SIGCONT)

    def forward(self, signum: int, frame) -> None:
        if not self.pid:
            self.pending.append(signum)
            return
        with contextlib.suppress(OSError):
            os.kill(self.pid, signum)

    def started(self, pid: int) -> None:
        self.pid = pid
        for signum in self.pending:
            (self.stop if signum == signal.SIGTSTP else self.forward)(signum, None)

    def restore(self) -> None:
        """Not served: the handlers as they were, and a signal that came meanwhile
        delivered to this process."""
        for name, handler in self.previous.items():
            signal.signal(getattr(signal, name), handler)
        for signum in self.pending:
            os.kill(os.getpid(), signum)


def _reply(link: socket.socket) -> tuple[bytes, int]:
    data = b""
    while len(data) < _REPLY.size:
        part = link.recv(_REPLY.size - len(data))
        if not part:
            raise ValueError("the server closed the connection")
        data += part
    return _REPLY.unpack(data)


def _follow(link: socket.socket) -> int:
    """Wait for the command to end (its signals forwarded by :class:`_Forward`); its exit
    status (a death by a signal repeated on this process)."""
    link.settimeout(None)
    try:
        kind, status = _reply(link)
    except (OSError, ValueError):
        kind, status = b"", 0
    if kind != _ENDED:
        sys.stderr.write("fccgrb: error: the fccgrb server ended before the command did; "
                         "run it again, or with FCCGRB_SERVER=0\n")
        return 1
    code = os.waitstatus_to_exitcode(status)
    if code < 0:  # killed by a signal: die of the same one, as the command did
        with contextlib.suppress(ValueError, OSError):
            signal.signal(-code, signal.SIG_DFL)
        os.kill(os.getpid(), -code)
        return 128 - code
    return code


def offer(environ: dict[str, str]) -> None:
    """After a command ran in its own process: start this install's server for ``environ``
    in the background, unless one is up or starting, the server is turned off, the user has
    :data:`MOST` servers up already (of other environments), or numba's kernels are not
    compiled yet (a first run's background compile is under way: the server would compile
    them again)."""
    if not enabled(environ) or not _kernels_ready():
        return
    path = socket_path(environ)
    if path is None or _locked(path) or len(servers(environ)) >= MOST:
        return
    import subprocess
    import warnings

    home = str(PACKAGE.parent)
    code = (f"import sys; sys.path[0] = {home!r}; from fccgrb_cli.entry import serve; "
            f"serve({str(path)!r})")
    # the command's own flags (-O, -W, -X dev, -X utf8, -B, ...): they are in the key
    flags = subprocess._args_from_interpreter_flags()  # type: ignore[attr-defined]
    with contextlib.suppress(OSError), warnings.catch_warnings():
        # never waited for (it outlives the command): not a "still running" ResourceWarning
        warnings.simplefilter("ignore", ResourceWarning)
        subprocess.Popen([sys.executable, *flags, "-c", code], stdin=subprocess.DEVNULL,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                         start_new_session=True, env=environ, cwd="/")


def _kernels_ready() -> bool:
    from importlib.util import find_spec

    if find_spec("numba") is None:
        return True
    cache = sys.modules.get("fccgrb_cli.core.kernel_cache")
    if cache is None or not os.environ.get("NUMBA_CACHE_DIR"):
        return False  # the command loaded no kernel (--help): nothing says they are built
    from fccgrb_cli.pipeline.precompile import compiling

    return cache.compiled_here() and not compiling(Path(os.environ["NUMBA_CACHE_DIR"]))


def _locked(path: Path) -> bool:
    """Whether a server holds ``path``'s lock (is up or starting)."""
    import fcntl

    try:
        with open(path.with_suffix(".lock"), "a") as lock:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            fcntl.flock(lock, fcntl.LOCK_UN)
    except BlockingIOError:
        return True
    except OSError:
        return True  # no lock can be taken: no server either
    return False


def servers(environ: dict[str, str] | os._Environ = os.environ) -> list[tuple[int, Path]]:
    """The user's servers up now (any install, any key): (pid, socket) each."""
    place = folder(environ)
    found = []
    for lock in sorted(place.glob("*.lock")) if place is not None else []:
        if _locked(lock.with_suffix(".sock")):
            with contextlib.suppress(OSError, ValueError):
                found.append((int(lock.read_text().split()[0]), lock.with_suffix(".sock")))
    return found


def stop(environ: dict[str, str] | os._Environ = os.environ) -> list[int]:
    """Ask every server of the user's to end (SIGTERM: the commands running finish first);
    their pids."""
    stopped = []
    for pid, _ in servers(environ):
        with _suppress():
            os.kill(pid, signal.SIGTERM)
            stopped.append(pid)
    return stopped


# --- the server's side ----------------------------------------------------------------------
def source_stamp(root: Path = PACKAGE, also: tuple[str, ...] = ()) -> tuple:
    """The code as the server imported it: (path, size, modification time, inode) of every
    file under ``root`` but the bytecode, and of the files ``also`` (:func:`dependencies`)."""
    paths = []
    for here, folders, files in os.walk(root):
        folders[:] = sorted(name for name in folders if name != "__pycache__")
        paths += [os.path.join(here, name) for name in sorted(files)]
    stamp = []
    for path in (*paths, *also):
        try:
            info = os.stat(path)
        except OSError:
            stamp.append((path, -1, -1, -1))  # absent: its coming back is a change too
            continue
        stamp.append((path, info.st_size, info.st_mtime_ns, info.st_ino))
    return tuple(stamp)


DEPENDENCIES = ("numpy", "scipy", "numba", "llvmlite", "h5py", "ezc3d", "click", "yaml")


def dependencies() -> tuple[str, ...]:
    """The entry files of the libraries a command runs on (their ``__init__.py``): an upgrade
    in the same environment (``pip install -U numpy``) rewrites them, and the server, which
    imported the old ones, then refuses and ends."""
    from importlib.util import find_spec

    found = []
    for name in DEPENDENCIES:
        try:
            spec = find_spec(name)
        except (ImportError, ValueError):
            continue
        if spec is not None and spec.origin:
            found.append(spec.origin)
    return tuple(found)


def serve(path: str | Path, command: Callable[[], object], warm_up: Callable[[], object],
          root: str | Path = PACKAGE, idle: float = IDLE,
          also: tuple[str, ...] | None = None) -> None:
    """The server's process: hold ``path``'s lock (else another server is up: return), run
    ``warm_up`` (imports, kernels), listen on ``path``, and fork ``command`` for each request
    until ``idle`` seconds pass without a command or the package under ``root`` changes."""
    import fcntl

    path = Path(path)
    if path.stem != key(os.environ):
        return  # not the interpreter (flags), limits or environment its commands have
    with open(path.with_suffix(".lock"), "a") as lock:  # held for the server's life
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
            os.close(os.pidfd_open(os.getpid()))  # Linux ≥ 5.3: how a command's end is seen
        except OSError:
            return  # another server holds it, or no pidfds
        lock.truncate(0)
        lock.write(f"{os.getpid()}\n")  # who serves: for `fccgrb server --stop`
        lock.flush()
        begun = dict(os.environ)
        # the files as they were before the warm-up imported them: one edited meanwhile is
        # seen as changed, not taken as what was imported
        watched = dependencies() if also is None else also
        stamp = source_stamp(Path(root), watched)
        warm_up()
        own = {name: value for name, value in os.environ.items() if begun.get(name) != value}
        _Server(path, command, (Path(root), watched), stamp, own, lock).run(idle)


class _Server:
    """The listening socket and the commands running (a pidfd and the command line's
    connection each)."""

    def __init__(self, path: Path, command: Callable[[], object],
                 root: tuple[Path, tuple[str, ...]], stamp: tuple,
                 own: dict[str, str], lock) -> None:
        import selectors

        self.path, self.command, self.root, self.own = path, command, root, own
        self.lock = lock  # closed in each command: a command outliving its server holds none
        self.stamp = stamp
        self.listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        path.unlink(missing_ok=True)
        self.listener.bind(str(path))
        self.inode = os.stat(path).st_ino  # the socket's file, removed at the end if still ours
        self.listener.listen(16)
        self.events = selectors.DefaultSelector()
        self.events.register(self.listener, selectors.EVENT_READ, None)
        self.running: dict[int, tuple[socket.socket, int]] = {}  # pidfd -> (link, pid)
        # SIGTERM (`fccgrb server --stop`): no new command; those running finish first
        self.wake, awake = socket.socketpair()
        self.wake.setblocking(False)
        awake.setblocking(False)
        signal.set_wakeup_fd(awake.fileno(), warn_on_full_buffer=False)
        signal.signal(signal.SIGTERM, lambda number, frame: None)
        self.awake = awake
        self.events.register(self.wake, selectors.EVENT_READ, ("stop",))

    def run(self, idle: float) -> None:
        try:
            while True:
                ready = self.events.select(None if self.running else idle)
                if not ready:
                    return  # idle
                for handle, _ in ready:
                    if handle.data is None:
                        if not self.accept():
                            return  # the package changed: the next command starts a fresh one
                    elif handle.data[0] == "stop":
                        with _suppress():
                            self.wake.recv(64)
                        self.close()
                        if not self.running:
                            return
                    elif handle.data[0] == "ended":
                        self.ended(handle.fd)
                    elif isinstance(handle.fileobj, socket.socket):  # a command line's link
                        self.hung_up(handle.fileobj, handle.data[1])
                if self.listener.fileno() < 0 and not self.running:
                    return  # stopped, and the last command ended
        finally:
            self.close()

    def close(self) -> None:
        """No more commands: the socket's file removed (if still this server's), the
        listening socket closed."""
        if self.listener.fileno() < 0:
            return
        with _suppress():
            if os.stat(self.path).st_ino == self.inode:
                self.path.unlink()
        with contextlib.suppress(KeyError, ValueError):
            self.events.unregister(self.listener)
        self.listener.close()

    def accept(self) -> bool:
        """Start the next request's command; False where the package changed (refused)."""
        import selectors

        link, _ = self.listener.accept()
        try:
            link.settimeout(FIRST_REPLY)
            request, descriptors = _request(link)
        except (OSError, ValueError):
            link.close()
            return True
        try:
            if time.monotonic() - request.get("sent", 0.0) > FIRST_REPLY / 2:
                # its command line may have given up waiting and run the command itself:
                # never run it twice (the server was held up, by a connection that said
                # nothing)
                link.close()
                return True
            if source_stamp(*self.root) != self.stamp:
                with _suppress():
                    link.sendall(_REPLY.pack(_REFUSED, 0))
                link.close()
                return False
            pid = os.fork()
            if pid == 0:
                self.child(link, request, descriptors)
        except OSError:  # no fork: nothing started, the command runs in its own process
            link.close()
            return True
        finally:
            for descriptor in descriptors:
                os.close(descriptor)
        pidfd = os.pidfd_open(pid)  # the server started only where pidfds work (serve)
        self.running[pidfd] = (link, pid)
        self.events.register(pidfd, selectors.EVENT_READ, ("ended", pid))
        try:
            link.sendall(_REPLY.pack(_STARTED, pid))
        except OSError:  # the command line is gone: its command ends as on a hang-up
            self.hung_up(link, pid)
            return True
        self.events.register(link, selectors.EVENT_READ, ("hung up", pid))
        return True

    def ended(self, pidfd: int) -> None:
        """A command ended: its wait status to its command line."""
        link, pid = self.running.pop(pidfd)
        self.events.unregister(pidfd)
        os.close(pidfd)
        _, status = os.waitpid(pid, 0)
        with contextlib.suppress(KeyError, ValueError):
            self.events.unregister(link)
        with _suppress():
            link.sendall(_REPLY.pack(_ENDED, status))
        link.close()

    def hung_up(self, link: socket.socket, pid: int) -> None:
        """The command line's end of the connection is readable: it died (or says what it
        should not). Its command ends as a command that gets SIGTERM does."""
        with contextlib.suppress(KeyError, ValueError):
            self.events.unregister(link)
        with _suppress():
            os.kill(pid, signal.SIGTERM)
            os.kill(pid, signal.SIGCONT)  # stopped with its command line (Ctrl-Z): it ends too

    def child(self, link: socket.socket, request: dict, descriptors: list[int]) -> None:
        """The forked command: becomes the command line's process in all it can see
        (descriptors, folder, umask, environment, arguments, signals), runs the command
        (which ends the process), and never returns into the server's loop."""
        try:
            scratch.terminated_with_parent()  # the server's death ends the command
            for name in ("SIGINT", "SIGTERM", "SIGHUP", "SIGQUIT", "SIGCHLD"):
                signal.signal(getattr(signal, name), signal.SIG_DFL)
            signal.set_wakeup_fd(-1)
            self.events.close()
            self.listener.close()
            self.wake.close()
            self.awake.close()
            self.lock.close()
            for pidfd, (other, _) in self.running.items():
                os.close(pidfd)
                other.close()
            link.close()
            for target, descriptor in enumerate(descriptors):
                os.dup2(descriptor, target)
                os.close(descriptor)
            descriptors.clear()
            os.chdir(request["cwd"])
            os.umask(request["umask"])
            os.environ.clear()
            os.environ.update({**request["env"], **self.own})
            import tempfile

            time.tzset()
            tempfile.tempdir = None
            sys.argv = list(request["argv"])
            _reopen_streams(bool(request.get("unbuffered")))
            self.command()
        except BaseException as error:  # the child must never return into the loop
            with _suppress():
                os.write(2, f"fccgrb: error: the server could not run the command: {error}\n"
                            .encode())
            os._exit(1)
        os._exit(0)


def _request(link: socket.socket) -> tuple[dict, list[int]]:
    """The command's request and its three descriptors (stdin, stdout, stderr), from a
    process of this user only."""
    uid = _peer_uid(link)
    message, descriptors, _, _ = socket.recv_fds(link, 65536, 3)
    try:
        if uid != os.getuid() or len(descriptors) != 3 or len(message) < _HEADER.size:
            raise ValueError("not a request of this user's")
        size = _HEADER.unpack_from(message)[0]
        data = message[_HEADER.size:]
        while len(data) < size:
            part = link.recv(size - len(data))
            if not part:
                raise ValueError("a request cut short")
            data += part
        return json.loads(data), descriptors
    except ValueError:
        for descriptor in descriptors:
            os.close(descriptor)
        raise


def _peer_uid(link: socket.socket) -> int:
    """The user of the process at the other end of ``link`` (as it connected or listened)."""
    credentials = link.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED,
                                  struct.calcsize("3i"))
    return struct.unpack("3i", credentials)[1]


def _suppress() -> contextlib.suppress:
    return contextlib.suppress(OSError)


def _reopen_streams(unbuffered: bool) -> None:
    """sys.stdin, stdout and stderr on the command line's descriptors, as the interpreter
    makes them at start (stdout line-buffered on a terminal, stderr always; both unbuffered
    under ``-u`` or PYTHONUNBUFFERED, ``unbuffered``), with the server's encodings (the
    locale is in the key)."""
    import io

    streams = []
    for descriptor, old in ((0, sys.__stdin__), (1, sys.__stdout__), (2, sys.__stderr__)):
        raw = io.FileIO(descriptor, "rb" if descriptor == 0 else "wb", closefd=False)
        if descriptor == 0:
            buffer: Any = io.BufferedReader(raw)
        else:
            buffer = raw if unbuffered else io.BufferedWriter(raw)
        encoding = getattr(old, "encoding", None) or "utf-8"
        errors = getattr(old, "errors", None) or ("backslashreplace" if descriptor == 2
                                                  else "strict")
        streams.append(io.TextIOWrapper(
            buffer, encoding=encoding, errors=errors,
            line_buffering=descriptor == 2 or (descriptor == 1 and raw.isatty()),
            write_through=unbuffered and descriptor != 0))
    for name, stream in zip(("stdin", "stdout", "stderr"), streams, strict=True):
        setattr(sys, name, stream)
        setattr(sys, f"__{name}__", stream)  # what the interpreter made at start


def warm_up() -> None:
    """What a command would load, loaded once: every module of the package, h5py, ezc3d,
    scipy.signal (the filters' fast path) and (where numba is installed) every compiled
    kernel, by ``fccgrb compile``'s passes on the built-in pendulum; then the kernels' clock
    and compile notice reset, so that a command reports only its own (a kernel the warm-up
    compiled stays known as compiled)."""
    import importlib
    import pkgutil

    import fccgrb_cli

    global warm
    warm = True
    for module in pkgutil.walk_packages(fccgrb_cli.__path__, "fccgrb_cli."):
        with contextlib.suppress(ImportError):
            importlib.import_module(module.name)
    for optional in ("h5py", "ezc3d"):
        with contextlib.suppress(ImportError):
            importlib.import_module(optional)
    from fccgrb_cli.signals.butterworth import preload

    preload()  # every command's filters in lfilter's C loop
    from fccgrb_cli.solvers import engine

    if engine.numba_available():
        from fccgrb_cli.pipeline.precompile import precompile

        precompile()
        engine.KernelClock.take()
        engine.KernelClock.told = False
