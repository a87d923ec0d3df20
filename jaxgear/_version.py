"""The package version (one place; written into every saved result)."""

__version__ = "0.2.0"
