"""The lowest layer: what every other layer uses and nothing of fccgrb's own above it — the one
error type, inputs read safely, numbers in range, atomic writes and locks, scratch files, progress,
BLAS threads and runs of frames."""
