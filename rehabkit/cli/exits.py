"""The command line's exit codes, the same for every command, and the output folder's check that decides an exit 2
before anything runs."""

from __future__ import annotations

from pathlib import Path

EXIT_OK = 0  # done; every expectation met
EXIT_FAILED = 1  # ran, and an expectation failed, a safety stop happened, a log was tampered with, a run failed
EXIT_INVALID = 2  # bad input, said where: nothing was run
EXIT_INTERRUPTED = 130  # Ctrl-C (128 + SIGINT, as shells report it)


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
