"""Mixed coordinates by Newton–Raphson on (weighted) least squares (NRM-LS / NRM-WLS,
FORMULATION §3.1): the numpy reference and the compiled engine."""
