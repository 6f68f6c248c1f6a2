"""Vicon's Plug-in Gait (the Conventional Gait Model): its segments from markers, its static
calibration, and its output angles, moments and powers from a solved motion."""
