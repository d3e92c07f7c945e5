"""Exact and reference solutions the benchmarks are checked against."""
