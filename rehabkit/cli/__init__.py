"""The ``rehabkit`` command line: one module per command, the exit codes in :mod:`rehabkit.cli.exits`."""

from rehabkit.cli.main import entry, main, parser

__all__ = ["entry", "main", "parser"]
