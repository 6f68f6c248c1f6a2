"""Results storage: runs written to and read from HDF5 (atomically), their gait, Plug-in Gait and
residual parts, and exports for other tools (OpenSim, CSV, C3D)."""
