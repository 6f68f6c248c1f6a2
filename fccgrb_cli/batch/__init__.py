"""Many solves: resumable cells, the paper's sweeps and gait studies."""
