"""The protocol table: serial protocol names (docs/sources.md) -> incremental byte
decoders (``Codec``s), their default baud and sample rate. The one place that knows
which codec decodes which protocol; a new protocol is one entry in ``CODECS``."""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from fogmon.errors import FogmonError
from fogmon.formats.capture import DECODER_FIELDS
from fogmon.sources.base import Codec
from fogmon.sources.codecs import dsp3000, kvh, lines


@dataclass(frozen=True)
class Protocol:
    """One serial protocol: its default ``baud``, default ``sample_rate_hz`` (Hz) and
    ``make(sample_rate_hz, kvh_rot, kvh_units, axis, columns, max_rate_dph, kvh_accel)``,
    the codec (``make_codec`` fills in the defaults)."""

    baud: int
    sample_rate_hz: float
    make: Callable[[float, str | None, str, str | None, str, float | None, str], Codec]


def _kvh(fmt: str) -> Callable[[float, str | None, str, str | None, str, float | None, str], Codec]:
    def make(sample_rate_hz, kvh_rot, kvh_units, axis, columns, max_rate_dph, kvh_accel) -> Codec:
        return kvh.KvhCodec(fmt, kvh_rot or "delta", kvh_units, axis, sample_rate_hz, max_rate_dph, kvh_accel)
    return make


def _dsp3000(sample_rate_hz, kvh_rot, kvh_units, axis, columns, max_rate_dph, kvh_accel) -> Codec:
    return dsp3000.Dsp3000Codec(kvh_rot or "rate", sample_rate_hz, max_rate_dph)


def _lines(sample_rate_hz, kvh_rot, kvh_units, axis, columns, max_rate_dph, kvh_accel) -> Codec:
    return lines.LinesCodec(columns, sample_rate_hz, max_rate_dph, axis)


#: protocol name -> Protocol
CODECS: dict[str, Protocol] = {
    "kvh-a": Protocol(921600, kvh.DEFAULT_RATE_HZ, _kvh("a")),
    "kvh-b": Protocol(921600, kvh.DEFAULT_RATE_HZ, _kvh("b")),
    "kvh-c": Protocol(921600, kvh.DEFAULT_RATE_HZ, _kvh("c")),
    "dsp3000": Protocol(38400, dsp3000.DEFAULT_RATE_HZ, _dsp3000),
    "lines": Protocol(115200, lines.DEFAULT_RATE_HZ, _lines),
}
PROTOCOLS = tuple(CODECS)
#: the values a raw capture's sidecar may give the decoder options the codecs define
#: (fogmon.formats.capture.read_sidecar's ``choices``)
SIDECAR_CHOICES = {"protocol": PROTOCOLS, "kvh_accel": tuple(kvh.ACCEL_UNITS)}


def make_codec(protocol: str, sample_rate_hz: float | None = None, kvh_rot: str | None = None,
               kvh_units: str = "rad", axis: str | None = None, columns: str = "rate_dph",
               max_rate_dph: float | None = None, kvh_accel: str = "g") -> Codec:
    """A fresh decoder for ``protocol``; ``sample_rate_hz`` None takes the protocol default;
    ``kvh_rot`` None takes 'delta' for KVH binary and 'rate' for DSP-3000; ``axis`` (KVH)
    None decodes all three gyros (lines: every rate column), ``kvh_accel`` the accelerometers' output (kvh.ACCEL_UNITS);
    ``max_rate_dph`` (deg/h) None takes the device's gate (fogmon.sources.plausibility)."""
    if protocol not in CODECS:
        raise FogmonError(f"unknown protocol {protocol!r} (use one of {', '.join(PROTOCOLS)})")
    p = CODECS[protocol]
    sample_rate_hz = p.sample_rate_hz if sample_rate_hz is None else float(sample_rate_hz)
    return p.make(sample_rate_hz, kvh_rot, kvh_units, axis, columns, max_rate_dph, kvh_accel)


def codec_from_options(opts: dict) -> Codec:
    """Rebuild a decoder from its ``options()`` dict (raw-capture sidecar: the keys of
    fogmon.formats.capture.DECODER_FIELDS)."""
    o = dict(opts)
    return make_codec(o.pop("protocol"), **{k: v for k, v in o.items() if k in DECODER_FIELDS})
