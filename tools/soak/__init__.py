"""Soaks: a real daemon run for minutes under faults and bad input, and their helpers."""
