"""Benchmarks and measurements: the figures docs/performance.md and the other docs quote."""
