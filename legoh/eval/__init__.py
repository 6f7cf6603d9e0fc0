"""Benchmark evaluation: the paper's metrics over episode records, and their tables."""
