"""What users hand fccgrb, read safely: files, YAML, and names that become paths.

* Input files must be regular files (a FIFO would block the read forever, a link to /dev/zero
  would fill the memory) of a bounded size where the whole file is read at once.
* Text is UTF-8 (a byte-order mark is allowed); a byte that is not is one line naming the file,
  the line and the byte.
* YAML is scanned event by event (libyaml's parser keeps its own stack) before it is built
  into Python objects: nesting deeper than ``MAX_DEPTH`` or a document whose aliases expand to
  more than ``MAX_VALUES`` values (a "billion laughs": 9 aliases of 9 aliases, nine levels
  deep, is 387 million strings) is refused, so that neither the loader's recursion nor a
  later walk, copy or message of the expanded document can run away.
* A name that becomes one component of a file or an HDF5 path (a run's ``--name``, a sweep's
  ``name``) holds no ``/``, is not ``.`` or ``..`` and has no control characters: it can neither
  leave its folder or group nor reach another (``--name /reference`` would be the file's root
  group ``/reference``).
"""

from __future__ import annotations

import os
import stat
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from fccgrb_cli.core.errors import InputError

MAX_TEXT = 16 << 20      # bytes: a model, sweep config, label map or normative CSV
MAX_DEPTH = 64           # nested YAML collections
MAX_VALUES = 1_000_000   # YAML values after alias expansion
MAX_NAME = 200           # characters of a run or sweep name
KINDS = {stat.S_IFIFO: "a FIFO", stat.S_IFCHR: "a character device", stat.S_IFBLK:
         "a block device", stat.S_IFSOCK: "a socket", stat.S_IFDIR: "a folder"}


def regular_file(path: str | Path, what: str) -> Path:
    """``path`` if it is (a link to) a regular file; else an InputError naming it and ``what``
    it should have been ('model file', 'trial file', …)."""
    path = Path(path)
    try:
        info = path.stat()
    except FileNotFoundError:
        broken = " (a link to nothing)" if path.is_symlink() else ""
        raise InputError(f"{path}: {what} not found{broken}") from None
    except OSError as error:
        raise InputError(f"{path}: cannot read the {what} ({error.strerror})") from None
    if stat.S_ISDIR(info.st_mode):
        raise InputError(f"{path}: expected a {what}, got a folder")
    if not stat.S_ISREG(info.st_mode):
        kind = KINDS.get(stat.S_IFMT(info.st_mode), "not a regular file")
        raise InputError(f"{path}: expected a {what} (a regular file), got {kind}")
    return path


def read_bytes(path: str | Path, what: str, limit: int = MAX_TEXT) -> bytes:
    """The whole file, at most ``limit`` bytes; opened without blocking and checked again once
    open (the path may have changed into a FIFO since it was looked at)."""
    path = regular_file(path, what)
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NONBLOCK)
    except OSError as error:
        raise InputError(f"{path}: cannot read the {what} ({error.strerror})") from None
    with os.fdopen(fd, "rb") as handle:
        info = os.fstat(handle.fileno())
        if not stat.S_ISREG(info.st_mode):
            raise InputError(f"{path}: expected a {what} (a regular file)")
        data = b"" if info.st_size > limit else handle.read(info.st_size + 1)
    if info.st_size > limit or len(data) > limit:
        raise InputError(f"{path}: expected a {what} of at most {limit >> 20} MiB, got a larger "
                         "file")
    return data


def decode(data: bytes, path: str | Path, what: str) -> str:
    """UTF-8 text (a leading byte-order mark dropped); a byte that is not UTF-8 is an InputError
    naming its line."""
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data[:error.start].count(b"\n") + 1
        raise InputError(f"{path}: line {line}: expected UTF-8 text in the {what}, got the byte "
                         f"{data[error.start]:#04x}") from None


def read_text(path: str | Path, what: str, limit: int = MAX_TEXT) -> str:
    """A text file read whole: regular, bounded, UTF-8."""
    return decode(read_bytes(path, what, limit), path, what)


def load_yaml(text: str, source: str, loader: type | None = None) -> Any:
    """The YAML document in ``text`` built by ``loader`` (libyaml's safe loader by default)
    once its depth and alias expansion are known to be bounded; an InputError naming
    ``source`` and the line otherwise."""
    import yaml

    loader = loader or getattr(yaml, "CSafeLoader", yaml.SafeLoader)
    try:
        _check_bounds(text, source, loader)
        return yaml.load(text, Loader=loader)
    except yaml.YAMLError as error:
        mark = getattr(error, "problem_mark", None)
        where = f"line {mark.line + 1}, column {mark.column + 1}: " if mark else ""
        problem = getattr(error, "problem", None) or str(error).splitlines()[0]
        raise InputError(f"{source}: {where}invalid YAML ({problem})") from None


