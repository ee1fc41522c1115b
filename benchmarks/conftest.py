"""Benchmarks are run explicitly: python3 -m pytest benchmarks/ --benchmark-only (see README)."""
