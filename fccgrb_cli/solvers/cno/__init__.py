"""Constrained nonlinear optimization (CNO, docs/formulation.md §3): the paper's reference per frame
(scipy) and the structured stabilized SQP / interior point."""
