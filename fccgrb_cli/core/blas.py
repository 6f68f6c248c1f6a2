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
        path = folder / f"_flapack{suffix}"
        if path.is_file():
            spec = spec_from_file_location(name, path, loader=ExtensionFileLoader(name,
                                                                                  str(path)))
            if spec is not None:
                module = module_from_spec(spec)
                spec.loader.exec_module(module)
                return module
    from scipy.linalg import lapack as ordinary

    return ordinary


lapack = _scipy_lapack()


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
