"""Trials in (C3D, TRC), results out (C3D, HDF5); every write is atomic."""
