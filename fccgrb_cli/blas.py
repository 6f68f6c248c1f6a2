"""One BLAS thread for the solvers: their matrices have tens of rows, and a multi-threaded BLAS
spends more time waking its threads than computing (measured 3× slower on 2 cores). The
package sets OPENBLAS_NUM_THREADS at import, which only works before numpy loads; threadpoolctl
limits the already loaded library, whatever the import order."""

from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TypeVar

from threadpoolctl import threadpool_limits

F = TypeVar("F", bound=Callable)


def single_threaded(function: F) -> F:
    """Run ``function`` with BLAS limited to one thread (restored afterwards)."""

    @functools.wraps(function)
    def wrapper(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return function(*args, **kwargs)

    return wrapper  # type: ignore[return-value]


def limit_this_process() -> None:
    """One BLAS thread for the rest of this process (a pool worker's initializer)."""
    threadpool_limits(limits=1, user_api="blas")
