"""Suggestions for misspelt names (plugins, fields, joints, metrics)."""

from __future__ import annotations

from collections.abc import Iterable


def nearest(name: str, candidates: Iterable[str]) -> str:
    """``"did you mean 'x'?"`` for the closest candidates, or the list of choices ("" where there are none): the fix
    of a misspelt name, as an error's ``fix`` field holds it."""
    import difflib  # (asked for only when a name is wrong: not imported with every run)

    candidates = sorted(candidates)
    close = difflib.get_close_matches(name, candidates, n=3, cutoff=0.5)
    if close:
        return "did you mean " + " or ".join(f"'{c}'" for c in close) + "?"
    return f"choices: {', '.join(candidates)}" if candidates else ""


def suggest(name: str, candidates: Iterable[str]) -> str:
    """``"; did you mean 'x'?"`` for the closest candidates, or the list of choices: :func:`nearest` said after a
    message."""
    fix = nearest(name, candidates)
    return f"; {fix}" if fix else ""
