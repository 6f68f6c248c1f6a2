"""Multi-objective goal attainment (MO-TC / MO-ED, docs/formulation.md §3): the paper's reference
per frame (scipy's SLSQP) and the structured active-set SQP, in numpy and compiled."""