def _check_bounds(text: str, source: str, loader: type) -> None:
    """Walk the parser's events: the nesting depth, and the number of values the document
    holds once every alias is replaced by what its anchor names (each anchor's expanded size
    is counted once, when its collection closes, so that the walk is linear in the text). An
    error names the line and the key path where the bound is passed (``name``,
    ``bodies.crank.points.A``, ``cells[0]``)."""
    import yaml

    sizes: dict[str, int] = {}
    open_: list[tuple[str | None, int]] = []
    keys = _KeyPath()
    total = 0
    for event in yaml.parse(text, Loader=loader):
        if isinstance(event, (yaml.ScalarEvent, yaml.AliasEvent, yaml.CollectionStartEvent)):
            keys.node(event)
        if isinstance(event, yaml.CollectionStartEvent):
            total += 1
            open_.append((event.anchor, total))
            keys.open(isinstance(event, yaml.MappingStartEvent))
            if len(open_) > MAX_DEPTH:
                raise InputError(f"{source}: line {event.start_mark.line + 1}: {keys}expected "
                                 f"YAML nested at most {MAX_DEPTH} levels deep")
        elif isinstance(event, yaml.CollectionEndEvent):
            anchor, start = open_.pop()
            keys.close()
            if anchor is not None:
                sizes[anchor] = total - start + 1
        elif isinstance(event, yaml.ScalarEvent):
            total += 1
            if event.anchor is not None:
                sizes[event.anchor] = 1
        elif isinstance(event, yaml.AliasEvent):
            total += sizes.get(event.anchor, 1)
        if total > MAX_VALUES:
            raise InputError(f"{source}: line {event.start_mark.line + 1}: {keys}expected a "
                             f"YAML document of at most {MAX_VALUES:,} values once its aliases "
                             "are expanded (aliases of aliases?)")


class _KeyPath:
    """Where the parser is in the document: the keys and list positions from the top."""

    def __init__(self) -> None:
        self.frames: list[list] = []  # [is_mapping, key or index, expecting a key]
        self.started = False

    def node(self, event) -> None:
        """A node begins (a key or a value of the innermost collection)."""
        import yaml

        if not self.frames:
            return
        frame = self.frames[-1]
        if not frame[0]:
            frame[1] += 1
        elif frame[2]:
            frame[1] = event.value if isinstance(event, yaml.ScalarEvent) else "?"
            frame[2] = False
        else:
            frame[2] = True

    def open(self, mapping: bool) -> None:
        self.frames.append([True, None, True] if mapping else [False, -1, False])

    def close(self) -> None:
        self.frames.pop()

    def __str__(self) -> str:
        text = ""
        for mapping, key, _ in self.frames:
            if mapping and key is not None:
                text += f".{key}" if text else str(key)
            elif not mapping and key >= 0:
                text += f"[{key}]"
        return f"{text}: " if text else ""


def shown(value: Any) -> str:
    """``repr(value)`` cut to one short line (a value from a file can be a list of a million
    elements, or a text of a megabyte)."""
    import reprlib

    brief = reprlib.Repr()
    brief.maxstring, brief.maxother, brief.maxlist, brief.maxdict, brief.maxlevel = \
        60, 60, 6, 4, 3
    return brief.repr(value)


def check_name(value: Any, what: str) -> str:
    """``value`` if it can be one component of a file or HDF5 path; else an InputError naming
    ``what`` ('--name', 'sweep.yaml: name')."""
    problem = None
    if not isinstance(value, str) or not value.strip():
        problem = "a non-empty name"
    elif "/" in value or "\\" in value:
        problem = "a name without '/' or '\\' (it names one file or HDF5 group)"
    elif not value.strip("."):  # '.', '..', and '....', which Windows reads as ''
        problem = "a name other than dots alone ('.', '..')"
    elif value != value.strip() or any(ord(c) < 32 or ord(c) == 127 for c in value):
        problem = "a name without leading or trailing blanks or control characters"
    elif len(value) > MAX_NAME:
        problem = f"a name of at most {MAX_NAME} characters"
    if problem is not None:
        raise InputError(f"{what}: expected {problem}, got {shown(value)}")
    return value


def same_file(a: str | Path, b: str | Path) -> bool:
    """Whether two paths name one file: the same path once links and '..' are resolved, or
    (hard links) the same file on disk."""
    a, b = Path(a), Path(b)
    if a.resolve() == b.resolve():
        return True
    try:
        return os.path.samefile(a, b)
    except OSError:
        return False


def refuse_inputs(output: str | Path, inputs: Sequence[str | Path | None], option: str = ""
                  ) -> None:
    """An InputError when ``output`` is one of the command's ``inputs`` (inputs are never
    modified); an input not given (None) is skipped."""
    for given in inputs:
        if given is not None and same_file(output, given):
            name = f"{option} " if option else ""
            raise InputError(f"{output}: expected {name}an output other than the command's "
                             f"input {given} (inputs are never modified)")
