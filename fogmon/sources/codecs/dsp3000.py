"""KVH DSP-3000 ASCII output: one line per sample, ``<value> <valid flag>`` such as
``"       0.015733   1\\r\\n"`` (38400 baud, ~100 Hz). The value is a rate in deg/s
(``rot='rate'``, the default) or an incremental angle in deg per sample
(``rot='delta'``); flag 1 = valid. No sequence counter: only outages are detected.
Rates beyond the DSP-3000's range x margin (fogmon.sources.plausibility) are invalid."""
from __future__ import annotations

import math

from fogmon.errors import FogmonError
from fogmon.sources import plausibility
from fogmon.sources.codecs.framing import LineFramer
from fogmon.sources.codecs.kvh import output_unit
from fogmon.sources.frames import Frames
from fogmon.sources.grid import check_sample_rate
from fogmon.units import to_dph

DEFAULT_RATE_HZ = 100.0


class Dsp3000Codec:
    """Incremental decoder. Counters: ``frames_ok`` (lines decoded), ``bad_lines``
    (lines that are not ``value flag``), ``bytes_skipped`` (bytes of bad lines),
    ``implausible_samples`` (lines flagged valid whose rate is beyond ``max_rate_dph``
    deg/h, None = the DSP-3000 range x margin: made invalid)."""

    seq_modulus: int | None = None
    protocol = "dsp3000"
    aux_names: tuple[str, ...] = ()
    axes: tuple[str, ...] = ()          # one axis

    def __init__(
        self, rot: str = "rate", sample_rate_hz: float = DEFAULT_RATE_HZ, max_rate_dph: float | None = None
    ) -> None:
        if rot not in ("rate", "delta"):
            raise FogmonError(f"`kvh_rot` must be rate or delta, got {rot!r}")
        sample_rate_hz = check_sample_rate(sample_rate_hz)
        self.rot, self.sample_rate_hz = rot, float(sample_rate_hz)
        self.max_rate_dph = plausibility.max_rate_dph(max_rate_dph, plausibility.KVH_DSP3000_MAX_ABS_DPH)
        self._framer = LineFramer(64)
        self.counters = {"frames_ok": 0, "bad_lines": 0, "bytes_skipped": 0, plausibility.COUNTER: 0}

    @property
    def pending(self) -> int:
        return self._framer.pending

    def options(self) -> dict:
        return {"protocol": self.protocol, "kvh_rot": self.rot, "sample_rate_hz": self.sample_rate_hz,
                "max_rate_dph": self.max_rate_dph}

    def describe(self) -> str:
        return f"KVH DSP-3000 ASCII ({'deg/s' if self.rot == 'rate' else 'deg per sample'}), {self.sample_rate_hz:g} Hz"

    def feed(self, data: bytes) -> Frames:
        fr = self._framer
        before = fr.dropped_bytes, fr.dropped_lines
        vals, valid = [], []
        bad = bad_bytes = 0
        for line in fr.feed(data):
            parts = line.split()
            try:
                if len(parts) != 2 or parts[1] not in (b"0", b"1"):
                    raise ValueError
                v = float(parts[0])
                if not math.isfinite(v):
                    raise ValueError
            except ValueError:
                if line.strip():          # blank lines (\r\n\r\n) are not errors
                    bad += 1
                bad_bytes += len(line)
                continue
            vals.append(v)
            valid.append(parts[1] == b"1")
        c = self.counters
        c["frames_ok"] += len(vals)
        c["bad_lines"] += bad + fr.dropped_lines - before[1]
        c["bytes_skipped"] += bad_bytes + fr.dropped_bytes - before[0]
        rate, n = plausibility.gate(
            to_dph(vals, output_unit(self.rot, "deg"), self.sample_rate_hz), self.max_rate_dph, valid
        )
        c[plausibility.COUNTER] += n
        return Frames.from_lists([-1] * len(vals), rate, valid)
