"""The kinematic analysis with angular drivers (AD, FORMULATION §2): its solve (numpy, batched
and compiled), and the classical baseline that computes the drivers from the markers."""
