"""One BLAS thread for the solvers: their matrices have tens of rows, and a multi-threaded BLAS
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
from typing import TypeVar

F = TypeVar("F", bound=Callable)


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
