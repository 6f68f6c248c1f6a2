"""Which engine a solve's per-frame arithmetic runs in: the compiled kernels (numba) or numpy."""

from __future__ import annotations

from fccgrb_cli.errors import InputError

NRM_COMPILED_FROM = 1000  # frames from which 'auto' takes the compiled NRM (use_kernels)


def use_kernels(engine: str, takes: bool, n_frames: int, threshold: int = NRM_COMPILED_FROM
                ) -> bool:
    """Whether a solve runs in the compiled kernels, ``takes`` saying whether they take the
    model (no reduced body). 'compiled' insists (one-line errors where they cannot); 'auto'
    takes them for trials of ``threshold`` frames or more: loading numba and the cached machine
    code costs ~0.25 s once per process, about what the numpy path spends on 500–700 five-bar
    frames. The choice depends on the trial and the model only, never on what the process
    loaded before, so that a CLI run, a sweep cell and an API call give the same bits."""
    if engine == "numpy":
        return False
    if engine == "compiled":
        if not takes:
            raise InputError("--engine compiled: the compiled kernels take models without "
                             "reduced bodies (form: full); use --engine numpy or auto")
        if not numba_available():
            raise InputError("--engine compiled needs numba (pip install numba)")
        return True
    return takes and n_frames >= threshold and numba_available()


def numba_available() -> bool:
    from importlib.util import find_spec

    return find_spec("numba") is not None
