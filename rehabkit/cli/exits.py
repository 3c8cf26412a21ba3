"""The command line's exit codes, the same for every command, and the output folder's check that decides an exit 2
before anything runs."""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

EXIT_OK = 0  # done; every expectation met
EXIT_FAILED = 1  # ran, and an expectation failed, a safety stop happened, a log was tampered with, a run failed
EXIT_INVALID = 2  # bad input, said where: nothing was run
EXIT_INTERRUPTED = 130  # Ctrl-C (128 + SIGINT, as shells report it)


@dataclass(frozen=True)
class Refusal:
    """A command's own refusal of its input (exit 2, nothing run) that no error class carries, as fields: ``code``
    why (``out-unwritable``, ``out-killed-run``, ``bag-needs-scenario``, ``listen-needs-key``, …), ``option`` the
    option refused (``--out``, ``--scenario``, ``--listen``), ``message`` what it said on standard error."""

    code: str
    option: str
    message: str


# the last such refusal of a command run in this process (``rehabkit.cli.main`` clears it as a command starts): what
# a caller running the command line in-process reads, rather than parsing its message
last_refusal: Refusal | None = None


def refuse(message: str, code: str, option: str = "") -> int:
    """Say ``message`` on standard error, keep it as :data:`last_refusal` with its ``code`` and ``option``, and
    return the exit code of a refusal (2)."""
    global last_refusal
    last_refusal = Refusal(code, option, message)
    print(message, file=sys.stderr)
    return EXIT_INVALID


def unwritable(out: Path) -> str | None:
    """Why the run could not write its outputs to ``out``, found before anything runs (or ``None``)."""
    import tempfile

    try:
        out.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=out):
            pass
    except OSError as exc:
        return f"error: --out {out}: cannot write there ({exc.strerror or exc}); choose another directory"
    return None
