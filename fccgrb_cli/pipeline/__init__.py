"""One solve as named stages (``pipeline.solve``): options, perturbation, kinematic solve,
assessment, smoothing, inverse dynamics, residuals; the ``Run`` it returns; synthesis of trials
and ahead-of-time compilation."""
