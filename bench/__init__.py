"""Benchmarks: ``python -m bench.run`` (``make bench``) writes bench/results.json."""
