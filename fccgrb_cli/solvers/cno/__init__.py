"""Constrained nonlinear optimization (CNO, FORMULATION §3): the paper's reference per frame
(scipy) and the structured stabilized SQP / interior point."""
