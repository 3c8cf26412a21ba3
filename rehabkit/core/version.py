"""The package version, for the core and the summary (a module of its own: nothing below it)."""

__version__ = "0.1.0"
