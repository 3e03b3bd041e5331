"""Fuzzing: the harness and one target per parser (docs/reliability.md)."""
