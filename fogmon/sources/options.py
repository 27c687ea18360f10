"""What the user asked of a source: device, decoder and gate options (None = not given,
so a raw capture's sidecar or the protocol's default applies). Built from the command
line by fogmon.cli.source_options, or by hand."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from fogmon.sources import plausibility


@dataclass(frozen=True)
class SourceOptions:
    """Options of fogmon.sources.open and its readers: ``serial``/``baud`` or ``can``/``interface``/
    ``can_bitrate`` (a live device), the serial decoder (``protocol``, ``sample_rate_hz`` Hz,
    ``kvh_rot``, ``kvh_units``, ``kvh_accel``, ``axis``, ``columns``; ``axis`` also picks the
    axes of a multi-axis replay log: a name or a comma list), the CAN decoder (``dbc``,
    ``can_message``, ``can_rate``, ``can_rate_unit``, ``can_temp``, ``can_counter``,
    ``can_valid``), the plausibility gate ``max_rate_dph`` (deg/h), for a replay log
    ``tolerate_bad_rows``, and for other recording formats (fogmon.sources.files: ROS bags,
    ULogs, MDF4, LAS) ``topic``, ``channel``, ``time_channel``, ``rate_unit``, and for MDF4
    ``accel_channels`` (accelerometer channels: a comma list, each ``CHANNEL`` (named x, y,
    z in order) or ``AXIS=CHANNEL``). Files whose
    samples carry time stamps (fogmon.sources.files.timing): ``resample_hz`` (block means
    on a coarser uniform grid, Hz) and ``force_rate`` (use ``sample_rate_hz``, a DBC cycle
    time or a replay log's stated rate although the stamps say otherwise)."""

    serial: str | None = None
    baud: int | None = None
    can: str | None = None
    interface: str = "socketcan"
    can_bitrate: int | None = None
    protocol: str | None = None
    sample_rate_hz: float | None = None
    kvh_rot: str | None = None
    kvh_units: str | None = None
    kvh_accel: str | None = None
    axis: str | None = None
    columns: str | None = None
    dbc: str | None = None
    can_message: str | None = None
    can_rate: str | None = None
    can_rate_unit: str | None = None
    can_temp: str | None = None
    can_counter: str | None = None
    can_valid: str | None = None
    max_rate_dph: float | None = None
    tolerate_bad_rows: bool = False
    topic: str | None = None
    channel: str | None = None
    time_channel: str | None = None
    rate_unit: str | None = None
    accel_channels: str | None = None
    resample_hz: float | None = None
    force_rate: bool = False

    def codec_options(self) -> dict[str, Any]:
        """Serial decoder options given (None = not given), as make_codec names them."""
        return {"protocol": self.protocol, "sample_rate_hz": self.sample_rate_hz, "kvh_rot": self.kvh_rot,
                "kvh_units": self.kvh_units, "kvh_accel": self.kvh_accel, "axis": self.axis, "columns": self.columns,
                "max_rate_dph": self.max_rate_dph}

    def can_options(self) -> dict[str, Any]:
        """CAN decoder options given (None = not given), as CanDecoder names them."""
        return {"message": self.can_message, "rate_signal": self.can_rate, "rate_unit": self.can_rate_unit,
                "temp_signal": self.can_temp, "counter_signal": self.can_counter, "valid_signal": self.can_valid,
                "sample_rate_hz": self.sample_rate_hz, "max_rate_dph": self.max_rate_dph}

    @property
    def file_gate_dph(self) -> float:
        """The plausibility gate (deg/h) of a recording read from a file without a
        device's range: ``max_rate_dph`` (checked: ``plausibility.max_rate_dph``), or the
        generic gate."""
        return plausibility.max_rate_dph(self.max_rate_dph, plausibility.GENERIC_MAX_ABS_DPH)

    def asks_decoding(self, axis: bool = True) -> bool:
        """Whether a decoder option other than the gate (and, with ``axis=False``, other
        than ``axis``) is given (an archive is then decoded again from its raw capture)."""
        given = {**self.codec_options(), **self.can_options(), "dbc": self.dbc}
        ignored = ("max_rate_dph",) if axis else ("max_rate_dph", "axis")
        return any(v is not None for k, v in given.items() if k not in ignored)
