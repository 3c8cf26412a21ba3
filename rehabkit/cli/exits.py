"""The command line's exit codes, the same for every command."""

EXIT_OK = 0  # done; every expectation met
EXIT_FAILED = 1  # ran, and an expectation failed, a safety stop happened, a log was tampered with, a run failed
EXIT_INVALID = 2  # bad input, said where: nothing was run
EXIT_INTERRUPTED = 130  # Ctrl-C (128 + SIGINT, as shells report it)
