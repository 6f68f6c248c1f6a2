"""BLAS and LAPACK for the solvers.

One BLAS thread: their matrices have tens of rows, and a multi-threaded BLAS
spends more time waking its threads than computing (measured 3× slower on 2 cores). The
package sets OPENBLAS_NUM_THREADS at import, which only works before numpy loads; threadpoolctl
limits the already loaded library, whatever the import order.

Finding the loaded libraries costs ~0.3 ms (threadpoolctl reads the process's shared objects),
so it is done once, at the first solve: a BLAS loaded later (scipy's own, say) was loaded after
the package set OPENBLAS_NUM_THREADS and starts with one thread anyway (unless the user set the
variable to more, which that library then keeps)."""

from __future__ import annotations

import functools
from collections.abc import Callable
from pathlib import Path
from types import ModuleType
from typing import TypeVar

F = TypeVar("F", bound=Callable)


def _scipy_lapack() -> ModuleType:
    """scipy's LAPACK wrappers (``scipy.linalg.lapack``'s functions: dposv, dpotrf, ...) from
    their compiled module, loaded from its file without importing the ``scipy.linalg`` package:
    that import costs ~0.1 s of every solve's start-up (its array-API layer touches every numpy
    submodule, f2py and testing included), the module itself ~3 ms. Where scipy's layout is
    not the expected one, the ordinary import."""
    from importlib.machinery import EXTENSION_SUFFIXES, ExtensionFileLoader
    from importlib.util import find_spec, module_from_spec, spec_from_file_location

    name = "scipy.linalg._flapack"
    scipy = find_spec("scipy")
    folder = Path(scipy.origin).parent / "linalg" if scipy and scipy.origin else None
    for suffix in EXTENSION_SUFFIXES if folder else ():
        assert folder is not None  # no suffixes are tried without it
        path = folder / f"_flapack{suffix}"
        if path.is_file():
            spec = spec_from_file_location(name, path, loader=ExtensionFileLoader(name,
                                                                                  str(path)))
            if spec is not None:
                module = module_from_spec(spec)
                assert spec.loader is not None  # the one given to spec_from_file_location
                spec.loader.exec_module(module)
                return module
    from scipy.linalg import lapack as ordinary

    return ordinary


lapack = _scipy_lapack()


def cython_modules_for_numba() -> tuple[str, ...]:
    """Put scipy's Cython BLAS and LAPACK (``scipy.linalg.cython_blas``, ``cython_lapack``) in
    ``sys.modules``, each loaded from its compiled file without the ``scipy.linalg`` package,
    unless that package or numba's array functions are loaded already (or numba is not
    installed); the names it put there.

    numba imports those two modules when it loads its first kernel (``numba.np.arraymath``
    checks that a BLAS is there; its compiled code takes the routines' addresses from the
    modules' ``__pyx_capi__``). Through the package that import costs ~0.3 s of every solve's
    start-up (the package's array-API layer, see ``_scipy_lapack``); the modules alone ~10 ms,
    the ``scipy`` package's own ``__init__`` ~25 ms. They are the package's own files, so the
    kernels call the same routines; ``scipy.linalg`` imported later finds them in
    ``sys.modules`` (``import scipy.linalg.cython_blas as blas`` and ``from scipy.linalg
    import cython_blas`` give them; the package's attribute ``scipy.linalg.cython_blas`` is
    not set, even after ``import scipy.linalg.cython_blas``). Where scipy's layout is not the
    expected one, nothing is put there and numba imports the package as usual."""
    import sys
    from importlib.machinery import EXTENSION_SUFFIXES, ExtensionFileLoader
    from importlib.util import find_spec, module_from_spec, spec_from_file_location

    if "scipy.linalg" in sys.modules or "numba.np.arraymath" in sys.modules or \
            find_spec("numba") is None:
        return ()
    scipy = find_spec("scipy")
    if not scipy or not scipy.origin:
        return ()
    folder = Path(scipy.origin).parent / "linalg"
    found = {}
    for short in ("cython_blas", "cython_lapack"):
        name = f"scipy.linalg.{short}"
        path = next((folder / f"{short}{suffix}" for suffix in EXTENSION_SUFFIXES
                     if (folder / f"{short}{suffix}").is_file()), None)
        spec = None if path is None else spec_from_file_location(
            name, path, loader=ExtensionFileLoader(name, str(path)))
        if spec is None or name in sys.modules:
            return ()
        found[name] = spec
    done: list[str] = []
    for name, spec in found.items():
        module = module_from_spec(spec)
        sys.modules[name] = module
        assert spec.loader is not None  # the one given to spec_from_file_location
        try:
            spec.loader.exec_module(module)
        except Exception:  # as if never tried: numba's own import then says what is wrong
            for put in (*done, name):
                del sys.modules[put]
            return ()
        done.append(name)
    return tuple(done)


@functools.cache
def _controller():
    from threadpoolctl import ThreadpoolController

    return ThreadpoolController()


def single_threaded(function: F) -> F:
    """Run ``function`` with BLAS limited to one thread (restored afterwards)."""

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with _controller().limit(limits=1, user_api="blas"):
            return function(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def limit_this_process() -> None:
    """One BLAS thread for the rest of this process (a pool worker's initializer)."""
    _controller().limit(limits=1, user_api="blas")
