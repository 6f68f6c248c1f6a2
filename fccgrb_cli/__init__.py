"""fccgrb: FCC-GRB multibody kinematics and inverse dynamics with mixed coordinates.

Gonçalves, Roupa, Flores, Tavares da Silva, Mechanism and Machine Theory 214 (2025) 106080.

The public Python API (see docs/api.md), importable from the package itself::

    import fccgrb_cli as fc
    run = fc.solve(fc.load_model("model.yaml"), fc.read_trial("trial.c3d"), method="cno-sqp")

Everything else is internal and may change; the names below are public and versioned with the
results file's format (``RESULTS_FORMAT``).
"""

import os

# The per-frame matrices are small (tens of rows): a multi-threaded BLAS spends more time waking
# threads than computing. One thread unless the user chose otherwise (set before numpy loads).
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

__version__ = "0.2.0"
__all__ = ["RESULTS_FORMAT", "InputError", "NamedArray", "Run", "SolveOptions", "calibrate",
           "load_model", "read_results", "read_trial", "solve", "write_results"]

# Loaded on first use, so that `fccgrb --help` and `import fccgrb_cli` stay fast.
_PUBLIC = {**dict.fromkeys(("load_model", "read_trial", "solve", "calibrate", "read_results",
                            "write_results"),
                           "fccgrb_cli.api"),
           "SolveOptions": "fccgrb_cli.pipeline.options", "Run": "fccgrb_cli.pipeline.run",
           "NamedArray": "fccgrb_cli.core.named", "InputError": "fccgrb_cli.core.errors"}


def __getattr__(name: str):
    if name == "RESULTS_FORMAT":
        from fccgrb_cli.results.format import FORMAT_VERSION

        return FORMAT_VERSION
    if name in _PUBLIC:
        import importlib

        return getattr(importlib.import_module(_PUBLIC[name]), name)
    raise AttributeError(f"module 'fccgrb_cli' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted([*globals(), *__all__])
