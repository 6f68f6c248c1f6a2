"""Gait analysis of a solved walking trial: events, normalized cycles, spatiotemporal parameters."""
