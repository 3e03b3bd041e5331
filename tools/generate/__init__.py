"""Generators of files the repository ships: package data, the DBC, the station table, goldens."""
