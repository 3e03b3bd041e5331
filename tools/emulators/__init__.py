"""Emulators: a CIGI host, cockpit hardware and capture replay that drive wxsky from outside."""
