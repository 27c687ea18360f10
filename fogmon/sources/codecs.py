"""Serial protocol names (docs/sources.md) -> incremental byte decoders."""
from __future__ import annotations

from fogmon.errors import FogmonError
from fogmon.sources import dsp3000, kvh, lines

PROTOCOLS = ("kvh-a", "kvh-b", "kvh-c", "dsp3000", "lines")
#: protocol -> (default baud, default sample rate Hz)
DEFAULTS = {"kvh-a": (921600, kvh.DEFAULT_RATE_HZ), "kvh-b": (921600, kvh.DEFAULT_RATE_HZ),
            "kvh-c": (921600, kvh.DEFAULT_RATE_HZ), "dsp3000": (38400, dsp3000.DEFAULT_RATE_HZ),
            "lines": (115200, lines.DEFAULT_RATE_HZ)}
#: the decoder options (names of make_codec's parameters and of the codecs' options()),
#: as a raw capture's sidecar records them so that its replay decodes and gates alike
OPTION_KEYS = ("protocol", "sample_rate_hz", "kvh_rot", "kvh_units", "axis", "columns", "max_rate_dph", "kvh_accel")


def make_codec(protocol: str, sample_rate_hz: float | None = None, kvh_rot: str | None = None,
               kvh_units: str = "rad", axis: str | None = None, columns: str = "rate_dph",
               max_rate_dph: float | None = None, kvh_accel: str = "g"):
    """A fresh decoder for ``protocol``; ``sample_rate_hz`` None takes the protocol default;
    ``kvh_rot`` None takes 'delta' for KVH binary and 'rate' for DSP-3000; ``axis`` (KVH)
    None decodes all three gyros (lines: every rate column), ``kvh_accel`` the accelerometers' output (kvh.ACCEL_UNITS);
    ``max_rate_dph`` (deg/h) None takes the device's gate (fogmon.sources.plausibility)."""
    if protocol not in PROTOCOLS:
        raise FogmonError(f"unknown protocol {protocol!r} (use one of {', '.join(PROTOCOLS)})")
    sample_rate_hz = DEFAULTS[protocol][1] if sample_rate_hz is None else float(sample_rate_hz)
    if protocol.startswith("kvh-"):
        return kvh.KvhCodec(protocol[-1], kvh_rot or "delta", kvh_units, axis, sample_rate_hz, max_rate_dph,
                            kvh_accel)
    if protocol == "dsp3000":
        return dsp3000.Dsp3000Codec(kvh_rot or "rate", sample_rate_hz, max_rate_dph)
    return lines.LinesCodec(columns, sample_rate_hz, max_rate_dph, axis)


def codec_from_options(opts: dict):
    """Rebuild a decoder from its ``options()`` dict (raw-capture sidecar)."""
    o = dict(opts)
    return make_codec(o.pop("protocol"), **{k: v for k, v in o.items() if k in OPTION_KEYS})
