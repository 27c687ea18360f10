"""User-facing errors: one line, no traceback, exit code 2 from the CLI."""


class FogmonError(Exception):
    """A user mistake or bad input. The message is one line naming what was wrong
    (file, line, field where known); the CLI prints it and exits with code 2."""


class FogmonWarning(UserWarning):
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
