"""Signals over a trial's frames: the Butterworth low-pass filter and the soft-tissue artefact."""
