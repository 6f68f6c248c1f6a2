"""The kinematic analysis with angular drivers (AD, docs/formulation.md §3): its solve (numpy,
batched and compiled), and the classical baseline that computes the drivers from the markers."""
