"""Benchmarks: ``python -m bench.run`` (``make bench``) writes bench/results.json."""

import service  # noqa: F401  (caps the BLAS thread pools before numpy loads, as the service does)
