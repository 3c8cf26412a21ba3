"""Scenario errors that point at a file, line and column."""

from __future__ import annotations

from dataclasses import dataclass

from rehabkit.core.kinds.errors import with_fix


@dataclass(frozen=True)
class Mark:
    """A place in a source: file, 1-based line and column."""

    file: str
    line: int
    col: int

    def __str__(self) -> str:
        return f"{self.file}:{self.line}:{self.col}" if self.line else self.file


@dataclass(frozen=True)
class Diagnostic:
    """One problem in a scenario: where (``mark``, the setting's ``path``), what is wrong (``message``) and, where
    there is one, how to put it right (``fix``: kept out of the message, so it is read as a field, not parsed out)."""

    mark: Mark
    path: str
    message: str
    fix: str = ""

    @property
    def text(self) -> str:
        """The message as a person reads it: its fix after it."""
        return with_fix(self.message, self.fix)

    def __str__(self) -> str:
        where = f"{self.path}: " if self.path else ""
        return f"{self.mark}: {where}{self.text}"


class ScenarioError(Exception):
    """A scenario that can't be loaded; carries every problem found, not just the first."""

    def __init__(self, diagnostics: list[Diagnostic]):
        self.diagnostics = diagnostics
        super().__init__("\n".join(str(d) for d in diagnostics))
