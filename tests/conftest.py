"""Hypothesis profiles for the property-based tests (tests/test_generated.py).

``ci`` (the default): derandomized (a fixed seed: every run draws the same cases), no
deadline (solver times vary on a shared machine), no example database written into the tree;
the generated tests scale their own example counts from ``max_examples`` so that they run in
about a minute on two cores. ``long`` (``pytest --hypothesis-profile long``): random seeds,
ten times the examples, for local runs.
"""

from hypothesis import HealthCheck, settings

SLOW = [HealthCheck.too_slow, HealthCheck.data_too_large]

settings.register_profile("ci", derandomize=True, deadline=None, max_examples=25,
                          database=None, suppress_health_check=SLOW, print_blob=True)
settings.register_profile("long", deadline=None, max_examples=250,
                          suppress_health_check=SLOW, print_blob=True)
settings.load_profile("ci")
