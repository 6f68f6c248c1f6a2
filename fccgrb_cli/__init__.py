"""fccgrb: FCC-GRB multibody kinematics and inverse dynamics with mixed coordinates.

Gonçalves, Roupa, Flores, Tavares da Silva, Mechanism and Machine Theory 214 (2025) 106080.
"""

import os

# The per-frame matrices are small (tens of rows): a multi-threaded BLAS spends more time waking
# threads than computing. One thread unless the user chose otherwise (set before numpy loads).
for _variable in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_variable, "1")

__version__ = "0.1.0"
