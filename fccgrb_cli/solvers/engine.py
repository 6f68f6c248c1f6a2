"""Which engine a solve's per-frame arithmetic runs in: the compiled kernels (numba) or numpy."""

from __future__ import annotations

import functools
from typing import ClassVar

from fccgrb_cli.core.errors import InputError


def use_kernels(engine: str, takes: bool) -> bool:
    """Whether a solve runs in the compiled kernels, ``takes`` saying whether they take the
    model (no reduced body). 'compiled' insists (one-line errors where they cannot); 'auto'
    takes them wherever they take the model and numba is installed, whatever the trial's
    length: per frame they are 3–5× faster than numpy, and loading them (numba and its cached
    machine code, ~0.3 s once per process) is reported apart (:class:`KernelClock`). The choice
    depends on the model and the installation only, never on the trial, the machine's cache or
    what the process loaded before, so that a CLI run, a sweep cell and an API call give the
    same bits (the engines agree to 1e-12, not bit for bit: ``engine='numpy'`` is the numpy
    reference)."""
    if engine == "numpy":
        return False
    if engine == "compiled":
        if not takes:
            raise InputError("--engine compiled: the compiled kernels take models without "
                             "reduced bodies (form: full) or moving joints (an imported "
                             "OpenSim model); use --engine numpy or auto")
        if not numba_available():
            raise InputError("--engine compiled needs numba (pip install numba)")
        return True
    return takes and numba_available()


def numba_available() -> bool:
    from importlib.util import find_spec

    return find_spec("numba") is not None


# --- loading the kernels: apart from the timed per-frame work ---------------------------------
NOTICE_AFTER = 2.0  # s: loading a kernel from numba's cache takes ~0.1–0.3 s; longer: compiling
REPORT_EVERY = 10.0  # s between the lines that say compiling goes on


class KernelClock:
    """The seconds this process spent loading (or compiling) compiled kernels, which no
    ms/frame includes: :func:`ready` adds to it, ``fccgrb solve`` reports it apart."""

    seconds = 0.0
    told = False  # whether the compile notice was printed
    compiled: ClassVar[list[str]] = []  # kernels this process compiled (not in numba's cache)

    @classmethod
    def take(cls) -> tuple[float, list[str]]:
        """The seconds and the compiled kernels since the last call, then zero."""
        out = cls.seconds, list(cls.compiled)
        cls.seconds, cls.compiled = 0.0, []
        return out


def ready(kernel, *args) -> float:
    """Load (or, the first time after an install, compile) ``kernel`` for the types of
    ``args``, a call that does no work (an empty block of frames), before the caller's clock
    starts; while numba compiles, a line on stderr says so and how long it has taken. Returns
    the seconds it took. Loads take the light path (:func:`light_loads`)."""
    import sys
    import threading
    import time

    started = time.perf_counter()
    light_loads()
    done = threading.Event()

    def tell() -> None:
        if done.wait(NOTICE_AFTER):
            return
        if not KernelClock.told:  # the notice once per process; progress for each kernel
            KernelClock.told = True
            sys.stderr.write("fccgrb: compiling the compiled kernels for this machine, once "
                             "per install (about a minute; 'fccgrb compile' does it ahead of "
                             "time)\n")
        while not done.wait(REPORT_EVERY):
            sys.stderr.write(f"fccgrb: compiling … {time.perf_counter() - started:.0f} s\n")
        sys.stderr.flush()

    watcher = threading.Thread(target=tell, daemon=True)
    watcher.start()
    try:
        kernel(*args)
    finally:
        done.set()
        watcher.join()
    seconds = time.perf_counter() - started
    KernelClock.seconds += seconds
    name = f"{kernel.__module__}.{kernel.__name__}"
    if sum(kernel.stats.cache_misses.values()) and name not in _COMPILED:
        _COMPILED.add(name)
        KernelClock.compiled.append(name)
    return seconds


_COMPILED: set[str] = set()


@functools.cache
def light_loads() -> bool:
    """Load this package's cached kernels without numba's full context refresh; whether the
    light path is in place.

    Before it loads a cached kernel, numba refreshes its whole target context: it imports some
    forty of its own modules and installs every typing and lowering registry, ~0.15–0.3 s of
    every command, which compiling needs and loading does not. Loading machine code needs the
    runtime (NRT) initialized and the symbols numba installs when its context is created (its C
    helpers, the math library). So for a kernel of this package (``fccgrb_cli.*``) the cache
    loads after ``rtsys.initialize`` alone; anything else (a user's own cached functions)
    loads as numba does, and a compile (a cache miss) refreshes the context itself (numba's
    compiler does). The kernels use arrays, tuples and math only: none needs the symbols of
    the registries' modules (string hashing, parallel loops), which a test checks by running
    every compiled path after a light load in a fresh process. Where numba's cache is not laid
    out as expected (another numba version), nothing changes."""
    from numba.core import caching
    from numba.core.runtime import rtsys

    cache = caching.Cache
    full = cache.load_overload
    if getattr(full, "light", False):
        return True
    if not (hasattr(cache, "_load_overload")
            and hasattr(cache, "_guard_against_spurious_io_errors")):
        return False

    def load_overload(self, sig, target_context):
        function = getattr(self, "_py_func", None)
        if not getattr(function, "__module__", "").startswith("fccgrb_cli."):
            return full(self, sig, target_context)
        rtsys.initialize(target_context)
        with self._guard_against_spurious_io_errors():
            return self._load_overload(sig, target_context)
        return None  # the guard swallowed an I/O error: not in the cache

    load_overload.light = True  # type: ignore[attr-defined]
    cache.load_overload = load_overload  # type: ignore[method-assign]  # numba's own class
    return True
