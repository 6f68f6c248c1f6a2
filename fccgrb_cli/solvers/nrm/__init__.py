"""Mixed coordinates by Newton–Raphson on (weighted) least squares (NRM-LS / NRM-WLS,
docs/formulation.md §3.1): the numpy reference and the compiled engine."""
