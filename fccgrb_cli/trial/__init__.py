"""Trials in: markers and analogs (C3D, TRC), force plates, events, labels, virtual markers, a
synthesized trial's truth, and the subject's measurements (C3D PROCESSING, VSK)."""
