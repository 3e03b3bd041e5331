"""wxsky: a flight-simulator weather and cloud daemon."""

__version__ = "0.1.0"
