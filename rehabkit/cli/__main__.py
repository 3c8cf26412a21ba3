"""``python -m rehabkit.cli``: the same as the ``rehabkit`` command."""

from rehabkit.cli.main import entry

entry()
