"""``python -m rehabkit``: the ``rehabkit`` command (where no console script is on the PATH, e.g. a virtual
environment that sees a system-wide rehabkit)."""

from rehabkit.cli.main import entry

entry()
