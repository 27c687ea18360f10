"""User-facing errors: one line, no traceback, exit code 2 from the CLI."""


class FogmonError(Exception):
    """A user mistake or bad input. The message is one line naming what was wrong
    (file, line, field where known); the CLI prints it and exits with code 2."""


class FogmonWarning(UserWarning):
    """Something the user asked for was not done in full (e.g. taus that cannot be
    computed); the CLI prints it as one line ``fogmon COMMAND: warning: ...``."""
