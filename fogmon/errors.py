"""User-facing errors: one line, no traceback, exit code 2 from the CLI.

A message names a parameter by its Python name in backticks: ``FogmonError("`sample_rate_hz`
must be > 0, got 0")``. ``str(err)`` shows the name plainly (what an API user passed);
``err.render(flags)`` shows it as the command-line flag the table ``flags`` gives
(``{"sample_rate_hz": "--rate-hz"}``: what ``fogmon`` prints, fogmon.cli)."""
from __future__ import annotations

import re
from collections.abc import Mapping

#: a parameter name in a message: a Python identifier in backticks
NAME = re.compile(r"(?<!`)`([A-Za-z_][A-Za-z0-9_]*)`(?!`)")


def render_names(text: str, flags: Mapping[str, str] | None = None) -> str:
    """``text`` with every backticked parameter name replaced by its flag in ``flags``
    (name -> flag), or by the plain name when ``flags`` is None or has no such name."""
    table = flags or {}
    return NAME.sub(lambda m: table.get(m.group(1), m.group(1)), text)


class _Names:
    """What FogmonError and FogmonWarning share: a message naming parameters in
    backticks (``message``), shown plainly by ``str`` and as flags by ``render``."""

    @property
    def message(self) -> str:
        """The message as raised, parameter names in backticks (to pass on in another
        message, so that it can still be rendered)."""
        return Exception.__str__(self)  # type: ignore[arg-type]  # only mixed into Exceptions

    def __str__(self) -> str:
        return render_names(self.message)

    def render(self, flags: Mapping[str, str] | None) -> str:
        """The message with each parameter name as its flag in ``flags`` (name -> flag)."""
        return render_names(self.message, flags)


class FogmonError(_Names, Exception):
    """A user mistake or bad input. The message is one line naming what was wrong
    (file, line, field where known; parameters as `name`); the CLI prints it and exits
    with code 2."""


class FogmonWarning(_Names, UserWarning):
    """Something the user asked for was not done in full (e.g. taus that cannot be
    computed); the CLI prints it as one line ``fogmon COMMAND: warning: ...``."""


#: Error counters of the sources (decoders, readers) that are reported as events as they
#: grow: counter -> (event kind, what it counts). Every source keeps these counts exact;
#: the events are rate-limited (fogmon.sources.grid.ErrorEvents: one per kind per block).
ERROR_COUNTERS = {
    "crc_errors": ("crc_error", "frame(s) failed the CRC"),
    "bad_lines": ("bad_input", "line(s) could not be parsed"),
    "bad_frames": ("bad_input", "CAN frame(s) of the gyro's message could not be decoded"),
    "implausible_samples": ("implausible", "sample(s) with an implausible rate (beyond the device's range or "
                                           "--max-rate-dph, or not a number) made invalid"),
    "implausible_temp_c": ("implausible", "temperature reading(s) outside the plausible range set to NaN"),
    "implausible_accel_g": ("implausible", "acceleration reading(s) beyond any KVH accelerometer's range set to "
                                           "NaN"),
}
